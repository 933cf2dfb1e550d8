"""The plan of one compute_kernels call (psf.engine): the request checked, the pupil-plane window and
the display's mask on it, the field phases (d > 0) with the mask shifts they sample (field_shifts) and
the phases a mirror or inner translation of a periodic display maps onto one another (computed once,
then reflected: docs/PHYSICS.md §4, cost).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace

import numpy as np
import scipy.fft as sfft

from . import fourier
from .banding import disc_quadrant, orders
from .errors import AliasingWarning, PSFError
from .lens import Lens
from .propagation import frequencies
from .pupil import MASK_RASTERS, aperture_slices, display_grid, lens_grid, tile_mask

METHODS = ("mft", "czt", "paper")
PRECISIONS = {"float32": np.complex64, "float64": np.complex128}
DEFAULT_PUPIL_SAMPLES = 1024
DEFAULT_FIELD_PHASES = 4  # per axis; study: mean kernel 2.3e-4 L1, banding within 15 % of its amplitude
ALIAS_GUARD = 1.05
SYMMETRY_TOL = 1e-9  # relative: rasters symmetric to this share their field phases' kernels (_phase_sources)
WAVELENGTH_RANGE_NM = (200.0, 2000.0)  # scalar optics of visible/NIR cameras; sensitivities end well inside
# Pupil windows larger than this are refused at once: at d > 0 every field phase and wavelength FFTs the
# window (aperiodic tiles) or its display period and the doubled aperture crop (8192² ≈ 0.5 GB per complex64
# copy, minutes per kernel set beyond it); at d = 0 only the aperture crop is transformed and the bound is
# the window's memory (16384²: 2 GB per copy).
MAX_PUPIL_WINDOW_SAMPLES = 8192 ** 2
MAX_PUPIL_WINDOW_SAMPLES_D0 = 16384 ** 2
# A periodic display's transmitted power is the exact series of psf.banding over (4 m_x + 1)(4 m_y + 1) lags,
# m = ⌊p / λ⌋: 1.0e8 for a 1008 µm period at 400 nm (its bank ran on the 24 GB machine), 7.2e8 for 2688 µm (out of
# memory there; where between the two memory runs out is not measured). Beyond this bound it is refused at once;
# such a period of turned tiles is given as the tile and its tile_arrangement, rastered tile by tile.
MAX_SERIES_LAGS = 2.5e8


def validate_request(wavelengths_nm, pixel_um, size_px, distance_mm, field_phases, method, precision, pupil_samples,
              mask_raster):
    wl = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
    if wl.ndim != 1 or wl.size == 0 or not np.all(np.isfinite(wl)) or np.any(wl <= 0):
        raise PSFError(f"wavelengths_nm must be positive finite numbers, got "
                       f"{[float(v) for v in np.ravel(np.asarray(wavelengths_nm, dtype=float))]}")
    lo, hi = WAVELENGTH_RANGE_NM
    if wl.min() < lo or wl.max() > hi:
        bad = float(wl.min() if wl.min() < lo else wl.max())
        raise PSFError(f"wavelengths_nm = {bad:g}: expected {lo:g} to {hi:g} nm")
    if not (isinstance(size_px, (int, np.integer)) and size_px >= 3 and size_px % 2 == 1):
        raise PSFError(f"size_px must be an odd integer ≥ 3 (kernel centred at size//2), got {size_px}")
    if not (pixel_um > 0 and math.isfinite(pixel_um)):
        raise PSFError(f"pixel_um must be > 0, got {pixel_um}")
    if not (distance_mm >= 0 and math.isfinite(distance_mm)):
        raise PSFError(f"distance_mm must be ≥ 0 and finite, got {distance_mm}")
    if field_phases is not None and not (isinstance(field_phases, (int, np.integer)) and field_phases >= 1):
        raise PSFError(f"field_phases must be an integer ≥ 1, got {field_phases}")
    if method not in METHODS:
        raise PSFError(f"method must be one of {', '.join(METHODS)}, got '{method}'")
    if precision not in PRECISIONS:
        raise PSFError(f"precision must be one of {', '.join(PRECISIONS)}, got '{precision}'")
    if mask_raster not in MASK_RASTERS:
        raise PSFError(f"mask_raster must be one of {', '.join(MASK_RASTERS)}, got '{mask_raster}'")
    if pupil_samples is not None and not (isinstance(pupil_samples, (int, np.integer)) and pupil_samples >= 16):
        raise PSFError(f"pupil_samples must be an integer ≥ 16, got {pupil_samples}")
    return wl


def series_lags(period_um, wavelength_nm: float) -> int:
    """(4 m_x + 1)(4 m_y + 1), m = ⌊p / λ⌋: the lags of a periodic display's exact power series at λ."""
    mx, my = orders(period_um, wavelength_nm * 1e-3)
    return (4 * mx + 1) * (4 * my + 1)


