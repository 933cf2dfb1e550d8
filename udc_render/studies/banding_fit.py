"""The banding study's profile measurement and its analytic and interpolated predictions
(udc_render.studies.banding: its module doc has the formulas): the Gr sites' profile of a flat field,
the harmonic fit of its period, the per-pixel noise, and the harmonics of Σ_k a_k P_k(s(x)).
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar

from psf.banding import PowerSeries
from psf.engine import field_shifts
from udc_render.optics import phase_weights
from udc_render.sensor import SensorConfig, band_electron_weights

DISPLAYS = ("toled", "poled")
AXES = ("x", "y")
GREEN = 1  # camera channel index (R, G, B) of the Gr sites
GR_SITE = (0, 1)  # RGGB: Gr at even rows, odd columns
HARMONICS = 3
COLUMNS = ["axis", "display", "distance_mm", "field_phases", "field_power", "field_rank",
           "period_formula_um", "period_formula_px", "period_fit_um", "period_error_rel", "harmonic_order",
           "analytic_order", "periods_in_frame",
           "a1_measured_rel", "a1_analytic_rel", "psf_mtf", "a1_expected_rel", "a1_interpolated_rel",
           "ratio_measured_analytic", "ratio_measured_expected", "ratio_measured_interpolated", "sinc2_interp",
           "mean_dn", "a1_dn", "sigma_dn", "rows_averaged", "snr_pixel", "snr_averaged", "regime", "visible_pixel",
           "visible_averaged", "kernel_s", "synth_s"]


def period_formula_um(z_i_um: float, period_um: float, distance_mm: float) -> float:
    """Band period on the sensor T = z_i · p / d (µm)."""
    return z_i_um * period_um / (distance_mm * 1000.0)


def sinc2(h: int, phases: int) -> float:
    """sinc²(h / P): what linear interpolation between P samples per period keeps of harmonic h."""
    return float(np.sinc(h / phases) ** 2)


# ----------------------------------------------------------------------------------------------
# Measuring a profile


def site_positions_um(shape_hw, pitch_um: float) -> tuple[np.ndarray, np.ndarray]:
    """(x of the Gr columns, y of the Gr rows) in µm from the optical axis (frame centre), as the optics
    place pixel centres (optics.field.field_weights)."""
    H, W = shape_hw
    x = (np.arange(W)[GR_SITE[1]::2] - (W - 1) / 2) * pitch_um
    y = (np.arange(H)[GR_SITE[0]::2] - (H - 1) / 2) * pitch_um
    return x, y


def green_sites(mosaic: np.ndarray) -> np.ndarray:
    """The Gr sites [H/2, W/2] of an RGGB mosaic."""
    return np.asarray(mosaic, np.float64)[GR_SITE[0]::2, GR_SITE[1]::2]


def flat_profile(clean_dn: np.ndarray, glass_dn: np.ndarray, axis: str = "x") -> np.ndarray:
    """The Gr sites of clean_dn / glass_dn averaged across the bands (column means for bands along x,
    row means along y), divided by its mean."""
    p = (green_sites(clean_dn) / green_sites(glass_dn)).mean(axis=0 if axis == "x" else 1)
    return p / p.mean()


def harmonic_design(x_um: np.ndarray, period_um: float, harmonics: int = HARMONICS) -> np.ndarray:
    """Columns 1, cos(2πhx/T), sin(2πhx/T) for h = 1…H."""
    cols = [np.ones_like(x_um)]
    for h in range(1, harmonics + 1):
        ph = 2 * np.pi * h * x_um / period_um
        cols += [np.cos(ph), np.sin(ph)]
    return np.stack(cols, axis=1)


def harmonic_fit(x_um, y, period_um: float, harmonics: int = HARMONICS) -> tuple[np.ndarray, float]:
    """(relative amplitudes |c_h| / c0 for h = 0…H (entry 0 is c0), residual sum of squares) of the
    least-squares fit at period T."""
    coef, *_ = np.linalg.lstsq(harmonic_design(x_um, period_um, harmonics), y, rcond=None)
    resid = y - harmonic_design(x_um, period_um, harmonics) @ coef
    amps = np.concatenate([[coef[0]], np.hypot(coef[1::2], coef[2::2]) / coef[0]])
    return amps, float(resid @ resid)


def fft_peak_period_um(x_um: np.ndarray, y: np.ndarray, pad: int = 16) -> float:
    """Period of the largest peak of |FFT(y − mean)| (zero-padded pad×) above the lowest whole-frame bin."""
    n = y.size
    spec = np.abs(np.fft.rfft(y - y.mean(), n=pad * n))
    spec[:pad] = 0.0  # below one period per frame: a gradient
    dx = float(x_um[1] - x_um[0])
    return pad * n * dx / int(np.argmax(spec))


def fit_period(x_um: np.ndarray, y: np.ndarray, harmonics: int = HARMONICS) -> tuple[float, np.ndarray]:
    """(period T (µm), relative amplitudes) of y: the residual of harmonic_fit minimised over T within
    ± one unpadded FFT bin of the FFT peak (bounded Brent search); the expected period is not used."""
    span = float(x_um[-1] - x_um[0] + (x_um[1] - x_um[0]))
    f0 = 1.0 / fft_peak_period_um(x_um, y)
    lo, hi = max(f0 - 1.0 / span, 0.5 / span), f0 + 1.0 / span
    best = minimize_scalar(lambda f: harmonic_fit(x_um, y, 1.0 / f, harmonics)[1], bounds=(lo, hi),
                           method="bounded", options={"xatol": 1e-6 / span})
    period = 1.0 / float(best.x)
    return period, harmonic_fit(x_um, y, period, harmonics)[0]


def noise_sigma_dn(capture) -> float:
    """Per-pixel noise σ (DN): std of mosaic_dn − clean_dn over the Gr sites."""
    return float((green_sites(capture.mosaic_dn) - green_sites(capture.clean_dn)).std())


# ----------------------------------------------------------------------------------------------
# The analytic profile


def green_band_weights(band_image, display, exposure_s: float) -> np.ndarray:
    """a_k = w_Gk · L_k · T_k: electrons of a green pixel per unit transmitted power fraction, band k."""
    w = band_electron_weights(band_image.edges_nm, SensorConfig(exposure_s=exposure_s))[GREEN]
    return w * band_image.white_bands() * display.transmission.band_means(band_image.edges_nm)


def band_series(display, lens, centres_nm, distance_mm: float) -> list[PowerSeries]:
    """P_k(s) of every band centre at distance d (psf.banding.PowerSeries)."""
    return [PowerSeries(display.layout, lens, wl * 1e-3, distance_mm * 1000.0) for wl in centres_nm]


def kernel_otf(kernels: np.ndarray, pixel_um: float, period_um: float, axis: str = "x",
               harmonics: int = HARMONICS) -> np.ndarray:
    """OTF [K, H] of each band's kernel [K, S, S] (centred at S // 2, unit sum) along `axis` at the band
    frequencies h / T, h = 1…H: Σ_u k(u) e^{−2πi h u · pixel / T} of the kernel summed across the axis."""
    line = np.asarray(kernels, np.float64).sum(axis=1 if axis == "x" else 2)  # [K, S] along the axis
    u_um = (np.arange(line.shape[-1]) - line.shape[-1] // 2) * pixel_um
    h = np.arange(1, harmonics + 1)
    return line @ np.exp(-2j * np.pi * np.outer(u_um, h) / period_um)


def analytic_harmonics(series, weights, display, distance_mm: float, across_um: np.ndarray, z_i_um: float,
                       axis: str = "x", samples: int = 64, harmonics: int = HARMONICS,
                       otf: np.ndarray | None = None) -> np.ndarray:
    """Relative harmonic amplitudes h = 1…H along `axis` of Σ_k a_k P_k(s) averaged over the positions
    across_um on the other axis, s = (x, y) · d / z_i: P sampled at `samples` shifts over one period
    along the axis (exact DFT below samples / 2), the mean across taken, the DFT along. otf [K, H]
    (kernel_otf): each band's harmonics times its kernel's OTF, the PSF's smoothing of the flat field
    (blend 'source' at the kernels' mean shape)."""
    a = AXES.index(axis)
    shifts = np.zeros((across_um.size, samples, 2))
    shifts[..., a] = (np.arange(samples) * display.layout.period_um[a] / samples)[None, :]
    shifts[..., 1 - a] = (across_um * distance_mm * 1000.0 / z_i_um)[:, None]
    spec = np.stack([a * np.fft.rfft(ps(shifts).mean(axis=0)) for ps, a in zip(series, weights)])  # [K, S/2+1]
    lines = spec[:, 1:harmonics + 1] * (1.0 if otf is None else otf[:, :harmonics])
    return 2 * np.abs(lines.sum(axis=0)) / abs(spec[:, 0].sum())


def interpolated_harmonics(series, weights, display, distance_mm: float, x_um: np.ndarray, y_um: np.ndarray,
                           z_i_um: float, phases: int, frame_um: tuple[float, float], order: int = 1,
                           axis: str = "x") -> float:
    """Relative amplitude of harmonic `order` of the profile the synthesis' phase interpolation alone
    would give: Σ_k a_k P_k at the kernels' P × P field shifts (psf.engine.field_shifts), blended
    bilinearly over the Gr pixels (optics.field.phase_weights), averaged across the bands, fit at
    T = z_i p / d along `axis`."""
    d_um = distance_mm * 1000.0
    period = display.layout.period_um
    shifts = field_shifts(period, d_um, z_i_um, phases, frame_um)  # [P, P, 2]: rows y, columns x
    power = sum(a * ps(shifts) for ps, a in zip(series, weights))
    periodic = [span * d_um / z_i_um >= p for span, p in zip(frame_um, period)]
    wx = phase_weights(x_um, shifts[0, :, 0], d_um, z_i_um, period[0], periodic[0])
    wy = phase_weights(y_um, shifts[:, 0, 1], d_um, z_i_um, period[1], periodic[1])
    a = AXES.index(axis)
    prof = (wy.T @ power @ wx).mean(axis=a)  # [rows y, columns x]: across the bands
    amps, _ = harmonic_fit((x_um, y_um)[a], prof / prof.mean(), period_formula_um(z_i_um, period[a], distance_mm),
                           max(HARMONICS, order))
    return float(amps[order])
