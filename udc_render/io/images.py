"""PNG previews (8-bit sRGB; 16-bit accepted). The RAW mosaic is a DNG: udc_render.io.dng."""
from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np

from udc_render.io.files import atomic_path


def write_png(path: Path, img: np.ndarray) -> None:
    """8-bit (or 16-bit) image [H, W] or [H, W, C] as PNG."""
    with atomic_path(path, ".png") as tmp:
        iio.imwrite(tmp, img, extension=".png")
