"""The PSF fit: the exposures merged (hdr), the orders' lattice (lattice), their powers (photometry), each
family's opening (refine), the lattice's centroid bias removed with the fitted model, the family chosen.

The centroid bias: the light of an order's neighbours and the pixels pull each centroid a little (on the
T-OLED's weak y orders beside the zeroth, 6e-4 of the pitch: 8 σ of a good measurement). The fitted model
is rendered where the measurement's lattice is (synthetic.psf_image: the engine's kernel at the fitted
pitch, shape, origin and rotation, times the fitted vignetting) and centroided at the same pixels; its centroids
minus its known orders' positions are each peak's bias, taken off before the lattice is solved again
(lattice.centroid_bias). The orders' powers are then measured again where the debiased lattice puts them and
the opening fitted again from its minima (a matched filter 0.06 px off an order loses 1 % of its power: on one
axis only, a bias of the shape), and the lattice debiased with that fit.

Auto: every family whose visible lattice matches the peaks' (lattice.cell_basis) is fitted; the lowest χ²/dof wins,
and its last fit is made once more with the σ of the profile likelihood and the search again at the engine's δ
(_settled; the others' would be wasted). A family is refused when its residual is far above the noise: χ²/dof over
the rows with signal > CHI2_MAX and the noise-weighted RMS of their relative residuals > REL_RMS_MAX (orders' powers
off by more than 20 % on average); when the orders do not determine its opening (fewer rows with signal than
parameters + 2, a shape parameter's σ above SHAPE_REL_SIGMA_MAX of its value, or another minimum that fits as well:
refine); and when the synthesis with the written display file misses the measured orders' powers by more than
SYNTHESIS_MAX × what the noise alone gives (refuse_synthesis). Shape parameters that trade off (|correlation| >
CORRELATED) are named in a note.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from udc_render.fit import lattice as lat_mod
from udc_render.fit.families import Family, family
from udc_render.fit.hdr import Plane
from udc_render.fit.inputs import FitError
from udc_render.fit.photometry import Optics, Orders, aperture_px, lattice_orders, measure, measure_exposures
from udc_render.fit.refine import AMBIGUOUS_CHI2, SIGNAL_SNR, FamilyFit, Geometry, fit_family
from udc_render.fit.synthetic import render_window

CHI2_MAX, REL_RMS_MAX = 9.0, 0.2
SHAPE_REL_SIGMA_MAX = 0.05  # a shape parameter whose σ exceeds this share of its value is not determined: the
# issue's bar is an open fraction within 10 %, which 2 σ of 5 % keep
CORRELATED = 0.9
SYNTHESIS_MAX = 5.0  # the synthesis check's orders' relative L2 over the noise's alone
MIN_ORDERS_ACROSS = 3  # the window must hold ± this many spacings (and an aperture) around the spot


@dataclass(frozen=True)
class Candidate:
    """One family's lattice and fit."""
    family: Family
    lattice: lat_mod.Lattice
    orders: Orders
    fit: FamilyFit
    pitch_um: tuple  # ((p_x, σ), (p_y, σ))
    rotation_deg: tuple  # (φ, σ)
    skew_deg: float
    radius_px: float
    raw_pitch_um: tuple  # before the centroid bias was removed
    saturated_orders: int = 0  # orders whose centre is saturated in every exposure
    stage: tuple = ()  # the last fit's geometry, pitch, the lattice as measured, the index basis, the window's size


@dataclass(frozen=True)
class PsfFit:
    """The plane, window, peaks, every candidate (and why the others were not fitted), the chosen one."""
    plane: Plane
    window: lat_mod.Window
    peaks: lat_mod.Peaks
    candidates: list
    skipped: dict
    chosen: Candidate


def pitch_of(lattice: lat_mod.Lattice, optics: Optics) -> tuple:
    """((p_x, σ), (p_y, σ)) µm: p = λ z_i / (|e| pixel), σ_p = p σ_|e| / |e|."""
    out = []
    for k in (0, 1):
        n, s = lattice.length(k)
        p = optics.lz_px / n
        out.append((p, p * s / n))
    return tuple(out)


