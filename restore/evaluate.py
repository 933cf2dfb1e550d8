"""Scoring restorers on a dataset split: PSNR, SSIM, LPIPS, size, MACs and run time, under both
metric protocols (udc_render.metrics: 'paper' first, the default for comparisons with the paper;
'srgb' for perceptual comparisons), every table naming its protocol.

Image metrics: restore.metrics (paper: linear [0, 1], PSNR and SSIM, the input row on its packed
RAW; srgb: display-referred, PSNR, SSIM and LPIPS; both border cropped).
Values are means over the split's images; the run time is the median over images of the restorer's
wall time (models: forward pass only, data on the device) per megapixel of output.

Methods (RESTORERS): 'input' (the degraded capture, bilinear demosaic ÷ γ: the identity baseline,
with γ the split's own ratio of sums, restore.known.measured_gamma_rggb), 'dep' (restore.dep with
the display's γ and the paper's computed PSF, as the paper ran it), 'dep_exact' (DeP (exact kernel):
the camera-weighted channel kernels; restore.known has both), or a checkpoint from `udc-render train`. Each run
merges its rows into <out>/results.json and rewrites results.md and results.csv, the layout of the
paper's pipeline comparison (rows: methods; columns: displays).
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from restore.data import DataError, Pair, dataset_displays, list_pairs, load_pair
from restore.dep import dep_restore
from restore.metrics import LEVEL_KEYS, image_metrics
from udc_render.io.files import csv_text, save_figure, save_json, save_text
from udc_render.io.plots import pyplot
from udc_render.io.previews import daylight_balance
from udc_render.metrics import BORDER_TEXT, PROTOCOLS, border_px, encode_srgb
from udc_render.sensor import demosaic_bilinear, unpack_rggb

MAC_INPUT_SHAPE = (1, 4, 512, 1024)  # the paper's: 512 × 1024 × 4 packed RAW
ROW_ORDER = ("input", "dep", "dep_exact", "resnet", "unet_syn", "unet", "unet_random")  # the paper's Table 2 order,
# DeP (exact kernel) after its DeP, UNet (randomized) after the UNet; unet_syn: UNet (Syn)
DISPLAY_TITLES = {"toled": "T-OLED", "poled": "P-OLED"}
METRICS = {"paper": ("psnr_db_paper", "ssim_paper"), "srgb": ("psnr_db_srgb", "ssim_srgb", "lpips_srgb")}
# the paper protocol's text describes udc_render.metrics.paper_linear, which keeps the border: restore.metrics
# crops it here; the srgb text already names display_referred's crop
PROTOCOLS_TEXT = {name: text + ("; " + BORDER_TEXT if name == "paper" else "") + "; PSNR peak 1; SSIM Gaussian σ 1.5"
                  + ("; LPIPS AlexNet v0.1" if name == "srgb" else "; the input row on its packed RAW")
                  + "; means over images; ms/MP: median restorer wall time per output megapixel"
                  for name, text in PROTOCOLS.items()}


@dataclass(frozen=True)
class EvalSettings:
    """How a method is scored: the split, displays (None: a checkpoint's own, else all of the dataset's),
    the row name (None: the method or model type), torch device, previews per display, DeP's denoiser
    (None: restore.dep's default), DeP's kernel size (None: restore.known's default) and the items scored
    (image_prefix: only those whose image label starts with it; None: all); display_specs: the --display items as
    given, from which a model that needs the panel's description gets it (restore.conditioning)."""
    split: str = "test"
    displays: tuple[str, ...] | None = None
    name: str | None = None
    device: str = "auto"
    previews: int = 4
    denoiser: str | None = None
    kernel_px: int | None = None
    image_prefix: str | None = None
    display_specs: tuple[str, ...] | None = None  # the --display items as given (restore.conditioning)


def check_frame_size(pair: Pair) -> None:
    """Refuse a pair whose scored image (border cropped) is smaller than LPIPS's AlexNet takes
    (restore.lpips.MIN_SIDE_PX: 31 px, so frames of 31 px or more on each side)."""
    from restore.lpips import MIN_SIDE_PX
    h, w = load_pair(pair)[1].shape[1:]
    if min(h, w) - 2 * border_px(h, w) < MIN_SIDE_PX:
        raise DataError(f"{pair.folder}: frames of {w} × {h} px are too small for LPIPS (AlexNet), which needs "
                        f"at least {MIN_SIDE_PX} × {MIN_SIDE_PX} px: make the dataset with a larger --sensor-px")


class InputRestorer:
    """'input': the degraded capture, bilinear demosaic ÷ the split's measured γ (module doc); scored
    on its packed RAW under the paper protocol."""
    scores_packed = True

    def __init__(self, method: str, settings: EvalSettings):
        self.method, self.settings, self.name, self.gamma = method, settings, settings.name or method, {}

    def displays(self, data_dir: Path) -> list[str]:
        return dataset_displays(data_dir)

    def prepare(self, pairs_by_display: dict) -> None:
        from restore.known import measured_gamma_rggb
        self.gamma = {d: measured_gamma_rggb(pairs) for d, pairs in pairs_by_display.items()}

    def restore(self, packed: np.ndarray, pair: Pair) -> tuple[np.ndarray, float, dict]:
        t0 = time.perf_counter()
        g = self.gamma[pair.display][:, None, None]
        out = demosaic_bilinear(unpack_rggb(packed / g)).astype(np.float32)
        return out, time.perf_counter() - t0, {}

    def describe(self) -> dict:
        return {"method": self.method, "params": None, "macs_g": None,
                "gamma_rggb": {d: g.tolist() for d, g in self.gamma.items()}}


class DepRestorer(InputRestorer):
    """'dep' and 'dep_exact': restore.dep with the display's γ and its kernels as restore.known gives them:
    the paper's computed PSF ('dep') or the camera-weighted channel kernels ('dep_exact')."""
    scores_packed = False

    def prepare(self, pairs_by_display: dict) -> None:
        from restore.known import known_gamma_rggb, known_kernels_rggb
        self.gamma, self.kernels = {}, {}
        for d, pairs in pairs_by_display.items():
            self.gamma[d] = known_gamma_rggb(pairs[0])
            self.kernels[d] = known_kernels_rggb(pairs[0], self.settings.kernel_px, source=self.kernel_source)

    @property
    def kernel_source(self) -> str:
        return DEP_KERNEL_SOURCE[self.method]

    def restore(self, packed: np.ndarray, pair: Pair) -> tuple[np.ndarray, float, dict]:
        kwargs = {} if self.settings.denoiser is None else {"denoiser": self.settings.denoiser}
        t0 = time.perf_counter()
        res = dep_restore(packed, self.gamma[pair.display], self.kernels[pair.display],
                          rng=np.random.default_rng(pair.item), **kwargs)
        return res.rgb, time.perf_counter() - t0, {"denoiser": res.denoiser}

    def describe(self) -> dict:
        return dict(super().describe(), kernel_px={d: int(k.shape[-1]) for d, k in self.kernels.items()},
                    kernels=self.kernel_source)


class ModelRestorer:
    """A checkpoint from `udc-render train` (`method` is its path), loaded on settings.device."""
    scores_packed = False

    def __init__(self, method: str, settings: EvalSettings):
        from restore.train import load_model
        self.method = method
        self.model, self.record = load_model(Path(method), settings.device)
        self.name = settings.name or self.record["model_config"]["type"]
        self.settings, self.descriptions = settings, {}

    def displays(self, data_dir: Path) -> list[str]:
        """The display it was trained on; a model trained online, the bank's panels it drew from."""
        return self.record["display"].split(",")

    def prepare(self, pairs_by_display: dict) -> None:
        """The panel's description of each display, for a model that needs one (restore.conditioning)."""
        from restore.conditioning import evaluation_descriptions
        self.descriptions = evaluation_descriptions(self.model, self.name, pairs_by_display,
                                                    self.settings.display_specs)

    def restore(self, packed: np.ndarray, pair: Pair) -> tuple[np.ndarray, float, dict]:
        import torch

        from restore.conditioning import predict_described
        from restore.train import predict
        dev = next(self.model.parameters()).device
        t0 = time.perf_counter()
        d = self.descriptions.get(pair.display)
        out = predict(self.model, packed, dev) if d is None else predict_described(self.model, packed, d, dev)
        if dev.type == "cuda":
            torch.cuda.synchronize()
        return out, time.perf_counter() - t0, {}

    def describe(self) -> dict:
        from restore.counting import count_macs, count_parameters
        cfg = self.record["model_config"]
        return {"method": self.method, "model_config": cfg, "params": count_parameters(self.model),
                "macs_g": count_macs(cfg, MAC_INPUT_SHAPE) / 1e9, "trained_on": self.record["display"],
                "train_settings": self.record["settings"], "device": self.record["device"],
                **({"descriptions": {d: v.source for d, v in self.descriptions.items()}} if self.descriptions else {})}


# method → factory(method, settings) of a restorer: `name`, `displays(data_dir)` (its default displays),
# `prepare(pairs_by_display)`, `restore(packed, pair)` -> (restored [3, H, W], seconds, notes), `describe()`
RESTORERS = {"input": InputRestorer, "dep": DepRestorer, "dep_exact": DepRestorer, "model": ModelRestorer}
BUILTIN_METHODS = ("input", "dep", "dep_exact")  # every other method is a checkpoint's path
DEP_KERNEL_SOURCE = {"dep": "paper", "dep_exact": "exact"}  # restore.known.DEP_KERNELS


def preview_panel(panels: list[tuple[str, np.ndarray]], balance: np.ndarray, path: Path, title: str) -> None:
    """Side-by-side sRGB previews (degraded | restored | ground truth) with labels."""
    plt = pyplot()
    h, w = panels[0][1].shape[1:]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 4.2 * h / w + 0.5))
    for ax, (label, img) in zip(axes, panels):
        x = encode_srgb(np.clip(np.asarray(img, np.float64) * balance[:, None, None], 0, 1))
        ax.imshow(np.moveaxis(x, 0, -1))
        ax.set_title(label, fontsize=9)
        ax.axis("off")
    fig.suptitle(title, fontsize=10)
    save_figure(fig, path)
    plt.close(fig)


