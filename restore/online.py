"""Training on degradations made on the fly (`udc-render train --degrade online --bank DIR`): no capture dataset
on disk; crops of clean linear images, each degraded through a panel drawn from a kernel bank at every step
(restore.degrade, on the training device).

Clean images (--data): a dataset folder's gt.exr files by split (the manifest's train and val items), or a
folder of linear RGB .exr files (searched recursively, sorted; all train, no validation), in units of the white
level at gain 1 (1.0 = full well), as gt.exr.

Streams (udc_render.streams: named, so no two share a generator, crop 0 included): the epoch's order is
stream(seed, 'online order', e).permutation of images × crops_per_image; crop k of epoch e (k in that order)
draws from stream(seed, 'online crop', e, k) the image, the panel (uniform over the bank's), the Bayer-safe
transform (one of the 8 flips and transposes, applied to the clean crop: a scene seen as transformed by the same
sensor), the crop's place (even rows and columns: it starts on an R site) and the noise seed of a torch
generator on the device.
The crop takes the panel's margin of scene around it; beyond the frame (gt.exr holds no more scene) the image is
mirrored. Input: the degraded crop's (DN − black) / (white − black) [4, c/2, c/2]; target: the clean crop × the
panel's brightness [3, c, c] (a drawn panel's exposure.brightness; 1 for a preset), the input made from the same
scaled crop. A panel's far field and haze come from the crop's whole clean frame (restore.degrade_wide.
WideSource: the image, its brightness and the crop's transform). With capture draws (--capture-draws,
restore.captures) the crop also draws its own sensor and exposure, brightness included, and its own defect
pixels and fixed-pattern noise (maps of the crop's size from its own seeds), instead of its panel's. A resumed
run sees the same crops, panels, captures and noise (they depend on (seed, epoch, k) alone); each epoch's draws
are recorded in online.jsonl.

Validation: each val image whole, through panel j mod N, its noise from the stream (seed, 'online val', j),
made once.

With workers > 0 on the CPU the crops are degraded in DataLoader worker processes, one CPU thread each, while the
training step runs: the same numbers (the draws fix every crop; a Degrader runs on one thread either way), the
degradation's time hidden where a core is free (benchmarks/bench_degrade.py --train). On a GPU, workers = 1
makes the next batches in a thread on a CUDA stream of its own (_ahead), the same numbers. workers None (the
default): 1, a worker process on the CPU (it starts each epoch, in ~0.05 s), a thread on a GPU.
"""
from __future__ import annotations

import hashlib
import json
import queue
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from restore.augment import ONLINE_WHY
from restore.captures import CaptureDraws, captured_panel, crop_capture, crop_values, load_capture_draws
from restore.data import DataError, dihedral, load_gt, read_manifest
from restore.degrade import Degrader, WideSource, normalised
from restore.tensors import per_crop, region, stream_seed
from udc_render.dataset.bank import Bank, read_bank
from udc_render.io.exr import read_exr
from udc_render.io.files import save_text
from udc_render.optics import fft_shape
from udc_render.streams import stream


@dataclass(frozen=True)
class CleanImage:
    """One clean image: where it came from and its pixels [3, H, W] float32 (H, W even)."""
    name: str
    pixels: np.ndarray


def _read_rgb(path: Path) -> np.ndarray:
    ch = read_exr(path)
    missing = [c for c in "RGB" if c not in ch]
    if missing:
        raise DataError(f"{path}: no {missing[0]} channel: expected a linear RGB OpenEXR image")
    return np.stack([ch[c] for c in "RGB"]).astype(np.float32)


def checked_image(name: str, rgb: np.ndarray) -> CleanImage:
    """A CleanImage of linear RGB [3, H, W], refused in one line unless finite and ≥ 0, cut to whole RGGB cells."""
    bad = np.count_nonzero(~np.isfinite(rgb)) + np.count_nonzero(rgb < 0)
    if bad:
        raise DataError(f"{name}: {bad} negative, NaN or infinite values: expected finite linear RGB ≥ 0")
    h, w = rgb.shape[1] // 2 * 2, rgb.shape[2] // 2 * 2  # whole RGGB cells
    return CleanImage(name, np.ascontiguousarray(rgb[:, :h, :w]))


