"""Laser PSF measurements from closed forms alone: no call into the PSF engine (psf.*) nor into the fit's own
forward model (udc_render.fit.synthetic, .families). What `udc-render fit` is checked against.

A display at the lens's pupil with cell p_x × p_y and transmission t(x, y) = Σ c_mn exp(2πi (m x / p_x + n y / p_y))
sends the lens's field into orders: in the focal plane (Fraunhofer, the lens of focal length f and aperture D)
    A(u) = Σ_mn c_mn a(|u − u_mn|),   u_mn = u_0 + R(φ) (m λ f / p_x, n λ f / p_y),
    a(r) = 2 J₁(v) / v,   v = π D r / (λ f)          (the lens's Airy amplitude),
and the PSF is |A|² (the orders' spots interfere where their wings overlap). The coefficients of a cell's
openings, each centred at (x_j, y_j) in cell units (the phase exp(−2πi (m x_j + n y_j))):
    a rectangle w × h:   c = w h sinc(m w) sinc(n h)        (P_mn / P_00 = sinc²(m w) sinc²(n h): a slit grating)
    a circle of diameter D_o (cell units of a square cell):   c = (π D_o² / 4) · 2 J₁(π ρ D_o) / (π ρ D_o),
        ρ = √(m² + n²)                                       (the Airy form).
Each pixel is |A|²'s integral over it, exact (psf: |A|² is band-limited); the frame is then exposed:
Poisson photons, Gaussian read noise, a conversion gain, a black level, rounding and the white level's clip.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import j1

from udc_render.streams import stream

F_UM, F_NUMBER = 6000.0, 1.8  # the fit's default lens (FitSpec): f = 6 mm, f/1.8
PAD_PX = 150.0  # the orders this far beyond the frame are summed: an order 1e-5 of the zeroth's power within
# 0.5 % of its sum over 1200 px (the Airy amplitude's wings fall as r^-3/2)


@dataclass(frozen=True)
class Rectangle:
    """A rectangular opening: centre (cell units) and width, height (fractions of the cell)."""
    cx: float
    cy: float
    w: float
    h: float

    def coefficient(self, m: np.ndarray, n: np.ndarray) -> np.ndarray:
        return self.w * self.h * np.sinc(m * self.w) * np.sinc(n * self.h) * _phase(m, n, self.cx, self.cy)

    @property
    def area(self) -> float:
        return self.w * self.h


@dataclass(frozen=True)
class Circle:
    """A circular opening: centre and diameter (units of a square cell's side)."""
    cx: float
    cy: float
    d: float

    def coefficient(self, m: np.ndarray, n: np.ndarray) -> np.ndarray:
        v = math.pi * np.hypot(m, n) * self.d
        form = np.where(v > 0, 2 * j1(np.where(v > 0, v, 1.0)) / np.where(v > 0, v, 1.0), 1.0)
        return self.area * form * _phase(m, n, self.cx, self.cy)

    @property
    def area(self) -> float:
        return math.pi * self.d ** 2 / 4


def _phase(m, n, cx, cy):
    return np.exp(-2j * math.pi * (m * cx + n * cy))


def stripe(width: float, height: float) -> tuple:
    """The T-OLED's cell: one centred rectangle."""
    return (Rectangle(0.5, 0.5, width, height),)


def pentile(open_fraction: float, small_to_large: float) -> tuple:
    """The P-OLED's cell (psf.layouts.poled's arrangement, written out here): large circles of radius r at
    (¼, ¼), (¾, ¾), small ones of radius k r at (¾, ¼), (¼, ¾); 2π r² (1 + k²) = open fraction."""
    r = math.sqrt(open_fraction / (2 * math.pi * (1 + small_to_large ** 2)))
    k = small_to_large
    return (Circle(0.25, 0.25, 2 * r), Circle(0.75, 0.75, 2 * r), Circle(0.75, 0.25, 2 * k * r),
            Circle(0.25, 0.75, 2 * k * r))


def holes(open_fraction: float) -> tuple:
    """One centred circular hole per square cell."""
    return (Circle(0.5, 0.5, math.sqrt(4 * open_fraction / math.pi)),)


def coefficients(cell: tuple, m: np.ndarray, n: np.ndarray) -> np.ndarray:
    return sum(o.coefficient(m, n) for o in cell)


@dataclass(frozen=True)
class Shot:
    """Where the spot is and how it is turned: the zeroth order's centre (frame px, pixel (0, 0)'s centre at 0),
    the display's x axis turned by rotation_deg from the frame's x towards +y, the laser's wavelength, the
    sensor's pixel."""
    centre_px: tuple
    rotation_deg: float = 0.0
    wavelength_um: float = 0.65
    pixel_um: float = 1.55


def order_positions(cell_pitch_um: tuple, shot: Shot, m: np.ndarray, n: np.ndarray) -> np.ndarray:
    """[N, 2] frame positions (px) of orders (m, n)."""
    lz = shot.wavelength_um * F_UM / shot.pixel_um
    a = math.radians(shot.rotation_deg)
    e = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]) @ \
        np.diag([lz / cell_pitch_um[0], lz / cell_pitch_um[1]])
    return np.asarray(shot.centre_px, float)[None, :] + np.stack([m, n], axis=1) @ e.T


