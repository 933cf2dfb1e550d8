"""Least squares of the opening on the orders' powers: in the power domain, weighted by the noise at the
model, searched from many starts, the project's PSF engine as the forward model.

Data: every row (order k, exposure i) the photometry measured, whatever its signal (no row is chosen by the
noise, nor by what the model predicts there: an opening that predicts a null where the measurement shows an
order pays for it in full). Residual r_ki = (P_ki − M_ki) / √V_ki, finite wherever M is, 0 included. V is the
measured variance moved to the model's level, V = max(σ²_ki + B_ki (M̄_ki − P_ki), R_ki) (photometry: B the
order's own shot noise per unit power, R the read noise alone; M̄ the model of the previous step, held while
least_squares runs, then updated: iteratively reweighted least squares, which solves the quasi-likelihood
equations Σ (P − M) ∂M/∂θ / V(M) = 0, unbiased at the truth; a weight from the measured variance alone would
favour the rows whose noise came out low). Why not the log domain: ln P has no finite variance where P may be
≤ 0, its weight M/σ sends the residual of a row the model predicts at 0 to 0, and its curvature near a zero of
|c|² (the T-OLED's first y orders when the slit fills the cell) made the slit height's pulls spread 1.7×.
Model: M_ki = exp(ln s + ln f_i + g_x X_k + g_y Y_k + q R_k² + q₂ R_k⁴) Q_k(θ) (R² = X² + Y²); f_i: exposure
i's factor against the reference (the brightest exposure with signal; fitted here with the orders, so that their
error is in the covariance); X, Y: the order's position over the window's half side (the vignetting: a gradient
where the spot is off the axis, a radial fall-off whose log has an r⁴ term); Q_k(θ) = κ C_k(θ) + δ_k, C_k =
Σ_Δ X(Δ) |c_(k+Δ)(θ)|² the order's own |c|² and its neighbours' Airy wings in its matched filter (photometry.
crosstalk: without it the search's first stage, before any render, could not fit a weak order beside a
saturated one: a 0.11-wide stripe at 190× the full well went to a slit height of 0.15). δ is what the
engine's PSF holds at each order beyond κ C: the orders' interference, the pixels' phases, the far wings: the
layout at θ̂ and the fitted pitch rendered where the measurement's spot is (synthetic.render_window), the same
photometry run on it: Q^eng, κ = Σ Q^eng C / Σ C² and δ_k = Q^eng_k − κ C_k(θ̂). Renders are repeated until θ
moves by less than 0.05 σ (at most ENGINE_PASSES).
Search (search.py, minima): the family's grid scored on all rows, its best local minima, a spread of its
points and the stripe's twins each polished, the distinct minima kept; each one within CONTEND_CHI2 ·
max(1, χ²/dof) of the best gets its own render (δ at its own shape: the neighbours' light differs between two
openings) and is polished again, at every pass; the lowest χ² is taken, so no solution another start beats
is accepted, and a distinct one within AMBIGUOUS_CHI2 · max(1, χ²/dof) of it is reported (alike: psf_fit
refuses the fit, the orders do not tell them apart).
Covariance: the Jacobian's (JᵀJ)⁻¹ · max(1, χ²/dof), raised where White's sandwich gives more, and each shape
parameter's σ widened to its profile likelihood's where the χ² rises less than the linear covariance says
(search.profile). Then the search again with the engine's δ at the best (the first stage, with δ = 0, can miss
a basin where the neighbours' interference is a large part of the orders' light, as beside saturated ones):
a basin it or the profile finds within CONTEND_CHI2 gets its own render and the passes go on (once).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from udc_render.fit.families import Family
from udc_render.fit.inputs import border
from udc_render.fit.photometry import Optics, Orders, crosstalk, measure
from udc_render.fit.search import FIELD_TERMS, OrderSet, Rows, Solution, distinct, grid_starts, polish, profile
from udc_render.fit.synthetic import render_window

SIGNAL_SNR, START_SNR = 3.0, 5.0
ENGINE_PASSES = 3
AMBIGUOUS_CHI2 = 4.0  # a distinct minimum this close (× max(1, χ²/dof)) fits as well: Δχ² < 4 is 2 σ
CONTEND_CHI2, MAX_CONTENDERS, KEEP_MINIMA = 100.0, 4, 6
PROFILE_ROUNDS = 2  # the engine's passes again from a point of the profile below the minimum, once


@dataclass(frozen=True)
class FamilyFit:
    """A family's fit: x = (shape parameters, ln s, g_x, g_y, q, q₂, ln f of the other exposures), its covariance,
    χ² and dof over every row used, over the rows with signal (measured or model ≥ SIGNAL_SNR σ) and the
    noise-weighted RMS of their relative residuals √(χ² / Σ (M / √V)²); the rows used, the model's power of
    every row (its exposure's units), the renders made, the exposures with rows (the reference first), the last
    render, the starts polished and the distinct minima that fit as well (shape parameters, χ²)."""
    family: Family
    x: np.ndarray
    cov: np.ndarray
    chi2: float
    dof: int
    chi2_signal: float
    signal_rows: int
    rms_rel: float
    used: np.ndarray
    model_power: np.ndarray
    passes: int  # the renders made
    exposures: tuple
    image: np.ndarray | None = None  # the last render of the model (at θ within 0.05 σ of the result)
    starts: int = 1
    alternatives: tuple = ()

    def exposure_log_factor(self, exposure: np.ndarray) -> np.ndarray:
        """ln f of each row's exposure against the reference (0 for it)."""
        k = len(self.family.names) + FIELD_TERMS
        table = dict(zip(self.exposures, np.concatenate([[0.0], self.x[k:]])))
        return np.array([table.get(int(e), np.nan) for e in exposure])

    def log_field(self, xy: np.ndarray, half: int) -> np.ndarray:
        """ln s + g_x X + g_y Y + q R² + q₂ R⁴ at window positions xy [N, 2]."""
        k = len(self.family.names)
        return field_columns(xy / half) @ self.x[k:k + FIELD_TERMS]

    @property
    def params(self) -> np.ndarray:
        return self.x[:len(self.family.names)]

    @property
    def sigma(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))[:len(self.family.names)]

    @property
    def correlation(self) -> np.ndarray:
        """The shape parameters' correlation matrix [k, k]."""
        s = self.sigma
        return np.clip(self.cov[:len(s), :len(s)] / np.outer(s, s), -1.0, 1.0)

    @property
    def chi2_red(self) -> float:
        return self.chi2 / max(self.dof, 1)

    @property
    def chi2_signal_red(self) -> float:
        return self.chi2_signal / max(self.signal_rows - len(self.x), 1)


