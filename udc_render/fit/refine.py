"""Least squares of the opening on the orders' powers: log domain, weighted by the noise, the project's
PSF engine as the forward model.

Data: one row per order k and exposure i where the order is measured (photometry), y = ln P_ki with
σ = σ(P_ki) / M_ki (the model's power: a weight from the measurement would favour the rows whose noise came
out positive), the model's log shifted by −σ(P)² / (2 M²) (the log's bias, E ln P̂ = ln P − σ² / (2 P²)); the
rows used are those the model predicts at SNR ≥ MIN_SNR (the first pass: measured at ≥ START_SNR), so that
the selection does not follow the noise.
Model: ln M_ki = ln s + ln f_i + g_x X_k + g_y Y_k + q R_k² + q₂ R_k⁴ + ln Q_k(θ) (R² = X² + Y²); f_i: exposure i's factor
against the reference (the brightest exposure with rows; the exposures' HDR factors are fitted here with
the orders, so that their error is in the covariance); X, Y: the order's position over the window's half
side (the vignetting across the spot: a gradient where the spot is off the axis, a radial fall-off where it
is on it, whose log is not a pure square: ln cos⁴θ and ln(1 − a r²) have r⁴ terms); Q_k(θ) = κ |c_k(θ)|² + δ_k.
δ is what the engine's PSF holds at each order beyond κ |c|²: the neighbours' light, the orders' interference,
the pixels' phases; it is the layout at θ̂ and the fitted pitch rendered where the measurement's spot is
(synthetic.render_window: psf.compute_kernels at a third of the pixel, turned by the lattice's rotation,
centred on its origin, summed back to pixels), the same photometry run on it at its own orders: Q^eng,
κ = Σ Q^eng |c|² / Σ |c|⁴ and δ_k = Q^eng_k − κ |c_k(θ̂)|². The fit is repeated with δ until θ moves by less
than 0.05 σ (at most ENGINE_PASSES renders).
Covariance: refine._covariance (the Jacobian's, widened by the residual and by White's sandwich).
Start: the χ² of many orders has a minimum between every two zeros of |c|² (~1 / (2 n_max) apart in a
shape parameter), so the start continues from the low orders to all: the grid's best point (the linear
parameters solved at each, a robust score) on the orders with |m|, |n| ≤ START_ORDERS[0], polished there by
least squares with a Cauchy loss, then on |m|, |n| ≤ each next bound in turn; then
scipy.optimize.least_squares (trf, within the family's bounds) on all; covariance (JᵀJ)⁻¹ · max(1, χ²/dof): a residual beyond the
noise widens it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from udc_render.fit.families import Family
from udc_render.fit.inputs import border
from udc_render.fit.photometry import Optics, Orders, measure
from udc_render.fit.synthetic import render_window

MIN_SNR, START_SNR = 3.0, 5.0
START_ORDERS = (3, 6, 12, 24)
ROBUST_SCALE = 5.0  # the start's score: Σ ln(1 + (r / 5)²), so that an order near a zero of |c|² (its log
# residual steep in θ) cannot hide the right basin from a grid point a step away
FIELD_TERMS = 5  # ln s, g_x, g_y, q, q₂
ENGINE_PASSES = 3
TINY = 1e-300


@dataclass(frozen=True)
class FamilyFit:
    """A family's fit: x = (shape parameters, ln s, g_x, g_y, q, q₂, ln f of the other exposures), its covariance,
    χ² and dof, the noise-weighted RMS of the log residuals √(χ² / Σ σ⁻²), the rows used, the model's power
    of every row (its exposure's units), the renders made, the exposures with rows (the reference first), the
    last render."""
    family: Family
    x: np.ndarray
    cov: np.ndarray
    chi2: float
    dof: int
    rms_log: float
    used: np.ndarray
    model_power: np.ndarray
    passes: int
    exposures: tuple
    image: np.ndarray | None = None  # the last render of the model (at θ within 0.05 σ of the result)

    def exposure_log_factor(self, exposure: np.ndarray) -> np.ndarray:
        """ln f of each row's exposure against the reference (0 for it)."""
        k = len(self.family.names) + FIELD_TERMS
        table = dict(zip(self.exposures, np.concatenate([[0.0], self.x[k:]])))
        return np.array([table.get(int(e), np.nan) for e in exposure])

    def log_field(self, xy: np.ndarray, half: int) -> np.ndarray:
        """ln s + g_x X + g_y Y + q R² + q₂ R⁴ at window positions xy [N, 2]."""
        k = len(self.family.names)
        return _field(xy / half) @ self.x[k:k + FIELD_TERMS]

    @property
    def params(self) -> np.ndarray:
        return self.x[:len(self.family.names)]

    @property
    def sigma(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))[:len(self.family.names)]

    @property
    def chi2_red(self) -> float:
        return self.chi2 / max(self.dof, 1)


