"""OpenEXR: linear float32 images with named channels (the one reader and writer of udc_render)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR

from udc_render.io.files import atomic_path

# Lossless compressions a caller may choose: OpenEXR's ZIP (16 scanlines a block), ZIPS (one), PIZ, RLE and none
COMPRESSIONS = {"zip": OpenEXR.ZIP_COMPRESSION, "zips": OpenEXR.ZIPS_COMPRESSION, "piz": OpenEXR.PIZ_COMPRESSION,
                "rle": OpenEXR.RLE_COMPRESSION, "none": OpenEXR.NO_COMPRESSION}


def save_exr(path, channels: dict, compression: str = "zip") -> None:
    """Linear float32 image channels [H, W] (named, e.g. 'psf_450nm') as one scanline OpenEXR, compressed
    losslessly (COMPRESSIONS; ZIP by default)."""
    if compression not in COMPRESSIONS:
        raise ValueError(f"EXR compression {compression!r}: expected one of {', '.join(COMPRESSIONS)}")
    header = {"compression": COMPRESSIONS[compression], "type": OpenEXR.scanlineimage}
    data = {name: np.ascontiguousarray(a, dtype=np.float32) for name, a in channels.items()}
    with atomic_path(path, ".exr") as tmp:
        with OpenEXR.File(header, data) as f:
            f.write(str(tmp))


def read_exr(path: str | Path) -> dict[str, np.ndarray]:
    """{channel name: [H, W] float32} of an EXR file. OpenEXR ≥ 3.3 groups R, G, B (and A) into one
    [H, W, 3|4] channel named 'RGB' / 'RGBA': it is split back into R, G, B (A)."""
    out = {}
    with OpenEXR.File(str(path)) as f:
        for name, ch in f.channels().items():
            a = np.asarray(ch.pixels, np.float32)
            if name in ("RGB", "RGBA") and a.ndim == 3:
                out.update({c: np.ascontiguousarray(a[..., i]) for i, c in enumerate(name)})
            else:
                out[name] = a
    return out