def evaluate(data_dir: Path, method: str, out: Path, settings: EvalSettings = EvalSettings(),
             progress: bool = True) -> dict:
    """Score `method` (BUILTIN_METHODS or a checkpoint path) as `settings` say; merge into
    <out>/results.json and rewrite the tables; returns its entry."""
    from restore.lpips import LPIPS
    data_dir, out = Path(data_dir), Path(out)
    restorer = RESTORERS[method if method in BUILTIN_METHODS else "model"](method, settings)
    displays = restorer.displays(data_dir) if settings.displays is None else settings.displays
    pairs_by_display = {d: [p for p in list_pairs(data_dir, settings.split, [d])
                            if settings.image_prefix is None or (p.image or "").startswith(settings.image_prefix)]
                        for d in displays}
    for d, pairs in pairs_by_display.items():
        if not pairs:
            raise DataError(f"{data_dir}: split = {settings.split!r} has no items (display {d}"
                            + ("" if settings.image_prefix is None else f", --image-prefix {settings.image_prefix!r}")
                            + ")")
        check_frame_size(pairs[0])  # a dataset has one frame size
    restorer.prepare(pairs_by_display)
    lp = LPIPS()
    entry = dict(restorer.describe(), name=restorer.name, split=settings.split, displays={})
    for d, pairs in pairs_by_display.items():
        entry["displays"][d] = _score_display(restorer, d, pairs, lp, out / restorer.name, settings.previews,
                                              progress)
    results = merge_results(out, entry)
    save_text(out / "results.md", results_markdown(results))
    save_text(out / "results.csv", results_csv(results))
    return entry


