"""The PSF engine: display layout × lens × wavelength × display-to-lens distance → sensor kernels.

Pipeline per wavelength (and per field phase when d > 0):
  mask raster (commensurate, exactly periodic) ─► [angular-spectrum propagation over d and a
  phase-ramp shift of the mask] ─► crop to the aperture × area-weighted disc × defocus phase
  ─► autocorrelation (OTF) ─► exact pixel integration and MFT / chirp-z to the sensor grid.
With d = 0 the propagation is skipped, the pupil is wavelength-independent (in focus) and its
autocorrelation is computed once for all wavelengths; field phases are skipped (no field dependence).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft

from . import fourier
from .banding import PowerSeries
from .errors import AliasingWarning, PSFError, UnderSamplingWarning  # noqa: F401 (re-exported)
from .lens import Lens
from .propagation import angular_spectrum_tf, frequencies, shift_ramp
from .pupil import MASK_RASTERS, aperture_slices, display_grid, lens_grid, tile_mask

__all__ = ["METHODS", "PRECISIONS", "DEFAULT_PUPIL_SAMPLES", "DEFAULT_FIELD_PHASES", "ALIAS_GUARD",
           "WAVELENGTH_RANGE_NM", "MAX_PUPIL_WINDOW_SAMPLES", "MAX_PUPIL_WINDOW_SAMPLES_D0", "PAPER_SENSOR_UM", "KernelSet", "auto_pupil_samples",
           "field_shifts", "compute_kernels", "PSFError", "AliasingWarning", "UnderSamplingWarning"]

METHODS = ("mft", "czt", "paper")
PRECISIONS = {"float32": np.complex64, "float64": np.complex128}
DEFAULT_PUPIL_SAMPLES = 1024
DEFAULT_FIELD_PHASES = 4  # per axis; study: mean kernel 2.3e-4 L1, banding within 15 % of its amplitude
ALIAS_GUARD = 1.05
WAVELENGTH_RANGE_NM = (200.0, 2000.0)  # scalar optics of visible/NIR cameras; sensitivities end well inside
# Pupil windows larger than this are refused at once: at d > 0 every field phase and wavelength FFTs the
# whole window (8192² ≈ 0.5 GB per complex64 copy, minutes per kernel set beyond it); at d = 0 only the
# aperture crop is transformed and the bound is the window's memory (16384²: 2 GB per copy).
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
    mask_spec: np.ndarray | None
    fx: np.ndarray | None
    fy: np.ndarray | None


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
    mask_spec = sfft.fft2(mask.astype(cdtype), workers=fourier.WORKERS) if use_field else None
    fx, fy = (frequencies(grid.nx, grid.dx_um), frequencies(grid.ny, grid.dy_um)) if use_field else (None, None)
    # De-apodise where the pupil's spectrum is box-filtered: an area-weighted mask or a bare aperture
    # (not with defocus: its phase is point-sampled, not box-filtered). Transmitted power: the exact
    # series of psf.banding for periodic displays; the raster sum (× κ) for aperiodic tiles.
    return _Plan(display, lens, wl, float(pixel_um), size_px, d_um, method, cdtype, pixel_integration,
                 display is None or mask_raster == "area", n_pupil, grid, mask, kappa, pgrid, sy, sx,
                 lens.aperture_area_fraction(pgrid.x_edges_um, pgrid.y_edges_um), use_field,
                 display is not None and getattr(display, "periodic", True), phases, shifts, mask_spec, fx, fy)


def _pupil_mask(plan: _Plan, tf, shift) -> np.ndarray:
    """The display's amplitude over the aperture: propagated by d and shifted (d > 0), else as rastered."""
    if plan.use_field:
        spec = plan.mask_spec * (tf * shift_ramp(plan.fx, plan.fy, *shift)).astype(plan.cdtype)
        return sfft.ifft2(spec, workers=fourier.WORKERS)[plan.sy, plan.sx]
    if plan.mask is not None:
        return plan.mask[plan.sy, plan.sx]
    return np.ones(plan.aperture.shape)


