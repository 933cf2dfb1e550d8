"""The scene a study's clean images hold, in the terms the design objective takes a scene (udc_render.design.metrics:
a mean μ, an RMS contrast c and a power spectrum A / |ν|^p): what `udc-render design --mean-level --contrast` set so
that the objective's scene is `study layout-trained`'s (docs/guides/design.md).

    μ  the mean of the images' values (a fraction of the glass capture's full well: restore.studies.robustness's
       white at WHITE_FILL of it),
    c  √(mean over windows of the window's variance) / μ, windows of window_px (the objective's kernel grid: 255 px
       of 3.1 µm ≈ 128 px of the study's 6.2 µm), every half window; the objective's spectrum has that variance
       over its grid (metrics.natural_spectrum: the mean of S over the DFT grid, S_0 = 0),
    p  the slope of the windows' mean periodogram against |ν| on log axes, 1/64 … 0.4 cycles per pixel, over the
       frequencies that carry power above float64's round-off (ROUND_OFF of the largest; NaN when fewer than two radii
       do: a scene without a spectrum to fit).
"""
from __future__ import annotations

import numpy as np

from restore.studies.robustness import clean_image, clean_manifest

__all__ = ["WINDOW_PX", "image_statistics", "scene_statistics"]

WINDOW_PX = 128  # the design objective's 255-px kernel grid of 3.1 µm on the study's 6.2 µm pixels
ROUND_OFF = 1e-12  # powers below this fraction of the largest are float64 round-off of an FFT, not the scene's


def _windows(plane: np.ndarray, n: int):
    h, w = plane.shape
    for y in range(0, h - n + 1, n // 2):
        for x in range(0, w - n + 1, n // 2):
            yield plane[y:y + n, x:x + n]


def image_statistics(images, window_px: int = WINDOW_PX) -> dict:
    """{mean_level, contrast, spectrum_slope, windows, images} of images [.., h, w] (each [C, h, w] or [h, w]; module
    doc), over their channels."""
    means, variances, power = [], [], 0.0
    for image in images:
        planes = np.asarray(image, np.float64).reshape(-1, *np.shape(image)[-2:])
        means.append(planes.mean())
        for window in (w for plane in planes for w in _windows(plane, window_px)):
            variances.append(window.var())
            power = power + np.abs(np.fft.fft2(window - window.mean())) ** 2
    f = np.fft.fftfreq(window_px)
    radius = np.hypot(f[None, :], f[:, None]).ravel()
    power = np.ravel(power)
    band = (radius >= 1 / 64) & (radius <= 0.4) & (power > ROUND_OFF * power.max())
    slope = np.polyfit(np.log(radius[band]), np.log(power[band]), 1)[0] if np.unique(radius[band]).size > 1 \
        else float("nan")
    mu = float(np.mean(means))
    return {"mean_level": mu, "contrast": float(np.sqrt(np.mean(variances)) / mu), "spectrum_slope": float(slope),
            "windows": len(variances), "images": len(means)}


def scene_statistics(b, split: str = "val", window_px: int = WINDOW_PX) -> dict:
    """image_statistics of the budget's clean images of `split` (restore.studies.robustness.clean_image)."""
    items = [i for i, line in enumerate(clean_manifest(b)) if line["split"] == split]
    return image_statistics((clean_image(b, i) for i in items), window_px)