@dataclass(frozen=True)
class Geometry:
    """Where the measurement's spot is: the window's size, the zeroth order's place (window px) and the
    display's rotation (degrees, x towards +y)."""
    size: int
    origin: np.ndarray
    rotation_deg: float

    def orders_xy(self, index: np.ndarray, pitch_um, optics: Optics) -> np.ndarray:
        """Window positions of cell orders [N, 2] of a display of that pitch (x, y), turned and placed."""
        a = math.radians(self.rotation_deg)
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        e = rot @ np.diag([optics.lz_px / pitch_um[0], optics.lz_px / pitch_um[1]])
        return self.origin[None, :] + index @ e.T


def engine_powers(fam: Family, params, pitch_um, optics: Optics, geometry: Geometry, index: np.ndarray,
                  radius_px: float) -> tuple[Orders, np.ndarray]:
    """(the photometry, the image [S, S]) of the family's layout at `params` and pitch (x, y) rendered where the
    spot is (module doc)."""
    img = render_window(fam.layout(pitch_um[0], pitch_um[1], params), optics.lens, optics.wavelength_nm,
                        optics.pixel_um, geometry.size, geometry.origin, geometry.rotation_deg)
    k = img - np.median(img[border(img.shape)])
    orders = measure(k, np.ones_like(k), np.ones(k.shape, bool), geometry.orders_xy(index, pitch_um, optics), index,
                     radius_px, optics.lens, optics.wavelength_nm, optics.pixel_um)
    return orders, img


def _field(u: np.ndarray) -> np.ndarray:
    """Columns 1, X, Y, R², R⁴ of positions u [N, 2] over the window's half side."""
    r2 = np.sum(u * u, axis=1)
    return np.column_stack([np.ones(len(u)), u, r2, r2 * r2])


def _design(orders: Orders, half: int, exposures: list[int]) -> np.ndarray:
    """The field's columns and one per exposure other than the reference (exposures[0])."""
    cols = [(orders.exposure == e).astype(float) for e in exposures[1:]]
    return np.column_stack([_field(orders.xy / half)] + cols)


def _linear(y, sig, q, a, robust: bool = False):
    """(linear coefficients; χ², or with `robust` Σ ln(1 + (r/ROBUST_SCALE)²)) of y − q on the design a,
    weighted by 1/σ²."""
    w = 1.0 / sig
    coef = np.linalg.lstsq(a * w[:, None], (y - q) * w, rcond=None)[0]
    r = (y - q - a @ coef) * w
    return coef, float(np.sum(np.log1p((r / ROBUST_SCALE) ** 2))) if robust else float(r @ r)


def _log_q(fam, params, index, kappa, delta):
    return np.log(np.maximum(kappa * fam.power(params, index) + delta, TINY))


def _start(fam: Family, index, y, sig, a, kappa, delta) -> np.ndarray:
    """The grid point (and its linear parameters) with the smallest χ²."""
    best, key = None, math.inf
    grid = np.stack(np.meshgrid(*fam.grid, indexing="ij"), -1).reshape(-1, len(fam.grid)) if fam.grid else [()]
    for point in grid:
        coef, chi2 = _linear(y, sig, _log_q(fam, point, index, kappa, delta), a, robust=True)
        if chi2 < key:
            best, key = np.concatenate([np.asarray(point, float), coef]), chi2
    return best


