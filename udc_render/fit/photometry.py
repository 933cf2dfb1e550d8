"""The orders' powers: a matched filter at every order of the lattice.

Each order of a display at d = 0 is the lens's Airy pattern (the pupil's PSF) shifted to u_mn, with power
P_mn ∝ |c_mn|² (c: the mask's Fourier coefficients). Its power is estimated by weighted least squares of
the template t_j (the Airy pattern's energy on pixel j, centred at u_mn: A / (λ z_i)² ∫ (2 J1(v)/v)² over the
pixel, v = π D r / (λ z_i), by a NODES × NODES Gauss–Legendre rule) on the data d_j within the aperture
(APERTURE_SPACING of the shortest order spacing, at most APERTURE_MAX_PX) of u_mn:
    P = Σ_j t_j d_j / Σ_j t_j²,   var P = Σ_j t_j² var_j / (Σ_j t_j²)²,   over the unmasked pixels,
and the parts of var P the fit moves to its model's level (refine): the order's own shot noise per unit power
B = Σ_j t_j² (κ / G_j) t_j / (Σ_j t_j²)² (the order puts P t_j on pixel j; κ / G_j its DN per electron) and the
read noise alone R = Σ_j t_j² σ_r,j² / (Σ_j t_j²)².
The weights are uniform, not 1 / var_j: the same filter runs on the model's kernel (refine), so the light
that neighbours and interference add to an order is counted alike in both only when the pixels weigh the
same in both (an HDR image's pixels come from different exposures, with variances that differ 100-fold
between an order's core and its wings: inverse-variance weights made the brightest T-OLED orders 5–9 %
brighter than the same filter on the engine's kernel, uniform weights 0.1–4 %). The template is the
diffraction-limited lens's: a lens PSF that differs from it scales every order alike (the fit's free scale).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import j1

from psf import Lens

NODES = 4
APERTURE_MAX_PX = 8.0
APERTURE_SPACING = 0.45  # the aperture's radius: this fraction of the shortest order spacing (at most 8 px)
MIN_TEMPLATE_SHARE = 0.99  # an order is measured in an exposure when its unmasked pixels hold ≥ this of Σ t²
CROSSTALK_REACH = 3  # the neighbours (± orders) whose Airy wings crosstalk counts


@dataclass(frozen=True)
class Optics:
    """The measurement's optics: the lens (focal length, aperture, focus), the laser's wavelength and the
    sensor's pixel pitch; lz_px = λ z_i / pixel, the order spacing (px) of a 1 µm period."""
    lens: Lens
    wavelength_nm: float
    pixel_um: float

    @property
    def lz_px(self) -> float:
        return self.wavelength_nm * 1e-3 * self.lens.image_distance_um / self.pixel_um


@dataclass(frozen=True)
class Orders:
    """One row per order and exposure: cell orders [N, 2] (m, n), window positions [N, 2], powers and their
    σ (the exposure's units), measured (the aperture inside the window and its pixels unmasked), the
    exposure's number, B and R (module doc)."""
    index: np.ndarray
    xy: np.ndarray
    power: np.ndarray
    sigma: np.ndarray
    measured: np.ndarray
    exposure: np.ndarray
    shot: np.ndarray
    floor: np.ndarray

    def snr(self) -> np.ndarray:
        return np.where(self.sigma > 0, self.power / np.where(self.sigma > 0, self.sigma, 1.0), 0.0)


def aperture_px(spacing_px: float) -> float:
    return min(APERTURE_MAX_PX, APERTURE_SPACING * spacing_px)


def airy_pixels(dx: np.ndarray, dy: np.ndarray, lens: Lens, wavelength_nm: float, pixel_um: float) -> np.ndarray:
    """Energy share of the Airy pattern on pixels centred at (dx, dy) px from its centre (module doc)."""
    x, w = np.polynomial.legendre.leggauss(NODES)
    x, w = x / 2, w / 2
    lz = wavelength_nm * 1e-3 * lens.image_distance_um
    px = (dx[..., None, None] + x[:, None]) * pixel_um
    py = (dy[..., None, None] + x[None, :]) * pixel_um
    v = math.pi * lens.aperture_um * np.hypot(px, py) / lz
    safe = np.where(v > 0, v, 1.0)
    airy = np.where(v > 0, (2 * j1(safe) / safe) ** 2, 1.0)
    area = math.pi * lens.aperture_um ** 2 / 4
    return np.einsum("...ij,i,j->...", airy, w, w) * area / lz ** 2 * pixel_um ** 2


