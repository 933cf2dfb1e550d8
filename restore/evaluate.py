"""Scoring restorers on a dataset split: PSNR, SSIM, LPIPS, size, MACs and run time, one protocol.

Metric protocol (every number in the tables): the restored image and the ground truth are linear
camera RGB in units of the white level; both are multiplied by the camera's daylight balance
(capture_io.daylight_balance: D65 neutral), clipped to [0, 1], sRGB-encoded (IEC 61966-2-1, no
colour matrix) and cropped by BORDER_PX pixels on each side. PSNR: peak 1. SSIM: Wang et al.
(Gaussian window σ = 1.5, data range 1, population statistics, mean over R, G, B; skimage). LPIPS:
AlexNet v0.1 (restore.lpips) on the same images. Values are means over the split's images; the run
time is the median over images of the restorer's wall time (models: forward pass only, data on the
device) per megapixel of output.

Methods: 'input' (the degraded capture, bilinear demosaic ÷ γ: the identity baseline, with γ the
split's own ratio of sums, restore.known.measured_gamma_rggb), 'dep' (restore.dep with the
display's known kernels and γ, restore.known), or a checkpoint from
`udc-render train`. Each run merges its rows into <out>/results.json and rewrites results.md and
results.csv, the layout of the paper's pipeline comparison (rows: methods; columns: displays).
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from restore.data import DataError, Pair, dataset_displays, list_pairs, load_pair
from udc_render.io.previews import encode_srgb
from udc_render.io.previews import daylight_balance
from udc_render.sensor import demosaic_bilinear
from udc_render.io.files import csv_text, save_figure, save_json, save_text
from udc_render.sensor import unpack_rggb

BORDER_PX = 16
MAC_INPUT_SHAPE = (1, 4, 512, 1024)  # the paper's: 512 × 1024 × 4 packed RAW
ROW_ORDER = ("input", "dep", "resnet", "unet")
DISPLAY_TITLES = {"toled": "T-OLED", "poled": "P-OLED"}
PROTOCOL = (f"daylight-balanced camera RGB, clipped to [0, 1], sRGB-encoded, {BORDER_PX}-px border cropped; "
            "PSNR peak 1; SSIM Gaussian σ 1.5; LPIPS AlexNet v0.1; means over images; "
            "ms/MP: median restorer wall time per output megapixel")


def border_px(h: int, w: int) -> int:
    """The border cropped from an h × w frame: BORDER_PX, none for frames of 4 · BORDER_PX px or less."""
    return BORDER_PX if min(h, w) > 4 * BORDER_PX else 0


def display_referred(rgb: np.ndarray, balance: np.ndarray) -> np.ndarray:
    """[3, H, W] → the protocol's image [3, H − 2b, W − 2b] in [0, 1] (module doc)."""
    x = np.clip(np.asarray(rgb, np.float64) * balance[:, None, None], 0, 1)
    b = border_px(*x.shape[1:])
    x = x[:, b:x.shape[1] - b or None, b:x.shape[2] - b or None]
    return encode_srgb(x)


def check_frame_size(pair: Pair) -> None:
    """Refuse a pair whose scored image (border cropped) is smaller than LPIPS's AlexNet takes
    (restore.lpips.MIN_SIDE_PX: 31 px, so frames of 31 px or more on each side)."""
    from restore.lpips import MIN_SIDE_PX
    h, w = load_pair(pair)[1].shape[1:]
    if min(h, w) - 2 * border_px(h, w) < MIN_SIDE_PX:
        raise DataError(f"{pair.folder}: frames of {w} × {h} px are too small for LPIPS (AlexNet), which needs "
                        f"at least {MIN_SIDE_PX} × {MIN_SIDE_PX} px: make the dataset with a larger --sensor-px")


