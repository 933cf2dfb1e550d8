"""The display-to-lens distance d from a flat field through the display (--flat).

A display a distance d in front of the lens prints bands of period T = z_i p / d on a flat field
(psf.banding: the power through the aperture, P(s), at the mask shift s = x d / z_i; docs/PHYSICS.md §4).
Measured: the frame (a CFA's sites and a colour image's channels each divided by their median) is
profiled across the bands along the display's axes as the PSF's lattice found them (rotation φ: the
coordinate ξ = x cos φ + y sin φ, 1-px bins); the log of the profile is fitted by least squares with
    ln I(ξ) = Σ_{j ≤ POLY_DEGREE} a_j L_j(ξ / ξ_max) + Σ_{h ≤ HARMONICS} [b_h cos(2π h ξ / T) + c_h sin(2π h ξ / T)]
(Legendre polynomials: the vignetting; T₀ the strongest line of the detrended profile's Hann-tapered
periodogram, refined by a bounded search of the residual, then scipy.optimize.least_squares with T free for its
σ). Then d = z_i p / T, σ_d / d = √((σ_p / p)² + (σ_T / T)²), the axes combined by inverse variance.
The check: A_1 = √(b_1² + c_1²) against the fitted layout's series at d (studies.banding_fit.analytic_harmonics,
equal-energy white over CHECK_WAVELENGTHS_NM, averaged across the frame) × its PSF's OTF at 1/T
(banding_fit.kernel_otf); it passes when their ratio lies within CHECK_RATIO.
Which period: the strongest line need not be the bands' fundamental. It may be a harmonic of longer bands
(a T-OLED's along y, whose first harmonic is weak), or a leftover illumination trend that the polynomial did
not take (a 5 % sine of 1.3 cycles per frame made the old rule, "2 T₀ or 3 T₀ whenever its first harmonic
passes 5 σ", halve d on the T-OLED of the guide). The candidates are FACTORS × T₀ (each with ≥ MIN_PERIODS
in the frame; at n T₀, n HARMONICS harmonics, T₀ among them); each must show its first harmonic ≥ MIN_SNR σ,
and the layout arbitrates: a longer period (2 T₀, 3 T₀) is taken only where the contrast the layout predicts
at its d agrees with the measured one (the check's range), the largest such; else T₀ where it agrees; else the
candidate that agrees most closely (T₀ / 2, T₀ / 3: the line at T₀ was a trend); else T₀, the check FAILS.
fit.json keeps every candidate, its contrast ratio and why it was or was not taken (flat.axes[].harmonic).
The other axis counts only when its d agrees with the leading one's within 3 σ (a T-OLED's bands along y can
be a high harmonic of a period longer than the frame).
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
MIN_PERIOD_PX = 2.0  # a candidate's period: at least two pixels per half period
FACTORS = (1.0, 2.0, 3.0, 0.5, 1.0 / 3.0)  # the candidates' periods, × the strongest line's
CHECK_WAVELENGTHS_NM = (430.0, 490.0, 550.0, 610.0, 670.0)
CHECK_RATIO = (0.67, 1.5)  # measured / predicted first harmonic: the check passes inside this range


@dataclass(frozen=True)
class AxisFit:
    """One axis: period T ± σ (px), frames' periods, A_1 ± σ, the predicted A_1, d ± σ (mm), whether it counts,
    the candidate periods weighed (Candidate.record) and why the one taken was."""
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
    candidates: tuple = ()
    choice: str = ""


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


def profile(img: np.ndarray, usable: np.ndarray, rotation_deg: float, axis: str
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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


def _design(xi, period, span, harmonics=HARMONICS, trend_px=None):
    """The columns: POLY_DEGREE + 1 Legendre polynomials, a trend line's cosine and sine (trend_px), the harmonics."""
    u = (xi - xi.mean()) / span
    cols = [legendre.legval(u, np.eye(POLY_DEGREE + 1)[j]) for j in range(POLY_DEGREE + 1)]
    if trend_px is not None:
        cols += [np.cos(2 * np.pi * xi / trend_px), np.sin(2 * np.pi * xi / trend_px)]
    for h in range(1, harmonics + 1):
        cols += [np.cos(2 * np.pi * h * xi / period), np.sin(2 * np.pi * h * xi / period)]
    return np.stack(cols, axis=1)