def _solve(fam: Family, index, y, sig, a, kappa, delta, x0, loss: str = "linear", s_abs=None):
    """scipy.optimize.least_squares from x0: (x, covariance, χ², normalised residuals); loss 'cauchy' for the
    start's polish (scale ROBUST_SCALE). With s_abs (σ of each power) the log residual is taken against the
    model, unbiased to second order: r = (ln P − ln M + s² / (2 M²)) M / s (E ln P̂ = ln P − σ² / (2 P²), and a
    weight σ / P̂ from the measurement would favour the rows whose noise came out positive)."""
    from scipy.optimize import least_squares
    k = len(fam.names)
    if k == 0 and s_abs is None:  # a micrograph's start: the model is linear in what is left
        coef, chi2 = _linear(y, sig, _log_q(fam, (), index, kappa, delta), a)
        r = (y - _log_q(fam, (), index, kappa, delta) - a @ coef) / sig
        cov = np.linalg.pinv((a / sig[:, None]).T @ (a / sig[:, None])) * max(1.0, chi2 / max(len(y) - a.shape[1], 1))
        return coef, cov, chi2, r

    def resid(x):
        lm = _log_q(fam, x[:k], index, kappa, delta) + a @ x[k:]
        if s_abs is None:
            return (y - lm) / sig
        return _weighted_log_residual(y, lm, s_abs)
    lo = np.concatenate([fam.lower, [-np.inf] * a.shape[1]])
    hi = np.concatenate([fam.upper, [np.inf] * a.shape[1]])
    span = np.where(np.isfinite(hi - lo), hi - lo, 0.0)
    res = least_squares(resid, np.clip(x0, lo + 1e-9 * span, hi - 1e-9 * span), bounds=(lo, hi), method="trf",
                        x_scale="jac", xtol=1e-10, ftol=1e-10, loss=loss, f_scale=ROBUST_SCALE)
    chi2 = float(res.fun @ res.fun)
    return res.x, _covariance(res.jac, res.fun, len(y) - len(x0)), chi2, res.fun


def _weighted_log_residual(y: np.ndarray, lm: np.ndarray, s_abs: np.ndarray, floor: float = 1e-6,
                           ceiling: float = 1e8) -> np.ndarray:
    """r(ln M) = (y − ln M + s² / (2 M²)) M / s, continued linearly in ln M (value and slope) outside
    floor · s ≤ M ≤ ceiling · s. Below, it diverges as s / (2 M): an order that a trial step predicts at ~0
    still costs the barrier's huge residual (~1 / (2 floor)), but a finite one (an infinite residual made a NaN
    Jacobian that stopped least_squares). Above, it grows as M / s: a start that overshoots by e¹³⁰ (a wrong
    family's extrapolated field) made a Jacobian whose scaled singular values underflowed in least_squares'
    trust region. No row the fit uses (MIN_SNR s ≤ M, a power's SNR ≪ 10⁸) is changed."""
    at = np.clip(lm, np.log(floor * s_abs), np.log(ceiling * s_abs))
    m = np.exp(at)
    r = (y - at + s_abs ** 2 / (2 * m * m)) * m / s_abs
    slope = ((y - at - 1.0) * m - s_abs ** 2 / (2 * m)) / s_abs  # dr / d ln M at the clip
    return r + slope * (lm - at)


def _covariance(jac: np.ndarray, r: np.ndarray, dof: int) -> np.ndarray:
    """(JᵀJ)⁻¹ max(1, χ²/dof), each parameter's variance raised where the sandwich (JᵀJ)⁻¹ Jᵀ diag(r²) J (JᵀJ)⁻¹
    gives more (White's estimator: a residual beyond the noise where the parameter draws on it)."""
    a_inv = np.linalg.pinv(jac.T @ jac)
    cov = a_inv * max(1.0, float(r @ r) / max(dof, 1))
    sandwich = a_inv @ (jac.T @ (jac * (r * r)[:, None])) @ a_inv * len(r) / max(dof, 1)
    scale = np.sqrt(np.maximum(1.0, np.diag(sandwich) / np.maximum(np.diag(cov), 1e-300)))
    return cov * np.outer(scale, scale)