def render(layout, optics: Optics, size: int, origin: np.ndarray, rotation_deg: float) -> np.ndarray:
    """The layout's noise-free PSF on the window, centred at `origin`, turned by rotation_deg."""
    return render_window(layout, optics.lens, optics.wavelength_nm, optics.pixel_um, size, origin, rotation_deg)


def field_map(fit: FamilyFit, size: int) -> np.ndarray:
    """exp(g_x X + g_y Y + q R² + q₂ R⁴) on the window [S, S]: the fitted vignetting (without the scale)."""
    g = np.arange(size) - size // 2
    xy = np.stack(np.broadcast_arrays(g[None, :], g[:, None]), -1).reshape(-1, 2)
    log = fit.log_field(xy, size // 2) - fit.log_field(np.zeros((1, 2)), size // 2)
    return np.exp(np.clip(log, -300.0, 300.0)).reshape(size, size)  # a refused family's wild field stays finite


def _candidate(fam: Family, plane: Plane, window, peaks, visible, optics: Optics):
    """The family's lattice, powers and fit; None (and why) when its lattice does not match the peaks'."""
    m = fam.index_basis()
    e0 = lat_mod.cell_basis(visible, m)
    if e0 is None:
        return None, "its lattice of orders does not match the peaks' (spacing, angle or centring)"
    lattice, _ = lat_mod.fit_lattice(peaks, e0, m, lat_mod.light_centre(plane.value, plane.usable, window))
    radius = aperture_px(lattice.spacing_px)
    longest = max(np.hypot(*lattice.e1), np.hypot(*lattice.e2))
    need = 2 * int(math.ceil(MIN_ORDERS_ACROSS * longest + radius)) + 1
    if window.size < need:
        raise FitError(f"the spot is clipped by the frame: its centre at pixel ({window.x0}, {window.y0}) leaves a "
                       f"{window.size}-px window; at least {need} px (± {MIN_ORDERS_ACROSS} orders) are needed")
    raw, fit, measured, searched = pitch_of(lattice, optics), None, lattice, 0
    for stage in range(2):  # the orders measured where the lattice is, then again where its debiased solve puts them
        index = lattice_orders(lattice, m, window.half, radius)
        orders = measure_exposures(plane.exposures, window, lattice.points(index), index, radius, optics,
                                   plane.dn_per_e)
        geometry = Geometry(window.size, lattice.origin, lattice.angle_deg(0)[0])
        pitch = pitch_of(lattice, optics)
        fit = fit_family(fam, orders, plane.factors, (pitch[0][0], pitch[1][0]), optics, geometry, radius,
                         None if fit is None else _starts(fit), profiled=False)
        lattice = _debiased(fam, fit, measured, pitch, geometry, optics, window.size, m)
        searched = searched or fit.starts  # the first stage's search
    fit = replace(fit, starts=searched)
    rot = lattice.angle_deg(0)
    skew = lattice.angle_deg(1)[0] - rot[0]
    centre = np.rint(lattice.points(index)).astype(int) + window.half
    saturated = int(window.crop(plane.clipped)[centre[:, 1], centre[:, 0]].sum())
    return Candidate(fam, lattice, orders, fit, pitch_of(lattice, optics), rot, skew, radius, raw, saturated,
                     (geometry, pitch, measured, m, window.size)), ""


def _starts(fit: FamilyFit) -> list:
    """A fit's minimum and the others that fit alike, as starts for the same orders measured again."""
    return [fit.x] + [np.concatenate([a, fit.x[len(a):]]) for a, _ in fit.alternatives]


def _settled(c: Candidate, plane: Plane, optics: Optics) -> Candidate:
    """The chosen family's last fit made again from its minima with the σ of the profile likelihood and the
    search again at the engine's δ (refine.fit_family, profiled), and its lattice debiased with it."""
    geometry, pitch, measured, m, size = c.stage
    fit = fit_family(c.family, c.orders, plane.factors, (pitch[0][0], pitch[1][0]), optics, geometry, c.radius_px,
                     _starts(c.fit), profiled=True)
    lattice = _debiased(c.family, fit, measured, pitch, geometry, optics, size, m)
    rot = lattice.angle_deg(0)
    return replace(c, fit=replace(fit, starts=c.fit.starts, passes=c.fit.passes + fit.passes), lattice=lattice,
                   pitch_um=pitch_of(lattice, optics), rotation_deg=rot, skew_deg=lattice.angle_deg(1)[0] - rot[0])


def _debiased(fam: Family, fit: FamilyFit, lattice, pitch, geometry: Geometry, optics: Optics, size: int, m):
    """The lattice solved again from the measured lattice's peaks less their centroid bias (module doc),
    measured on the fitted model (its last render, times the fitted vignetting) whose orders lie at the pitch
    and geometry it was rendered with."""
    model = fit.image if fit.image is not None else render(fam.layout(pitch[0][0], pitch[1][0], fit.params), optics,
                                                            size, geometry.origin, geometry.rotation_deg)
    phi = math.radians(geometry.rotation_deg)
    e_model = np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]]) @ \
        np.diag([optics.lz_px / pitch[0][0], optics.lz_px / pitch[1][0]])
    bias = lat_mod.centroid_bias(model * field_map(fit, size), lattice, e_model, geometry.origin)
    bias = np.where(np.isfinite(bias), bias, 0.0)  # a peak where the model has no light: as measured
    return lat_mod.solve_lattice(lattice.xy - bias, lattice.sigma, lattice.index, m)


