"""Files of a synthesis: RAW mosaics (DNG), ground truth, previews, sidecars, summary.

Layout of one synthesis (one scene, several displays) in a folder:

    gt.exr               linear camera RGB ground truth, float32 channels R, G, B (pipeline.py: units),
                         uncompressed (GT_EXR_COMPRESSION)
    gt_preview.png       its sRGB preview (daylight white balance, see preview_srgb); with previews only
    <display>/raw.dng    RAW mosaic, DNG 1.4 (uint16, RGGB, DN, black and white levels, colour matrix;
                         uncompressed: io/dng.py), read by libraw/rawpy and RAW editors; load_packed
                         reads it for training as [4, H/2, W/2] (R, Gr, Gb, B)
    <display>/preview.png  sRGB preview of the bilinear-demosaiced RAW; with previews only
    <display>/capture.json every parameter: sensor, display, optics, noise seeds and sampled noise
    synth.json           shared parameters: render, exposure, lens, kernels, forms
    side_by_side.png     the previews next to each other, with PSNR; with side_by_side only
    summary.json / summary.md  mean level per channel, PSNR of each view against the ground truth

Every file is written atomically and holds nothing that changes between identical runs (no times,
no host names), so re-running with the same seeds gives byte-identical files; run times go to the
caller's log.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from udc_render.errors import UdcError
from udc_render.io.dng import DngError, read_dng_mosaic, save_dng
from udc_render.io.exr import read_exr, save_exr
from udc_render.io.files import save_json, save_text
from udc_render.io.images import write_png
from udc_render.io.plots import plot_side_by_side
from udc_render.io.previews import daylight_balance, preview_srgb
from udc_render.metrics import PROTOCOLS, display_referred, display_referred_quarters, paper_linear, psnr_db
from udc_render.sensor import CHANNELS, bilinear_quarters, mosaic_of, pack_rggb

# gt.exr uncompressed: ZIP saves 11-19 % of a frame's ground truth (its low bits are noise, or a photograph that
# fills the frame) for 10× the write and 6× the read CPU (`benchmarks/bench_gt_exr.py`, 2048 × 1024: 470 against
# 37 ms, 124 against 19 ms, 22.5 against 25.2 MB for the 16-frame mean)
GT_EXR_COMPRESSION = "none"


class CaptureFileError(UdcError):
    """A capture or ground-truth file that is missing or unreadable; one line."""


def gt_references(gt: np.ndarray, balance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ground truth [3, H, W] as each protocol compares it, made once per item: (its RGGB samples
    packed [4, H/2, W/2] ('paper'), its display-referred image ('srgb'))."""
    return pack_rggb(paper_linear(mosaic_of(gt))), display_referred(gt, balance)


def capture_psnr_db(packed: np.ndarray, shown: np.ndarray, refs: tuple) -> dict:
    """PSNR of a capture against the ground truth under both protocols: 'paper' on the packed RAW
    [4, H/2, W/2] (white-level units) against the ground truth's RGGB samples; 'srgb' on its display-referred
    image `shown` (metrics.display_referred of its demosaiced camera RGB) against the ground truth's. refs:
    gt_references(gt, balance), made once per item."""
    return {"paper": psnr_db(paper_linear(packed), refs[0]), "srgb": psnr_db(shown, refs[1])}


def capture_summary(cap, refs: tuple, quarters: np.ndarray, balance: np.ndarray, white_level_dn: int,
                    black_level_dn: int) -> dict:
    """Mean level per RGGB channel (fraction of the range), and PSNR against the ground truth under the
    paper protocol (packed RAW) and the srgb protocol (`quarters`: the bilinear demosaic of the mosaic above black,
    in quarter DN, sensor.bilinear_quarters; udc_render.metrics). refs: gt_references of the item's ground truth."""
    rng_dn = white_level_dn - black_level_dn
    norm = (cap.packed_dn.astype(np.float64) - black_level_dn) / rng_dn
    shown = display_referred_quarters(quarters, rng_dn, balance)  # display_referred(demosaic / range), bit for bit
    psnr = capture_psnr_db(norm, shown, refs)
    return {"mean_level": {c: float(norm[i].mean()) for i, c in enumerate(CHANNELS)},
            "psnr_db_vs_gt": psnr["paper"], "psnr_db_vs_gt_srgb": psnr["srgb"],
            "saturated_fraction": float((cap.mosaic_dn >= white_level_dn).mean())}


