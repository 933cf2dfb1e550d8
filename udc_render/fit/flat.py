"""The display-to-lens distance d from a flat field through the display (--flat).

A display a distance d in front of the lens prints bands of period T = z_i p / d on a flat field
(psf.banding: the power through the aperture, P(s), at the mask shift s = x d / z_i; docs/PHYSICS.md §4).
Measured: the frame (a CFA's sites and a colour image's channels each divided by their median) is
profiled across the bands along the display's axes as the PSF's lattice found them (rotation φ: the
coordinate ξ = x cos φ + y sin φ, 1-px bins); the log of the profile is fitted by least squares with
    ln I(ξ) = Σ_{j ≤ POLY_DEGREE} a_j L_j(ξ / ξ_max) + Σ_{h ≤ HARMONICS} [b_h cos(2π h ξ / T) + c_h sin(2π h ξ / T)]
(Legendre polynomials: the vignetting; T started at the FFT peak of the detrended profile, refined by a
bounded search of the residual, then scipy.optimize.least_squares with T free for its σ). Then
d = z_i p / T, σ_d / d = √((σ_p / p)² + (σ_T / T)²), the axes combined by inverse variance.
An axis counts when its first harmonic A_1 = √(b_1² + c_1²) is ≥ MIN_SNR σ and the frame holds ≥ MIN_PERIODS;
the most significant axis leads, and the other counts only when its d agrees with it within 3 σ (a T-OLED's
bands along y are a high harmonic of a period longer than the frame).
The check: A_1 against the fitted layout's series at d (studies.banding_fit.analytic_harmonics, equal-energy
white over CHECK_WAVELENGTHS_NM, averaged across the frame) × its PSF's OTF at 1/T (banding_fit.kernel_otf).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np
from numpy.polynomial import legendre

from psf import compute_kernels
from psf.banding import PowerSeries
from udc_render.fit.inputs import FitError, Frame, robust_sigma, saturated
from udc_render.fit.photometry import Optics

POLY_DEGREE, HARMONICS = 4, 2
MIN_SNR, MIN_PERIODS = 5.0, 2.0
CHECK_WAVELENGTHS_NM = (430.0, 490.0, 550.0, 610.0, 670.0)
CHECK_RATIO = (0.67, 1.5)  # measured / predicted first harmonic: the check passes inside this range


@dataclass(frozen=True)
class AxisFit:
    """One axis: period T ± σ (px), frames' periods, A_1 ± σ, the predicted A_1, d ± σ (mm), whether it counts."""
    axis: str
    period_px: float
    period_sigma_px: float
    periods_in_frame: float
    a1: float
    a1_sigma: float
    a1_predicted: float
    distance_mm: float
    distance_sigma_mm: float
    counts: bool


@dataclass(frozen=True)
class FlatFit:
    axes: tuple
    distance_mm: float
    distance_sigma_mm: float
    notes: tuple


def relative_image(frame: Frame) -> tuple[np.ndarray, np.ndarray]:
    """(the flat field with each CFA site class or colour channel divided by its median, the usable pixels)."""
    above = frame.above_black()
    planes = [(frame.dn[..., c], above[..., c]) for c in range(frame.dn.shape[-1])] if frame.kind == "rgb" else \
        [(frame.dn, above)]
    out, usable = np.zeros(frame.shape), np.ones(frame.shape, bool)
    for raw, d in planes:
        usable &= ~saturated(frame, raw)
        d = d.copy()
        sites = frame.site_map()
        for s in np.unique(sites):
            sel = sites == s
            d[sel] /= max(np.median(d[sel]), 1e-12)
        out += d / len(planes)
    usable &= out > 0.05
    return out, usable