def _rss(xi, y, sig, period, span, harmonics=HARMONICS, trend_px=None):
    a = _design(xi, period, span, harmonics, trend_px) / sig[:, None]
    coef = np.linalg.lstsq(a, y / sig, rcond=None)[0]
    r = y / sig - a @ coef
    return float(r @ r), coef


def _refine(xi, y, sig, period, span, harmonics, trend_px=None):
    """(T, σ_T, A_1, σ_A1): least squares with T free from `period` (covariance × max(1, χ²/dof))."""
    from scipy.optimize import least_squares

    first = POLY_DEGREE + 1 + (0 if trend_px is None else 2)  # the harmonics' first column
    h = np.repeat(np.arange(1, harmonics + 1), 2)

    def resid(p):
        return (y - _design(xi, p[0], span, harmonics, trend_px) @ p[1:]) / sig

    def jac(p):
        d = _design(xi, p[0], span, harmonics, trend_px)
        phase = 2 * np.pi * np.outer(xi, h) / p[0]
        # d/dT of cos(2π h ξ / T) is sin(·) 2π h ξ / T², of sin(·) is −cos(·) 2π h ξ / T²
        dt = np.where(np.arange(h.size) % 2 == 0, np.sin(phase), -np.cos(phase)) * phase / p[0]
        return -np.concatenate([(dt @ p[1 + first:])[:, None], d], axis=1) / sig[:, None]
    coef = _rss(xi, y, sig, period, span, harmonics, trend_px)[1]
    res = least_squares(resid, np.concatenate([[period], coef]), jac=jac, x_scale="jac")
    cov = np.linalg.pinv(res.jac.T @ res.jac) * max(1.0, float(res.fun @ res.fun) / max(xi.size - res.x.size, 1))
    i = POLY_DEGREE + 2 + (0 if trend_px is None else 2)
    b, c = res.x[i], res.x[i + 1]
    a1 = math.hypot(b, c)
    g = np.array([b, c]) / max(a1, 1e-300)
    return float(res.x[0]), math.sqrt(cov[0, 0]), a1, math.sqrt(float(g @ cov[i:i + 2, i:i + 2] @ g))


def peak_period(xi: np.ndarray, y: np.ndarray, sig: np.ndarray) -> float:
    """T₀ px: the strongest line of the detrended profile's periodogram (a Hann taper, so that a leftover trend
    leaks little; lines below MIN_PERIODS per frame masked), refined by a bounded search of the residual."""
    from scipy.optimize import minimize_scalar
    span = 0.5 * (xi.max() - xi.min())
    poly = _design(xi, 1e12, span)[:, :POLY_DEGREE + 1]
    detrended = y - poly @ np.linalg.lstsq(poly, y, rcond=None)[0]
    pad = 16 * xi.size
    spec = np.abs(np.fft.rfft((detrended - detrended.mean()) * np.hanning(xi.size), n=pad))
    spec[:int(MIN_PERIODS * 16)] = 0.0
    f0 = np.argmax(spec) / pad
    best = minimize_scalar(lambda f: _rss(xi, y, sig, 1.0 / f, span)[0],
                           bounds=(f0 - 1.0 / xi.size, f0 + 1.0 / xi.size), method="bounded", options={"xatol": 1e-7})
    return 1.0 / float(best.x)


@dataclass(frozen=True)
class Candidate:
    """One hypothesis for the bands' period: `factor` × T₀ (2, 3: T₀ is a harmonic of the bands; 1/2, 1/3: the
    line at T₀ is a trend and the bands are shorter), the fit there (T ± σ, A_1 ± σ, periods in the frame),
    d, the first harmonic the layout predicts at that d, and why it was or was not taken."""
    factor: float
    period_px: float
    period_sigma_px: float
    a1: float
    a1_sigma: float
    periods_in_frame: float
    distance_mm: float = math.nan
    a1_predicted: float = math.nan
    verdict: str = ""

    def ratio(self) -> float:
        return self.a1 / self.a1_predicted if self.a1_predicted > 0 else math.nan

    def agrees(self) -> bool:
        return CHECK_RATIO[0] <= self.ratio() <= CHECK_RATIO[1]

    def record(self) -> dict:
        return {"factor_of_peak": self.factor, "period_px": self.period_px, "a1": self.a1,
                "a1_sigma": self.a1_sigma, "periods_in_frame": self.periods_in_frame, "distance_mm": self.distance_mm,
                "a1_predicted": self.a1_predicted, "contrast_ratio": self.ratio(), "verdict": self.verdict}