def _check_series(period_um, wavelength_nm: float) -> None:
    """Refuse a periodic display whose exact power series would exceed MAX_SERIES_LAGS lags."""
    lags = series_lags(period_um, wavelength_nm)
    if lags > MAX_SERIES_LAGS:
        raise PSFError(f"display period {period_um[0]:g} × {period_um[1]:g} µm at {wavelength_nm:g} nm: its exact "
                       f"power series needs {lags:.3g} lags; allowed ≤ {MAX_SERIES_LAGS:.3g} (a period of turned "
                       f"tiles: give the tile and its tile_arrangement)")


def auto_pupil_samples(lens: Lens, wavelength_min_nm: float, pixel_um: float, size_px: int) -> int:
    """Samples across the aperture: DEFAULT_PUPIL_SAMPLES, raised until λ_min z / δ ≥ 1.05 × window and,
    with aberrations, until the pupil phase steps less than π per sample (δ ≤ λ_min / (2 max|∇OPD|), times
    1.05: the light the aberration throws stays inside the alias-free field)."""
    window = size_px * pixel_um
    need = ALIAS_GUARD * lens.aperture_um * window / (wavelength_min_nm * 1e-3 * lens.image_distance_um)
    phase = ALIAS_GUARD * 2 * lens.aperture_um * lens.max_phase_slope() / (wavelength_min_nm * 1e-3)
    return max(DEFAULT_PUPIL_SAMPLES, int(math.ceil(need)), int(math.ceil(phase)))


PAPER_SENSOR_UM = (2048 * 1.55, 1024 * 1.55)


def field_shifts(period_um, distance_um: float, image_distance_um: float, phases: int,
                 sensor_um=PAPER_SENSOR_UM, periodic: bool = True) -> np.ndarray:
    """Mask shifts [P, P, 2] (µm) at which field kernels are sampled, per axis:
    the whole display period (s_i = i p / P) when the display is periodic and the sensor sees at least one
    banding period (sensor · d / z_i ≥ p), else P points across the sensor (s_i = x_i d / z_i, x_i centred
    cells). An aperiodic display (randomly turned tiles) repeats under no shift, so its phases always span
    the part of it the sensor sees. The field average tends to the principal-plane kernel (s = 0) as d → 0.
    """
    axes = []
    for p, width in zip(period_um, sensor_um):
        span = width * distance_um / image_distance_um
        i = np.arange(phases)
        axes.append(i / phases * p if periodic and span >= p else ((i + 0.5) / phases - 0.5) * span)
    out = np.zeros((phases, phases, 2))
    out[..., 0], out[..., 1] = axes[0][None, :], axes[1][:, None]
    return out


def _spread_margin_um(distance_um, wavelength_um, d_um):
    """Lateral spread over d of the highest angle the grid carries (sin θ = λ / 2δ)."""
    s = min(wavelength_um / (2 * d_um), 0.999)
    return distance_um * s / math.sqrt(1 - s * s)


def _window(display, lens: Lens, n_pupil: int, wl: np.ndarray, d_um: float, mask_raster: str,
            shifts: np.ndarray):
    """The pupil-plane window and the display's amplitude raster on it: (grid, mask or None, κ).

    Periodic displays need no margin (the window holds whole periods, propagation is exact);
    aperiodic tiles at d > 0 get a margin for the lateral spread over d plus the largest field shift (at least
    one period), so that no shifted phase wraps the window's far edge into the aperture.
    """
    if display is None:
        return lens_grid(lens, n_pupil), None, 1.0
    period = display.period_um
    margin = 0.0
    if not getattr(display, "periodic", True) and d_um > 0:
        step = min(period) / math.ceil(min(period) * n_pupil / lens.aperture_um)
        margin = _spread_margin_um(d_um, float(wl.max()) * 1e-3, step) + max(float(np.abs(shifts).max()),
                                                                              max(period))
        if margin > 20 * lens.aperture_um:
            raise PSFError(f"distance_mm={d_um / 1000:g}: an aperiodic display (random tile rotation) needs "
                           f"{margin / 1000:.1f} mm of padding; allowed ≤ {20 * lens.aperture_um / 1000:.1f} mm "
                           f"(use a periodic display or a smaller distance)")
    grid, cell_n, tiles = display_grid(period, lens, n_pupil, margin)
    limit = MAX_PUPIL_WINDOW_SAMPLES if d_um > 0 else MAX_PUPIL_WINDOW_SAMPLES_D0
    if grid.nx * grid.ny > limit:
        raise PSFError(f"the pupil window needs {grid.nx} × {grid.ny} samples (display period {max(period):g} µm "
                       f"at δ = aperture / {n_pupil} = {lens.aperture_um / n_pupil:.3g} µm); allowed ≤ {limit:.3g} "
                       f"at d {'>' if d_um > 0 else '='} 0: use fewer pupil_samples or an aperture of several periods")
    try:
        mask, kappa = tile_mask(display, cell_n, tiles, mask_raster)
    except ValueError as exc:
        raise PSFError(str(exc)) from None
    return grid, mask, kappa


