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
inner translation of a periodic display maps onto one another (psf.plan) are computed once and
reflected: 9 of 16 for the T-OLED, 6 of 16 for the P-OLED. All of this is exact (to rounding).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft

from . import fourier, paper
from .banding import PowerSeries
from .errors import AliasingWarning, PSFError, UnderSamplingWarning  # noqa: F401 (re-exported)
from .lens import Lens
from .plan import (
    ALIAS_GUARD,
    DEFAULT_FIELD_PHASES,
    DEFAULT_PUPIL_SAMPLES,
    MAX_PUPIL_WINDOW_SAMPLES,
    MAX_PUPIL_WINDOW_SAMPLES_D0,
    METHODS,
    PAPER_SENSOR_UM,
    PRECISIONS,
    WAVELENGTH_RANGE_NM,
    Plan,
    auto_pupil_samples,
    check_alias,
    field_shifts,
    make_plan,
    validate_request,
)
from .propagation import angular_spectrum_tf, ramp

__all__ = ["METHODS", "PRECISIONS", "DEFAULT_PUPIL_SAMPLES", "DEFAULT_FIELD_PHASES", "ALIAS_GUARD",
           "WAVELENGTH_RANGE_NM", "MAX_PUPIL_WINDOW_SAMPLES", "MAX_PUPIL_WINDOW_SAMPLES_D0", "PAPER_SENSOR_UM",
           "KernelSet", "auto_pupil_samples", "field_shifts", "compute_kernels", "PSFError", "AliasingWarning",
           "UnderSamplingWarning"]