def first_lattice(plane: Plane, optics: Optics, family_name: str, micrograph=None, window_px: int = 511):
    """(window, lattice, index basis, aperture radius px) of the first family whose lattice matches the peaks
    (no opening fitted: where the orders are, for fit.cfa); None when none does (fit_psf then says why)."""
    window = lat_mod.spot_window(plane.value, plane.clipped, window_px)
    peaks = lat_mod.find_peaks(plane.value, plane.var, plane.usable, plane.clipped, window)
    visible = lat_mod.visible_basis(peaks)
    names = ("toled", "poled") + (("micrograph",) if micrograph else ()) if family_name == "auto" else (family_name,)
    for fam in (f for name in names for f in family(name, micrograph)):
        m = fam.index_basis()
        e0 = lat_mod.cell_basis(visible, m)
        if e0 is not None:
            lattice, _ = lat_mod.fit_lattice(peaks, e0, m, lat_mod.light_centre(plane.value, plane.usable, window))
            return window, lattice, m, aperture_px(lattice.spacing_px)
    return None


def fit_psf(plane: Plane, optics: Optics, family_name: str, micrograph=None, window_px: int = 511,
            progress=None) -> PsfFit:
    """The PSF fit of the module doc; progress(text) is told each stage."""
    say = progress or (lambda text: None)
    window = lat_mod.spot_window(plane.value, plane.clipped, window_px)
    if window.size < 33:
        raise FitError(f"the spot is clipped by the frame: its centre at pixel ({window.x0}, {window.y0}) is "
                       f"{window.half} px from the edge; at least 16 px are needed")
    say("orders' lattice")
    peaks = lat_mod.find_peaks(plane.value, plane.var, plane.usable, plane.clipped, window)
    visible = lat_mod.visible_basis(peaks)
    names = ("toled", "poled") + (("micrograph",) if micrograph else ()) if family_name == "auto" else (family_name,)
    candidates, skipped = [], {}
    for name in names:
        for fam in family(name, micrograph):
            say(f"family {name}{' (' + fam.orientation + ')' if fam.orientation else ''}")
            cand, why = _candidate(fam, plane, window, peaks, visible, optics)
            if cand is None:
                skipped[f"{name} {fam.orientation}".strip()] = why
            else:
                candidates.append(cand)
    if not candidates:
        raise FitError(f"--family {family_name}: no family's lattice matches the orders found "
                       f"({'; '.join(f'{k}: {v}' for k, v in skipped.items())})")
    chosen = min(candidates, key=lambda c: c.fit.chi2_red)
    say(f"family {chosen.family.name}: the profile likelihood")
    settled = _settled(chosen, plane, optics)
    candidates = [settled if c is chosen else c for c in candidates]
    chosen = settled
    f = chosen.fit
    if f.chi2_signal_red > CHI2_MAX and f.rms_rel > REL_RMS_MAX:
        saturated = (f"{chosen.saturated_orders} orders are saturated in every exposure, the orders beside them "
                     "hold more of their light than of their own: add a shorter exposure that keeps the zeroth order "
                     "and its neighbours unsaturated, or ") if chosen.saturated_orders else ""
        raise FitError(f"--family {family_name}: the best family ({chosen.family.name}) leaves a residual far above "
                       f"the noise (χ²/dof {f.chi2_signal_red:.3g} over the orders with signal, their powers off by "
                       f"{f.rms_rel * 100:.3g} % RMS): {saturated}the layout is not one of the families; try --family "
                       "micrograph with the panel's micrograph")
    _refuse_undetermined(chosen, family_name)
    return PsfFit(plane, window, peaks, candidates, skipped, chosen)


