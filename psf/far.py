"""The far field of a periodic display (or the bare lens) at a coarse pitch, from its diffraction orders:
cheap where psf.engine is not (a window of ±R at any pitch needs a pupil raster of step λz/2R: 5000² samples
and ~15 s before the first wavelength for the paper's lens at ±1.8 mm).

A periodic mask m (Fourier coefficients c_ν per cell, ν = (k_x/p_x, k_y/p_y)) over the aperture A gives the
pupil field spectrum G(f) = Σ_ν c_ν Â(f − ν): order ν is the aperture's Airy pattern centred on the sensor at
u_ν = λ z_i ν (the engine's paraxial mapping) with the power |c_ν|² · area(A). On pixels of pitch ρ much wider
than the Airy core (λ z_i / D ≈ 1 µm for the paper's lens) the pixel-integrated PSF is

    K = (Σ_ν w_ν δ_{pixel of u_ν}) ⊗ a,     w_ν = |c_ν|² / Σ_ν' |c_ν'|²   (propagating orders, |ν| < 1/λ)

with a the Airy pattern's ring-averaged wing on the pixels (airy_tail). Left out: the interference of
neighbouring orders (the banding's cross terms b_k Â(k/p), k ≠ 0, which integrate to the banding contrast,
1e-2 of the power for the T-OLED and 3e-4 for the P-OLED, and lie near the low orders, inside a core window)
and the wing's ripple. Against compute_kernels at 23.25 µm (450 and 650 nm, a ±709 µm window;
tests/psf/test_far.py): the energy beyond 200 and 400 µm within 0.12 % (P-OLED) and 2.3 % (T-OLED), per pixel
2.6–3.0 % (P-OLED) and 1.1–9.6 % (T-OLED) L1; the bare lens's beyond 100, 200 and 400 µm within 0.73, 0.23 and
0.071 % of the analytic Airy pattern's pixel integrals (the engine, at the 2000² pupil that window needs, is
2–13 % off there). The display at a distance d changes no order's power (|H_ν| = 1 for propagating orders):
one set serves every d.
"""
from __future__ import annotations

import math

import numpy as np
import scipy.fft as sfft

from . import paper
from .engine import KernelSet
from .errors import PSFError
from .lens import Lens

__all__ = ["CACHE_NAME", "ORDER_PIXEL_FACTOR", "airy_tail", "order_kernels"]

CACHE_NAME = "far-orders-2"  # psf.cache's call name of order_kernels (raise it when its kernels change)
ORDER_PIXEL_FACTOR = 3.0  # pixels of at least 3 λ z / D: an order's Airy core within its pixel


def _orders(display, wavelength_um: float):
    """(k_x, k_y, |c|² [ky, kx], |ν|² [ky, kx]) of the orders up to the propagating limit at λ (|k/p| < 1/λ);
    the bare lens (display None) is the one order ν = 0."""
    if display is None:
        return np.zeros(1, int), np.zeros(1, int), np.ones((1, 1)), np.zeros((1, 1))
    px, py = display.period_um
    mx, my = int(px / wavelength_um), int(py / wavelength_um)
    kx, ky = np.arange(-mx, mx + 1), np.arange(-my, my + 1)
    return kx, ky, np.abs(display.fourier_coefficients(kx, ky)) ** 2, np.add.outer((ky / py) ** 2, (kx / px) ** 2)


def airy_tail(lens: Lens, wavelength_um: float, pixel_um: float, size_px: int) -> np.ndarray:
    """The bare lens's PSF on size_px² pixels of pixel_um ≫ λ z / D (unit total power): off the centre pixel
    the Airy pattern's ring-averaged wing, ρ² λ z / (π³ D r³) (from (2 J1(v)/v)² → 4 / (π v³), v = π D r / λ z;
    its integral beyond R is 2 λ z / (π² D R), the large-R limit of 1 − EE = J0² + J1²); the centre pixel the
    rest, less the wing beyond the box (the area-equivalent radius of its (size_px · pixel_um)² square)."""
    h = size_px // 2
    u = (np.arange(size_px) - h) * pixel_um
    r = np.hypot(u[None, :], u[:, None])
    lz, D = wavelength_um * lens.image_distance_um, lens.aperture_um
    tail = np.where(r > 0, pixel_um ** 2 * lz / (math.pi ** 3 * D * np.where(r > 0, r, 1.0) ** 3), 0.0)
    beyond = 2 * lz / (math.pi ** 2 * D * size_px * pixel_um / math.sqrt(math.pi))
    tail[h, h] = 1.0 - tail.sum() - beyond
    return tail


