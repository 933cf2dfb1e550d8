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

from . import fourier
from .errors import PSFError
from .lens import Lens
from .propagation import angular_spectrum_tf

__all__ = ["order_autocorrelation", "even_order_autocorrelation", "orders", "disc_quadrant", "PowerSeries",
           "power_grid", "power_lattice", "banding_profile"]

# PowerSeries.truncated: the bound on the dropped weights, relative to the mean power w_0. 1e-5 keeps
# 413 × 200 of the T-OLED's 3169 × 1585 half weights at 400 nm (measured error 3.5e-7 of w_0, 1e-4 keeps
# 91 × 32 at 1e-5): 1e-3 of its bands' amplitude.
SERIES_RTOL = 1e-5


def order_autocorrelation(c: np.ndarray) -> np.ndarray:
    """b_k = Σ_m c_{m+k} c*_m for k_y ∈ [−2my, 2my], k_x ∈ [0, 2mx] of orders c [2my+1, 2mx+1] (exact); the
    other half is b_{−k} = b_k* (|C|² below is real).

    Zero-padded FFT pair: C = FFT(c) (along x over c's rows only, the padding rows being zero), then
    b = IFFT(|C|²), whose half k_x ≥ 0 is conj(rfft2(|C|²)) / L²."""
    ny, nx = c.shape
    my, mx = ny // 2, nx // 2
    ly, lx = sfft.next_fast_len(2 * ny - 1), sfft.next_fast_len(2 * nx - 1)
    C = sfft.fft(sfft.fft(c, n=lx, axis=1, workers=fourier.WORKERS), n=ly, axis=0, workers=fourier.WORKERS)
    power = C.real ** 2
    power += C.imag ** 2
    half = sfft.rfft2(power, workers=fourier.WORKERS)[np.arange(-2 * my, 2 * my + 1) % ly, :2 * mx + 1]
    np.conj(half, out=half)
    half /= ly * lx
    return half


def even_order_autocorrelation(c: np.ndarray) -> np.ndarray:
    """order_autocorrelation's b for orders even in each axis (c[−ky, kx] = c[ky, −kx] = c[ky, kx], a display
    symmetric about its cell's centre lines): b is then real and even, returned for k_y = 0…2my, k_x = 0…2mx.

    The FFTs of even sequences of even length L are DCT-Is of their first L/2 + 1 samples,
    F_k = f_0 + (−1)^k f_{L/2} + 2 Σ_{0<n<L/2} f_n cos(2πkn/L): C = DCT-I(c) and b = DCT-I(|C|²) / L² on the
    quadrant, a quarter of the data of the complex FFTs."""
    ny, nx = c.shape
    my, mx = ny // 2, nx // 2
    hy, hx = sfft.next_fast_len(2 * my + 1), sfft.next_fast_len(2 * mx + 1)  # L/2 ≥ 2m + 1: no wrap
    q = np.zeros((hy + 1, hx + 1), c.dtype)
    q[:my + 1, :mx + 1] = c[my:, mx:]
    C = sfft.dct(sfft.dct(q, type=1, axis=1, workers=fourier.WORKERS), type=1, axis=0, workers=fourier.WORKERS)
    power = C.real ** 2
    power += C.imag ** 2
    b = sfft.dct(sfft.dct(power, type=1, axis=1, workers=fourier.WORKERS), type=1, axis=0, workers=fourier.WORKERS)
    return b[:2 * my + 1, :2 * mx + 1] / (4 * hy * hx)


def _even(c: np.ndarray) -> bool:
    """Whether orders c [2my+1, 2mx+1] are even in each axis (to 1e-12 of their largest)."""
    tol = 1e-12 * np.abs(c).max()
    return bool(np.abs(c - c[::-1]).max() <= tol and np.abs(c - c[:, ::-1]).max() <= tol)


def orders(period_um, wavelength_um: float) -> tuple[int, int]:
    """(mx, my) = ⌊p / λ⌋: the propagating orders |m| ≤ m of the display at λ."""
    return int(period_um[0] / wavelength_um), int(period_um[1] / wavelength_um)


def disc_quadrant(period_um, diameter_um: float, wavelength_um: float) -> np.ndarray:
    """Â(k/p) / Â(0) = 2 J1(q)/q, q = π D |k/p|, for k_y = 0…2my, k_x = 0…2mx with (mx, my) the orders at
    λ: the lags of the power series at λ and at every longer wavelength (the disc is even in each axis)."""
    mx, my = orders(period_um, wavelength_um)
    qx, qy = np.arange(2 * mx + 1) / period_um[0], np.arange(2 * my + 1) / period_um[1]
    q = math.pi * diameter_um * np.hypot(qx[None, :], qy[:, None])
    return np.where(q > 0, 2 * j1(q) / np.where(q > 0, q, 1.0), 1.0)