def _score_display(restorer, display: str, pairs: list[Pair], lp, folder: Path, previews: int,
                   progress: bool) -> dict:
    """Score one display's pairs (`lp`: the LPIPS model): <folder>/metrics_<display>.csv and the first
    `previews` previews; returns the display's entry (metric means, median ms/MP, the restorer's notes)."""
    balance, rows, notes = daylight_balance(), [], {}
    bar = tqdm(pairs, desc=f"evaluate {restorer.name} {display}", unit="image", disable=not progress)
    for i, p in enumerate(bar):
        packed, gt = load_pair(p)
        restored, seconds, notes = restorer.restore(packed, p)
        if not np.all(np.isfinite(restored)):
            raise DataError(f"{restorer.name} on {p.folder}/{display}: the restored image is not finite")
        m = image_metrics(restored, gt, balance, lp, packed if restorer.scores_packed else None)
        rows.append({"item": p.item, "image": p.image, **m, "ms_per_mp": 1e3 * seconds / (gt[0].size / 1e6)})
        if i < previews:
            degraded = demosaic_bilinear(unpack_rggb(packed))
            preview_panel([("captured (linear, not scaled)", degraded), (restorer.name, restored),
                           ("ground truth", gt)], balance, folder / "previews" / f"{display}_{p.name}.png",
                          f"{DISPLAY_TITLES.get(display, display)} · {p.image} · PSNR {m['psnr_db_paper']:.2f} dB "
                          f"(paper), {m['psnr_db_srgb']:.2f} dB (srgb), LPIPS {m['lpips_srgb']:.4f}")
    keys = [k for ks in METRICS.values() for k in ks] + list(LEVEL_KEYS)
    save_text(folder / f"metrics_{display}.csv", csv_text(rows, ["item", "image", *keys, "ms_per_mp"]))
    return {"images": len(rows), **{k: float(np.mean([r[k] for r in rows])) for k in keys},
            "ms_per_mp": float(np.median([r["ms_per_mp"] for r in rows])), **notes}