@dataclass(frozen=True)
class Plan:
    """Everything fixed for one compute_kernels call: the request, the pupil window and mask, the
    field phases (d > 0) and the mask spectrum they are shifted from."""
    display: object
    lens: Lens
    wl: np.ndarray
    pixel_um: float
    size_px: int
    d_um: float
    method: str
    cdtype: type
    pixel_integration: bool
    deapodize: bool
    n_pupil: int
    grid: object
    mask: np.ndarray | None
    kappa: float
    pgrid: object
    sy: slice
    sx: slice
    aperture: np.ndarray
    use_field: bool
    exact_power: bool
    phases: int
    shifts: np.ndarray
    field_raster: np.ndarray | None
    mask_spec: np.ndarray | None
    fx: np.ndarray | None
    fy: np.ndarray | None
    crop_rows: np.ndarray | None
    crop_cols: np.ndarray | None
    disc: np.ndarray | None
    sources: tuple = ((0, False, False),)


def check_alias(plan: Plan) -> None:
    """Warn when the kernel window reaches past the alias-free field λz/δ of the pupil raster."""
    lens, wl, pg = plan.lens, plan.wl, plan.pgrid
    window = plan.size_px * plan.pixel_um
    slope = lens.max_phase_slope()
    for axis, step in (("x", pg.dx_um), ("y", pg.dy_um)):
        free = float(wl.min()) * 1e-3 * lens.image_distance_um / step
        if slope * step > float(wl.min()) * 1e-3 / 2:
            need = auto_pupil_samples(lens, float(wl.min()), plan.pixel_um, plan.size_px)
            warnings.warn(f"the lens's aberrations step the pupil phase by more than π per sample along {axis} at "
                          f"{wl.min():g} nm (pupil_samples={plan.n_pupil}); need pupil_samples ≥ {need}",
                          AliasingWarning, stacklevel=3)
            break
        if window > free and plan.method != "paper":
            need = auto_pupil_samples(lens, float(wl.min()), plan.pixel_um, plan.size_px)
            warnings.warn(f"kernel window {window:.0f} µm exceeds the alias-free field λz/δ{axis} = {free:.0f} µm "
                          f"at {wl.min():g} nm (pupil_samples={plan.n_pupil}); need pupil_samples ≥ {need}",
                          AliasingWarning, stacklevel=3)
            break


def make_plan(display, lens, wl, pixel_um, size_px, distance_mm, field_phases, method, pupil_samples, precision,
          pixel_integration, mask_raster, sensor_um, notes: list) -> Plan:
    """The pupil window and mask, the aperture, the field phases; notes on what was skipped."""
    cdtype = PRECISIONS[precision]
    n_pupil = pupil_samples or auto_pupil_samples(lens, float(wl.min()), pixel_um, size_px)
    d_um = distance_mm * 1000.0
    use_field = d_um > 0 and display is not None
    periodic = display is not None and getattr(display, "periodic", True)
    if periodic:
        _check_series(display.period_um, float(wl.min()))
    phases = (field_phases or DEFAULT_FIELD_PHASES) if use_field else 1
    shifts = (field_shifts(display.period_um, d_um, lens.image_distance_um, phases, sensor_um, periodic) if use_field
              else np.zeros((1, 1, 2)))
    grid, mask, kappa = _window(display, lens, n_pupil, wl, d_um, mask_raster, shifts)
    sy, sx = aperture_slices(grid, lens.aperture_um)
    pgrid = grid.crop(sy, sx)
    if d_um > 0 and display is None:
        notes.append("distance_mm > 0 with a bare lens: nothing to propagate, principal-plane result")
    if not use_field and field_phases is not None and field_phases > 1:
        notes.append("field phases skipped: the PSF is field-independent when d = 0 or without a display")
    raster = _field_raster(display, grid, mask) if use_field else None
    mask_spec = sfft.fft2(raster.astype(cdtype), workers=fourier.WORKERS) if use_field else None
    ny, nx = raster.shape if use_field else (0, 0)
    fx, fy = (frequencies(nx, grid.dx_um), frequencies(ny, grid.dy_um)) if use_field else (None, None)
    rows, cols = (np.arange(sy.start, sy.stop) % ny, np.arange(sx.start, sx.stop) % nx) if use_field else (None, None)
    disc = disc_quadrant(display.period_um, lens.aperture_um, float(wl.min()) * 1e-3) if periodic else None
    # De-apodise where the pupil's spectrum is box-filtered: an area-weighted mask or a bare aperture
    # (not with defocus: its phase is point-sampled, not box-filtered). Transmitted power: the exact
    # series of psf.banding for periodic displays; the raster sum (× κ) for aperiodic tiles.
    plan = Plan(display, lens, wl, float(pixel_um), size_px, d_um, method, cdtype, pixel_integration,
                 display is None or mask_raster == "area", n_pupil, grid, mask, kappa, pgrid, sy, sx,
                 lens.aperture_area_fraction(pgrid.x_edges_um, pgrid.y_edges_um), use_field,
                 periodic, phases, shifts, raster, mask_spec, fx, fy, rows, cols, disc)
    return replace(plan, sources=_phase_sources(plan)) if use_field else plan


