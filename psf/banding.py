"""Transmitted power and banding for a display a distance d in front of the pupil (docs/PHYSICS.md §4).

A scene point imaged at sensor position x sends a beam that crosses the display over the
aperture disc shifted by s = x · d / z_i, so the power that reaches the sensor is
    P(s) = ∫ |m_d(x' − s)|² A(x') dx' = Σ_k b_k(d) Â(k/p) exp(−2πi k·s/p),
exactly, for a periodic display with Fourier coefficients c_m (per cell):
    b_k(d) = Σ_m c_{m+k} c*_m · H_{m+k} H*_m,  H_m = angular-spectrum transfer of order m over d,
over the propagating orders |m/p| < 1/λ (evanescent orders carry no power to the sensor), and
    Â(ν) = π D²/4 · 2 J1(π D |ν|) / (π D |ν|), the disc's Fourier transform.
The banding period on the sensor is z_i · p / d; at d = 0 every image point sees s = 0.
"""
from __future__ import annotations

import math

import numpy as np
import scipy.fft as sfft
from scipy.special import j1

from .errors import PSFError
from .lens import Lens
from .propagation import angular_spectrum_tf

__all__ = ["PowerSeries", "banding_profile"]


class PowerSeries:
    """P(s) for one display, lens, wavelength and distance, evaluated at any mask shift s."""

    def __init__(self, display, lens: Lens, wavelength_um: float, distance_um: float):
        px, py = display.period_um
        mx, my = int(px / wavelength_um), int(py / wavelength_um)
        kx, ky = np.arange(-mx, mx + 1), np.arange(-my, my + 1)
        nux, nuy = kx / px, ky / py
        c = display.fourier_coefficients(kx, ky) * angular_spectrum_tf(nux, nuy, wavelength_um, distance_um)
        c[nux[None, :] ** 2 + nuy[:, None] ** 2 >= 1.0 / wavelength_um ** 2] = 0.0
        # b_k = Σ_m c_{m+k} c*_m  (autocorrelation over orders, zero-padded FFT: exact)
        ly, lx = sfft.next_fast_len(4 * my + 1), sfft.next_fast_len(4 * mx + 1)
        C = sfft.fft2(c, s=(ly, lx))
        b = sfft.ifft2(np.abs(C) ** 2)
        self.kx, self.ky = np.arange(-2 * mx, 2 * mx + 1), np.arange(-2 * my, 2 * my + 1)
        b = b[np.ix_(self.ky % ly, self.kx % lx)]
        q = math.pi * lens.aperture_um * np.hypot(self.kx[None, :] / px, self.ky[:, None] / py)
        jinc = np.where(q > 0, 2 * j1(q) / np.where(q > 0, q, 1.0), 1.0)
        self.weights = b * (math.pi * lens.aperture_um ** 2 / 4) * jinc
        self.period_um = (px, py)

    def __call__(self, shifts_um: np.ndarray) -> np.ndarray:
        """Transmitted power (µm² × unit irradiance) at mask shifts [..., 2] (x, y) in µm."""
        s = np.asarray(shifts_um, dtype=np.float64)
        ex = np.exp(-2j * np.pi * s[..., 0, None] * self.kx / self.period_um[0])  # [..., Kx]
        ey = np.exp(-2j * np.pi * s[..., 1, None] * self.ky / self.period_um[1])  # [..., Ky]
        return np.einsum("...y,yx,...x->...", ey, self.weights, ex).real


def banding_profile(display, lens: Lens | None = None, wavelength_nm: float = 520.0, distance_mm: float = 1.0,
                    positions_um=None, axis: str = "x") -> tuple[np.ndarray, np.ndarray]:
    """(sensor positions µm, transmitted power / its mean) along one axis through the image centre.

    positions_um default: 400 samples over two banding periods. Needs a periodic display and d > 0.
    """
    lens = lens or Lens()
    if display is None or not getattr(display, "periodic", True):
        raise PSFError("banding needs a periodic display (a bare lens or randomly rotated tiles have no period)")
    if not distance_mm > 0:
        raise PSFError(f"banding needs distance_mm > 0, got {distance_mm}")
    if axis not in ("x", "y"):
        raise PSFError(f"axis must be 'x' or 'y', got '{axis}'")
    z, d_um = lens.image_distance_um, distance_mm * 1000.0
    period = display.period_um[0 if axis == "x" else 1]
    if positions_um is None:
        positions_um = np.linspace(0.0, 2 * z * period / d_um, 400)
    positions_um = np.asarray(positions_um, dtype=np.float64)
    shifts = np.zeros(positions_um.shape + (2,))
    shifts[..., 0 if axis == "x" else 1] = positions_um * d_um / z
    power = PowerSeries(display, lens, wavelength_nm * 1e-3, d_um)(shifts)
    return positions_um, power / power.mean()
