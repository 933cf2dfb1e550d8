"""Image-quality figures shared by capture summaries, DeP and the restorers (one definition each)."""
from __future__ import annotations

import math

import numpy as np


def psnr_db(a: np.ndarray, b: np.ndarray, peak: float = 1.0) -> float:
    """10 log10(peak² / MSE); inf for identical images."""
    mse = float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(peak ** 2 / mse)