def _one_kernel(plan: _Plan, m, defocus, lam_nm: float, state: dict) -> np.ndarray:
    """The (unnormalised) kernel of the pupil field m · aperture [· defocus] at λ, by the chosen method.
    With d = 0 and no defocus the pupil is the same at every wavelength: its autocorrelation is kept
    in state['R'] and the field is not rebuilt."""
    pg, lam, z, S = plan.pgrid, lam_nm * 1e-3, plan.lens.image_distance_um, plan.size_px
    reuse = plan.pixel_integration and plan.method != "paper" and not plan.use_field and defocus is None
    if not (reuse and state.get("R") is not None):
        g = (m * plan.aperture).astype(plan.cdtype)
        if defocus is not None:
            g = g * defocus.astype(plan.cdtype)
    deapodize = plan.deapodize and defocus is None
    if plan.method == "paper":
        kern, r_used = fourier.paper_kernel(g, pg.dx_um, pg.dy_um, lam, z, plan.pixel_um, S)
        if r_used < 1 and not state.get("warned_r"):
            warnings.warn(f"paper recipe under-sampled at {lam_nm:g} nm: r = {r_used:.3g} < 1, the DFT grid is "
                          f"coarser than the {plan.pixel_um} µm pixel", UnderSamplingWarning, stacklevel=4)
            state["warned_r"] = True
        return kern
    if not plan.pixel_integration:
        return fourier.point_kernel(g, pg.x_um, pg.y_um, pg.dx_um, pg.dy_um, lam, z, plan.pixel_um, S, plan.method,
                                    plan.cdtype, deapodize)
    if reuse and state.get("R") is not None:
        R = state["R"]
    else:
        R = fourier.autocorrelation_half(g, pg.dx_um, pg.dy_um)
        state["R"] = R if reuse else None
    return fourier.pixel_kernel(R, pg.dx_um, pg.dy_um, lam, z, plan.pixel_um, S, plan.method, True, plan.cdtype,
                                deapodize)


def _wavelength(plan: _Plan, lam_nm: np.float64, state: dict, progress) -> tuple:
    """(kernel [S, S], energy outside, transmittance, field kernels [P, P, S, S] | None, field power
    [P, P] | None) at one wavelength: the power-weighted sum over the field phases."""
    lens, P, S = plan.lens, plan.phases, plan.size_px
    lam = lam_nm * 1e-3
    defocus = lens.pupil_phase(plan.pgrid.x_um, plan.pgrid.y_um, lam)
    tf = angular_spectrum_tf(plan.fx, plan.fy, lam, plan.d_um) if plan.use_field else None
    series = PowerSeries(plan.display, lens, lam, plan.d_um) if plan.exact_power else None
    field_k = np.zeros((P, P, S, S)) if plan.use_field else None
    field_p = np.zeros((P, P)) if plan.use_field else None
    acc, acc_power, acc_window = np.zeros((S, S)), 0.0, 0.0
    for j in range(P):
        for i in range(P):
            m = _pupil_mask(plan, tf, plan.shifts[j, i])
            if series is not None:
                power = float(series(plan.shifts[j, i]))
            else:
                power = plan.kappa * float(np.sum(np.abs(m) ** 2 * plan.aperture)) * plan.pgrid.dx_um * plan.pgrid.dy_um
            kern = _one_kernel(plan, m, defocus, lam_nm, state)
            window = float(kern.sum())
            if not (np.all(np.isfinite(kern)) and window > 0):
                raise PSFError(f"kernel at {lam_nm:g} nm is not finite or carries no energy "
                               f"(window sum {window}); check the display and lens")
            acc += kern
            acc_power += power
            acc_window += window
            if plan.use_field:
                field_k[j, i] = kern / window
                field_p[j, i] = power
            if progress:
                progress(1)
    if plan.use_field:
        field_p /= field_p.mean()
    bare_power = math.pi * lens.aperture_um ** 2 / 4
    return acc / acc_window, 1.0 - acc_window / acc_power, acc_power / P ** 2 / bare_power, field_k, field_p


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
    field_k = np.stack([r[3] for r in results]).astype(out_dtype) if plan.use_field else None
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
    progress: optional callable(n) called after each kernel (for progress bars).

    Steps: _plan (window, mask, phases) ─► _wavelength per λ (_pupil_mask, _one_kernel per phase) ─► _assemble.
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