def _convolve_same(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Linear convolution of two S × S arrays centred at S // 2, cropped to a's window."""
    S = a.shape[0]
    n = sfft.next_fast_len(2 * S - 1, real=True)
    full = sfft.irfft2(sfft.rfft2(a, s=(n, n)) * sfft.rfft2(b, s=(n, n)), s=(n, n))
    return full[S // 2:S // 2 + S, S // 2:S // 2 + S]


def order_kernels(display, lens: Lens | None = None, wavelengths_nm=(450.0, 520.0, 640.0), pixel_um: float = 24.8,
                  size_px: int = 143, precision: str = "float32") -> KernelSet:
    """The PSF of a periodic display (None: the bare lens) on size_px² pixels of pixel_um (odd size, centred)
    from its diffraction orders, each with the Airy wing of the aperture (module doc): a KernelSet like
    compute_kernels' (kernels of unit sum in the window, energy_outside: the power outside it, transmittance:
    Σ |c_ν|², the mean power the orders carry over the bare aperture's, without the banding's cross terms)."""
    lens = lens or Lens()
    if display is not None and (not getattr(display, "periodic", True) or not hasattr(display, "fourier_coefficients")):
        raise PSFError("order_kernels needs a periodic display with Fourier coefficients (use compute_kernels)")
    if not (isinstance(size_px, (int, np.integer)) and size_px >= 3 and size_px % 2 == 1):
        raise PSFError(f"size_px must be an odd integer ≥ 3 (kernel centred at size//2), got {size_px}")
    wl = np.atleast_1d(np.asarray(wavelengths_nm, np.float64))
    z, h = lens.image_distance_um, size_px // 2
    least = ORDER_PIXEL_FACTOR * float(wl.max()) * 1e-3 * z / lens.aperture_um
    if not (pixel_um >= least and math.isfinite(pixel_um)):
        raise PSFError(f"pixel_um = {pixel_um}: expected ≥ {ORDER_PIXEL_FACTOR:g} λ z / D = {least:.3g} µm "
                       "(orders as points)")
    px, py = (1.0, 1.0) if display is None else display.period_um
    kx, ky, c2, nu2 = _orders(display, float(wl.min()) * 1e-3)  # the coefficients do not depend on λ
    kernels, outside, trans = [], [], []
    for lam in wl * 1e-3:
        propagating = nu2 < 1.0 / lam ** 2
        total = float(c2[propagating].sum())
        reach = (h + 0.5) * pixel_um / (lam * z)  # the window's half-width in frequency
        sx, sy = np.abs(kx / px) <= reach, np.abs(ky / py) <= reach
        w = np.where(propagating, c2, 0.0)[np.ix_(sy, sx)] / total
        jx = np.floor(lam * z * kx[sx] / px / pixel_um + 0.5).astype(int) + h
        jy = np.floor(lam * z * ky[sy] / py / pixel_um + 0.5).astype(int) + h
        okx, oky = (jx >= 0) & (jx < size_px), (jy >= 0) & (jy < size_px)
        k = np.zeros((size_px, size_px))
        rows = np.zeros((oky.sum(), size_px))  # orders' power summed into pixel columns, row by row of orders
        np.add.at(rows.T, jx[okx], w[np.ix_(oky, okx)].T)
        np.add.at(k, jy[oky], rows)
        k = _convolve_same(k, airy_tail(lens, lam, pixel_um, size_px))
        inside = float(k.sum())
        if not inside > 0:
            raise PSFError(f"no diffraction order of the display falls in the {size_px}-px window at {lam * 1e3:g} nm")
        kernels.append(k / inside)
        outside.append(1.0 - inside)
        trans.append(total)
    dtype = np.float32 if precision == "float32" else np.float64
    params = {"display": None if display is None else display.describe(), "lens": lens.describe(),
              "wavelengths_nm": wl.tolist(), "pixel_um": float(pixel_um), "size_px": int(size_px), "distance_mm": 0.0,
              "method": "orders", "precision": precision, "model": "diffraction orders × the Airy wing (psf.far)"}
    ratio = np.array([paper.formula_ratio_r(float(v), lens, pixel_um) for v in wl])
    period = None if display is None else (float(px), float(py))
    return KernelSet(np.stack(kernels).astype(dtype), wl, float(pixel_um), np.array(outside), np.array(trans), ratio,
                     params, period_um=period, image_distance_um=z)