class PowerSeries:
    """P(s) for one display, lens, wavelength and distance, evaluated at any mask shift s.

    Kept as the half k_x ≥ 0 of the weights w_k = b_k Â(k/p) (w_{−k} = w_k*, so P = Re Σ_{k_x ≥ 0} γ w_k
    e^{−2πi k·s/p} with γ = 2 for k_x > 0); `weights` gives the whole grid [ky, kx]."""

    def __init__(self, display, lens: Lens, wavelength_um: float, distance_um: float, disc: np.ndarray | None = None):
        """disc: disc_quadrant for this display and lens at this or a shorter wavelength (shared between
        wavelengths; None: computed)."""
        px, py = display.period_um
        mx, my = orders((px, py), wavelength_um)
        kx, ky = np.arange(-mx, mx + 1), np.arange(-my, my + 1)
        nux, nuy = kx / px, ky / py
        c = display.fourier_coefficients(kx, ky) * angular_spectrum_tf(nux, nuy, wavelength_um, distance_um)
        c[np.add.outer(nuy ** 2, nux ** 2) >= 1.0 / wavelength_um ** 2] = 0.0
        self.kx, self.ky = np.arange(-2 * mx, 2 * mx + 1), np.arange(-2 * my, 2 * my + 1)
        self.period_um = (px, py)
        disc = disc_quadrant((px, py), lens.aperture_um, wavelength_um) if disc is None else disc
        area = math.pi * lens.aperture_um ** 2 / 4
        if _even(c):
            self._half = (even_order_autocorrelation(c) * disc[:2 * my + 1, :2 * mx + 1] * area)[np.abs(self.ky)]
        else:
            self._half = order_autocorrelation(c)
            self._half *= disc[np.abs(self.ky), :2 * mx + 1]
            self._half *= area

    @property
    def weights(self) -> np.ndarray:
        """w_k on the grid ky[:, None], kx[None, :] (µm²)."""
        return np.concatenate([np.conj(self._half[::-1, :0:-1]), self._half], axis=1)

    def __call__(self, shifts_um: np.ndarray) -> np.ndarray:
        """Transmitted power (µm² × unit irradiance) at mask shifts [..., 2] (x, y) in µm: power_grid on
        the grid of the distinct x and y shifts (a field-phase grid or a line of shifts costs one pass
        over the weights), gathered."""
        s = np.asarray(shifts_um, dtype=np.float64)
        xs, ix = np.unique(s[..., 0], return_inverse=True)
        ys, iy = np.unique(s[..., 1], return_inverse=True)
        grid = power_grid(self._half, self.period_um, xs, ys)
        return grid[iy.reshape(s.shape[:-1]), ix.reshape(s.shape[:-1])]

    def truncated(self, rtol: float = SERIES_RTOL) -> np.ndarray:
        """The half weights [2ny+1, nx+1] (k_y = −ny…ny, k_x = 0…nx) of the smallest orders box whose
        dropped weights sum (× γ) to at most rtol · w_0: rows |k_y| > ny and columns k_x > nx each drop
        at most rtol/2, so |P − P_box| ≤ rtol · w_0 at every shift (the mean power w_0 is kept)."""
        mag = np.abs(self._half) * np.where(np.arange(self._half.shape[1]) > 0, 2.0, 1.0)[None, :]
        c = self._half.shape[0] // 2
        budget = 0.5 * rtol * abs(self._half[c, 0])
        rows = mag[c:].sum(axis=1) + mag[c::-1].sum(axis=1) * (np.arange(c + 1) > 0)  # |k_y| = 0…2my
        cols = mag.sum(axis=0)
        ny = _smallest_kept(rows, budget)
        nx = _smallest_kept(cols, budget)
        return self._half[c - ny:c + ny + 1, :nx + 1].copy()


def _smallest_kept(mass: np.ndarray, budget: float) -> int:
    """The smallest n with Σ_{i > n} mass_i ≤ budget."""
    tail = np.concatenate([np.cumsum(mass[::-1])[::-1][1:], [0.0]])  # tail[n] = Σ_{i > n}
    return int(np.argmax(tail <= budget))


def power_grid(half: np.ndarray, period_um, xs_um: np.ndarray, ys_um: np.ndarray) -> np.ndarray:
    """P on the grid [ys, xs] of mask shifts (µm) from half weights [2ny+1, nx+1] (k_y = −ny…ny, k_x = 0…nx):
    Re Σ_ky e_y Σ_kx γ w e_x with γ = 2 for k_x > 0 (w_{−k} = w_k*): two matrix products."""
    ny, nx = half.shape[0] // 2, half.shape[1] - 1
    ex = np.exp(-2j * np.pi * np.outer(np.arange(nx + 1), xs_um) / period_um[0])  # [nx+1, X]
    ex[1:] *= 2.0
    ey = np.exp(-2j * np.pi * np.outer(ys_um, np.arange(-ny, ny + 1)) / period_um[1])  # [Y, 2ny+1]
    return (ey @ (half @ ex)).real


def _chirp_sum(x: np.ndarray, m: int, frequency: float) -> np.ndarray:
    """X[..., j] = Σ_n x[..., n] e^{−2πi f n j} for j = 0…m−1 (last axis): scipy's chirp z-transform
    (Bluestein, N log N), the one psf.fourier's 'czt' method uses."""
    from scipy.signal import czt  # here: scipy.signal costs a dataset worker's start-up ~1 s, and it has the maps
    return czt(x, m=m, w=np.exp(-2j * np.pi * frequency), a=1.0, axis=-1)


def power_lattice(half: np.ndarray, period_um, x0_um: float, dx_um: float, nx: int, y0_um: float, dy_um: float,
                  ny: int) -> np.ndarray:
    """power_grid [ny, nx] on the lattice of shifts x0 + i dx, y0 + j dy, by two chirp sums (_chirp_sum):
    O(N log N) where power_grid's products cost ny · nx · (rows of half)."""
    ky = np.arange(half.shape[0]) - half.shape[0] // 2
    kx = np.arange(half.shape[1])
    start = half * np.where(kx > 0, 2.0, 1.0) * np.exp(-2j * np.pi * kx * x0_um / period_um[0])[None, :]
    along_x = _chirp_sum(start, nx, dx_um / period_um[0])                            # [rows ky, nx]
    along_x *= np.exp(-2j * np.pi * ky * y0_um / period_um[1])[:, None]
    grid = _chirp_sum(along_x.T, ny, dy_um / period_um[1]).T  # [ny, nx]: e^{−2πi (ky − ky_0) j dy / p_y}
    return (grid * np.exp(-2j * np.pi * ky[0] * dy_um * np.arange(ny) / period_um[1])[:, None]).real


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