def write_synthesis(out: Path, result, camera: str, side_by_side: bool = True, previews: bool = True) -> dict:
    """Write every file of a synth.SynthResult into `out` (module doc); returns the summary. previews:
    also write gt_preview.png and <display>/preview.png (the summary's PSNRs are computed either way);
    side_by_side: also plot side_by_side.png (from the previews, made in memory when not written)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    balance = daylight_balance(camera)
    save_exr(out / "gt.exr", {c: result.gt[i] for i, c in enumerate("RGB")}, compression=GT_EXR_COMPRESSION)
    if previews:
        write_png(out / "gt_preview.png", preview_srgb(result.gt, balance))
    summary = {"views": {}, "units": f"mean_level: fraction of white − black; psnr_db_vs_gt: protocol paper "
                                     f"({PROTOCOLS['paper']}); psnr_db_vs_gt_srgb: protocol srgb ({PROTOCOLS['srgb']})"}
    images, refs = {}, gt_references(result.gt, balance)
    for name, cap in result.captures.items():
        d = out / name
        d.mkdir(exist_ok=True)
        s = cap.params["sensor"]
        save_dng(d / "raw.dng", cap.mosaic_dn, s["camera"], s["black_level_dn"], s["white_level_dn"])
        quarters = bilinear_quarters(cap.mosaic_dn.astype(np.int32) - np.int32(s["black_level_dn"]))
        if previews or side_by_side:
            images[name] = preview_srgb(quarters / 4 / (s["white_level_dn"] - s["black_level_dn"]), balance)
        if previews:
            write_png(d / "preview.png", images[name])
        save_json(d / "capture.json", {**cap.params, **result.display_meta[name]})
        summary["views"][name] = capture_summary(cap, refs, quarters, balance, s["white_level_dn"], s["black_level_dn"])
    save_json(out / "synth.json", result.meta)
    save_json(out / "summary.json", summary)
    save_text(out / "summary.md", summary_markdown(summary))
    if side_by_side:
        plot_side_by_side(images, summary, out / "side_by_side.png")
    return summary


def summary_markdown(summary: dict) -> str:
    lines = ["| view | mean R | mean Gr | mean Gb | mean B | PSNR vs GT, paper (dB) | PSNR vs GT, srgb (dB) "
             "| saturated |",
             "|---|---|---|---|---|---|---|---|"]
    for name, v in summary["views"].items():
        m = v["mean_level"]
        lines.append(f"| {name} | {m['R']:.4f} | {m['Gr']:.4f} | {m['Gb']:.4f} | {m['B']:.4f} | "
                     f"{v['psnr_db_vs_gt']:.2f} | {v['psnr_db_vs_gt_srgb']:.2f} | {v['saturated_fraction']:.2%} |")
    return "\n".join(lines) + f"\n\n{summary['units']}\n"


def load_packed(capture_dir: Path) -> np.ndarray:
    """[4, h, w] float32 packed RAW (R, Gr, Gb, B) of <capture_dir>/raw.dng in units of the white
    level: (DN − black) / (white − black), the levels from the DNG's tags."""
    path = Path(capture_dir) / "raw.dng"
    try:
        raw = read_dng_mosaic(path)
    except FileNotFoundError:
        raise CaptureFileError(f"{path}: missing (is the dataset complete? re-run `udc-render dataset`)") from None
    except DngError as exc:
        raise CaptureFileError(str(exc)) from None
    black, white = float(raw.black_level_dn), float(raw.white_level_dn)
    return ((pack_rggb(raw.mosaic_dn).astype(np.float32) - black) / (white - black)).astype(np.float32)


def load_gt(item_dir: Path) -> np.ndarray:
    """[3, H, W] float32 ground truth (gt.exr channels R, G, B)."""
    path = Path(item_dir) / "gt.exr"
    if not path.is_file():
        raise CaptureFileError(f"{path}: missing (is the dataset complete? re-run `udc-render dataset`)")
    ch = read_exr(path)
    return np.stack([ch[c] for c in "RGB"])