def _named(names, values) -> str:
    return ", ".join(f"{n} {v:.2f}" for n, v in zip(names, values))


def trade_offs(c: Candidate) -> list[str]:
    """The pairs of shape parameters whose |correlation| exceeds CORRELATED, as 'a and b (correlation ρ)'."""
    names, rho = c.family.names, c.fit.correlation
    return [f"{names[i]} and {names[j]} (correlation {rho[i, j]:+.3f})" for i in range(len(names))
            for j in range(i + 1, len(names)) if abs(rho[i, j]) > CORRELATED]


def _refuse_undetermined(c: Candidate, family_name: str) -> None:
    """Refuse a shape the orders do not determine: fewer rows with signal than parameters + 2, a shape
    parameter's σ above SHAPE_REL_SIGMA_MAX of its value (a P-OLED in one exposure at 0.1 of the full well:
    the open fraction 0.41 ± 3.1 or 0.005 ± 0.15, where the truth is 0.23), or another minimum that fits as
    well (a stripe whose zeroth and nearest orders are saturated: widths w and 1 − w give every other
    order's power alike)."""
    f, fam = c.fit, c.family
    k = len(fam.names)
    sig = np.sqrt(np.maximum(np.diag(f.cov)[:k], 0.0))
    loose = [f"{n} {v:.3g} ± {s:.2g}" for n, v, s in zip(fam.names, f.x[:k], sig)
             if not s <= SHAPE_REL_SIGMA_MAX * abs(v)]
    trade = "; " + ", ".join(trade_offs(c)) + " trade off" if trade_offs(c) else ""
    what = f"--family {family_name}: the orders measured ({f.signal_rows} powers with signal) do not determine the " \
        f"{fam.name} opening"
    todo = (f"{c.saturated_orders} orders are saturated in every exposure: add a shorter exposure that keeps the "
            "zeroth order and its neighbours unsaturated") if c.saturated_orders else \
        "give a brighter exposure, or a second one 10x longer, or a wider --window-px (more orders)"
    if f.signal_rows < len(f.x) + 2 or loose:
        raise FitError(f"{what} ({', '.join(loose) or 'fewer powers than parameters + 2'}{trade}): {todo}")
    if f.alternatives:
        others = "; ".join(f"{_named(fam.names, x)} (χ² {chi2:.1f})" for x, chi2 in f.alternatives)
        raise FitError(f"{what}: {_named(fam.names, f.x[:k])} (χ² {f.chi2:.1f}) and {others} fit alike (Δχ² < "
                       f"{AMBIGUOUS_CHI2:g}{trade}): the orders that tell them apart are too weak or saturated: {todo}")


def refuse_synthesis(check: dict, family_name: str) -> None:
    """Refuse a fit whose display file's synthesis misses the measured orders' powers by more than
    SYNTHESIS_MAX × the noise's relative L2 (synthesis_check)."""
    ratio = check["orders_relative_l2"] / check["orders_noise_l2"]
    if ratio > SYNTHESIS_MAX:
        raise FitError(f"--family {family_name}: the fitted display's PSF misses the measured orders' powers by a "
                       f"relative L2 of {check['orders_relative_l2']:.3g}, {ratio:.3g}× the noise's "
                       f"{check['orders_noise_l2']:.2g} (at most {SYNTHESIS_MAX:g}×): the opening found is not the "
                       "panel's; try --family micrograph with the panel's micrograph")


