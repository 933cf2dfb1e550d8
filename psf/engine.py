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

METHODS = ("mft", "czt", "paper")
PRECISIONS = {"float32": np.complex64, "float64": np.complex128}
DEFAULT_PUPIL_SAMPLES = 1024
DEFAULT_FIELD_PHASES = 4  # per axis; study: mean kernel 2.3e-4 L1, banding within 15 % of its amplitude
ALIAS_GUARD = 1.05


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

    @property
    def size_px(self) -> int:
        return self.kernels.shape[-1]


def _validate(wavelengths_nm, pixel_um, size_px, distance_mm, field_phases, method, precision, pupil_samples,
              mask_raster):
    wl = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
    if wl.ndim != 1 or wl.size == 0 or not np.all(np.isfinite(wl)) or np.any(wl <= 0):
        raise PSFError(f"wavelengths_nm must be positive finite numbers, got "
                       f"{[float(v) for v in np.ravel(np.asarray(wavelengths_nm, dtype=float))]}")
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
    try:
        mask, kappa = tile_mask(display, cell_n, tiles, mask_raster)
    except ValueError as exc:
        raise PSFError(str(exc)) from None
    return grid, mask, kappa


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
    """
    lens = lens or Lens()
    wl = _validate(wavelengths_nm, pixel_um, size_px, distance_mm, field_phases, method, precision, pupil_samples,
                   mask_raster)
    cdtype = PRECISIONS[precision]
    n_pupil = pupil_samples or auto_pupil_samples(lens, float(wl.min()), pixel_um, size_px)
    z = lens.image_distance_um
    # De-apodise where the pupil's spectrum is box-filtered: an area-weighted mask or a bare aperture
    # (not with defocus: its phase is point-sampled, not box-filtered).
    deapodize = display is None or mask_raster == "area"
    d_um = distance_mm * 1000.0
    notes = []

    grid, mask, kappa = _window(display, lens, n_pupil, wl, d_um, mask_raster)
    period = display.period_um if display is not None else None

    sy, sx = aperture_slices(grid, lens.aperture_um)
    pgrid = grid.crop(sy, sx)
    aperture = lens.aperture_area_fraction(pgrid.x_edges_um, pgrid.y_edges_um)
    bare_power = math.pi * lens.aperture_um ** 2 / 4

    # Alias check: the window must fit inside the alias-free field λz/δ of the pupil raster.
    window = size_px * pixel_um
    for axis, step in (("x", pgrid.dx_um), ("y", pgrid.dy_um)):
        free = float(wl.min()) * 1e-3 * z / step
        if window > free and method != "paper":
            need = auto_pupil_samples(lens, float(wl.min()), pixel_um, size_px)
            warnings.warn(f"kernel window {window:.0f} µm exceeds the alias-free field λz/δ{axis} = {free:.0f} µm "
                          f"at {wl.min():g} nm (pupil_samples={n_pupil}); need pupil_samples ≥ {need}",
                          AliasingWarning, stacklevel=2)
            break

    use_field = d_um > 0 and display is not None
    # Transmitted power: the exact series of psf.banding for periodic displays; for a bare lens
    # the exact disc area; for aperiodic tiles the raster sum, corrected by κ for raster losses.
    exact_power = display is not None and getattr(display, "periodic", True)
    if d_um > 0 and display is None:
        notes.append("distance_mm > 0 with a bare lens: nothing to propagate, principal-plane result")
    if not use_field and field_phases is not None and field_phases > 1:
        notes.append("field phases skipped: the PSF is field-independent when d = 0 or without a display")
    phases = (field_phases or DEFAULT_FIELD_PHASES) if use_field else 1
    shifts = field_shifts(period, d_um, z, phases, sensor_um) if use_field else np.zeros((1, 1, 2))

    if use_field:
        mask_spec = sfft.fft2(mask.astype(cdtype), workers=fourier.WORKERS)
        fx, fy = frequencies(grid.nx, grid.dx_um), frequencies(grid.ny, grid.dy_um)

    K, S = wl.size, size_px
    kernels = np.zeros((K, S, S))
    field_k = np.zeros((K, phases, phases, S, S)) if use_field else None
    field_p = np.zeros((K, phases, phases)) if use_field else None
    outside = np.zeros(K)
    trans = np.zeros(K)
    ratio = np.zeros(K)
    cache_R = None
    warned_r = False

    for k, lam_nm in enumerate(wl):
        lam = lam_nm * 1e-3
        ratio[k] = lens.aperture_um * pixel_um / (lam * lens.focal_length_um)
        defocus = lens.pupil_phase(pgrid.x_um, pgrid.y_um, lam)
        tf = angular_spectrum_tf(fx, fy, lam, d_um) if use_field else None
        series = PowerSeries(display, lens, lam, d_um) if exact_power else None
        acc, acc_power, acc_window = np.zeros((S, S)), 0.0, 0.0
        for j in range(phases):
            for i in range(phases):
                if use_field:
                    spec = mask_spec * (tf * shift_ramp(fx, fy, *shifts[j, i])).astype(cdtype)
                    m = sfft.ifft2(spec, workers=fourier.WORKERS)[sy, sx]
                elif mask is not None:
                    m = mask[sy, sx]
                else:
                    m = np.ones(aperture.shape)
                if series is not None:
                    power = float(series(shifts[j, i]))
                else:
                    power = kappa * float(np.sum(np.abs(m) ** 2 * aperture)) * pgrid.dx_um * pgrid.dy_um
                # With d = 0 and no defocus the pupil is the same at every wavelength: its
                # autocorrelation is computed once and the field is not rebuilt.
                reuse = pixel_integration and method != "paper" and not use_field and defocus is None
                if not (reuse and cache_R is not None):
                    g = (m * aperture).astype(cdtype)
                    if defocus is not None:
                        g = g * defocus.astype(cdtype)
                if method == "paper":
                    kern, r_used = fourier.paper_kernel(g, pgrid.dx_um, pgrid.dy_um, lam, z, pixel_um, S)
                    if r_used < 1 and not warned_r:
                        warnings.warn(f"paper recipe under-sampled at {lam_nm:g} nm: r = {r_used:.3g} < 1, the "
                                      f"DFT grid is coarser than the {pixel_um} µm pixel", UnderSamplingWarning,
                                      stacklevel=2)
                        warned_r = True
                elif not pixel_integration:
                    kern = fourier.point_kernel(g, pgrid.x_um, pgrid.y_um, pgrid.dx_um, pgrid.dy_um, lam, z,
                                                pixel_um, S, method, cdtype, deapodize and defocus is None)
                else:
                    if reuse and cache_R is not None:
                        R = cache_R
                    else:
                        R = fourier.autocorrelation_half(g, pgrid.dx_um, pgrid.dy_um)
                        cache_R = R if reuse else None
                    kern = fourier.pixel_kernel(R, pgrid.dx_um, pgrid.dy_um, lam, z, pixel_um, S, method,
                                                True, cdtype, deapodize and defocus is None)
                window = float(kern.sum())
                if not (np.all(np.isfinite(kern)) and window > 0):
                    raise PSFError(f"kernel at {lam_nm:g} nm is not finite or carries no energy "
                                   f"(window sum {window}); check the display and lens")
                acc += kern
                acc_power += power
                acc_window += window
                if use_field:
                    field_k[k, j, i] = kern / window
                    field_p[k, j, i] = power
                if progress:
                    progress(1)
        kernels[k] = acc / acc_window
        outside[k] = 1.0 - acc_window / acc_power
        trans[k] = acc_power / phases ** 2 / bare_power
        if use_field:
            field_p[k] /= field_p[k].mean()

    if trans.max() < 1e-6:
        notes.append(f"almost nothing is transmitted (transmittance {trans.max():.2e}): the aperture sees "
                     f"little or no display opening; kernels are normalised all the same")
    out_dtype = np.float32 if precision == "float32" else np.float64
    params = {"display": display.describe() if display is not None else {"kind": "none"},
              "lens": lens.describe(), "wavelengths_nm": wl.tolist(), "pixel_um": pixel_um,
              "size_px": int(size_px), "distance_mm": distance_mm, "field_phases": int(phases),
              "method": method, "pupil_samples": int(n_pupil), "precision": precision,
              "pixel_integration": bool(pixel_integration), "mask_raster": mask_raster,
              "deapodize": bool(deapodize),
              "pupil_pitch_um": [pgrid.dx_um, pgrid.dy_um], "pupil_shape": [pgrid.ny, pgrid.nx],
              "image_distance_um": z, "sensor_um": list(sensor_um), "model": "finite-distance" if use_field else "principal-plane"}
    return KernelSet(kernels.astype(out_dtype), wl, float(pixel_um), outside, trans, ratio, params,
                     field_k.astype(out_dtype) if use_field else None, field_p,
                     shifts if use_field else None, notes)