def image_metrics(restored: np.ndarray, gt: np.ndarray, balance: np.ndarray, lpips_model) -> dict:
    """PSNR (dB), SSIM and LPIPS of one restored image against its ground truth (module doc)."""
    import torch
    from skimage.metrics import structural_similarity
    a, b = display_referred(restored, balance), display_referred(gt, balance)
    mse = float(np.mean((a - b) ** 2))
    psnr = math.inf if mse == 0 else 10 * math.log10(1 / mse)
    ssim = float(structural_similarity(a, b, channel_axis=0, data_range=1.0, gaussian_weights=True, sigma=1.5,
                                       use_sample_covariance=False))
    with torch.inference_mode():
        lp = float(lpips_model(torch.from_numpy(a[None]).float(), torch.from_numpy(b[None]).float())[0])
    return {"psnr_db": psnr, "ssim": ssim, "lpips": lp}


class Restorer:
    """A method under test: restore(packed, pair) -> [3, H, W] and its description."""

    def __init__(self, method: str, pairs_by_display: dict, device: str = "auto", denoiser: str | None = None,
                 name: str | None = None, loaded: tuple | None = None, kernel_px: int | None = None):
        self.method, self.device = method, device
        self.model, self.record, self.known = None, {}, {}
        if method in ("input", "dep"):
            from restore.known import known_gamma_rggb, known_kernels_rggb, measured_gamma_rggb
            self.name = name or method
            for d, pairs in pairs_by_display.items():
                self.known[d] = ({"gamma": known_gamma_rggb(pairs[0]),
                                  "kernels": known_kernels_rggb(pairs[0], kernel_px)}
                                 if method == "dep" else {"gamma": measured_gamma_rggb(pairs), "kernels": None})
            self.denoiser = denoiser
        else:
            from restore.train import load_model
            self.model, self.record = loaded or load_model(Path(method), device)
            self.name = name or self.record["model_config"]["type"]

    def restore(self, packed: np.ndarray, pair: Pair) -> tuple[np.ndarray, float, dict]:
        """(restored [3, H, W], seconds, notes)."""
        if self.model is not None:
            import torch
            from restore.train import predict
            dev = next(self.model.parameters()).device
            t0 = time.perf_counter()
            out = predict(self.model, packed, dev)
            if dev.type == "cuda":
                torch.cuda.synchronize()
            return out, time.perf_counter() - t0, {}
        k = self.known[pair.display]
        t0 = time.perf_counter()
        if self.method == "input":
            g = k["gamma"][:, None, None]
            out = demosaic_bilinear(unpack_rggb(packed / g)).astype(np.float32)
            return out, time.perf_counter() - t0, {}
        from restore.dep import dep_restore
        kwargs = {} if self.denoiser is None else {"denoiser": self.denoiser}
        res = dep_restore(packed, k["gamma"], k["kernels"], rng=np.random.default_rng(pair.item), **kwargs)
        return res.rgb, time.perf_counter() - t0, {"denoiser": res.denoiser}

    def describe(self) -> dict:
        if self.model is None:
            d = {"method": self.method, "params": None, "macs_g": None,
                 "gamma_rggb": {k: v["gamma"].tolist() for k, v in self.known.items()}}
            if self.method == "dep":
                d["kernel_px"] = {k: int(v["kernels"].shape[-1]) for k, v in self.known.items()}
            return d
        from restore.counting import count_macs, count_parameters
        cfg = self.record["model_config"]
        return {"method": self.method, "model_config": cfg, "params": count_parameters(self.model),
                "macs_g": count_macs(cfg, MAC_INPUT_SHAPE) / 1e9, "trained_on": self.record["display"],
                "train_settings": self.record["settings"], "device": self.record["device"]}


