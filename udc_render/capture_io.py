"""Files of a synthesis: RAW mosaics, packed RAW, ground truth, previews, sidecars, summary.

Layout of one synthesis (one scene, several displays) in a folder:

    gt.exr               linear camera RGB ground truth, float32 channels R, G, B (synth.py: units)
    gt_preview.png       its sRGB preview (daylight white balance, see preview_srgb)
    <display>/raw.png    RAW mosaic, 16-bit grey PNG (lossless), RGGB, DN
    <display>/packed.tiff  packed RAW, uint16 [4, H/2, W/2] (R, Gr, Gb, B), zlib, planar
    <display>/preview.png  sRGB preview of the bilinear-demosaiced RAW
    <display>/capture.json every parameter: sensor, display, optics, noise seeds and sampled noise
    synth.json           shared parameters: render, exposure, lens, kernels, forms
    side_by_side.png     the previews next to each other, with PSNR
    summary.json / summary.md  mean level per channel, PSNR of each view against the ground truth

Every file is written atomically and holds nothing that changes between identical runs (no times,
no host names), so re-running with the same seeds gives byte-identical files; run times go to the
caller's log.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from udc_render.band_io import encode_srgb
from udc_render.fileio import atomic_path, save_exr, save_figure, save_json, save_text
from udc_render.sensor import CHANNELS, SITE_COLOUR, SITES, pack_rggb

_BILINEAR_G = np.array([[0, 1, 0], [1, 4, 1], [0, 1, 0]], float) / 4
_BILINEAR_RB = np.array([[1, 2, 1], [2, 4, 2], [1, 2, 1]], float) / 4


def demosaic_bilinear(mosaic: np.ndarray) -> np.ndarray:
    """[3, H, W] from an RGGB mosaic [H, W] by bilinear interpolation (mirror boundary)."""
    from scipy.ndimage import convolve
    m = np.asarray(mosaic, dtype=np.float64)
    out = np.zeros((3,) + m.shape)
    for c in range(3):
        sparse = np.zeros_like(m)
        for s, (i, j) in enumerate(SITES):
            if SITE_COLOUR[s] == c:
                sparse[i::2, j::2] = m[i::2, j::2]
        out[c] = convolve(sparse, _BILINEAR_G if c == 1 else _BILINEAR_RB, mode="mirror")
    return out


def mosaic_of(rgb: np.ndarray) -> np.ndarray:
    """RGGB mosaic [H, W] sampled from a full-resolution [3, H, W] image."""
    out = np.empty(rgb.shape[1:], dtype=rgb.dtype)
    for s, (i, j) in enumerate(SITES):
        out[i::2, j::2] = rgb[SITE_COLOUR[s], i::2, j::2]
    return out


def daylight_balance(camera: str = "Nikon 5100 (NPL)") -> np.ndarray:
    """[3] channel gains that make D65 neutral in this camera (for previews only; RAW is never balanced)."""
    from udc_render import spectra
    from udc_render.sensor import photon_weights
    edges = np.arange(380.0, 781.0, 5.0)
    d65 = spectra.band_means(spectra.illuminant("D65"), edges)
    resp = photon_weights(edges, camera) @ (d65 * np.diff(edges))
    return resp[1] / resp


def preview_srgb(rgb: np.ndarray, balance: np.ndarray, white: float = 1.0) -> np.ndarray:
    """8-bit sRGB [H, W, 3] of camera RGB [3, H, W] (white → 1.0 after `balance`); no colour matrix."""
    x = np.asarray(rgb, float) * balance[:, None, None] / white
    return (encode_srgb(np.moveaxis(x, 0, -1)) * 255 + 0.5).astype(np.uint8)


def psnr_db(a: np.ndarray, b: np.ndarray, peak: float = 1.0) -> float:
    """10 log10(peak² / MSE); inf for identical images."""
    mse = float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(peak ** 2 / mse)


def _png(path: Path, img: np.ndarray) -> None:
    import imageio.v3 as iio
    with atomic_path(path, ".png") as tmp:
        iio.imwrite(tmp, img, extension=".png")


def save_raw_png(path: Path, mosaic: np.ndarray) -> None:
    """16-bit greyscale PNG, lossless (pypng: deterministic bytes)."""
    import png
    a = np.ascontiguousarray(mosaic, dtype=np.uint16)
    with atomic_path(path, ".png") as tmp, open(tmp, "wb") as f:
        png.Writer(a.shape[1], a.shape[0], greyscale=True, bitdepth=16).write(f, a)


def load_raw_png(path: Path) -> np.ndarray:
    import png
    w, h, rows, _ = png.Reader(filename=str(path)).read()
    return np.vstack([np.asarray(r, dtype=np.uint16) for r in rows]).reshape(h, w)


def save_packed_tiff(path: Path, packed: np.ndarray) -> None:
    import tifffile
    with atomic_path(path, ".tiff") as tmp:
        tifffile.imwrite(tmp, np.ascontiguousarray(packed, dtype=np.uint16), photometric="minisblack",
                         planarconfig="separate", compression="zlib", metadata={"axes": "CYX"}, software=None)


def capture_summary(cap, gt: np.ndarray, white_level_dn: int, black_level_dn: int) -> dict:
    """Mean level per RGGB channel (fraction of the range) and PSNR against the ground truth's mosaic."""
    rng_dn = white_level_dn - black_level_dn
    norm = (cap.packed_dn.astype(np.float64) - black_level_dn) / rng_dn
    ref = pack_rggb(np.clip(mosaic_of(gt), 0, 1))
    return {"mean_level": {c: float(norm[i].mean()) for i, c in enumerate(CHANNELS)},
            "psnr_db_vs_gt": psnr_db(norm, ref),
            "saturated_fraction": float((cap.mosaic_dn >= white_level_dn).mean())}