def profile(img: np.ndarray, usable: np.ndarray, rotation_deg: float, axis: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ξ px, ln mean, its σ) in 1-px bins of ξ across the bands of `axis` (module doc)."""
    h, w = img.shape
    y, x = np.mgrid[0:h, 0:w]
    x, y = x - (w - 1) / 2, y - (h - 1) / 2
    a = math.radians(rotation_deg)
    xi = x * math.cos(a) + y * math.sin(a) if axis == "x" else -x * math.sin(a) + y * math.cos(a)
    b = np.rint(xi[usable] - xi.min()).astype(int)
    v = img[usable]
    n = np.bincount(b)
    s1, s2 = np.bincount(b, v), np.bincount(b, v * v)
    ok = n >= max(8, 0.5 * np.median(n[n > 0]))
    mean = s1[ok] / n[ok]
    sd = np.sqrt(np.maximum(s2[ok] / n[ok] - mean ** 2, 0.0) / n[ok])
    return np.nonzero(ok)[0] + xi.min(), np.log(mean), np.maximum(sd / mean, 1e-9)


def _design(xi, period, span, harmonics=HARMONICS):
    u = (xi - xi.mean()) / span
    cols = [legendre.legval(u, np.eye(POLY_DEGREE + 1)[j]) for j in range(POLY_DEGREE + 1)]
    for h in range(1, harmonics + 1):
        cols += [np.cos(2 * np.pi * h * xi / period), np.sin(2 * np.pi * h * xi / period)]
    return np.stack(cols, axis=1)


def _rss(xi, y, sig, period, span, harmonics=HARMONICS):
    a = _design(xi, period, span, harmonics) / sig[:, None]
    coef = np.linalg.lstsq(a, y / sig, rcond=None)[0]
    r = y / sig - a @ coef
    return float(r @ r), coef


def _refine(xi, y, sig, period, span, harmonics):
    """(T, σ_T, A_1, σ_A1): least squares with T free from `period` (covariance × max(1, χ²/dof))."""
    from scipy.optimize import least_squares

    def resid(p):
        return (y - _design(xi, p[0], span, harmonics) @ p[1:]) / sig
    coef = _rss(xi, y, sig, period, span, harmonics)[1]
    res = least_squares(resid, np.concatenate([[period], coef]), x_scale="jac")
    cov = np.linalg.pinv(res.jac.T @ res.jac) * max(1.0, float(res.fun @ res.fun) / max(xi.size - res.x.size, 1))
    i = POLY_DEGREE + 2
    b, c = res.x[i], res.x[i + 1]
    a1 = math.hypot(b, c)
    g = np.array([b, c]) / max(a1, 1e-300)
    return float(res.x[0]), math.sqrt(cov[0, 0]), a1, math.sqrt(float(g @ cov[i:i + 2, i:i + 2] @ g))


def fit_axis(xi: np.ndarray, y: np.ndarray, sig: np.ndarray) -> tuple[float, float, float, float]:
    """(T, σ_T, A_1, σ_A1) px of the profile's fit (module doc). Where the strongest peak is harmonic n of
    the bands (the T-OLED along y), the fit at n T (n HARMONICS harmonics) finds a significant first
    harmonic within the frame: the largest such n ≤ 3 is taken."""
    from scipy.optimize import minimize_scalar
    span = 0.5 * (xi.max() - xi.min())
    poly = _design(xi, 1e12, span)[:, :POLY_DEGREE + 1]
    detrended = y - poly @ np.linalg.lstsq(poly, y, rcond=None)[0]
    pad = 16 * xi.size
    spec = np.abs(np.fft.rfft(detrended - detrended.mean(), n=pad))
    spec[:int(1.5 * 16)] = 0.0  # below 1.5 periods per frame: the polynomial's
    f0 = np.argmax(spec) / pad
    best = minimize_scalar(lambda f: _rss(xi, y, sig, 1.0 / f, span)[0], bounds=(f0 - 1.0 / xi.size, f0 + 1.0 / xi.size),
                           method="bounded", options={"xatol": 1e-7})
    period = 1.0 / float(best.x)
    for n in (3, 2):
        if (xi.max() - xi.min()) / (n * period) >= MIN_PERIODS:
            t, st, a1, sa1 = _refine(xi, y, sig, n * period, span, n * HARMONICS)
            if a1 >= MIN_SNR * sa1:
                return t, st, a1, sa1
    return _refine(xi, y, sig, period, span, HARMONICS)


def predicted_a1(layout, optics: Optics, distance_mm: float, axis: str, period_px: float, across_px: float) -> float:
    """The first harmonic the fitted layout's series predicts at d (module doc)."""
    from udc_render.studies.banding_fit import analytic_harmonics, kernel_otf
    lens = optics.lens
    series = [PowerSeries(layout, lens, wl * 1e-3, distance_mm * 1000.0) for wl in CHECK_WAVELENGTHS_NM]
    across = np.linspace(-0.5, 0.5, 16) * across_px * optics.pixel_um
    harm = analytic_harmonics(series, np.ones(len(series)), SimpleNamespace(layout=layout), distance_mm, across,
                              lens.image_distance_um, axis)
    ks = compute_kernels(layout, lens, [550.0], pixel_um=optics.pixel_um, size_px=255)
    otf = kernel_otf(ks.kernels, optics.pixel_um, period_px * optics.pixel_um, axis)
    return float(harm[0] * abs(otf[0, 0]))


