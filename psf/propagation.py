"""Free-space propagation of a sampled field between parallel planes (display → pupil).

Angular spectrum (exact scalar diffraction): H(ν) = exp(2πi d [sqrt(1/λ² − |ν|²) − 1/λ]),
evanescent for |ν| > 1/λ (decays, never NaN). The constant phase 2πd/λ is dropped and the
bracket is evaluated as −|ν|² / (1/λ + sqrt(1/λ² − |ν|²)) to avoid cancellation at large d.
The Fresnel transfer function exp(−iπλd|ν|²) is kept for the Talbot oracle (docs/PHYSICS.md §6).
"""
from __future__ import annotations

import numpy as np
import scipy.fft as sfft

__all__ = ["frequencies", "angular_spectrum_tf", "fresnel_tf", "ramp", "shift_ramp", "propagate"]


def frequencies(n: int, d_um: float) -> np.ndarray:
    """FFT sample frequencies (cycles/µm) of n samples spaced d_um."""
    return sfft.fftfreq(n, d=d_um)


def angular_spectrum_tf(fx, fy, wavelength_um: float, distance_um: float) -> np.ndarray:
    """Angular-spectrum transfer function on the grid fy[:, None], fx[None, :] (complex128).

    H depends on fx², fy² only: it is evaluated over the distinct |fx|, |fy| and gathered."""
    ux, ix = np.unique(np.abs(fx), return_inverse=True)
    uy, iy = np.unique(np.abs(fy), return_inverse=True)
    k2 = 1.0 / wavelength_um ** 2
    nu2 = np.add.outer(uy ** 2, ux ** 2)
    root = np.sqrt(np.abs(k2 - nu2))
    prop = nu2 <= k2
    phase = np.where(prop, -nu2 / (1.0 / wavelength_um + root), -1.0 / wavelength_um)
    phase *= 2 * np.pi * distance_um
    out = np.empty(phase.shape, np.complex128)
    np.cos(phase, out=out.real)
    np.sin(phase, out=out.imag)
    if not prop.all():
        out[~prop] *= np.exp(-2 * np.pi * distance_um * root[~prop])
    return out[np.ix_(iy.ravel(), ix.ravel())]


def fresnel_tf(fx, fy, wavelength_um: float, distance_um: float) -> np.ndarray:
    """Paraxial (Fresnel) transfer function exp(−iπλd|ν|²), constant phase dropped."""
    return np.exp(-1j * np.pi * wavelength_um * distance_um * (fx[None, :] ** 2 + fy[:, None] ** 2))


def ramp(f, shift_um: float) -> np.ndarray:
    """exp(−2πi f s) along one axis: the 1-D factor of shift_ramp."""
    return np.exp(-2j * np.pi * np.asarray(f) * shift_um)


def shift_ramp(fx, fy, shift_x_um: float, shift_y_um: float) -> np.ndarray:
    """exp(−2πi ν·s) = ramp(fy, s_y) ⊗ ramp(fx, s_x): multiplying a spectrum by it shifts the field by +s
    (band-limited shift)."""
    return np.outer(ramp(fy, shift_y_um), ramp(fx, shift_x_um))


def propagate(field: np.ndarray, dx_um: float, dy_um: float, wavelength_um: float, distance_um: float,
              transfer: str = "angular_spectrum", shift_um: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Propagate a periodic sampled field over distance_um and shift it by shift_um (window-periodic)."""
    ny, nx = field.shape
    fx, fy = frequencies(nx, dx_um), frequencies(ny, dy_um)
    tf = angular_spectrum_tf if transfer == "angular_spectrum" else fresnel_tf
    spec = sfft.fft2(field) * tf(fx, fy, wavelength_um, distance_um)
    if shift_um != (0.0, 0.0):
        spec *= shift_ramp(fx, fy, *shift_um)
    return sfft.ifft2(spec)
