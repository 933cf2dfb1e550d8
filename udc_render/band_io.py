"""Band images on disk: one multi-channel EXR, a JSON sidecar, an sRGB preview.

    DIR/render.exr    float32 channels band_0405nm … (zero-padded centres) and depth_m
    DIR/render.json   every parameter of the render (BandImage.meta) plus the preview's exposure
    DIR/preview.png   the sensor frame, CIE 1931 XYZ → sRGB (D65), exposure: 99th percentile of Y → 1
    DIR/depth.png     (3D scenes) axial depth, near = bright
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from udc_render import spectra
from udc_render.fileio import atomic_path, save_exr, save_json
from udc_render.render import BandImage, band_names

XYZ_TO_SRGB = np.array([[3.2404542, -1.5371385, -0.4985314],
                        [-0.9692660, 1.8760108, 0.0415560],
                        [0.0556434, -0.2040259, 1.0572252]])


def encode_srgb(linear: np.ndarray) -> np.ndarray:
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def preview_rgb(bands: np.ndarray, edges_nm) -> tuple[np.ndarray, float]:
    """8-bit sRGB [H, W, 3] of band radiance [K, H, W] and the luminance (cd/m²) shown as white."""
    xyz = np.einsum("ck,khw->chw", spectra.band_xyz(edges_nm), bands.astype(np.float64))
    white = float(np.percentile(xyz[1], 99)) if np.any(xyz[1] > 0) else 1.0
    rgb = np.einsum("ij,jhw->hwi", XYZ_TO_SRGB, xyz / white)
    return (encode_srgb(rgb) * 255 + 0.5).astype(np.uint8), white


def _save_png(path: Path, img: np.ndarray) -> None:
    import imageio.v3 as iio
    with atomic_path(path, ".png") as tmp:
        iio.imwrite(tmp, img, extension=".png")


def save_band_image(b: BandImage, out_dir: str | Path) -> dict:
    """Write the EXR, sidecar and previews; returns the paths written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    channels = dict(zip(band_names(b.edges_nm), b.bands))
    if b.depth_m is not None:
        channels["depth_m"] = b.depth_m
    save_exr(out / "render.exr", channels)
    img, white = preview_rgb(b.frame(b.bands), b.edges_nm)
    _save_png(out / "preview.png", img)
    written = {"exr": str(out / "render.exr"), "json": str(out / "render.json"), "preview": str(out / "preview.png")}
    if b.depth_m is not None:
        d = b.frame(b.depth_m)
        finite = d[np.isfinite(d)]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        shade = np.where(np.isfinite(d), 1 - (d - lo) / max(hi - lo, 1e-12), 0.0)
        _save_png(out / "depth.png", (np.clip(shade, 0, 1) * 255).astype(np.uint8))
        written["depth"] = str(out / "depth.png")
    meta = dict(b.meta, preview_white_cd_m2=white, pitch_um=b.pitch_um, margin_px=b.margin_px,
                shape_khw=list(b.bands.shape), channels=list(channels))
    save_json(out / "render.json", meta)
    return written


def load_band_image(out_dir: str | Path) -> BandImage:
    """Read back what :func:`save_band_image` wrote."""
    import OpenEXR
    out = Path(out_dir)
    meta = json.loads((out / "render.json").read_text())
    with OpenEXR.File(str(out / "render.exr")) as f:
        ch = {k: np.array(v.pixels, dtype=np.float32) for k, v in f.channels().items()}
    edges = np.asarray(meta["band_edges_nm"], float)
    bands = np.stack([ch[n] for n in band_names(edges)])
    return BandImage(bands=bands, edges_nm=edges, pitch_um=meta["pitch_um"], margin_px=meta["margin_px"],
                     depth_m=ch.get("depth_m"), meta=meta)