def measure(value, var, usable, xy, index, radius_px, lens: Lens, wavelength_nm: float, pixel_um: float,
            read_var=None, shot_per_dn=None, sites=None) -> Orders:
    """The matched-filter power of every order at window positions xy [N, 2] (module doc). value, var,
    usable: the window's arrays [S, S] (centre pixel at (0, 0)); read_var, shot_per_dn: σ_r² and κ / G per pixel
    (None: 0); sites: the pixels the filter is restricted to (one CFA colour's, fit.cfa; None: every pixel), the
    template's share asked of the usable ones counted among them."""
    size = value.shape[0]
    half = size // 2
    r = int(math.ceil(radius_px))
    off = np.arange(-r, r + 1)
    cx, cy = np.rint(xy[:, 0]).astype(int), np.rint(xy[:, 1]).astype(int)
    inside = (cx - r >= -half) & (cx + r <= half) & (cy - r >= -half) & (cy + r <= half)
    ix = np.clip(cx[:, None, None] + off[None, None, :] + half, 0, size - 1)
    iy = np.clip(cy[:, None, None] + off[None, :, None] + half, 0, size - 1)
    dx = ix - half - xy[:, 0, None, None]
    dy = iy - half - xy[:, 1, None, None]
    disc = np.hypot(dx, dy) <= radius_px
    t = np.where(disc, airy_pixels(dx, dy, lens, wavelength_nm, pixel_um), 0.0)
    if sites is not None:
        t = np.where(sites[iy, ix], t, 0.0)
    tt_full = t * t
    d, ok = value[iy, ix], usable[iy, ix]
    t = np.where(ok, t, 0.0)
    tt = t * t
    den = np.sum(tt, axis=(1, 2))
    measured = inside & (den >= MIN_TEMPLATE_SHARE * np.sum(np.where(disc, tt_full, 0.0), axis=(1, 2))) & (den > 0)
    den = np.where(den > 0, den, 1.0)
    power = np.sum(t * np.where(ok, d, 0.0), axis=(1, 2)) / den
    sigma = np.sqrt(np.sum(tt * np.where(ok, var[iy, ix], 0.0), axis=(1, 2))) / den
    zero = np.zeros(len(index))
    read = zero if read_var is None else np.sum(tt * read_var[iy, ix], axis=(1, 2)) / den ** 2
    shot = zero if shot_per_dn is None else np.sum(tt * t * shot_per_dn[iy, ix], axis=(1, 2)) / den ** 2
    return Orders(index, xy, np.where(measured, power, 0.0), np.where(measured, sigma, np.inf), measured,
                  np.zeros(len(index), int), np.where(measured, shot, 0.0), np.where(measured, read, 0.0))


def measure_exposures(exposures, window, xy, index, radius_px, optics: "Optics", dn_per_e: float) -> Orders:
    """measure() in every exposure (its own pixels and units; hdr.Exposure: σ_r² its read variance, κ / G its
    shot noise), rows stacked."""
    rows = [measure(window.crop(e.d), window.crop(e.var), window.crop(e.usable), xy, index, radius_px, optics.lens,
                    optics.wavelength_nm, optics.pixel_um, window.crop(e.sigma) ** 2, dn_per_e / window.crop(e.gain))
            for e in exposures]

    def cat(name):
        return np.concatenate([getattr(r, name) for r in rows])
    return Orders(cat("index"), cat("xy"), cat("power"), cat("sigma"), cat("measured"),
                  np.repeat(np.arange(len(rows)), len(index)), cat("shot"), cat("floor"))


def crosstalk(e_px: np.ndarray, radius_px: float, lens: Lens, wavelength_nm: float, pixel_um: float,
              reach: int = CROSSTALK_REACH) -> np.ndarray:
    """X [2 reach + 1, 2 reach + 1] (Δn, Δm): the matched filter's power at an order from a unit-power Airy
    spot Δm e_1 + Δn e_2 away (e_px: columns e_1, e_2), X(0) = 1: the neighbours' incoherent light each order's
    power holds, Σ_Δ X(Δ) P_(m+Δm, n+Δn) (the orders' interference and the pixels' phases aside: the engine's
    render adds those; the filter is centred on a pixel)."""
    r = int(math.ceil(radius_px))
    g = np.arange(-r, r + 1, dtype=float)
    dx, dy = np.meshgrid(g, g)
    disc = np.hypot(dx, dy) <= radius_px
    t = np.where(disc, airy_pixels(dx, dy, lens, wavelength_nm, pixel_um), 0.0)
    k = np.arange(-reach, reach + 1)
    out = np.zeros((len(k), len(k)))
    for a, dn in enumerate(k):
        for b, dm in enumerate(k):
            sx, sy = e_px @ np.array([dm, dn], float)
            out[a, b] = np.sum(t * airy_pixels(dx - sx, dy - sy, lens, wavelength_nm, pixel_um)) / np.sum(t * t)
    return out


def lattice_orders(lattice, index_basis: np.ndarray, half: int, radius_px: float) -> np.ndarray:
    """Every visible cell order (index_basis · Z²) whose aperture lies inside the window, [N, 2]."""
    e = np.stack([lattice.e1, lattice.e2], axis=1)
    corners = np.array([[-half, -half], [half, -half], [-half, half], [half, half]], float) - lattice.origin
    q = np.linalg.solve(e, corners.T)
    lo, hi = np.floor(q.min(axis=1)).astype(int), np.ceil(q.max(axis=1)).astype(int)
    m, n = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij")
    orders = np.stack([m.ravel(), n.ravel()], axis=1)
    vis = np.linalg.solve(index_basis, orders.T).T
    orders = orders[np.all(np.abs(vis - np.round(vis)) < 1e-6, axis=1)]
    xy = lattice.points(orders)
    inside = np.all(np.abs(xy) <= half - radius_px - 1, axis=1)
    return orders[inside]
