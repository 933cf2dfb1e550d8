"""The PSF engine: display layout × lens × wavelength × display-to-lens distance → sensor kernels.

Pipeline per wavelength (and per field phase when d > 0):
  mask raster (commensurate, exactly periodic) ─► [angular-spectrum propagation over d and a
  phase-ramp shift of the mask] ─► crop to the aperture × area-weighted disc × defocus phase
  ─► autocorrelation (OTF) ─► exact pixel integration and MFT / chirp-z to the sensor grid.
With d = 0 the propagation is skipped, the pupil is wavelength-independent (in focus) and its
autocorrelation is computed once for all wavelengths; field phases are skipped (no field dependence).

At d > 0 the P² field phases of one wavelength share everything but their own pupil FFT pair
(docs/PHYSICS.md §4, cost): the propagated mask spectrum (of one display period when the display is
periodic: the window is its tiling, so each phase is shifted and back-transformed on one period and
tiled over the aperture), the MFT matrices (fourier.PixelMFT), the power series. Phases that a mirror or
inner translation of a periodic display maps onto one another (_phase_sources) are computed once and
reflected: 9 of 16 for the T-OLED, 6 of 16 for the P-OLED. All of this is exact (to rounding).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.fft as sfft

from . import fourier
from .banding import PowerSeries, disc_quadrant
from .errors import AliasingWarning, PSFError, UnderSamplingWarning  # noqa: F401 (re-exported)
from .lens import Lens
from .propagation import angular_spectrum_tf, frequencies, ramp
from .pupil import MASK_RASTERS, aperture_slices, display_grid, lens_grid, tile_mask

__all__ = ["METHODS", "PRECISIONS", "DEFAULT_PUPIL_SAMPLES", "DEFAULT_FIELD_PHASES", "ALIAS_GUARD",
           "WAVELENGTH_RANGE_NM", "MAX_PUPIL_WINDOW_SAMPLES", "MAX_PUPIL_WINDOW_SAMPLES_D0", "PAPER_SENSOR_UM", "KernelSet", "auto_pupil_samples",
           "field_shifts", "compute_kernels", "PSFError", "AliasingWarning", "UnderSamplingWarning"]

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


@dataclass
class KernelSet:
    """Kernels for K wavelengths on a size_px² grid of pixel_um pixels, centred at size_px // 2.

    kernels            [K, S, S]  unit sum inside the window (power-weighted mean over field phases)
    energy_outside     [K]        fraction of the transmitted power that falls outside the window
                                  (point-sampled kernels: the Riemann estimate Σ ρ² I(u_j), which is
                                  negative where pixels undersample an Airy core; see pixel_integration)
    transmittance      [K]        power through display and aperture / power through the bare aperture
    ratio_r            [K]        the paper's down-sampling ratio r = δ_N N ρ / (λ f), N δ_N = aperture
    field_kernels      [K, P, P, S, S] per field phase (d > 0 only), each unit sum
    field_power        [K, P, P]  transmitted power per phase / its mean (the banding samples)
    field_shifts_um    [P, P, 2]  mask shift (x, y) of each phase; image position = shift · z_i / d
                                  (see field_shifts: a whole period, or the part the sensor sees)
    period_um          (x, y)     the display's period (None: bare lens)
    distance_mm, image_distance_um   the display-to-lens gap d and the lens-to-sensor distance z_i
    """
    kernels: np.ndarray
    wavelengths_nm: np.ndarray
    pixel_um: float
    energy_outside: np.ndarray
    transmittance: np.ndarray
    ratio_r: np.ndarray
    params: dict
    field_kernels: np.ndarray | None = None
    field_power: np.ndarray | None = None
    field_shifts_um: np.ndarray | None = None
    notes: list = field(default_factory=list)
    period_um: tuple[float, float] | None = None
    distance_mm: float = 0.0
    image_distance_um: float = math.nan

    @property
    def size_px(self) -> int:
        return self.kernels.shape[-1]


def _validate(wavelengths_nm, pixel_um, size_px, distance_mm, field_phases, method, precision, pupil_samples,
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


def auto_pupil_samples(lens: Lens, wavelength_min_nm: float, pixel_um: float, size_px: int) -> int:
    """Samples across the aperture: DEFAULT_PUPIL_SAMPLES, raised until λ_min z / δ ≥ 1.05 × window."""
    window = size_px * pixel_um
    need = ALIAS_GUARD * lens.aperture_um * window / (wavelength_min_nm * 1e-3 * lens.image_distance_um)
    return max(DEFAULT_PUPIL_SAMPLES, int(math.ceil(need)))


PAPER_SENSOR_UM = (2048 * 1.55, 1024 * 1.55)


def field_shifts(period_um, distance_um: float, image_distance_um: float, phases: int,
                 sensor_um=PAPER_SENSOR_UM) -> np.ndarray:
    """Mask shifts [P, P, 2] (µm) at which field kernels are sampled, per axis:
    the whole display period (s_i = i p / P) when the sensor sees at least one banding period
    (sensor · d / z_i ≥ p), else P points across the sensor (s_i = x_i d / z_i, x_i centred cells).
    So the field average tends to the principal-plane kernel (s = 0) as d → 0.
    """
    axes = []
    for p, width in zip(period_um, sensor_um):
        span = width * distance_um / image_distance_um
        i = np.arange(phases)
        axes.append(i / phases * p if span >= p else ((i + 0.5) / phases - 0.5) * span)
    out = np.zeros((phases, phases, 2))
    out[..., 0], out[..., 1] = axes[0][None, :], axes[1][:, None]
    return out


def _spread_margin_um(distance_um, wavelength_um, d_um):
    """Lateral spread over d of the highest angle the grid carries (sin θ = λ / 2δ)."""
    s = min(wavelength_um / (2 * d_um), 0.999)
    return distance_um * s / math.sqrt(1 - s * s)


def _window(display, lens: Lens, n_pupil: int, wl: np.ndarray, d_um: float, mask_raster: str):
    """The pupil-plane window and the display's amplitude raster on it: (grid, mask or None, κ).

    Periodic displays need no margin (the window holds whole periods, propagation is exact);
    aperiodic tiles at d > 0 get a margin for the lateral spread over d plus one period of shift.
    """
    if display is None:
        return lens_grid(lens, n_pupil), None, 1.0
    period = display.period_um
    margin = 0.0
    if not getattr(display, "periodic", True) and d_um > 0:
        step = min(period) / math.ceil(min(period) * n_pupil / lens.aperture_um)
        margin = _spread_margin_um(d_um, float(wl.max()) * 1e-3, step) + max(period)
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
class _Plan:
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


def _check_alias(plan: _Plan) -> None:
    """Warn when the kernel window reaches past the alias-free field λz/δ of the pupil raster."""
    lens, wl, pg = plan.lens, plan.wl, plan.pgrid
    window = plan.size_px * plan.pixel_um
    for axis, step in (("x", pg.dx_um), ("y", pg.dy_um)):
        free = float(wl.min()) * 1e-3 * lens.image_distance_um / step
        if window > free and plan.method != "paper":
            need = auto_pupil_samples(lens, float(wl.min()), plan.pixel_um, plan.size_px)
            warnings.warn(f"kernel window {window:.0f} µm exceeds the alias-free field λz/δ{axis} = {free:.0f} µm "
                          f"at {wl.min():g} nm (pupil_samples={plan.n_pupil}); need pupil_samples ≥ {need}",
                          AliasingWarning, stacklevel=3)
            break


def _plan(display, lens, wl, pixel_um, size_px, distance_mm, field_phases, method, pupil_samples, precision,
          pixel_integration, mask_raster, sensor_um, notes: list) -> _Plan:
    """The pupil window and mask, the aperture, the field phases; notes on what was skipped."""
    cdtype = PRECISIONS[precision]
    n_pupil = pupil_samples or auto_pupil_samples(lens, float(wl.min()), pixel_um, size_px)
    d_um = distance_mm * 1000.0
    grid, mask, kappa = _window(display, lens, n_pupil, wl, d_um, mask_raster)
    sy, sx = aperture_slices(grid, lens.aperture_um)
    pgrid = grid.crop(sy, sx)
    use_field = d_um > 0 and display is not None
    if d_um > 0 and display is None:
        notes.append("distance_mm > 0 with a bare lens: nothing to propagate, principal-plane result")
    if not use_field and field_phases is not None and field_phases > 1:
        notes.append("field phases skipped: the PSF is field-independent when d = 0 or without a display")
    phases = (field_phases or DEFAULT_FIELD_PHASES) if use_field else 1
    shifts = (field_shifts(display.period_um, d_um, lens.image_distance_um, phases, sensor_um) if use_field
              else np.zeros((1, 1, 2)))
    periodic = display is not None and getattr(display, "periodic", True)
    raster = _field_raster(display, grid, mask) if use_field else None
    mask_spec = sfft.fft2(raster.astype(cdtype), workers=fourier.WORKERS) if use_field else None
    ny, nx = raster.shape if use_field else (0, 0)
    fx, fy = (frequencies(nx, grid.dx_um), frequencies(ny, grid.dy_um)) if use_field else (None, None)
    rows, cols = (np.arange(sy.start, sy.stop) % ny, np.arange(sx.start, sx.stop) % nx) if use_field else (None, None)
    disc = disc_quadrant(display.period_um, lens.aperture_um, float(wl.min()) * 1e-3) if periodic else None
    # De-apodise where the pupil's spectrum is box-filtered: an area-weighted mask or a bare aperture
    # (not with defocus: its phase is point-sampled, not box-filtered). Transmitted power: the exact
    # series of psf.banding for periodic displays; the raster sum (× κ) for aperiodic tiles.
    plan = _Plan(display, lens, wl, float(pixel_um), size_px, d_um, method, cdtype, pixel_integration,
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


def _mirror_symmetries(plan: _Plan) -> list[tuple[bool, bool]]:
    """The flips (flip_y, flip_x) that leave both the mask raster over the window and the aperture crop
    unchanged (to SYMMETRY_TOL): reflections x → −x, y → −y about the optical axis (the window and,
    when the crop is centred in it, the crop are symmetric about the axis)."""
    centred = (plan.sy.start + plan.sy.stop == plan.grid.ny, plan.sx.start + plan.sx.stop == plan.grid.nx)
    out = []
    for flips in ((False, False), (False, True), (True, False), (True, True)):
        axes = tuple(a for a, f in enumerate(flips) if f)
        if all(centred[a] for a in axes) and all(
                np.abs(a - np.flip(a, axes)).max() <= SYMMETRY_TOL * np.abs(a).max() for a in (plan.mask, plan.aperture)):
            out.append(flips)
    return out


def _translation_test(plan: _Plan):
    """t ↦ whether the band-limited shift by t (µm, x and y) leaves the mask raster unchanged: its spectrum
    M carries only frequencies with ν·t ∈ ℤ, |M_ν| · |e^{−2πiν·t} − 1| ≤ SYMMETRY_TOL max |M| (whole periods
    always; a cell's inner translations, e.g. the pentile's (p/2, p/2))."""
    spec = np.abs(sfft.fft2(plan.field_raster, workers=fourier.WORKERS))
    iy, ix = np.nonzero(spec > SYMMETRY_TOL * spec.max())
    amp, fx, fy, tol = spec[iy, ix], plan.fx[ix], plan.fy[iy], SYMMETRY_TOL * spec.max()
    return lambda t: bool(np.max(amp * 2 * np.abs(np.sin(np.pi * (fx * t[0] + fy * t[1])))) <= tol)


def _phase_sources(plan: _Plan) -> tuple:
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


@dataclass(frozen=True)
class _Wave:
    """What the field phases of one wavelength share: the pupil weight (aperture [× defocus] in the
    working precision), the mask spectrum × the angular-spectrum transfer over d (d > 0), the MFT
    matrices (method 'mft' with pixel integration) and the transmitted-power series (periodic displays)."""
    lam_nm: float
    defocus: np.ndarray | None
    weight: np.ndarray
    spec: np.ndarray | None
    mft: fourier.PixelMFT | None
    series: PowerSeries | None


def _wave(plan: _Plan, lam_nm: float) -> _Wave:
    lens, pg, lam = plan.lens, plan.pgrid, lam_nm * 1e-3
    defocus = lens.pupil_phase(pg.x_um, pg.y_um, lam)
    weight = (plan.aperture.astype(np.finfo(plan.cdtype).dtype) if defocus is None
              else (plan.aperture * defocus).astype(plan.cdtype))
    spec = (plan.mask_spec * angular_spectrum_tf(plan.fx, plan.fy, lam, plan.d_um).astype(plan.cdtype)
            if plan.use_field else None)
    mft = (fourier.PixelMFT((2 * pg.ny - 1, pg.nx), pg.dx_um, pg.dy_um, lam, lens.image_distance_um, plan.pixel_um,
                            plan.size_px, True, plan.cdtype, plan.deapodize and defocus is None)
           if plan.method == "mft" and plan.pixel_integration else None)
    series = PowerSeries(plan.display, lens, lam, plan.d_um, plan.disc) if plan.exact_power else None
    return _Wave(lam_nm, defocus, weight, spec, mft, series)


def _field_masks(plan: _Plan, wave: _Wave, phases: list[int]):
    """(q, the display's amplitude over the aperture) for the field phases q = j·P + i listed: at d > 0 the
    field raster's spectrum propagated over d and shifted by s = (x_i, y_j) (ramp(fy, y_j) ⊗ ramp(fx, x_i)),
    back-transformed and gathered over the aperture crop (a periodic display's period tiled); at d = 0 the
    mask as rastered (a bare lens: ones)."""
    if not plan.use_field:
        yield 0, plan.mask[plan.sy, plan.sx] if plan.mask is not None else np.ones(plan.aperture.shape)
        return
    P = plan.phases
    for q in phases:
        x_um, y_um = plan.shifts[q // P, q % P]
        ramps = np.outer(ramp(plan.fy, y_um), ramp(plan.fx, x_um)).astype(plan.cdtype)
        field = sfft.ifft2(wave.spec * ramps, workers=fourier.WORKERS)
        yield q, field.take(plan.crop_rows, axis=0).take(plan.crop_cols, axis=1)


def _flip(kernel: np.ndarray, flip_y: bool, flip_x: bool) -> np.ndarray:
    """kernel [S, S] reflected about its centre pixel along y and/or x."""
    return np.flip(kernel, tuple(ax for ax, f in ((0, flip_y), (1, flip_x)) if f))


def _kernel_of_power(plan: _Plan, wave: _Wave, power: np.ndarray) -> np.ndarray:
    """The pixel-integrated kernel of a padded pupil power spectrum |G|² (PixelMFT, or chirp-z of its lags)."""
    pg = plan.pgrid
    if wave.mft is not None:
        return wave.mft.of_power(power, pg.dx_um, pg.dy_um)
    R = fourier.lags_from_power(power, (pg.ny, pg.nx), pg.dx_um, pg.dy_um)
    return fourier.pixel_kernel(R, pg.dx_um, pg.dy_um, wave.lam_nm * 1e-3, plan.lens.image_distance_um,
                                plan.pixel_um, plan.size_px, plan.method, True, plan.cdtype,
                                plan.deapodize and wave.defocus is None)


def _one_kernel(plan: _Plan, wave: _Wave, g: np.ndarray, state: dict) -> np.ndarray:
    """The (unnormalised) kernel of the pupil field g at λ, by the chosen method.
    With d = 0 and no defocus the pupil is the same at every wavelength: its power spectrum is kept
    in state['power']."""
    pg, lam, z, S = plan.pgrid, wave.lam_nm * 1e-3, plan.lens.image_distance_um, plan.size_px
    deapodize = plan.deapodize and wave.defocus is None
    if plan.method == "paper":
        kern, r_used = fourier.paper_kernel(g, pg.dx_um, pg.dy_um, lam, z, plan.pixel_um, S)
        if r_used < 1 and not state.get("warned_r"):
            warnings.warn(f"paper recipe under-sampled at {wave.lam_nm:g} nm: r = {r_used:.3g} < 1, the DFT grid is "
                          f"coarser than the {plan.pixel_um} µm pixel", UnderSamplingWarning, stacklevel=4)
            state["warned_r"] = True
        return kern
    if not plan.pixel_integration:
        return fourier.point_kernel(g, pg.x_um, pg.y_um, pg.dx_um, pg.dy_um, lam, z, plan.pixel_um, S, plan.method,
                                    plan.cdtype, deapodize)
    if plan.use_field or wave.defocus is not None:
        power = fourier.power_spectrum(g)
    else:  # the same pupil at every wavelength
        power = state.get("power")
        if power is None:
            power = state["power"] = fourier.power_spectrum(g)
    return _kernel_of_power(plan, wave, power)


def _wavelength(plan: _Plan, lam_nm: np.float64, state: dict, progress) -> tuple:
    """(kernel [S, S], energy outside, transmittance, field kernels [P, P, S, S] | None, field power
    [P, P] | None) at one wavelength: the power-weighted sum over the field phases."""
    lens, P, S = plan.lens, plan.phases, plan.size_px
    wave = _wave(plan, lam_nm)
    pg = plan.pgrid
    Q = P * P
    kernels = np.zeros((Q, S, S))
    power = wave.series(plan.shifts) if wave.series is not None else np.zeros((P, P))
    computed = [q for q, (q0, _, _) in enumerate(plan.sources) if q0 == q]
    for q, m in _field_masks(plan, wave, computed):
        g = (m * wave.weight).astype(plan.cdtype, copy=False)
        if wave.series is None:
            power[q // P, q % P] = plan.kappa * float(np.sum(np.abs(m) ** 2 * plan.aperture)) * pg.dx_um * pg.dy_um
        kernels[q] = _one_kernel(plan, wave, g, state)
        if progress:
            progress(1)
    for q, (q0, fy, fx) in enumerate(plan.sources):
        if q0 != q:  # a reflected copy of an earlier phase (_phase_sources)
            kernels[q] = _flip(kernels[q0], fy, fx)
    if progress and Q > len(computed):
        progress(Q - len(computed))
    kernels = kernels.reshape(P, P, S, S)
    windows = kernels.sum(axis=(-1, -2))
    if not (np.all(np.isfinite(kernels)) and np.all(windows > 0)):
        raise PSFError(f"kernel at {lam_nm:g} nm is not finite or carries no energy "
                       f"(window sums {windows.min():g} … {windows.max():g}); check the display and lens")
    acc_window, acc_power = float(windows.sum()), float(power.sum())
    mean_kernel = kernels.sum(axis=(0, 1)) / acc_window
    bare_power = math.pi * lens.aperture_um ** 2 / 4
    field_k = (kernels / windows[..., None, None]).astype(np.finfo(plan.cdtype).dtype) if plan.use_field else None
    field_p = power / power.mean() if plan.use_field else None
    return mean_kernel, 1.0 - acc_window / acc_power, acc_power / P ** 2 / bare_power, field_k, field_p


def _assemble(plan: _Plan, results: list, precision: str, mask_raster: str, sensor_um, notes: list) -> KernelSet:
    """The KernelSet of the per-wavelength results, with every parameter recorded."""
    lens, wl, pg = plan.lens, plan.wl, plan.pgrid
    kernels = np.stack([r[0] for r in results])
    outside, trans = np.array([r[1] for r in results]), np.array([r[2] for r in results])
    ratio = lens.aperture_um * plan.pixel_um / (wl * 1e-3 * lens.focal_length_um)
    if trans.max() < 1e-6:
        notes.append(f"almost nothing is transmitted (transmittance {trans.max():.2e}): the aperture sees "
                     f"little or no display opening; kernels are normalised all the same")
    out_dtype = np.float32 if precision == "float32" else np.float64
    params = {"display": plan.display.describe() if plan.display is not None else {"kind": "none"},
              "lens": lens.describe(), "wavelengths_nm": wl.tolist(), "pixel_um": plan.pixel_um,
              "size_px": int(plan.size_px), "distance_mm": plan.d_um / 1000.0, "field_phases": int(plan.phases),
              "method": plan.method, "pupil_samples": int(plan.n_pupil), "precision": precision,
              "pixel_integration": bool(plan.pixel_integration), "mask_raster": mask_raster,
              "deapodize": bool(plan.deapodize), "pupil_pitch_um": [pg.dx_um, pg.dy_um], "pupil_shape": [pg.ny, pg.nx],
              "image_distance_um": lens.image_distance_um, "sensor_um": list(sensor_um),
              "model": "finite-distance" if plan.use_field else "principal-plane"}
    field_k = np.stack([r[3] for r in results]).astype(out_dtype, copy=False) if plan.use_field else None
    field_p = np.stack([r[4] for r in results]) if plan.use_field else None
    period = None if plan.display is None else tuple(float(v) for v in plan.display.period_um)
    return KernelSet(kernels.astype(out_dtype), wl, plan.pixel_um, outside, trans, ratio, params, field_k, field_p,
                     plan.shifts if plan.use_field else None, notes, period, plan.d_um / 1000.0,
                     lens.image_distance_um)


def compute_kernels(display=None, lens: Lens | None = None, wavelengths_nm=(450.0, 520.0, 640.0),
                    pixel_um: float = 3.1, size_px: int = 255, distance_mm: float = 0.0,
                    field_phases: int | None = None, method: str = "mft", pupil_samples: int | None = None,
                    precision: str = "float32", pixel_integration: bool = True,
                    mask_raster: str = "band_limited", sensor_um=PAPER_SENSOR_UM, progress=None) -> KernelSet:
    """PSF kernels at the sensor for a display (None: bare lens) in front of a lens.

    display: a layout (psf.layouts, psf.micrograph: period_um, fourier_coefficients, cell_raster)
        or None for the bare lens.
    distance_mm: display-to-pupil gap d; 0 is the paper's principal-plane model.
    field_phases: P mask shifts per axis (d > 0 only; None: DEFAULT_FIELD_PHASES), over one display
        period or over the sensor extent sensor_um (x, y) when that sees less than a period (field_shifts).
    pupil_samples: samples across the aperture (None: auto, see auto_pupil_samples).
    precision: 'float32' (complex64 FFTs and products) or 'float64'.
    mask_raster: 'band_limited' (exact Fourier series, default) or 'area' (area-weighted, then
        de-apodised); see pupil.cell_raster. The aperture is always area-weighted.
    progress: optional callable(n) called with the number of kernels done (for progress bars).

    Steps: _plan (window, mask, phases, their symmetries) ─► _wavelength per λ (_wave shared by the phases,
    _field_masks, _one_kernel per distinct phase) ─► _assemble.
    """
    lens = lens or Lens()
    wl = _validate(wavelengths_nm, pixel_um, size_px, distance_mm, field_phases, method, precision, pupil_samples,
                   mask_raster)
    notes: list = []
    plan = _plan(display, lens, wl, pixel_um, size_px, distance_mm, field_phases, method, pupil_samples, precision,
                 pixel_integration, mask_raster, sensor_um, notes)
    _check_alias(plan)
    state: dict = {}
    results = [_wavelength(plan, lam_nm, state, progress) for lam_nm in wl]  # np.float64: keeps float64 products (NEP 50)
    return _assemble(plan, results, precision, mask_raster, sensor_um, notes)