def orders_table(c: Candidate) -> dict:
    """Per order (m, n): the row with the best SNR in the reference exposure's units (÷ its fitted factor):
    power, σ, model, whether any of its rows was fitted, its window position."""
    o, fit = c.orders, c.fit
    scale = np.exp(-fit.exposure_log_factor(o.exposure))
    snr = np.where(np.isfinite(scale) & o.measured, o.snr(), -np.inf)
    uniq, inv = np.unique(o.index, axis=0, return_inverse=True)
    inv = inv.ravel()
    best = np.full(len(uniq), -1)
    for row in np.argsort(snr):
        best[inv[row]] = row
    best = best[snr[best] > -np.inf]
    used = np.zeros(len(uniq), bool)
    np.logical_or.at(used, inv, fit.used)
    return {"m": o.index[best, 0], "n": o.index[best, 1], "x_px": o.xy[best, 0], "y_px": o.xy[best, 1],
            "power": o.power[best] * scale[best], "sigma": o.sigma[best] * scale[best],
            "model": fit.model_power[best] * scale[best], "used": used[inv[best]]}


def synthesis_check(psf: PsfFit, layout, optics: Optics) -> tuple[dict, np.ndarray]:
    """The display file's layout rendered where the measured spot is (origin, rotation) against the
    measurement: (measures, the rendered window scaled to the measurement). Orders: each row's model is
    exp(ln s + ln f + the field's terms) × the render's photometry at that order; image: the least-squares scale of the
    render (times the fitted vignetting) to the HDR window over the usable pixels. Each relative L2 beside
    the noise's alone."""
    c, w = psf.chosen, psf.window
    lattice, fit, o = c.lattice, c.fit, c.orders
    phi = math.radians(c.rotation_deg[0])
    half = w.half
    synth = render(layout, optics, w.size, lattice.origin, c.rotation_deg[0])
    p = layout.period_um
    rot = np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])
    e = rot @ np.diag([optics.lz_px / p[0], optics.lz_px / p[1]])
    uniq, inv = np.unique(o.index, axis=0, return_inverse=True)
    q = measure(synth, np.ones_like(synth), np.ones(synth.shape, bool), lattice.origin + uniq @ e.T, uniq,
                c.radius_px, optics.lens, optics.wavelength_nm, optics.pixel_um)
    synth = synth * field_map(fit, w.size)
    model = np.exp(fit.log_field(o.xy, half) + fit.exposure_log_factor(o.exposure)) * q.power[inv.ravel()]
    sg_all = np.where(fit.used, o.sigma, np.inf)
    u = fit.used & ((o.power >= SIGNAL_SNR * sg_all) | (model >= SIGNAL_SNR * sg_all))
    pw, sg = o.power[u], o.sigma[u]
    pos = (pw > 0) & (model[u] > 0)
    v, var, ok = w.crop(psf.plane.value), w.crop(psf.plane.var), w.crop(psf.plane.usable)
    a = float(np.sum(v[ok] * synth[ok]) / np.sum(synth[ok] ** 2))
    norm = float(np.sqrt(np.sum(v[ok] ** 2)))
    return {"orders_relative_l2": float(np.linalg.norm(pw - model[u]) / np.linalg.norm(pw)),
            "orders_noise_l2": float(np.linalg.norm(sg) / np.linalg.norm(pw)),
            "orders_median_abs_log": float(np.median(np.abs(np.log(pw[pos] / model[u][pos])))),
            "orders": int(u.sum()),
            "image_relative_l2": float(np.sqrt(np.sum((v[ok] - a * synth[ok]) ** 2)) / norm),
            "image_noise_l2": float(np.sqrt(np.sum(var[ok])) / norm)}, a * synth
