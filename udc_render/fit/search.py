"""The opening's search (refine's module doc): the grid's local minima as starts, each polished by least
squares in the power domain with the noise at the model (iteratively reweighted), the minima kept apart.

Grid: at every point θ of the family's grid, the rows' model without the field, M = s f_i Q_k(θ) (f_i the HDR
merge's exposure factors), s solved by weighted least squares, scored by Σ ln(1 + (r / ROBUST_SCALE)²) over
every row (robust: the vignetting left out of the grid's model must not pick the basin). The starts: the best
GRID_STARTS local minima of the score (a point no higher than its grid neighbours) and the grid's points at the
quarters of each axis (SPREAD per axis): a single saturated exposure leaves the nulls of |c|² as the sharpest
evidence, a basin 0.002 wide in the stripe's width that no grid point of the score finds, but least squares
from a point 0.05 away does.
Polish: scipy.optimize.least_squares (trf, within the family's bounds, the Jacobian analytic in the field's
and exposures' terms, a forward difference in θ), IRLS_STEPS times, each with V at the previous model.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np
from threadpoolctl import threadpool_limits

from udc_render.fit.families import Family

FIELD_TERMS = 5  # the design's first columns: ln s, g_x, g_y, q, q₂ (refine's module doc); then the exposures
GRID_STARTS = 12
SPREAD = 3  # and the grid's points at the quarters of each axis: starts wherever the grid's score misleads
ROBUST_SCALE = 5.0
IRLS_STEPS = 3
MAX_NFEV = 80  # a start still moving after this many steps is far from any minimum worth the time
STEP = 1e-7  # the forward difference of |c|² in θ, of the family's range
PROFILE_STEPS = (1.0, 2.0, 4.0, 8.0, 16.0, 32.0)  # σ's multiples where the profile likelihood is looked at


@dataclass(frozen=True)
class Rows:
    """The rows a fit uses: cell orders [N, 2], each row's distinct order (into the fit's OrderSet), the powers,
    their measured variance σ², B (the order's own shot noise per unit power) and R (the read noise alone),
    the design [N, F] (the field's columns, one per exposure but the reference), ln of each row's HDR factor
    against the reference."""
    index: np.ndarray
    inverse: np.ndarray
    power: np.ndarray
    var: np.ndarray
    shot: np.ndarray
    floor: np.ndarray
    design: np.ndarray
    log_factor: np.ndarray

    def subset(self, keep: np.ndarray) -> Rows:
        return Rows(*(getattr(self, f.name)[keep] for f in fields(self)))

    def with_signal(self, snr: float) -> Rows:
        """The rows of the orders measured at ≥ snr σ in some exposure (all their exposures' rows)."""
        strong = np.zeros(int(self.inverse.max()) + 1, bool)
        strong[self.inverse[self.power >= snr * np.sqrt(self.var)]] = True
        return self.subset(strong[self.inverse])

    def variance(self, model: np.ndarray) -> np.ndarray:
        """V = max(σ² + B (M − P), R) with M, P taken ≥ 0: the measured variance moved to the model's level."""
        moved = self.var + self.shot * (np.maximum(model, 0.0) - np.maximum(self.power, 0.0))
        return np.maximum(moved, self.floor)


@dataclass(frozen=True)
class OrderSet:
    """The fit's distinct orders [U, 2] by their m and n: |c|² is evaluated once on the grid of m in kx, n in ky
    (widened by the crosstalk's reach), and each order's power is its own |c|² plus its neighbours' times the
    crosstalk X (photometry.crosstalk; None: none)."""
    kx: np.ndarray
    ix: np.ndarray
    ky: np.ndarray
    iy: np.ndarray
    crosstalk: np.ndarray | None = None

    @classmethod
    def of(cls, uniq: np.ndarray, crosstalk: np.ndarray | None = None) -> OrderSet:
        reach = 0 if crosstalk is None else crosstalk.shape[0] // 2
        kx = np.arange(uniq[:, 0].min() - reach, uniq[:, 0].max() + reach + 1)
        ky = np.arange(uniq[:, 1].min() - reach, uniq[:, 1].max() + reach + 1)
        return cls(kx, uniq[:, 0] - kx[0], ky, uniq[:, 1] - ky[0], crosstalk)

    def power(self, fam: Family, theta) -> np.ndarray:
        grid = fam.power_grid(theta, self.kx, self.ky)
        if self.crosstalk is not None:
            reach = self.crosstalk.shape[0] // 2
            padded = np.pad(grid, reach)
            ny, nx = grid.shape
            grid = sum(w * padded[a:a + ny, b:b + nx] for (a, b), w in np.ndenumerate(self.crosstalk) if w != 0)
        return grid[self.iy, self.ix]


@dataclass(frozen=True)
class Solution:
    """A polished minimum: x (shape, then the linear terms), its covariance, χ², the model of every row."""
    x: np.ndarray
    cov: np.ndarray
    chi2: float
    model: np.ndarray


def _q(fam: Family, theta, orders: OrderSet, kappa, delta) -> np.ndarray:
    return kappa * orders.power(fam, theta) + delta


def grid_starts(fam: Family, rows: Rows, orders: OrderSet, kappa: float = 1.0, delta=0.0) -> list[np.ndarray]:
    """The starts x0 of the module doc, the model's Q = κ C + δ (a family without shape parameters: its one
    start)."""
    k = len(fam.names)
    exposure_cols = rows.design[:, FIELD_TERMS:]
    log_f = np.array([rows.log_factor[col > 0][0] for col in exposure_cols.T])
    w = 1.0 / rows.var

    def start(theta):
        q = _q(fam, theta, orders, kappa, delta)[rows.inverse] * np.exp(rows.log_factor)
        s = float(np.sum(w * rows.power * q) / max(np.sum(w * q * q), 1e-300))
        r = (rows.power - s * q) * np.sqrt(w)
        score = float(np.sum(np.log1p((r / ROBUST_SCALE) ** 2))) if s > 0 else np.inf
        field = [np.log(max(s, 1e-300))] + [0.0] * (FIELD_TERMS - 1)
        return score, np.concatenate([np.asarray(theta, float), field, log_f])
    if k == 0:
        return [start(())[1]]
    axes = [np.asarray(g, float) for g in fam.grid]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, k)
    scored = [start(p) for p in points]
    score = np.array([s for s, _ in scored]).reshape([len(a) for a in axes])
    from scipy.ndimage import minimum_filter
    local = (score <= minimum_filter(score, size=3, mode="nearest")) & np.isfinite(score)
    best = list(np.argsort(np.where(local, score, np.inf).ravel())[:GRID_STARTS])
    spread = np.stack(np.meshgrid(*[np.round(np.linspace(0, len(a) - 1, SPREAD + 2)[1:-1]).astype(int)
                                    for a in axes], indexing="ij"), -1).reshape(-1, k)
    best += [int(np.ravel_multi_index(tuple(i), score.shape)) for i in spread]
    return [scored[i][1] for i in dict.fromkeys(best) if np.isfinite(score.ravel()[i])]


def polish(fam: Family, rows: Rows, orders: OrderSet, kappa, delta, x0, steps: int = IRLS_STEPS) -> Solution:
    """The minimum of the module doc from x0: `steps` least-squares solves, each with V at the model of the one
    before (the first at x0's)."""
    x = np.asarray(x0, float)
    with threadpool_limits(limits=1, user_api="blas"):  # N × 12 matrices: a 3000-row SVD took 1.2 ms on one
        for _ in range(steps):  # thread, 157 ms on OpenBLAS's threads of a loaded 2-core machine
            var = rows.variance(_model(fam, rows, orders, kappa, delta, x))
            x, jac, r = _solve(fam, rows, orders, kappa, delta, x, var)
    cov = covariance(jac, r, len(r) - len(x))
    return Solution(x, cov, float(r @ r), _model(fam, rows, orders, kappa, delta, x))


def _model(fam, rows: Rows, orders, kappa, delta, x) -> np.ndarray:
    k = len(fam.names)
    return np.exp(np.clip(rows.design @ x[k:], -300.0, 300.0)) * _q(fam, x[:k], orders, kappa, delta)[rows.inverse]


def _solve(fam: Family, rows: Rows, orders, kappa, delta, x0, var):
    """scipy.optimize.least_squares of r = (P − M(x)) / √var from x0: (x, the Jacobian, r)."""
    from scipy.optimize import least_squares
    k = len(fam.names)
    w = 1.0 / np.sqrt(var)
    lo = np.concatenate([fam.lower, [-np.inf] * rows.design.shape[1]])
    hi = np.concatenate([fam.upper, [np.inf] * rows.design.shape[1]])
    span = np.where(np.isfinite(hi - lo), hi - lo, 0.0)

    def parts(x):
        field = np.exp(np.clip(rows.design @ x[k:], -300.0, 300.0))  # a trial step far out stays finite
        q = _q(fam, x[:k], orders, kappa, delta)
        return field, q, field * q[rows.inverse]

    def resid(x):
        return (rows.power - parts(x)[2]) * w

    def jac(x):
        field, q, m = parts(x)
        cols = []
        for i in range(k):
            h = STEP * span[i] * (1.0 if x[i] + STEP * span[i] <= hi[i] else -1.0)
            step = x.copy()
            step[i] += h
            cols.append(field * ((_q(fam, step[:k], orders, kappa, delta) - q) / h)[rows.inverse])
        return -np.column_stack(cols + [m[:, None] * rows.design]) * w[:, None]
    res = least_squares(resid, np.clip(x0, lo + 1e-9 * span, hi - 1e-9 * span), jac=jac, bounds=(lo, hi),
                        method="trf", x_scale="jac", xtol=1e-9, ftol=1e-9, max_nfev=MAX_NFEV)
    return res.x, res.jac, res.fun


def covariance(jac: np.ndarray, r: np.ndarray, dof: int) -> np.ndarray:
    """(JᵀJ)⁻¹ max(1, χ²/dof), each parameter's variance raised where the sandwich
    (JᵀJ)⁻¹ Jᵀ diag(r²) J (JᵀJ)⁻¹ gives more (White's estimator: a residual beyond the noise where the
    parameter draws on it)."""
    a_inv = np.linalg.pinv(jac.T @ jac)
    cov = a_inv * max(1.0, float(r @ r) / max(dof, 1))
    sandwich = a_inv @ (jac.T @ (jac * (r * r)[:, None])) @ a_inv * len(r) / max(dof, 1)
    scale = np.sqrt(np.maximum(1.0, np.diag(sandwich) / np.maximum(np.diag(cov), 1e-300)))
    return cov * np.outer(scale, scale)


def distinct(sols: list[Solution], best: Solution, k: int) -> list[Solution]:
    """best, then each other solution whose k shape parameters lie beyond 1 σ (best's) of every one kept."""
    sig = np.sqrt(np.diag(best.cov))[:k]
    kept = [best]
    for s in sorted(sols, key=lambda s: s.chi2):
        if k and all(np.any(np.abs(s.x[:k] - o.x[:k]) > sig) for o in kept):
            kept.append(s)
    return kept


def profile(fam: Family, rows: Rows, orders: OrderSet, kappa, delta, best: Solution) -> tuple[np.ndarray, list]:
    """(best's covariance, each shape parameter's σ widened to its profile likelihood's; the minima polished from
    profile points below best). The profile of θ_i: χ² minimised over every other parameter with θ_i held, at
    θ̂_i ± t σ_i for t in PROFILE_STEPS (until it rises by 25, a bound or the last t), in units of
    max(1, χ²/dof). Where it rises by less than t² at t σ, σ_i is widened to t σ_i / √rise: the linear
    covariance takes a valley that bends, or a second basin beyond a ridge, for a straight one (a P-OLED's open
    fraction traded for the vignetting's r² and r⁴ over three rings of orders had minima at 0.197 and 0.170,
    Δχ² 0.1, where the Jacobian's σ was 0.003)."""
    k = len(fam.names)
    sig = np.sqrt(np.diag(best.cov))
    one = max(1.0, best.chi2 / max(len(rows.power) - len(best.x), 1))
    span = np.asarray(fam.upper, float) - np.asarray(fam.lower, float)
    scale, found = np.ones(len(best.x)), []
    for i in range(k):
        for side in (-1.0, 1.0):
            for t in PROFILE_STEPS:
                at = best.x[i] + side * t * sig[i]
                if not fam.lower[i] < at < fam.upper[i]:
                    break
                lo, hi = np.array(fam.lower, float), np.array(fam.upper, float)
                lo[i], hi[i] = at - 1e-9 * span[i], at + 1e-9 * span[i]
                x0 = best.x.copy()
                x0[i] = at
                held = polish(replace(fam, lower=tuple(lo), upper=tuple(hi)), rows, orders, kappa, delta, x0)
                rise = (held.chi2 - best.chi2) / one
                scale[i] = max(scale[i], t / np.sqrt(max(rise, 1e-12)))
                if rise < 0:  # a basin below best: its own minimum
                    found.append(polish(fam, rows, orders, kappa, delta, held.x))
                if rise > 25:
                    break
    return best.cov * np.outer(scale, scale), found
