"""PNG and TIFF: 8-bit previews, 16-bit RAW mosaics (lossless) and packed RAW planes."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from udc_render.io.files import atomic_path


def write_png(path: Path, img: np.ndarray) -> None:
    """8-bit (or 16-bit) image [H, W] or [H, W, C] as PNG."""
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


def read_packed_tiff(path: Path) -> np.ndarray:
    """uint16 [4, H/2, W/2] packed RAW written by save_packed_tiff."""
    import tifffile
    return tifffile.imread(path)