def _orders(cell: tuple, pitch_um: tuple, shot: Shot, lo: np.ndarray, hi: np.ndarray):
    """(c_mn, positions [N, 2]) of every order whose spot lies in the box lo … hi (px, x then y)."""
    lz = shot.wavelength_um * F_UM / shot.pixel_um
    k = int(math.ceil(np.max(hi - lo) / (lz / max(pitch_um)))) + 1
    mm, nn = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1), indexing="ij")
    m, n = mm.ravel(), nn.ravel()
    xy = order_positions(pitch_um, shot, m, n)
    inside = np.all((xy >= lo) & (xy <= hi), axis=1)
    c = coefficients(cell, m[inside], n[inside])
    keep = np.abs(c) > 1e-12 * np.abs(c).max(initial=0.0)
    return c[keep], xy[inside][keep]


def cutoff_per_px(shot: Shot) -> float:
    """The pupil's cut-off frequency D / (2 λ f) in cycles per pixel: a(r) = 2 J₁(v) / v is the Fourier
    transform of the disc of that radius."""
    return (F_UM / F_NUMBER) * shot.pixel_um / (2 * shot.wavelength_um * F_UM)


def airy_amplitude(r_px: np.ndarray, shot: Shot) -> np.ndarray:
    """a(r) = 2 J₁(v) / v, v = π D r / (λ f) = 2π ρ_c r."""
    v = 2 * math.pi * cutoff_per_px(shot) * np.asarray(r_px, float)
    safe = np.where(v > 0, v, 1.0)
    return np.where(v > 0, 2 * j1(safe) / safe, 1.0)


def field_direct(cell: tuple, pitch_um: tuple, shot: Shot, xy_px: np.ndarray, lo_px, hi_px) -> np.ndarray:
    """A at points xy [P, 2] (px) by the sum of the module doc over the orders in the box lo_px … hi_px ((x, y)),
    J₁ evaluated at every point: the reference the fast field below is checked against."""
    c, uv = _orders(cell, pitch_um, shot, np.asarray(lo_px, float), np.asarray(hi_px, float))
    r = np.hypot(xy_px[:, None, 0] - uv[None, :, 0], xy_px[:, None, 1] - uv[None, :, 1])
    return airy_amplitude(r, shot) @ c


def field_grid(cell: tuple, pitch_um: tuple, shot: Shot, x_px: np.ndarray, y_px: np.ndarray, pad_px: float,
               guard_px: float = 0.0) -> np.ndarray:
    """A [len(y), len(x)] on a uniform grid (x_px, y_px: equally spaced, the same step) of the orders within
    pad_px of it (_periodic_field, cropped)."""
    amp, edge = _periodic_field(cell, pitch_um, shot, x_px, y_px, pad_px, guard_px)
    return amp[edge:edge + y_px.size, edge:edge + x_px.size]


