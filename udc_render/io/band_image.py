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

from udc_render.io.exr import read_exr, save_exr
from udc_render.io.files import save_json
from udc_render.io.images import write_png
from udc_render.io.previews import preview_rgb
from udc_render.render.band_image import BandImage, band_names


def save_band_image(b: BandImage, out_dir: str | Path) -> dict:
    """Write the EXR, sidecar and previews; returns the paths written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    channels = dict(zip(band_names(b.edges_nm), b.bands))
    if b.depth_m is not None:
        channels["depth_m"] = b.depth_m
    save_exr(out / "render.exr", channels)
    img, white = preview_rgb(b.frame(b.bands), b.edges_nm)
    write_png(out / "preview.png", img)
    written = {"exr": str(out / "render.exr"), "json": str(out / "render.json"), "preview": str(out / "preview.png")}
    if b.depth_m is not None:
        d = b.frame(b.depth_m)
        finite = d[np.isfinite(d)]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        shade = np.where(np.isfinite(d), 1 - (d - lo) / max(hi - lo, 1e-12), 0.0)
        write_png(out / "depth.png", (np.clip(shade, 0, 1) * 255).astype(np.uint8))
        written["depth"] = str(out / "depth.png")
    meta = dict(b.meta, preview_white_cd_m2=white, pitch_um=b.pitch_um, margin_px=b.margin_px,
                shape_khw=list(b.bands.shape), channels=list(channels))
    save_json(out / "render.json", meta)
    return written


def load_band_image(out_dir: str | Path) -> BandImage:
    """Read back what :func:`save_band_image` wrote."""
    out = Path(out_dir)
    meta = json.loads((out / "render.json").read_text())
    ch = read_exr(out / "render.exr")
    edges = np.asarray(meta["band_edges_nm"], float)
    bands = np.stack([ch[n] for n in band_names(edges)])
    return BandImage(bands=bands, edges_nm=edges, pitch_um=meta["pitch_um"], margin_px=meta["margin_px"],
                     depth_m=ch.get("depth_m"), meta=meta,
                     primaries_matrix=(None if meta.get("band_matrix") is None
                                       else np.asarray(meta["band_matrix"], float)))
