"""Scores of a PSF for restorability (numpy): UPC's ring statistics of the MTF, the Wiener estimate's expected
error under a natural-image spectrum and the sensor's noise, the open area.

Ring statistics (UPC's `utils/compute_mtf.m`): MTF = |fft2| of the unit-sum PSF without padding, DC at the
centre; rings of integer radius k = round(√(x² + y²)) bins; per ring the mean and the minimum; each averaged
over k = 1 … K (K = 146 on their 294² PSFs).

Restorability: y = T h ⊗ x + n, x with the natural-image power spectrum S(ν) = A / |ν|² (ν ≠ 0; exponent 2:
Field 1987, JOSA A 4:2379; van der Schaaf & van Hateren 1996, Vision Res. 36:2759), A set so that the image's
variance is (c μ)² (c: RMS contrast, μ: mean level), n white with the sensor's variance N. The Wiener (MMSE)
estimate's expected error per frequency is S N / (T² |H|² S + N), so per pixel
    MSE = (1/L²) Σ_{ν ≠ 0} S_ν N / (T² |H_ν|² S_ν + N),
in units of the glass capture's full well; reported as PSNR = −10 log10 MSE.
"""
from __future__ import annotations

import numpy as np

from udc_render.sensor.config import SensorConfig

__all__ = ["mtf", "ring_stats", "ring_summary", "natural_spectrum", "wiener_mse", "noise_variance",
           "restorability"]

RMS_CONTRAST = 0.3   # c: an assumption (a typical RMS contrast of natural scenes), a parameter of restorability
MEAN_LEVEL = 0.5     # μ: the scene's mean as a fraction of the full well through glass at the profile's exposure


def mtf(kernel: np.ndarray) -> np.ndarray:
    """|fft2| of the unit-sum kernel [S, S], DC moved to index S // 2 (UPC's ifftshift(fft2(fftshift(psf))))."""
    k = np.asarray(kernel, np.float64)
    return np.abs(np.fft.fftshift(np.fft.fft2(np.fft.ifftshift(k / k.sum()))))


def ring_stats(m: np.ndarray, rings: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(mean, minimum) of an MTF map [S, S] (DC at S // 2) over rings k = 0 … rings − 1 (default S // 2)."""
    s = m.shape[0]
    rings = rings or s // 2
    i = np.abs(np.arange(s) - s // 2)
    dist = np.rint(np.hypot(i[None, :], i[:, None])).astype(int)
    means = np.array([m[dist == k].mean() for k in range(rings)])
    mins = np.array([m[dist == k].min() for k in range(rings)])
    return means, mins


def ring_summary(kernels: np.ndarray, rings: int | None = None) -> dict:
    """Per channel: the mean over k ≥ 1 of the ring means and of the ring minima, and the curves."""
    curves = [ring_stats(mtf(k), rings) for k in kernels]
    return {"mean_of_ring_means": [float(c[0][1:].mean()) for c in curves],
            "mean_of_ring_minima": [float(c[1][1:].mean()) for c in curves],
            "ring_means": [c[0].tolist() for c in curves], "ring_minima": [c[1].tolist() for c in curves]}


def natural_spectrum(size: int, variance: float) -> np.ndarray:
    """S_ν = A / |ν|² on the size² DFT grid (cycles per pixel), S_0 = 0, mean over the grid = variance."""
    f = np.fft.fftfreq(size)
    f2 = f[None, :] ** 2 + f[:, None] ** 2
    s = np.where(f2 > 0, 1.0 / np.where(f2 > 0, f2, 1.0), 0.0)
    return s * variance / s.mean()


def wiener_mse(h, signal, noise, transmission=1.0, h_far=None):
    """Mean over the DFT grid of S N / (T² |H|² S + N) (module doc): h, signal [L, L] in fft2's order; numpy
    arrays or torch tensors (the designer's objective), the result of the same kind. With h_far, the light of that
    part of the kernel is interference (a scene independent of x, the same spectrum), N → N + T² S |H_far|²:
    S (N + T² S |H_far|²) / (T² (|H|² + |H_far|²) S + N)."""
    t2 = transmission ** 2
    far = 0.0 if h_far is None else t2 * signal * abs(h_far) ** 2
    v = signal * (noise + far) / (t2 * abs(h) ** 2 * signal + far + noise)
    return v.mean()


def noise_variance(sensor: SensorConfig, mean_level: float, transmission: float) -> float:
    """The sensor's noise variance in units of the full well², at mean T μ FW electrons: shot (T μ FW) plus read
    (read_noise_e²). The project's read noise is in electrons before the gain (sensor.noise), so the gain
    scales signal and noise alike and leaves this ratio unchanged."""
    fw = sensor.full_well_e
    return (transmission * mean_level * fw + sensor.read_noise_e ** 2) / fw ** 2


def restorability(kernels: np.ndarray, transmission, sensor: SensorConfig | None = None,
                  mean_level: float = MEAN_LEVEL, contrast: float = RMS_CONTRAST) -> dict:
    """Per channel: the Wiener estimate's PSNR (dB) and MSE on the kernel's own grid (module doc); transmission
    one number or one per kernel (e.g. the open area × the fraction of the light inside the window)."""
    sensor = sensor or SensorConfig()
    size = kernels.shape[-1]
    signal = natural_spectrum(size, (contrast * mean_level) ** 2)
    trans = np.broadcast_to(np.asarray(transmission, np.float64), (len(kernels),))
    noise = [noise_variance(sensor, mean_level, t) for t in trans]
    mses = [float(wiener_mse(np.fft.fft2(np.fft.ifftshift(k / k.sum())), signal, n, t))
            for k, n, t in zip(kernels, noise, trans)]
    return {"wiener_mse": mses, "wiener_psnr_db": [float(-10 * np.log10(v)) for v in mses],
            "transmission": trans.tolist(), "noise_variance": noise, "mean_level": mean_level,
            "rms_contrast": contrast, "full_well_e": sensor.full_well_e, "read_noise_e": sensor.read_noise_e}