def _periodic_field(cell, pitch_um, shot: Shot, x_px, y_px, pad_px: float, guard_px: float):
    """(A on the grid extended by pad_px + guard_px on each side, that extension in steps): the sum of the
    module doc as the inverse DFT of its spectrum Σ c_mn exp(−2πi ξ·u_mn) on the pupil's disc |ξ| < ρ_c (a(r)
    is the disc's transform). By Poisson's summation formula the DFT gives the sum exactly, periodised with
    the extended grid's period: the nearest image of an order is pad_px + 2 guard_px beyond the grid (with
    guard 0, as near as the farthest order summed)."""
    step = x_px[1] - x_px[0]
    edge = int(round((pad_px + guard_px) / step))
    nx, ny = x_px.size + 2 * edge, y_px.size + 2 * edge
    x0, y0 = x_px[0] - edge * step, y_px[0] - edge * step
    c, uv = _orders(cell, pitch_um, shot, np.array([x_px[0], y_px[0]]) - pad_px,
                    np.array([x_px[-1], y_px[-1]]) + pad_px)
    fx, fy = np.fft.fftfreq(nx, step), np.fft.fftfreq(ny, step)
    rho = cutoff_per_px(shot)
    ix, iy = np.nonzero(np.abs(fx) < rho)[0], np.nonzero(np.abs(fy) < rho)[0]
    ex = np.exp(-2j * math.pi * fx[ix, None] * (uv[None, :, 0] - x0))
    ey = np.exp(-2j * math.pi * fy[iy, None] * (uv[None, :, 1] - y0))
    spectrum = (ey * c[None, :]) @ ex.T  # [fy, fx]
    spectrum *= np.hypot(fx[ix][None, :], fy[iy][:, None]) < rho
    full = np.zeros((ny, nx), complex)
    full[np.ix_(iy, ix)] = spectrum
    return np.fft.ifft2(full) / (step * step * math.pi * rho ** 2), edge  # Σ F Δξ², Δξ = 1 / (n step); a(0) = 1


def psf(cell: tuple, pitch_um: tuple, shot: Shot, shape_hw: tuple, oversample: int = 3,
        pad_px: float | None = None) -> np.ndarray:
    """The noise-free PSF [H, W] (module doc; arbitrary units): |A|² integrated exactly over each pixel (pixel
    (0, 0)'s centre at 0), the orders within pad_px of the frame. |A|² is band-limited to 2 ρ_c (1.32 cycles
    per pixel at f/1.8, 650 nm, 1.55 µm): sampled at `oversample` (odd, ≥ 3: a Nyquist of 1.5) points per pixel
    it holds all of it, and its pixel integral is the sampled image times the pixel's transfer sinc(f_x) sinc(f_y)
    (a product in the DFT of the periodic grid) read at the pixels' centres."""
    if oversample % 2 == 0 or oversample / 2 <= 2 * cutoff_per_px(shot):
        raise ValueError(f"oversample {oversample}: expected an odd number above 4 ρ_c = "
                         f"{4 * cutoff_per_px(shot):.3g}")
    h, w = shape_hw
    pad = PAD_PX if pad_px is None else pad_px
    centre = (oversample - 1) // 2
    x, y = (np.arange(w * oversample) - centre) / oversample, (np.arange(h * oversample) - centre) / oversample
    amp, edge = _periodic_field(cell, pitch_um, shot, x, y, pad, 0.0)
    power = np.fft.fft2(amp.real ** 2 + amp.imag ** 2)
    fx, fy = np.fft.fftfreq(amp.shape[1], 1.0 / oversample), np.fft.fftfreq(amp.shape[0], 1.0 / oversample)
    pixel = np.fft.ifft2(power * np.outer(np.sinc(fy), np.sinc(fx))).real
    return pixel[edge + centre:edge + y.size:oversample, edge + centre:edge + x.size:oversample]


@dataclass(frozen=True)
class Camera:
    """The exposure: full well (e⁻), read noise (e⁻), bit depth, black level (DN); the conversion gain puts the
    full well at the white level."""
    full_well_e: float = 15506.0
    read_noise_e: float = 4.87
    bits: int = 12
    black_dn: int = 64

    @property
    def white_dn(self) -> int:
        return 2 ** self.bits - 1

    @property
    def dn_per_e(self) -> float:
        return (self.white_dn - self.black_dn) / self.full_well_e


def expose(image: np.ndarray, peak_fw: float, camera: Camera, seed: int, key: str,
           vignetting: float = 0.0) -> np.ndarray:
    """One uint16 frame: the brightest pixel at peak_fw of the full well (above 1: saturated), times a
    radial fall-off 1 − vignetting r² / r_corner² about the frame's centre."""
    h, w = image.shape
    y, x = np.mgrid[0:h, 0:w]
    r2 = (x - (w - 1) / 2) ** 2 + (y - (h - 1) / 2) ** 2
    e = image / image.max() * peak_fw * camera.full_well_e * (1.0 - vignetting * r2 / r2.max())
    rng = stream(seed, "closed-form-psf", key)
    electrons = rng.poisson(e) + rng.normal(0.0, camera.read_noise_e, e.shape)
    dn = np.rint(camera.black_dn + electrons * camera.dn_per_e)
    return np.clip(dn, 0, camera.white_dn).astype(np.uint16)