def candidates(xi: np.ndarray, y: np.ndarray, sig: np.ndarray) -> list[Candidate]:
    """The fits at FACTORS × T₀ that the frame holds ≥ MIN_PERIODS of (factor n ≥ 1: n HARMONICS harmonics, so
    that T₀ stays one of them; factor < 1: the line at T₀ fitted beside them as a trend)."""
    t0 = peak_period(xi, y, sig)
    span, length = 0.5 * (xi.max() - xi.min()), xi.max() - xi.min()
    out = []
    for f in FACTORS:
        if length / (f * t0) < MIN_PERIODS or f * t0 < 2 * MIN_PERIOD_PX:
            continue
        t, st, a1, sa1 = _refine(xi, y, sig, f * t0, span, max(1, round(f)) * HARMONICS, t0 if f < 1 else None)
        out.append(Candidate(f, t, st, a1, sa1, length / t))
    return out


def choose(cands: list[Candidate], predict) -> tuple[Candidate | None, list[Candidate]]:
    """(the chosen candidate or None, every candidate with its verdict): a significant first harmonic is asked
    of each; the layout's prediction at its d (predict(c) -> (d, A_1)) arbitrates, in the module doc's order,
    each prediction made only when it is needed."""
    done = {id(c): c for c in cands}

    def weigh(c):
        if c.a1 < MIN_SNR * c.a1_sigma:
            done[id(c)] = replace(c, verdict=f"first harmonic {c.a1 / c.a1_sigma:.1f} σ: below {MIN_SNR:g} σ")
            return None
        d, pred = predict(c)
        done[id(c)] = c = replace(c, distance_mm=d, a1_predicted=pred)
        return c
    order = sorted((c for c in cands if c.factor > 1), key=lambda c: -c.factor) + \
        [c for c in cands if c.factor == 1] + [c for c in cands if c.factor < 1]
    chosen, peak, shorter = None, None, []
    for c in order:
        w = weigh(c)
        if w is None:
            continue
        if c.factor == 1:
            peak = w
        if w.agrees() and c.factor >= 1:
            chosen = w
            break
        if c.factor < 1 and w.agrees():
            shorter.append(w)
    if chosen is None and shorter:  # the peak's contrast is not the layout's: the bands are shorter, the peak a trend
        chosen = min(shorter, key=lambda c: abs(math.log(c.ratio())))
    chosen = chosen or peak
    out = [_verdict(done[id(c)], chosen) for c in cands]
    return (next(o for o, c in zip(out, cands) if done[id(c)] is chosen) if chosen else None), out


def _verdict(c: Candidate, chosen: Candidate | None) -> Candidate:
    if c is chosen:
        why = "taken: the layout predicts its first harmonic within the check's range" if c.agrees() else \
            "taken: the strongest line (no candidate's contrast agrees with the layout's: the check FAILS)"
    elif c.verdict:
        why = c.verdict
    elif math.isnan(c.a1_predicted):
        why = "not weighed (a candidate before it was taken)"
    elif c.agrees():
        why = "agrees with the layout, less closely than the one taken"
    else:
        why = f"contrast {c.ratio():.2f} × the layout's at its d: outside {CHECK_RATIO[0]:g}–{CHECK_RATIO[1]:g}"
    return replace(c, verdict=why)


class Predictor:
    """The layout's first harmonic at a candidate's d (predicted_a1), the kernel for the OTF computed once."""

    def __init__(self, layout, optics: Optics, pitch_um: float, axis: str, across_px: float):
        self.layout, self.optics, self.pitch_um, self.axis, self.across_px = layout, optics, pitch_um, axis, across_px
        self.kernels = None

    def __call__(self, c: Candidate) -> tuple[float, float]:
        if self.kernels is None:
            self.kernels = compute_kernels(self.layout, self.optics.lens, [550.0], pixel_um=self.optics.pixel_um,
                                           size_px=255).kernels
        d = self.optics.lens.image_distance_um * self.pitch_um / (c.period_px * self.optics.pixel_um) / 1000.0
        return d, predicted_a1(self.layout, self.optics, d, self.axis, c.period_px, self.across_px, self.kernels)