def preview_panel(panels: list[tuple[str, np.ndarray]], balance: np.ndarray, path: Path, title: str) -> None:
    """Side-by-side sRGB previews (degraded | restored | ground truth) with labels."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
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


def evaluate(data_dir: Path, method: str, out: Path, split: str = "test", displays: list[str] | None = None,
             name: str | None = None, device: str = "auto", previews: int = 4, denoiser: str | None = None,
             progress: bool = True, kernel_px: int | None = None) -> dict:
    """Score `method` on `split` for `displays`; merge into <out>/results.json; returns its entry."""
    from tqdm import tqdm
    from restore.lpips import LPIPS
    data_dir, out = Path(data_dir), Path(out)
    loaded = None
    if method not in ("input", "dep"):
        from restore.train import load_model
        loaded = load_model(Path(method), device)
    if displays is None:
        displays = [loaded[1]["display"]] if loaded else dataset_displays(data_dir)
    pairs_by_display = {d: list_pairs(data_dir, split, [d]) for d in displays}
    for d, pairs in pairs_by_display.items():
        if not pairs:
            raise DataError(f"{data_dir}: split = {split!r} has no items (display {d})")
        check_frame_size(pairs[0])  # a dataset has one frame size
    restorer = Restorer(method, pairs_by_display, device, denoiser, name, loaded, kernel_px)
    lp, balance = LPIPS().eval(), daylight_balance()
    entry = dict(restorer.describe(), name=restorer.name, split=split, displays={})
    folder = out / restorer.name
    for d, pairs in pairs_by_display.items():
        rows, notes = [], {}
        for i, p in enumerate(tqdm(pairs, desc=f"evaluate {restorer.name} {d}", unit="image", disable=not progress)):
            packed, gt = load_pair(p)
            restored, seconds, notes = restorer.restore(packed, p)
            if not np.all(np.isfinite(restored)):
                raise DataError(f"{restorer.name} on {p.folder}/{d}: the restored image is not finite")
            m = image_metrics(restored, gt, balance, lp)
            rows.append({"item": p.item, "image": p.image, **m, "ms_per_mp": 1e3 * seconds / (gt[0].size / 1e6)})
            if i < previews:
                degraded = demosaic_bilinear(unpack_rggb(packed))
                preview_panel([("captured (linear, not scaled)", degraded), (restorer.name, restored),
                               ("ground truth", gt)], balance, folder / "previews" / f"{d}_{p.name}.png",
                              f"{DISPLAY_TITLES.get(d, d)} · {p.image} · PSNR {m['psnr_db']:.2f} dB, "
                              f"SSIM {m['ssim']:.4f}, LPIPS {m['lpips']:.4f}")
        save_text(folder / f"metrics_{d}.csv", csv_text(rows, ["item", "image", "psnr_db", "ssim", "lpips", "ms_per_mp"]))
        entry["displays"][d] = {"images": len(rows), **{k: float(np.mean([r[k] for r in rows]))
                                                         for k in ("psnr_db", "ssim", "lpips")},
                                "ms_per_mp": float(np.median([r["ms_per_mp"] for r in rows])), **notes}
    results = merge_results(out, entry)
    save_text(out / "results.md", results_markdown(results))
    save_text(out / "results.csv", results_csv(results))
    return entry


def merge_results(out: Path, entry: dict) -> dict:
    path = out / "results.json"
    results = json.loads(path.read_text()) if path.is_file() else {"protocol": PROTOCOL, "methods": {}}
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
    """The paper's pipeline-comparison layout: Method | Params | MACs | ms/MP | per display PSNR/SSIM, LPIPS."""
    names, displays = _ordered(results)
    head = ["Method", "Params", "G MACs (512×1024×4)", "ms/MP"]
    for d in displays:
        head += [f"{DISPLAY_TITLES.get(d, d)} PSNR/SSIM", f"{DISPLAY_TITLES.get(d, d)} LPIPS"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for n in names:
        m = results["methods"][n]
        times = [m["displays"][d]["ms_per_mp"] for d in displays if d in m["displays"]]
        row = [n, "—" if m.get("params") is None else f"{m['params'] / 1e6:.2f} M",
               "—" if m.get("macs_g") is None else f"{m['macs_g']:.2f}", f"{np.median(times):.0f}"]
        for d in displays:
            r = m["displays"].get(d)
            row += ["—", "—"] if r is None else [f"{r['psnr_db']:.2f}/{r['ssim']:.4f}", f"{r['lpips']:.4f}"]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + f"\n\nProtocol: {results['protocol']}.\n"


def results_csv(results: dict) -> str:
    names, displays = _ordered(results)
    rows = []
    for n in names:
        m = results["methods"][n]
        for d in displays:
            if d in m["displays"]:
                rows.append({"method": n, "display": d, "params": m.get("params"), "macs_g": m.get("macs_g"),
                             **m["displays"][d]})
    return csv_text(rows, ["method", "display", "params", "macs_g", "images", "psnr_db", "ssim", "lpips", "ms_per_mp"])
