"""`study layout --restore dep`: the restored PSNR by DeP of a natural image through a layout's exact kernels.

Per channel c (R, G, B of the rig's kernels k_c and the image's R, G, B), in units of the glass capture's full
well FW (udc_render.design.metrics.restorability's convention):
    y_c = (Poisson(FW · t_c · (x_c ⊗ k_c)) + N(0, read_noise_e²)) / FW,
x: fixed crops of skimage.data.astronaut (sRGB values / 255, taken as linear), scaled so the image's mean is the
restorability's scene mean μ (MEAN_LEVEL of the full well); k_c: the unit-sum kernel; t_c: the transmission
given (the study passes open area × the fraction of the light inside the kernel's window: the rest is lost).
Each crop is blurred with its margin of half a kernel (the image reflected at its edges), so the crop has no
boundary of its own. DeP's per-plane steps (restore.dep) restore it: x̂_c = max(0, Wiener(denoise(y_c) / t_c)),
NLM with the noise std estimated, the unsupervised Wiener-Hunt sampler with the same kernel (seeded).
PSNR = −10 log10 MSE(x̂, x) over the crops (peak: the full well), per channel; beside it the noisy input's,
y_c / t_c against x_c. Noise and sampler draw from named streams (udc_render.streams) keyed by crop and channel,
not by layout, so two layouts see the same draws. Cost: the Wiener sampler takes seconds per 192-px plane.
"""
from __future__ import annotations

import time

import numpy as np

from restore.dep import denoise_plane, wiener_plane
from udc_render.design.metrics import MEAN_LEVEL
from udc_render.sensor.config import SensorConfig
from udc_render.streams import stream

__all__ = ["RESTORERS", "CROP_PX", "CORNERS_PX", "QUICK_CROP_PX", "natural_crops", "degrade", "restored_psnr"]

RESTORERS = ("dep",)
CROP_PX = 192
CORNERS_PX = ((64, 160), (300, 280))  # top-left (row, column) on astronaut's 512²: the face; the suit and flag
QUICK_CROP_PX = 96


def natural_crops(crop_px: int, margin_px: int, corners_px=CORNERS_PX) -> np.ndarray:
    """[n, 3, crop + 2 margin, …] crops of astronaut (values / 255 scaled to mean MEAN_LEVEL), each with a margin
    of margin_px around the crop at its corner; the image is reflected past its edges."""
    from skimage.data import astronaut
    img = astronaut().astype(np.float64).transpose(2, 0, 1) / 255
    img *= MEAN_LEVEL / img.mean()
    m, size = int(margin_px), int(crop_px) + 2 * int(margin_px)
    padded = np.pad(img, ((0, 0), (m, m), (m, m)), mode="reflect")
    return np.stack([padded[:, r:r + size, c:c + size] for r, c in corners_px])


def degrade(region: np.ndarray, kernel: np.ndarray, transmission: float, sensor: SensorConfig,
            rng: np.random.Generator) -> np.ndarray:
    """y = (Poisson(FW t (x ⊗ k)) + N(0, read²)) / FW on the crop inside `region` (a margin of kernel // 2 on each
    side: 'valid' convolution), k normalised to unit sum."""
    from scipy.signal import fftconvolve
    k = kernel / kernel.sum()
    return noisy(fftconvolve(region, k, mode="valid"), transmission, sensor, rng)


def noisy(blurred: np.ndarray, transmission: float, sensor: SensorConfig, rng: np.random.Generator) -> np.ndarray:
    """(Poisson(FW t max(b, 0)) + N(0, read²)) / FW of a blurred image b (values in fractions of the full well)."""
    fw = sensor.full_well_e
    electrons = rng.poisson(fw * transmission * np.clip(blurred, 0, None)) + rng.normal(0.0, sensor.read_noise_e,
                                                                                        blurred.shape)
    return electrons / fw


def _psnr_db(mse: float) -> float:
    return float(-10 * np.log10(mse))


def restored_psnr(kernels: np.ndarray, transmission, sensor: SensorConfig | None = None, crop_px: int = CROP_PX,
                  corners_px=CORNERS_PX, seed: int = 0, denoiser: str = "nlm") -> dict:
    """DeP's restored PSNR (module doc) per channel of kernels [3, S, S] (odd S) at transmission t (one number or
    one per kernel); with the noisy input's PSNR (y / t against x), the crops and the seconds."""
    start = time.perf_counter()
    sensor = sensor or SensorConfig()
    kernels = np.asarray(kernels, np.float64)
    trans = np.broadcast_to(np.asarray(transmission, np.float64), (len(kernels),))
    margin = kernels.shape[-1] // 2
    regions = natural_crops(crop_px, margin, corners_px)
    inner = slice(margin, margin + crop_px)
    restored, noisy = np.zeros((2, len(kernels)))
    for c, (k, t) in enumerate(zip(kernels, trans)):
        for i, region in enumerate(regions):
            x = region[c, inner, inner]
            y = degrade(region[c], k, float(t), sensor, stream(seed, "layout_restore", "noise", i, c))
            est = wiener_plane(denoise_plane(y, denoiser) / t, k, stream(seed, "layout_restore", "wiener", i, c))
            restored[c] += np.mean((np.clip(est, 0, None) - x) ** 2) / len(regions)
            noisy[c] += np.mean((y / t - x) ** 2) / len(regions)
    dep = [_psnr_db(v) for v in restored]
    return {"restorer": "dep", "denoiser": denoiser, "psnr_db": dep, "mean_psnr_db": float(np.mean(dep)),
            "input_psnr_db": [_psnr_db(v) for v in noisy], "transmission": trans.tolist(), "crop_px": int(crop_px),
            "corners_px": [list(map(int, c)) for c in corners_px], "image": "skimage.data.astronaut",
            "mean_level": MEAN_LEVEL, "seed": int(seed), "seconds": time.perf_counter() - start}