@dataclass(frozen=True)
class Geometry:
    """Where the measurement's spot is: the window's size, the zeroth order's place (window px) and the
    display's rotation (degrees, x towards +y)."""
    size: int
    origin: np.ndarray
    rotation_deg: float

    def basis(self, pitch_um, optics: Optics) -> np.ndarray:
        """E [2, 2] (columns e_1, e_2, px per order) of a display of that pitch (x, y), turned."""
        a = math.radians(self.rotation_deg)
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        return rot @ np.diag([optics.lz_px / pitch_um[0], optics.lz_px / pitch_um[1]])

    def orders_xy(self, index: np.ndarray, pitch_um, optics: Optics) -> np.ndarray:
        """Window positions of cell orders [N, 2] of a display of that pitch (x, y), turned and placed."""
        return self.origin[None, :] + index @ self.basis(pitch_um, optics).T


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


def field_columns(u: np.ndarray) -> np.ndarray:
    """Columns 1, X, Y, R², R⁴ of positions u [N, 2] over the window's half side."""
    r2 = np.sum(u * u, axis=1)
    return np.column_stack([np.ones(len(u)), u, r2, r2 * r2])


def _reference(orders: Orders, factors) -> list[int]:
    """The exposures with a row of signal (≥ START_SNR σ), the reference (the largest factor) first."""
    rows = orders.measured & (orders.snr() >= START_SNR)
    return sorted({int(e) for e in orders.exposure[rows]}, key=lambda e: -factors[e])


