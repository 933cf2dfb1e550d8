"""Paired data for the restorers: what `udc-render dataset` writes, read as (packed RAW, ground truth).

    <data>/manifest.jsonl                      one line per item: folder, split, displays
    <data>/<split>/shard_k/item_i/gt.exr       linear camera RGB [3, H, W], units of the white level
    <data>/<split>/shard_k/item_i/<display>/raw.dng   uint16 RGGB mosaic [H, W] (DN) with its black and
                                               white levels (udc_render.io.dng), packed on reading

Input x = (DN − black) / (white − black) per packed plane [4, H/2, W/2] (R, Gr, Gb, B); target y = gt
(same units, not clipped). The DNG is uncompressed, so reading and packing it (~1.5 ms at 2048 × 1024)
is ~20× faster than the zlib packed TIFF it replaced (benchmarks/README.md, "bench_raw_files.py").

Augmentation keeps the Bayer pattern (Liu et al. 2019, docs/PHYSICS.md §7): the 8 flips/transposes are
applied to the full-resolution mosaic and to the ground truth; a flip along an axis moves R to odd
indices on that axis, so the crop starts one pixel in (crops start on the R site), and the crop is
packed again. A transpose keeps R at (0, 0) and swaps Gr with Gb (both green).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from restore.tensors import stream_seed
from udc_render.errors import UdcError
from udc_render.io import capture as capture_files
from udc_render.sensor import pack_rggb, unpack_rggb
from udc_render.streams import stream

SPLITS = ("train", "val", "test")


class DataError(UdcError):
    """A dataset folder the restorers cannot read; one line."""


@dataclass(frozen=True)
class Pair:
    """One (capture, ground truth) pair: item folder and the display seen through."""
    item: int
    split: str
    folder: Path
    display: str
    image: str

    @property
    def name(self) -> str:
        return f"item_{self.item:06d}_{self.display}"


def read_manifest(data_dir: Path) -> list[dict]:
    path = Path(data_dir) / "manifest.jsonl"
    if not path.is_file():
        raise DataError(f"{path}: no manifest.jsonl: expected a folder written by `udc-render dataset`")
    rows = []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if line.strip():
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError as exc:
                raise DataError(f"{path}:{n}: not JSON ({exc.msg})") from None
    return rows


def dataset_displays(data_dir: Path) -> list[str]:
    """Displays of the dataset (from the first manifest line), glass excluded."""
    rows = read_manifest(data_dir)
    return [d for d in (rows[0]["displays"] if rows else []) if d != "glass"]


def list_pairs(data_dir: Path, split: str, displays: list[str]) -> list[Pair]:
    """Pairs of `split` for each display, in item order; errors name what is missing."""
    if split not in SPLITS:
        raise DataError(f"split = {split!r}: expected one of {', '.join(SPLITS)}")
    rows = read_manifest(data_dir)
    pairs = []
    for d in displays:
        for r in rows:
            if r["split"] != split:
                continue
            if d not in r["displays"]:
                raise DataError(f"{Path(data_dir) / 'manifest.jsonl'}: display = {d!r} not in item {r['item']} "
                                f"(has {', '.join(r['displays'])})")
            pairs.append(Pair(int(r["item"]), split, Path(data_dir) / r["folder"], d, r.get("image", "")))
    return pairs


def load_packed(capture_dir: Path) -> np.ndarray:
    """[4, h, w] float32 packed RAW in units of the white level (udc_render.io.capture.load_packed)."""
    try:
        return capture_files.load_packed(capture_dir)
    except capture_files.CaptureFileError as exc:
        raise DataError(str(exc)) from None


def load_gt(item_dir: Path) -> np.ndarray:
    """[3, H, W] float32 ground truth (udc_render.io.capture.load_gt); NaN or ±inf in it is a DataError."""
    try:
        gt = capture_files.load_gt(item_dir)
    except capture_files.CaptureFileError as exc:
        raise DataError(str(exc)) from None
    bad = np.count_nonzero(~np.isfinite(gt))
    if bad:
        path = Path(item_dir) / "gt.exr"
        raise DataError(f"{path}: NaN or infinite values ({bad} of {gt.size}), expected finite linear RGB: "
                        f"delete {path.parent.name} and re-run `udc-render dataset` to make it again")
    return gt


def load_pair(pair: Pair) -> tuple[np.ndarray, np.ndarray]:
    packed, gt = load_packed(pair.folder / pair.display), load_gt(pair.folder)
    if gt.shape[1:] != (2 * packed.shape[1], 2 * packed.shape[2]):
        raise DataError(f"{pair.folder}: gt {gt.shape} does not match packed {packed.shape} (expected 2× its size)")
    return packed, gt


ALL_MODES = tuple(range(8))  # dihedral's


def dihedral(a, mode: int):
    """One of the 8 flips/transposes of the last two axes of an array or a tensor (views of an array): bit 0
    transpose, bit 1 flip rows, bit 2 flip columns."""
    flip = (lambda v, axis: v.flip(axis)) if isinstance(a, torch.Tensor) else np.flip
    if mode & 1:
        a = a.swapaxes(-1, -2)
    if mode & 2:
        a = flip(a, -2)
    if mode & 4:
        a = flip(a, -1)
    return a


def largest_crop_px(h: int, w: int) -> int:
    """The largest square crop of an h × w frame that augment_crop takes whatever the transform: the
    smaller side less 2 px (room for the shift after a flip), in whole RGGB cells."""
    return (min(h, w) - 2) // 2 * 2


def augment_crop(packed: np.ndarray, gt: np.ndarray, mode: int, crop_px: int | None, rng: np.random.Generator):
    """(packed [4, c/2, c/2], gt [3, c, c]): Bayer-preserving transform `mode`, then a random square
    crop of c = crop_px full-resolution pixels starting on an R site (module doc). A crop larger than
    the image is capped at its smaller side less 2 px (room for the shift after a flip), so that
    every crop has the same size whatever the transform. crop_px None: the whole (transformed) frame,
    less one row/column per flip."""
    mosaic, target = dihedral(unpack_rggb(packed), mode), dihedral(gt, mode)
    r_row, r_col = int(bool(mode & 2)), int(bool(mode & 4))  # R moved to odd rows/columns by a flip
    H, W = mosaic.shape
    if crop_px is None:
        ch, cw = (H - r_row) // 2 * 2, (W - r_col) // 2 * 2
    else:
        if min(H, W) < 4:
            raise DataError(f"image {H} × {W} px: too small for crops (at least 4 × 4)")
        ch = cw = min(crop_px, largest_crop_px(H, W))
    y0 = r_row + 2 * int(rng.integers(0, (H - r_row - ch) // 2 + 1))
    x0 = r_col + 2 * int(rng.integers(0, (W - r_col - cw) // 2 + 1))
    crop = np.ascontiguousarray(mosaic[y0:y0 + ch, x0:x0 + cw])
    return pack_rggb(crop), np.ascontiguousarray(target[:, y0:y0 + ch, x0:x0 + cw])


class PairDataset(torch.utils.data.Dataset):
    """Random square crops (crop_px full-resolution pixels, 256 by default) of the pairs, `crops_per_pair`
    per pair and epoch, with Bayer-preserving augmentation drawn from `modes` (all 8 by default; those the
    panel's kernel is symmetric under: restore.augment, modes_why says why). Deterministic: the crop and transform
    of index i in epoch e come from the named stream (seed, 'pair crop', e, i) (udc_render.streams; set_epoch),
    so resumed training sees the same samples. Every pair is read (and checked, load_pair) when the dataset is
    made, and kept in memory."""

    def __init__(self, pairs: list[Pair], crop_px: int | None = 256, augment: bool = True, seed: int = 0,
                 crops_per_pair: int = 1, modes: tuple[int, ...] = ALL_MODES, modes_why: str = ""):
        if not pairs:
            raise DataError("no pairs to train on: the split is empty")
        if crop_px is not None and (crop_px < 2 or crop_px % 2):
            raise DataError(f"crop_px = {crop_px}: expected an even number ≥ 2 (whole RGGB cells)")
        self.pairs, self.crop_px, self.augment, self.seed = pairs, crop_px, augment, seed
        self.crops_per_pair, self.epoch = crops_per_pair, 0
        if not modes or 0 not in modes or not set(modes) <= set(ALL_MODES):
            raise DataError(f"augmentation modes {modes}: expected the identity 0 and others of {ALL_MODES}")
        self.modes, self.modes_why = tuple(modes), modes_why
        self.arrays = [load_pair(p) for p in pairs]

    def __len__(self):
        return len(self.pairs) * self.crops_per_pair

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def __getitem__(self, i: int):
        packed, gt = self.arrays[i % len(self.pairs)]
        rng = stream(self.seed, "pair crop", self.epoch, i)
        mode = self.modes[int(rng.integers(0, len(self.modes)))] if self.augment else 0
        x, y = augment_crop(packed, gt, mode, self.crop_px, rng)
        return torch.from_numpy(x), torch.from_numpy(y)


class PairBatches:
    """The training batches of a PairDataset: per epoch, its crops (set_epoch) in the order of a torch generator
    seeded from the named stream (seed, 'pair order', epoch), `batch` at a time (what restore.train iterates;
    restore.online.OnlineBatches is the online degradation's)."""

    def __init__(self, data: PairDataset, batch: int, seed: int):
        self.data, self.batch, self.seed = data, batch, seed

    @property
    def count(self) -> int:
        return len(self.data.pairs)

    @property
    def record(self) -> dict:
        """What train_summary.json records of the data: the transforms drawn and why."""
        return {"augment": {"modes": list(self.data.modes if self.data.augment else (0,)), "why": self.data.modes_why}}

    def epoch(self, epoch: int):
        """(None: no draws to record, the epoch's batches (x, y))."""
        self.data.set_epoch(epoch)
        order = torch.Generator().manual_seed(stream_seed(self.seed, "pair order", epoch))
        return None, torch.utils.data.DataLoader(self.data, batch_size=self.batch, shuffle=True, generator=order)