def _continue(fam: Family, index, y, sig, a, kappa, delta) -> np.ndarray:
    """The start of the module doc: the grid on the lowest orders, then Cauchy-loss polishes on ever more."""
    x = None
    for bound in START_ORDERS:
        low = np.all(np.abs(index) <= bound, axis=1)
        if low.sum() < a.shape[1] + len(fam.names) + 5:
            continue
        args = (fam, index[low], y[low], sig[low], a[low], kappa, delta[low])
        if x is not None:  # the shape so far, the linear parameters solved again on these rows (the field's
            k = len(fam.names)  # R⁴ fitted on the low orders alone extrapolates wildly)
            x = np.concatenate([x[:k], _linear(y[low], sig[low], _log_q(fam, x[:k], index[low], kappa, delta[low]),
                                               a[low])[0]])
        x = _solve(*args, _start(*args) if x is None else x, loss="cauchy")[0]
    return x if x is not None else _start(fam, index, y, sig, a, kappa, delta)


def _reference(orders: Orders, rows: np.ndarray, factors) -> list[int]:
    """The exposures with rows, the reference (the largest factor) first."""
    have = sorted({int(e) for e in orders.exposure[rows]}, key=lambda e: -factors[e])
    return have


def fit_family(fam: Family, orders: Orders, factors, pitch_um, optics: Optics, geometry: Geometry,
               radius_px: float) -> FamilyFit:
    """The family's shape fitted to the measured orders' powers (module doc)."""
    half, k = geometry.size // 2, len(fam.names)
    uniq, row_order = np.unique(orders.index, axis=0, return_inverse=True)
    row_order = row_order.ravel()
    snr = orders.snr()
    used = orders.measured & (snr >= START_SNR)
    exposures = _reference(orders, used, factors)
    a = _design(orders, half, exposures)
    kappa, delta = 1.0, np.zeros(len(uniq))
    x = image = None
    for passes in range(ENGINE_PASSES + 1):
        y, sig = np.log(orders.power[used]), orders.sigma[used] / orders.power[used]
        if x is None:
            x = _continue(fam, orders.index[used], y, sig, a[used], kappa, delta[row_order][used])
        x_new, cov, chi2, r = _solve(fam, orders.index[used], y, sig, a[used], kappa, delta[row_order][used], x,
                                     s_abs=orders.sigma[used])
        moved = np.max(np.abs(x_new - x)[:k] / np.maximum(np.sqrt(np.diag(cov))[:k], 1e-12), initial=0.0)
        x = x_new
        if passes == ENGINE_PASSES or (passes > 0 and moved < 0.05) or k == 0 and passes > 0:
            break
        eng, image = engine_powers(fam, x[:k], pitch_um, optics, geometry, uniq, radius_px)
        c2 = fam.power(x[:k], uniq)
        ok = eng.measured & (c2 > 0)
        kappa = float(np.sum(eng.power[ok] * c2[ok]) / np.sum(c2[ok] ** 2))
        delta = np.where(eng.measured, eng.power - kappa * c2, 0.0)
        model = np.exp(a @ x[k:] + _log_q(fam, x[:k], uniq, kappa, delta)[row_order])
        used = orders.measured & eng.measured[row_order] & (orders.power > 0) & (model >= MIN_SNR * orders.sigma) \
            & np.isin(orders.exposure, exposures)
    model = np.exp(a @ x[k:] + _log_q(fam, x[:k], uniq, kappa, delta)[row_order])
    dof = max(int(used.sum()) - len(x), 1)
    weight = float(np.sum(sig ** -2.0))
    rms = math.sqrt(chi2 / weight) if weight > 0 else math.inf  # the noise-weighted RMS of the log residuals
    return FamilyFit(fam, x, cov, chi2, dof, rms, used, model, passes, tuple(exposures), image)