def _rows(orders: Orders, use: np.ndarray, exposures: list[int], half: int, inverse: np.ndarray, factors) -> Rows:
    """The rows `use` with the design: the field's columns and one per exposure other than the reference."""
    cols = [(orders.exposure[use] == e).astype(float) for e in exposures[1:]]
    design = np.column_stack([field_columns(orders.xy[use] / half)] + cols)
    ref = factors[exposures[0]]
    return Rows(orders.index[use], inverse[use], orders.power[use], orders.sigma[use] ** 2, orders.shot[use],
                orders.floor[use], design, np.log(np.array([factors[e] / ref for e in orders.exposure[use]])))


def _engine_terms(fam: Family, x, pitch_um, optics, geometry, grid: OrderSet, uniq, radius_px):
    """(κ, δ [U], the orders the render measured [U], the render) at shape x (module doc)."""
    eng, image = engine_powers(fam, x, pitch_um, optics, geometry, uniq, radius_px)
    c2 = grid.power(fam, x)
    ok = eng.measured & (c2 > 0)
    kappa = float(np.sum(eng.power[ok] * c2[ok]) / np.sum(c2[ok] ** 2))
    return kappa, np.where(eng.measured, eng.power - kappa * c2, 0.0), eng.measured, image


def fit_family(fam: Family, orders: Orders, factors, pitch_um, optics: Optics, geometry: Geometry,
               radius_px: float, starts: list | None = None, profiled: bool = True) -> FamilyFit:
    """The family's shape fitted to the measured orders' powers (module doc); starts: x of a fit before (the
    same orders measured elsewhere) to polish instead of the search's; profiled: the σ from the profile
    likelihood (search.profile; not needed for a fit the orders will be measured again for)."""
    half, k = geometry.size // 2, len(fam.names)
    uniq, inverse = np.unique(orders.index, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    exposures = _reference(orders, factors)
    use = orders.measured & np.isin(orders.exposure, exposures)
    rows = _rows(orders, use, exposures, half, inverse, factors)
    grid = OrderSet.of(uniq, crosstalk(geometry.basis(pitch_um, optics), radius_px, optics.lens, optics.wavelength_nm,
                                       optics.pixel_um))
    if starts is None:
        sols, starts = minima(fam, rows, grid)
    else:
        sols = [polish(fam, rows, grid, 1.0, np.zeros(len(uniq)), x) for x in starts]
        starts = len(sols)
    best, image, renders = min(sols, key=lambda s: s.chi2), None, 0
    for _ in range(PROFILE_ROUNDS):
        contenders = _contenders(sols, best, k, rows)
        for _ in range(ENGINE_PASSES):
            fitted = []
            renders += len(contenders)
            for c in contenders:
                kappa, delta, seen, render = _engine_terms(fam, c.x[:k], pitch_um, optics, geometry, grid, uniq,
                                                           radius_px)
                if not seen[inverse[use]].all():  # an order the render cannot measure (the same for every shape)
                    use = use & seen[inverse]
                    rows = _rows(orders, use, exposures, half, inverse, factors)
                fitted.append((polish(fam, rows, grid, kappa, delta, c.x), render, kappa, delta))
            new, image, kappa, delta = min(fitted, key=lambda f: f[0].chi2)
            moved = np.max(np.abs(new.x - best.x)[:k] / np.maximum(np.sqrt(np.diag(new.cov))[:k], 1e-12),
                           initial=0.0)
            best, sols = new, [f[0] for f in fitted]
            contenders = _contenders(sols, best, k, rows)
            if moved < 0.05 or k == 0:
                break
        if not profiled:
            cov = best.cov
            break
        cov, found = profile(fam, rows, grid, kappa, delta, best)
        again = minima(fam, rows, grid, kappa, delta)[0]  # the search again with the engine's δ at best: a basin
        near = _contenders(sols + found + again, best, k, rows)  # the first stage (δ = 0) could not see
        if all(any(np.allclose(n.x, s.x) for s in sols) for n in near):
            break
        sols = sols + found + again  # a basin within reach (or below): its own render, the passes again
        best = min(sols, key=lambda s: s.chi2)
    return _result(fam, orders, rows, use, replace(best, cov=cov), sols, renders, tuple(exposures), image, starts)


def minima(fam: Family, rows: Rows, grid: OrderSet, kappa: float = 1.0, delta=None) -> tuple[list[Solution], int]:
    """(the minima of the search (module doc) with κ and δ (before any render: 1, 0), the starts): every grid start
    polished once on the orders with signal (≥ START_SNR σ in some exposure: the basins, at a fraction of the
    rows), then the twins of the best (Family.twins), then the distinct minima (at most KEEP_MINIMA, the lowest
    first) polished on every row."""
    delta, k = np.zeros(len(grid.ix)) if delta is None else delta, len(fam.names)
    quick = rows.with_signal(START_SNR)
    sols = [polish(fam, quick, grid, kappa, delta, x0, steps=1) for x0 in grid_starts(fam, quick, grid, kappa, delta)]
    first = min(sols, key=lambda s: s.chi2)
    sols += [polish(fam, quick, grid, kappa, delta, np.concatenate([t, first.x[k:]]), steps=1)
             for t in fam.twins(first.x[:k])]
    best = min(sols, key=lambda s: s.chi2)
    return [polish(fam, rows, grid, kappa, delta, s.x) for s in distinct(sols, best, k)[:KEEP_MINIMA]], len(sols)


def alike(sols: list[Solution], best: Solution, k: int, dof: int) -> tuple:
    """(shape, χ²) of the distinct minima (a shape parameter beyond 3 σ of best's) within AMBIGUOUS_CHI2 ·
    max(1, χ²/dof) of best: the fits the data do not tell from it."""
    sig = np.sqrt(np.diag(best.cov))[:k]
    slack = AMBIGUOUS_CHI2 * max(1.0, best.chi2 / max(dof, 1))
    return tuple((s.x[:k].copy(), s.chi2) for s in distinct(sols, best, k)[1:]
                 if s.chi2 - best.chi2 < slack and np.any(np.abs(s.x[:k] - best.x[:k]) > 3 * sig))


def _contenders(sols: list[Solution], best: Solution, k: int, rows: Rows) -> list[Solution]:
    """best and the distinct minima within CONTEND_CHI2 · max(1, χ²/dof) of it (at most MAX_CONTENDERS): each
    gets its own render (δ at its own shape: the neighbours' light differs between two openings)."""
    slack = CONTEND_CHI2 * max(1.0, best.chi2 / max(len(rows.power) - len(best.x), 1))
    near = [s for s in distinct(sols, best, k) if s.chi2 - best.chi2 < slack]
    return near[:MAX_CONTENDERS]


def _result(fam, orders, rows, use, best: Solution, sols, renders, exposures, image, starts) -> FamilyFit:
    """The FamilyFit of the best solution: its χ² over every row and over the rows with signal, the distinct
    minima within AMBIGUOUS_CHI2 of it."""
    model = np.zeros(len(orders.power))
    model[use] = best.model
    var = rows.variance(best.model)
    r2 = (rows.power - best.model) ** 2 / var
    signal = (rows.power >= SIGNAL_SNR * np.sqrt(rows.var)) | (best.model >= SIGNAL_SNR * np.sqrt(var))
    weight = float(np.sum(best.model[signal] ** 2 / var[signal]))
    chi2_signal = float(r2[signal].sum())
    dof = max(int(use.sum()) - len(best.x), 1)
    alt = alike(sols, best, len(fam.names), dof)
    return FamilyFit(fam, best.x, best.cov, best.chi2, dof, chi2_signal, int(signal.sum()),
                     math.sqrt(chi2_signal / weight) if weight > 0 else math.inf, use, model, renders, exposures,
                     image, starts, alt)