def merge_results(out: Path, entry: dict) -> dict:
    path = out / "results.json"
    results = json.loads(path.read_text()) if path.is_file() else {"protocols": PROTOCOLS_TEXT, "methods": {}}
    if "protocols" not in results:
        raise DataError(f"{path}: written by an older udc-render (one protocol, no 'protocols'); move it away "
                        "or use another --out")
    old = results["methods"].get(entry["name"], {"displays": {}})
    merged = dict(entry, displays={**old.get("displays", {}), **entry["displays"]})
    results["methods"][entry["name"]] = merged
    save_json(path, results)
    return results


def _ordered(results: dict) -> tuple[list[str], list[str]]:
    names = sorted(results["methods"], key=lambda n: (ROW_ORDER.index(n) if n in ROW_ORDER else len(ROW_ORDER), n))
    displays = sorted({d for m in results["methods"].values() for d in m["displays"]},
                      key=lambda d: (list(DISPLAY_TITLES).index(d) if d in DISPLAY_TITLES else 9, d))
    return names, displays


def results_markdown(results: dict) -> str:
    """The paper's pipeline-comparison layout, one table per protocol (paper first): Method | Params |
    MACs | ms/MP | per display PSNR/SSIM (and LPIPS under srgb)."""
    return "\n\n".join(protocol_table(results, name) for name in METRICS) + "\n"


def protocol_table(results: dict, protocol: str) -> str:
    names, displays = _ordered(results)
    psnr, ssim_key, *lpips = METRICS[protocol]
    head = ["Method", "Params", "G MACs (512×1024×4)", "ms/MP"]
    for d in displays:
        head += [f"{DISPLAY_TITLES.get(d, d)} PSNR/SSIM"] + ([f"{DISPLAY_TITLES.get(d, d)} LPIPS"] if lpips else [])
    lines = [f"Protocol {protocol}: {results['protocols'][protocol]}.", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for n in names:
        m = results["methods"][n]
        times = [m["displays"][d]["ms_per_mp"] for d in displays if d in m["displays"]]
        row = [n, "—" if m.get("params") is None else f"{m['params'] / 1e6:.2f} M",
               "—" if m.get("macs_g") is None else f"{m['macs_g']:.2f}", f"{np.median(times):.0f}"]
        for d in displays:
            r = m["displays"].get(d)
            if r is None:
                row += ["—"] * (1 + len(lpips))
            else:
                row += [f"{r[psnr]:.2f}/{r[ssim_key]:.4f}"] + [f"{r[k]:.4f}" for k in lpips]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def results_csv(results: dict) -> str:
    names, displays = _ordered(results)
    rows = []
    for n in names:
        m = results["methods"][n]
        for d in displays:
            if d in m["displays"]:
                rows.append({"method": n, "display": d, "params": m.get("params"), "macs_g": m.get("macs_g"),
                             **m["displays"][d]})
    keys = [k for ks in METRICS.values() for k in ks] + list(LEVEL_KEYS)
    return csv_text(rows, ["method", "display", "params", "macs_g", "images", *keys, "ms_per_mp"])


def level_table(results: dict) -> str:
    """Per row and display, under the paper protocol: PSNR, the level-matched PSNR (each channel's gain solved
    with the truth, an oracle), what the level costs (their difference) and the output's mean level R/G/B
    (restore.metrics.level_scores; 1 = the truth's). Rows scored before these columns existed show —."""
    names, displays = _ordered(results)
    head = ["Method"] + [f"{DISPLAY_TITLES.get(d, d)} {c}" for d in displays
                         for c in ("PSNR", "matched", "level costs", "level R/G/B")]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for n in names:
        row = [n]
        for d in displays:
            r = results["methods"][n]["displays"].get(d, {})
            if "psnr_db_paper_matched" not in r:
                row += ["—"] * 4
                continue
            row += [f"{r['psnr_db_paper']:.2f}", f"{r['psnr_db_paper_matched']:.2f}",
                    f"{r['psnr_db_paper_matched'] - r['psnr_db_paper']:.2f}",
                    "/".join(f"{r[k]:.2f}" for k in ("level_r", "level_g", "level_b"))]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)