def write_synthesis(out: Path, result, camera: str, side_by_side: bool = True) -> dict:
    """Write every file of a synth.SynthResult into `out` (module doc); returns the summary."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    balance = daylight_balance(camera)
    save_exr(out / "gt.exr", {c: result.gt[i] for i, c in enumerate("RGB")})
    _png(out / "gt_preview.png", preview_srgb(result.gt, balance))
    summary = {"views": {}, "units": "mean_level: fraction of white − black; PSNR on packed RAW in [0, 1] "
                                     "against the ground truth's RGGB samples clipped to [0, 1]"}
    previews = {}
    for name, cap in result.captures.items():
        d = out / name
        d.mkdir(exist_ok=True)
        s = cap.params["sensor"]
        save_raw_png(d / "raw.png", cap.mosaic_dn)
        save_packed_tiff(d / "packed.tiff", cap.packed_dn)
        rgb = demosaic_bilinear(cap.mosaic_dn.astype(np.float64) - s["black_level_dn"]) / (s["white_level_dn"] - s["black_level_dn"])
        previews[name] = preview_srgb(rgb, balance)
        _png(d / "preview.png", previews[name])
        save_json(d / "capture.json", {**cap.params, **result.display_meta[name]})
        summary["views"][name] = capture_summary(cap, result.gt, s["white_level_dn"], s["black_level_dn"])
    save_json(out / "synth.json", result.meta)
    save_json(out / "summary.json", summary)
    save_text(out / "summary.md", summary_markdown(summary))
    if side_by_side:
        plot_side_by_side(previews, summary, out / "side_by_side.png")
    return summary


def summary_markdown(summary: dict) -> str:
    lines = ["| view | mean R | mean Gr | mean Gb | mean B | PSNR vs GT (dB) | saturated |",
             "|---|---|---|---|---|---|---|"]
    for name, v in summary["views"].items():
        m = v["mean_level"]
        lines.append(f"| {name} | {m['R']:.4f} | {m['Gr']:.4f} | {m['Gb']:.4f} | {m['B']:.4f} | "
                     f"{v['psnr_db_vs_gt']:.2f} | {v['saturated_fraction']:.2%} |")
    return "\n".join(lines) + f"\n\n{summary['units']}\n"


def plot_side_by_side(previews: dict, summary: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    n = len(previews)
    h, w = next(iter(previews.values())).shape[:2]
    fig, axes = plt.subplots(1, n, figsize=(4.5 * n, 4.5 * h / w + 0.6), squeeze=False)
    for ax, (name, img) in zip(axes[0], previews.items()):
        ax.imshow(img)
        ax.set_title(f"{name}: PSNR {summary['views'][name]['psnr_db_vs_gt']:.1f} dB")
        ax.axis("off")
    fig.suptitle("captures (bilinear demosaic, daylight balance, sRGB; RAW levels as recorded)")
    save_figure(fig, path)
    plt.close(fig)