def clean_images(data: Path, split: str) -> list[CleanImage]:
    """The clean images of `split` (module doc): a dataset folder's gt.exr, or every .exr under a plain folder
    (split 'train'; none for another split)."""
    data = Path(data)
    if (data / "manifest.jsonl").is_file():
        rows = [r for r in read_manifest(data) if r["split"] == split]
        return [checked_image(str(data / r["folder"] / "gt.exr"), load_gt(data / r["folder"])) for r in rows]
    if not data.is_dir():
        raise DataError(f"--data {data}: no such folder: expected a dataset folder or a folder of .exr images")
    if split != "train":
        return []
    paths = sorted(p for p in data.rglob("*") if p.suffix.lower() == ".exr")
    if not paths:
        raise DataError(f"--data {data}: no manifest.jsonl and no .exr image: expected a dataset folder "
                        "(`udc-render dataset`) or a folder of linear RGB .exr images")
    return [checked_image(str(p), _read_rgb(p)) for p in paths]


def images_fingerprint(data: Path) -> str:
    """sha256 of what the clean images are: a dataset's manifest, or a plain folder's files' paths and bytes."""
    data = Path(data)
    h = hashlib.sha256()
    if (data / "manifest.jsonl").is_file():
        h.update((data / "manifest.jsonl").read_bytes())
    else:
        for p in sorted(p for p in data.rglob("*") if p.suffix.lower() == ".exr"):
            h.update(str(p.relative_to(data)).encode())
            h.update(hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()[:16]


def panel_brightness(panel) -> float:
    """The scale of a panel's clean scene: a drawn panel's exposure.brightness, 1 for a preset (module doc)."""
    return float(panel.record.get("brightness", 1.0))


class OnlineBatches:
    """The training batches of the online degradation (module doc) on a device."""

    def __init__(self, images: list[CleanImage], bank: Bank, degrader: Degrader, crop_px: int, batch: int,
                 seed: int, crops_per_image: int = 1, workers: int | None = None,
                 captures: CaptureDraws | None = None):
        if not images:
            raise DataError("no clean images to train on: the split is empty")
        small = min(images, key=lambda im: min(im.pixels.shape[1:]))
        if crop_px > min(small.pixels.shape[1:]):
            raise DataError(f"--crop-px = {crop_px}: larger than the {small.pixels.shape[2]} × "
                            f"{small.pixels.shape[1]} px image {small.name}")
        self.images, self.bank, self.degrader = images, bank, degrader
        # the clean pixels where the degradation runs, moved once: a crop is then cut, turned and scaled there
        # (on a GPU, cutting crops on the CPU and sending them cost 6× the training step: bench_degrade --train)
        self.pixels = [torch.from_numpy(im.pixels).to(degrader.device) for im in images]
        self.crop_px, self.batch, self.seed, self.crops_per_image = crop_px, batch, seed, crops_per_image
        self.brightness = [panel_brightness(p) for p in bank.panels]
        self.captures = captures
        workers = 1 if workers is None else workers  # the default: one worker process (CPU) or thread (GPU)
        if workers > 1 and degrader.device.type != "cpu":
            raise DataError(f"--degrade-workers {workers}: on {degrader.device} the degradation runs in this process "
                            "(0) or in one thread on its own stream (1)")
        self.workers = workers
        if workers and degrader.device.type == "cpu":  # made once here: every epoch's forked workers inherit them
            shape = fft_shape((crop_px + 2 * degrader.margin_px,) * 2, 2 * degrader.margin_px + 1, degrader.margin_px)
            for i, p in enumerate(degrader.panels):
                p.spectra(shape)
                for frame in {im.pixels.shape[1:] for im in images}:
                    degrader.power_frame(i, frame)
            if degrader.wide is not None:  # each frame's coarse sums (the far field's and the haze's)
                degrader.wide.prepare([WideSource(i, px) for i, px in enumerate(self.pixels)])

    @property
    def count(self) -> int:
        """The clean images (as a dataset's PairBatches.count is its pairs)."""
        return len(self.images)

    @property
    def record(self) -> dict:
        """What train_summary.json records of the data: every transform, before the degradation."""
        return {"augment": {"modes": list(range(8)), "why": ONLINE_WHY}}

    @property
    def crops(self) -> int:
        """An epoch's crops: crops_per_image of each image."""
        return len(self.images) * self.crops_per_image

    def draw(self, epoch: int, k: int) -> dict:
        """Crop k of the epoch (module doc): image, panel, transform, origin (even), noise seed; with capture
        draws, its capture (restore.captures.crop_capture)."""
        rng = stream(self.seed, "online crop", epoch, k)
        image = int(rng.integers(len(self.images)))
        h, w = self.images[image].pixels.shape[1:]
        c = self.crop_px
        d = {"image": image, "panel": int(rng.integers(len(self.bank.panels))), "mode": int(rng.integers(8)),
             "y0": 2 * int(rng.integers((h - c) // 2 + 1)), "x0": 2 * int(rng.integers((w - c) // 2 + 1)),
             "noise_seed": int(rng.integers(2 ** 63 - 1))}
        if self.captures is not None:
            d["capture"] = crop_capture(self.captures, self.seed, epoch, k)
        return d

    def sample(self, d: dict) -> tuple[torch.Tensor, torch.Tensor]:
        """(input [4, c/2, c/2], target [3, c, c]) of draw d, on the device: samples of one draw."""
        x, y = self.samples([d])
        return x[0], y[0]

    def samples(self, draws: list[dict]) -> tuple[torch.Tensor, torch.Tensor]:
        """(inputs [B, 4, c/2, c/2], targets [B, 3, c, c]) of the draws, on the device, degraded as one batch
        (Degrader.degrade_batch: each crop's numbers those of its own degradation)."""
        m, c = self.degrader.margin_px, self.crop_px
        clean = torch.stack([dihedral(region(self.pixels[d["image"]], d["y0"] - m, d["x0"] - m, c + 2 * m, c + 2 * m),
                                      d["mode"]) for d in draws])
        panels = [self.bank.panels[d["panel"]] for d in draws]
        if self.captures is not None:
            panels = [captured_panel(p, d["capture"]) for p, d in zip(panels, draws)]
        brightness = [d["capture"].brightness if "capture" in d else self.brightness[d["panel"]] for d in draws]
        x = clean.mul_(per_crop(brightness, clean))  # the stacked crops are this batch's own: scaled in place
        gens = [torch.Generator(self.degrader.device).manual_seed(d["noise_seed"]) for d in draws]
        crops = [(self.pixels[d["image"]].shape[1:], (d["y0"], d["x0"])) for d in draws]
        sources = [WideSource(d["image"], self.pixels[d["image"]], b, d["mode"]) for d, b in zip(draws, brightness)]
        dn = self.degrader.degrade_batch(x, [d["panel"] for d in draws], crops, gens, captures=panels, sources=sources)
        return normalised(dn, panels).float(), x[:, :, m:m + c, m:m + c].float().contiguous()

    def epoch(self, epoch: int):
        """(the epoch's draws in order, an iterator of batches (x [B, 4, c/2, c/2], y [B, 3, c, c]) on the device)."""
        draws = self.epoch_draws(epoch)
        return draws, self.batches_of(draws)

    def epoch_draws(self, epoch: int) -> list[dict]:
        """The epoch's draws in its order (module doc)."""
        return [self.draw(epoch, int(k)) for k in stream(self.seed, "online order", epoch).permutation(self.crops)]

    def batches_of(self, draws: list[dict]):
        """An iterator of the batches of `draws` in their order, `batch` at a time, made where `workers` says (in
        this process, in worker processes, or in a thread on a GPU: the same numbers)."""
        def batches():
            for i in range(0, len(draws), self.batch):
                yield self.samples(draws[i:i + self.batch])
        if not self.workers:
            return batches()
        if self.degrader.device.type != "cpu":
            return _ahead(batches, self.degrader.device)
        return iter(torch.utils.data.DataLoader(_Crops(self, draws), batch_size=self.batch, num_workers=self.workers))


def _ahead(batches, device: torch.device, depth: int = 2):
    """The batches of `batches()` made `depth` ahead in a thread on a stream of its own (a GPU's), while the
    caller trains: torch leaves Python's lock while it launches work, so the two threads' launches overlap, and
    the caller's stream waits on each batch's event before using it. The same numbers: a crop depends on its
    draw alone."""
    side, done, out = torch.cuda.Stream(device), threading.Event(), queue.Queue(depth)
    side.wait_stream(torch.cuda.current_stream(device))  # the images and panels moved there before

    def put(item) -> bool:
        """Queue the item unless the caller has stopped (then False): never blocks past the caller."""
        while not done.is_set():
            try:
                out.put(item, timeout=0.1)
                return True
            except queue.Full:
                pass
        return False

    def make():
        try:
            with torch.cuda.stream(side):
                for x, y in batches():
                    ready = torch.cuda.Event()
                    ready.record(side)
                    if not put((x, y, ready)):
                        return
            put(None)
        except BaseException as e:  # raised again in the caller's thread
            put(e)
    thread = threading.Thread(target=make, daemon=True)
    thread.start()
    try:
        while (item := out.get()) is not None:
            if isinstance(item, BaseException):
                raise item
            x, y, ready = item
            main = torch.cuda.current_stream(device)
            main.wait_event(ready)
            x.record_stream(main)
            y.record_stream(main)
            yield x, y
    finally:
        done.set()
        thread.join()


class _Crops(torch.utils.data.Dataset):
    """An epoch's crops as a map-style dataset, degraded in DataLoader worker processes (one CPU thread each)."""

    def __init__(self, batches: OnlineBatches, draws: list[dict]):
        self.batches, self.draws = batches, draws

    def __len__(self):
        return len(self.draws)

    def __getitem__(self, i: int):
        return self.batches.sample(self.draws[i])


def validation_pairs(images: list[CleanImage], bank: Bank, degrader: Degrader, seed: int) -> list[tuple]:
    """[(packed input [4, H/2, W/2], target [3, H, W]) numpy] of each whole val image, through panel j mod N with
    the noise of (seed, 'val', j) (module doc)."""
    out, m = [], degrader.margin_px
    for j, im in enumerate(images):
        p = j % len(bank.panels)
        b = panel_brightness(bank.panels[p])
        h, w = im.pixels.shape[1:]
        x = region(torch.from_numpy(im.pixels), -m, -m, h + 2 * m, w + 2 * m) * b
        gen = torch.Generator(degrader.device).manual_seed(stream_seed(seed, "online val", j))
        source = WideSource(("val", j), torch.from_numpy(im.pixels).to(degrader.device), b)
        dn = degrader.degrade(x, p, (h, w), (0, 0), gen, source=source)
        out.append((normalised(dn, bank.panels[p]).float().cpu().numpy(), (im.pixels * b).astype(np.float32)))
    return out


def online_data(data: Path, bank_dir: Path, settings, device, workers: int | None = None
                ) -> tuple[OnlineBatches, list]:
    """(the training batches, the validation pairs) of the online degradation (module doc) for train settings
    with degrade = {"bank_fingerprint", "panels"}: the bank's panels on the device (float32), degraded in
    `workers` processes (CPU; 0: in this one)."""
    if bank_dir is None:
        raise DataError("the online degradation needs a kernel bank (--bank DIR, written by `udc-render bank`)")
    d = settings.degrade
    bank = read_bank(bank_dir, d["panels"])
    if bank.fingerprint != d["bank_fingerprint"]:
        raise DataError(f"--bank {bank_dir}: its bank.json (sha {bank.fingerprint}) is not the run's "
                        f"({d['bank_fingerprint']})")
    degrader = Degrader(bank.panels, device, torch.float32)
    batches = OnlineBatches(clean_images(data, "train"), bank, degrader, settings.crop_px, settings.batch,
                            settings.seed, settings.crops_per_pair, workers, run_captures(d, bank))
    return batches, validation_pairs(clean_images(data, "val"), bank, degrader, settings.seed)


def run_captures(degrade: dict, bank: Bank | None = None) -> CaptureDraws | None:
    """The capture draws a run's settings.degrade names ({"captures": CaptureDraws.describe()}), read again (from
    `bank` for 'bank') and checked against what the run recorded; None without."""
    if "captures" not in degrade:
        return None
    recorded = degrade["captures"]
    draws = load_capture_draws(recorded["spec"], bank)
    if draws.describe() != recorded:
        raise DataError(f"--capture-draws {recorded['spec']}: its distributions (sha {draws.describe()['sha256']}) "
                        f"are not the run's ({recorded['sha256']}): the file changed since the run began")
    return draws


class DrawLog:
    """online.jsonl in a run folder: one line per epoch, its crops' [image, panel, transform, y0, x0, noise seed]
    in the order trained, followed with capture draws by the crop's drawn values (restore.captures.CROP_KEYS) and
    its defect map's and FPN maps' seeds
    (written with each checkpoint; a resumed run keeps the epochs its checkpoint holds)."""
    FILE = "online.jsonl"

    def __init__(self, out: Path, epochs_done: int):
        self.path = Path(out) / self.FILE
        lines = self.path.read_text().splitlines() if self.path.is_file() else []
        self.lines = [ln for ln in lines if ln.strip() and json.loads(ln)["epoch"] <= epochs_done]

    def add(self, epoch: int, draws: list[dict]) -> None:
        keys = ("image", "panel", "mode", "y0", "x0", "noise_seed")
        self.lines.append(json.dumps({"epoch": epoch + 1, "crops": [[d[k] for k in keys] + (
            crop_values(d["capture"]) if "capture" in d else []) for d in draws]}))

    def save(self) -> None:
        save_text(self.path, "\n".join(self.lines) + "\n")