def _field_raster(display, grid, mask: np.ndarray) -> np.ndarray:
    """The raster the field phases propagate and shift: one display period of the window's mask when the
    display is periodic (the window is its tiling, so the window's band-limited shifts are the period's,
    tiled: the same field from FFTs of one period), else the whole window (with its margin)."""
    if not getattr(display, "periodic", True):
        return mask
    px, py = display.period_um
    return mask[:round(py / grid.dy_um), :round(px / grid.dx_um)]


def _mirror_symmetries(plan: Plan) -> list[tuple[bool, bool]]:
    """The flips (flip_y, flip_x) that leave both the mask raster over the window and the aperture crop
    unchanged (to SYMMETRY_TOL): reflections x → −x, y → −y about the optical axis (the window and,
    when the crop is centred in it, the crop are symmetric about the axis), and the lens's wavefront error
    too when it has one (coma along x, say, is not symmetric under x → −x)."""
    centred = (plan.sy.start + plan.sy.stop == plan.grid.ny, plan.sx.start + plan.sx.stop == plan.grid.nx)
    arrays = (plan.mask, plan.aperture)
    if plan.lens.zernike_waves:
        arrays += (plan.lens.wavefront_um(plan.pgrid.x_um, plan.pgrid.y_um) * plan.aperture,)
    out = []
    for flips in ((False, False), (False, True), (True, False), (True, True)):
        axes = tuple(a for a, f in enumerate(flips) if f)
        if all(centred[a] for a in axes) and all(
                np.abs(a - np.flip(a, axes)).max() <= SYMMETRY_TOL * np.abs(a).max() for a in arrays):
            out.append(flips)
    return out


def _translation_test(plan: Plan):
    """t ↦ whether the band-limited shift by t (µm, x and y) leaves the mask raster unchanged: its spectrum
    M carries only frequencies with ν·t ∈ ℤ, |M_ν| · |e^{−2πiν·t} − 1| ≤ SYMMETRY_TOL max |M| (whole periods
    always; a cell's inner translations, e.g. the pentile's (p/2, p/2))."""
    spec = np.abs(sfft.fft2(plan.field_raster, workers=fourier.WORKERS))
    iy, ix = np.nonzero(spec > SYMMETRY_TOL * spec.max())
    amp, fx, fy, tol = spec[iy, ix], plan.fx[ix], plan.fy[iy], SYMMETRY_TOL * spec.max()
    return lambda t: bool(np.max(amp * 2 * np.abs(np.sin(np.pi * (fx * t[0] + fy * t[1])))) <= tol)


def _phase_sources(plan: Plan) -> tuple:
    """(q0, flip_y, flip_x) for each field phase q = j·P + i: its kernel is phase q0's flipped (q0 = q:
    computed). Phase q repeats q0 when a symmetry σ of the periodic display (a mirror of _mirror_symmetries)
    and a translation t that leaves the raster unchanged give s_q = σ s_q0 + t: then
    m(x − s_q) = m(σ(x − s_q0)), the pupil field is phase q0's reflected, and so is its kernel (exact,
    up to rounding; the transmitted power comes from the series at every phase)."""
    P = plan.phases
    flat = plan.shifts.reshape(-1, 2)
    if not plan.exact_power:
        return tuple((q, False, False) for q in range(P * P))
    mirrors, invariant = _mirror_symmetries(plan), _translation_test(plan)
    sources = []
    for q, s in enumerate(flat):
        sources.append(next(((q0, fy, fx) for q0, (r, _, _) in enumerate(sources) if r == q0
                             for fy, fx in mirrors
                             if invariant(s - flat[q0] * (-1.0 if fx else 1.0, -1.0 if fy else 1.0))),
                            (q, False, False)))
    return tuple(sources)