def fit_flat(frame: Frame, pitch_um, rotation_deg: float, layout, optics: Optics) -> FlatFit:
    """d from the flat field (module doc); pitch_um ((p_x, σ), (p_y, σ)) from the PSF fit."""
    img, usable = relative_image(frame)
    z = optics.lens.image_distance_um
    axes, notes = [], []
    for k, axis in enumerate("xy"):
        xi, y, sig = profile(img, usable, rotation_deg, axis)
        sig = np.maximum(sig, 0.5 * robust_sigma(np.diff(y)) / math.sqrt(2))
        t, st, a1, sa1 = fit_axis(xi, y, sig)
        periods = (xi.max() - xi.min()) / t
        counts = a1 >= MIN_SNR * sa1 and periods >= MIN_PERIODS
        p, sp = pitch_um[k]
        d = z * p / (t * optics.pixel_um) / 1000.0
        sd = d * math.hypot(sp / p, st / t)
        across = img.shape[0] if axis == "x" else img.shape[1]
        pred = predicted_a1(layout, optics, d, axis, t, across) if counts else math.nan
        axes.append(AxisFit(axis, t, st, periods, a1, sa1, pred, d, sd, bool(counts)))
        if not counts:
            notes.append(f"--flat: no bands along {axis} (first harmonic {a1:.2g} ± {sa1:.1g}, {periods:.1f} periods "
                         f"in the frame; needed ≥ {MIN_SNR:g} σ and ≥ {MIN_PERIODS:g} periods)")
    good = sorted((a for a in axes if a.counts), key=lambda a: -a.a1 / a.a1_sigma)
    for a in good[1:]:
        if abs(a.distance_mm - good[0].distance_mm) > 3 * math.hypot(a.distance_sigma_mm, good[0].distance_sigma_mm):
            notes.append(f"--flat: the bands along {a.axis} give d = {a.distance_mm:.4g} mm, against {good[0].distance_mm:.4g} "
                         f"mm along {good[0].axis}: a harmonic of a longer period, not counted")
            axes[axes.index(a)] = replace(a, counts=False)
    good = [a for a in axes if a.counts]
    if not good:
        raise FitError(f"--flat {frame.path}: no bands found: {'; '.join(notes)}: the display may be at d = 0, or the "
                       "bands longer than the frame")
    w = np.array([1.0 / a.distance_sigma_mm ** 2 for a in good])
    d = float(np.sum(w * [a.distance_mm for a in good]) / w.sum())
    return FlatFit(tuple(axes), d, float(1.0 / math.sqrt(w.sum())), tuple(notes))
