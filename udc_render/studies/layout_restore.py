"""`study layout --restore dep`: the restored PSNR by DeP of a natural image through a layout's exact kernels.

Per channel c (R, G, B of the rig's kernels k_c and the image's R, G, B), in units of the glass capture's full
well FW (udc_render.design.metrics.restorability's convention):
    y_c = (Poisson(FW · t_c · (x_c ⊗ k_c)) + N(0, read_noise_e²)) / FW,
x: fixed crops of photographs of skimage.data (CROP_SETS: 'astronaut', two crops of it, the committed studies';
'photos', eight crops of four photographs), sRGB values / 255 taken as linear, each image scaled so its mean is
the restorability's scene mean μ (MEAN_LEVEL of the full well); k_c: the unit-sum kernel; t_c: the transmission
given (the study passes open area × the fraction of the light inside the kernel's window: the rest is lost).
Each crop is blurred with its margin of half a kernel (the image reflected at its edges), so the crop has no
boundary of its own. DeP's per-plane steps (restore.dep) restore it: x̂_c = max(0, Wiener(denoise(y_c) / t_c)),
NLM with the noise std estimated, the unsupervised Wiener-Hunt sampler with the same kernel (seeded).
PSNR = −10 log10 MSE(x̂, x) over the crops (peak: the full well), per channel; beside it the noisy input's,
y_c / t_c against x_c, and each crop's own (for paired comparisons of layouts: studies.layout_compare). Noise
and sampler draw from named streams (udc_render.streams) keyed by crop and channel, not by layout, so two layouts
see the same draws. Cost: the Wiener sampler takes seconds per 192-px plane.
"""
from __future__ import annotations

import time

import numpy as np

from restore.dep import denoise_plane, wiener_plane
from udc_render.design.metrics import MEAN_LEVEL
from udc_render.sensor.config import SensorConfig
from udc_render.streams import stream

__all__ = ["RESTORERS", "CROP_PX", "CROP_SETS", "QUICK_CROP_PX", "natural_crops", "degrade", "restored_psnr"]

RESTORERS = ("dep",)
CROP_PX = 192
# (skimage.data image, top-left row, column) of each crop: astronaut's face, her suit and helmet; the cat's left eye,
# its right eye and nose; the cup and saucer, the saucer and the table; two launch towers against the dusk sky
CROP_SETS = {"astronaut": (("astronaut", 64, 160), ("astronaut", 300, 280)),
             "photos": (("astronaut", 64, 160), ("astronaut", 300, 280), ("chelsea", 60, 40), ("chelsea", 100, 250),
                        ("coffee", 30, 40), ("coffee", 200, 380), ("rocket", 40, 60), ("rocket", 220, 420))}
QUICK_CROP_PX = 96


def _image(name: str) -> np.ndarray:
    """skimage.data's `name` [3, h, w] as sRGB values / 255, scaled to mean MEAN_LEVEL."""
    import skimage.data
    img = getattr(skimage.data, name)().astype(np.float64).transpose(2, 0, 1) / 255
    return img * (MEAN_LEVEL / img.mean())


def natural_crops(crop_px: int, margin_px: int, crops=CROP_SETS["astronaut"]) -> np.ndarray:
    """[n, 3, crop + 2 margin, …] crops (image, row, column) of skimage.data's photographs (each image's values / 255
    scaled to mean MEAN_LEVEL), each with a margin of margin_px around the crop at its corner; the image is
    reflected past its edges."""
    m, size = int(margin_px), int(crop_px) + 2 * int(margin_px)
    padded = {name: np.pad(_image(name), ((0, 0), (m, m), (m, m)), mode="reflect") for name in {c[0] for c in crops}}
    return np.stack([padded[name][:, r:r + size, c:c + size] for name, r, c in crops])


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
                  crops=CROP_SETS["astronaut"], seed: int = 0, denoiser: str = "nlm") -> dict:
    """DeP's restored PSNR (module doc) per channel of kernels [3, S, S] (odd S) at transmission t (one number or
    one per kernel), and per crop; with the noisy input's PSNR (y / t against x), the crops, the seconds and the
    first crop's truth, input y / t and estimate ('first_crop' [3 (x, y / t, x̂), 3, crop, crop]: the figure)."""
    start = time.perf_counter()
    sensor = sensor or SensorConfig()
    kernels = np.asarray(kernels, np.float64)
    trans = np.broadcast_to(np.asarray(transmission, np.float64), (len(kernels),))
    margin = kernels.shape[-1] // 2
    regions = natural_crops(crop_px, margin, crops)
    inner = slice(margin, margin + crop_px)
    restored, noisy = np.zeros((2, len(regions), len(kernels)))
    first = np.zeros((3, len(kernels), crop_px, crop_px))
    for c, (k, t) in enumerate(zip(kernels, trans)):
        for i, region in enumerate(regions):
            x = region[c, inner, inner]
            y = degrade(region[c], k, float(t), sensor, stream(seed, "layout_restore", "noise", i, c))
            est = np.clip(wiener_plane(denoise_plane(y, denoiser) / t, k, stream(seed, "layout_restore", "wiener", i,
                                                                                 c)), 0, None)
            restored[i, c], noisy[i, c] = np.mean((est - x) ** 2), np.mean((y / t - x) ** 2)
            if i == 0:
                first[:, c] = x, y / t, est
    dep = [_psnr_db(v) for v in restored.mean(axis=0)]
    return {"restorer": "dep", "denoiser": denoiser, "psnr_db": dep, "mean_psnr_db": float(np.mean(dep)),
            "input_psnr_db": [_psnr_db(v) for v in noisy.mean(axis=0)],
            "crop_psnr_db": [[_psnr_db(v) for v in row] for row in restored], "transmission": trans.tolist(),
            "crop_px": int(crop_px), "crops": [[name, int(r), int(c)] for name, r, c in crops],
            "image": "skimage.data " + ", ".join(dict.fromkeys(name for name, _, _ in crops)),
            "mean_level": MEAN_LEVEL, "seed": int(seed), "seconds": time.perf_counter() - start, "first_crop": first}