def predicted_a1(layout, optics: Optics, distance_mm: float, axis: str, period_px: float, across_px: float,
                 kernels=None) -> float:
    """The first harmonic the fitted layout's series predicts at d (module doc); kernels: the layout's 550-nm
    kernel (computed when None)."""
    from udc_render.studies.banding_fit import analytic_harmonics, kernel_otf
    lens = optics.lens
    series = [PowerSeries(layout, lens, wl * 1e-3, distance_mm * 1000.0) for wl in CHECK_WAVELENGTHS_NM]
    across = np.linspace(-0.5, 0.5, 16) * across_px * optics.pixel_um
    harm = analytic_harmonics(series, np.ones(len(series)), SimpleNamespace(layout=layout), distance_mm, across,
                              lens.image_distance_um, axis)
    if kernels is None:
        kernels = compute_kernels(layout, lens, [550.0], pixel_um=optics.pixel_um, size_px=255).kernels
    otf = kernel_otf(kernels, optics.pixel_um, period_px * optics.pixel_um, axis)
    return float(harm[0] * abs(otf[0, 0]))


def fit_flat(frame: Frame, pitch_um, rotation_deg: float, layout, optics: Optics) -> FlatFit:
    """d from the flat field (module doc); pitch_um ((p_x, σ), (p_y, σ)) from the PSF fit."""
    img, usable = relative_image(frame)
    z = optics.lens.image_distance_um
    axes, notes = [], []
    for k, axis in enumerate("xy"):
        xi, y, sig = profile(img, usable, rotation_deg, axis)
        sig = np.maximum(sig, 0.5 * robust_sigma(np.diff(y)) / math.sqrt(2))
        p, sp = pitch_um[k]
        across = img.shape[0] if axis == "x" else img.shape[1]
        chosen, cands = choose(candidates(xi, y, sig), Predictor(layout, optics, p, axis, across))
        if chosen is None:
            notes.append(f"--flat: no bands along {axis} (no first harmonic ≥ {MIN_SNR:g} σ with ≥ {MIN_PERIODS:g} "
                         "periods in the frame)")
            axes.append(AxisFit(axis, math.nan, math.nan, math.nan, 0.0, math.inf, math.nan, math.nan, math.nan,
                                False, tuple(c.record() for c in cands), ""))
            continue
        d = z * p / (chosen.period_px * optics.pixel_um) / 1000.0
        sd = d * math.hypot(sp / p, chosen.period_sigma_px / chosen.period_px)
        axes.append(AxisFit(axis, chosen.period_px, chosen.period_sigma_px, chosen.periods_in_frame, chosen.a1,
                            chosen.a1_sigma, chosen.a1_predicted, d, sd, True, tuple(c.record() for c in cands),
                            chosen.verdict))
        if chosen.factor != 1:
            notes.append(f"--flat: along {axis} the bands' period is {chosen.factor:.3g} × the strongest line's "
                         f"({chosen.verdict})")
    good = sorted((a for a in axes if a.counts), key=lambda a: -a.a1 / a.a1_sigma)
    for a in good[1:]:
        if abs(a.distance_mm - good[0].distance_mm) > 3 * math.hypot(a.distance_sigma_mm, good[0].distance_sigma_mm):
            notes.append(f"--flat: the bands along {a.axis} give d = {a.distance_mm:.4g} mm, against "
                         f"{good[0].distance_mm:.4g} mm along {good[0].axis}: a harmonic of a longer period, not "
                         "counted")
            axes[axes.index(a)] = replace(a, counts=False)
    good = [a for a in axes if a.counts]
    if not good:
        raise FitError(f"--flat {frame.path}: no bands found: {'; '.join(notes)}: the display may be at d = 0, or the "
                       "bands longer than the frame")
    w = np.array([1.0 / a.distance_sigma_mm ** 2 for a in good])
    d = float(np.sum(w * [a.distance_mm for a in good]) / w.sum())
    return FlatFit(tuple(axes), d, float(1.0 / math.sqrt(w.sum())), tuple(notes))