@dataclass
class KernelSet:
    """Kernels for K wavelengths on a size_px² grid of pixel_um pixels, centred at size_px // 2.

    kernels            [K, S, S]  unit sum inside the window (power-weighted mean over field phases)
    energy_outside     [K]        fraction of the transmitted power that falls outside the window
                                  (point-sampled kernels: the Riemann estimate Σ ρ² I(u_j), which is
                                  negative where pixels undersample an Airy core; see pixel_integration)
    transmittance      [K]        power through display and aperture / power through the bare aperture
    ratio_r            [K]        the paper's down-sampling ratio r: the formula's δ_N N ρ / (λ f), N δ_N =
                                  aperture; method 'paper': the printed r it resamples by (psf.paper)
    field_kernels      [K, P, P, S, S] per field phase (d > 0 only), each unit sum
    field_power        [K, P, P]  transmitted power per phase / its mean (the banding samples)
    field_shifts_um    [P, P, 2]  mask shift (x, y) of each phase; image position = shift · z_i / d
                                  (field_shifts: a whole period, or the part the sensor sees)
    field_series       [K, 2n+1, m+1] complex: field_power's exact series at any shift s (periodic display,
                                  d > 0): half weights k_y = −n…n, k_x = 0…m of P(s) / the phases' mean power
                                  (psf.banding.PowerSeries.truncated, one orders box for every band;
                                  evaluated by psf.banding.power_grid / power_lattice)
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
    field_series: np.ndarray | None = None

    @property
    def size_px(self) -> int:
        return self.kernels.shape[-1]



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


def _wave(plan: Plan, lam_nm: float) -> _Wave:
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


def _field_masks(plan: Plan, wave: _Wave, phases: list[int]):
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


def _kernel_of_power(plan: Plan, wave: _Wave, power: np.ndarray) -> np.ndarray:
    """The pixel-integrated kernel of a padded pupil power spectrum |G|² (PixelMFT, or chirp-z of its lags)."""
    pg = plan.pgrid
    if wave.mft is not None:
        return wave.mft.of_power(power, pg.dx_um, pg.dy_um)
    R = fourier.lags_from_power(power, (pg.ny, pg.nx), pg.dx_um, pg.dy_um)
    return fourier.pixel_kernel(R, pg.dx_um, pg.dy_um, wave.lam_nm * 1e-3, plan.lens.image_distance_um,
                                plan.pixel_um, plan.size_px, plan.method, True, plan.cdtype,
                                plan.deapodize and wave.defocus is None)


def _one_kernel(plan: Plan, wave: _Wave, g: np.ndarray, state: dict) -> np.ndarray:
    """The (unnormalised) kernel of the pupil field g at λ, by the chosen method.
    With d = 0 and no defocus the pupil is the same at every wavelength: its power spectrum is kept
    in state['power']."""
    pg, lam, z, S = plan.pgrid, wave.lam_nm * 1e-3, plan.lens.image_distance_um, plan.size_px
    deapodize = plan.deapodize and wave.defocus is None
    if plan.method == "paper":
        kern, r_used = paper.paper_kernel(g, pg.dx_um, pg.dy_um, wave.lam_nm, plan.lens, plan.pixel_um, S)
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


def _wavelength(plan: Plan, lam_nm: np.float64, state: dict, progress) -> tuple:
    """(kernel [S, S], energy outside, transmittance, field kernels [P, P, S, S] | None, field power
    [P, P] | None, its series (KernelSet.field_series) | None) at one wavelength: the power-weighted sum
    over the field phases."""
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
        if q0 != q:  # a reflected copy of an earlier phase (psf.plan._phase_sources)
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
    series = wave.series.truncated() / power.mean() if plan.use_field and wave.series is not None else None
    return mean_kernel, 1.0 - acc_window / acc_power, acc_power / P ** 2 / bare_power, field_k, field_p, series


def _common_box(series: list) -> np.ndarray:
    """The half weights [2n+1, m+1] of every wavelength zero-padded to the largest orders box, stacked."""
    n = max(h.shape[0] for h in series) // 2
    m = max(h.shape[1] for h in series) - 1
    out = np.zeros((len(series), 2 * n + 1, m + 1), complex)
    for k, h in enumerate(series):
        c = h.shape[0] // 2
        out[k, n - c:n + c + 1, :h.shape[1]] = h
    return out


def _assemble(plan: Plan, results: list, precision: str, mask_raster: str, sensor_um, notes: list) -> KernelSet:
    """The KernelSet of the per-wavelength results, with every parameter recorded."""
    lens, wl, pg = plan.lens, plan.wl, plan.pgrid
    kernels = np.stack([r[0] for r in results])
    outside, trans = np.array([r[1] for r in results]), np.array([r[2] for r in results])
    ratio_of = paper.paper_ratio_r if plan.method == "paper" else paper.formula_ratio_r
    ratio = np.array([ratio_of(float(lam), lens, plan.pixel_um) for lam in wl])
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
    series = _common_box([r[5] for r in results]) if results[0][5] is not None else None
    return KernelSet(kernels.astype(out_dtype), wl, plan.pixel_um, outside, trans, ratio, params, field_k, field_p,
                     plan.shifts if plan.use_field else None, notes, period, plan.d_um / 1000.0,
                     lens.image_distance_um, series)


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
        period or over the sensor extent sensor_um (x, y) when that sees less than a period, and always over
        the sensor extent for an aperiodic display (randomly turned tiles; field_shifts).
    pupil_samples: samples across the aperture (None: auto, see auto_pupil_samples).
    precision: 'float32' (complex64 FFTs and products) or 'float64'.
    mask_raster: 'band_limited' (exact Fourier series, default) or 'area' (area-weighted, then
        de-apodised); see pupil.cell_raster. The aperture is always area-weighted.
    progress: optional callable(n) called with the number of kernels done (for progress bars).

    Steps: psf.plan.make_plan (window, mask, phases, their symmetries) ─► _wavelength per λ (_wave shared by the phases,
    _field_masks, _one_kernel per distinct phase) ─► _assemble.
    """
    lens = lens or Lens()
    wl = validate_request(wavelengths_nm, pixel_um, size_px, distance_mm, field_phases, method, precision,
                          pupil_samples, mask_raster)
    notes: list = []
    plan = make_plan(display, lens, wl, pixel_um, size_px, distance_mm, field_phases, method, pupil_samples, precision,
                 pixel_integration, mask_raster, sensor_um, notes)
    check_alias(plan)
    state: dict = {}
    # lam_nm stays np.float64: it keeps float64 products (NEP 50)
    results = [_wavelength(plan, lam_nm, state, progress) for lam_nm in wl]
    return _assemble(plan, results, precision, mask_raster, sensor_um, notes)
