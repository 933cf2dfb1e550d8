"""Radiometry: band radiance at the sensor plane ──► mean collected electrons.

Radiometry (spectral form), per pixel p of colour c(p):

    E_k   = π L_k / (4 N²) · cos⁴θ            image-side irradiance (on-axis, object at infinity;
                                              cos⁴θ only when ``cos4_falloff``; tan θ = r / f)
    e(p)  = Σ_k E_k · A · t · Δλ_k · q_ck       electrons, A = pitch², t = exposure
    q_ck  = (1/Δλ_k) ∫_band QE_c(λ) λ/(h c) dλ  photon-weighted band mean of the quantum efficiency
    QE_c  = peak_qe · S_c(λ) / max_{c,λ} S      (S: camera sensitivities, linearly interpolated,
                                              0 outside their table)

q_ck is integrated exactly for the piecewise-linear S (Simpson on each sub-interval, exact for
the quadratic S·λ), so a band-constant radiance gives the exact electron count.

Signal chain, with R = white − black (DN) and g = gain · conversion_gain (DN per e⁻):
"""
from __future__ import annotations

import functools
import math

import numpy as np

from udc_render.sensor.bayer import SITE_COLOUR, SITES, check_even
from udc_render.sensor.config import SensorConfig, SensorError

H_PLANCK_J_S = 6.62607015e-34
C_LIGHT_M_S = 299792458.0
NEGATIVE_TOLERANCE_REL = 1e-4  # negatives above −1e-4 × max|x| are FFT round-off: clamped to 0


@functools.lru_cache(maxsize=8)
def _relative_sensitivity(camera: str) -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths_nm [M], S [3, M]) with max S = 1 over all channels."""
    from psf.engine import PSFError
    from psf.spectral import load_sensitivities
    try:
        wl, s, _ = load_sensitivities(camera)
    except PSFError as exc:
        raise SensorError(f"sensor.camera = {camera!r}: {exc}") from None
    if s.shape[0] != 3:
        raise SensorError(f"sensor.camera = {camera!r}: {s.shape[0]} channels, expected 3 (r, g, b)")
    if not np.all(np.isfinite(s)) or s.max() <= 0:
        raise SensorError(f"sensor.camera = {camera!r}: sensitivities must be finite with a positive maximum")
    return wl, s / s.max()


def photon_weights(edges_nm, camera: str = "Nikon 5100 (NPL)", peak_qe: float = 1.0) -> np.ndarray:
    """q [3, K] in e⁻ per J: q_ck = (1/Δλ_k) ∫_band QE_c(λ) λ/(h c) dλ (λ in m), so
    electrons = Σ_k E_k A t Δλ_k q_ck. Exact for the linearly interpolated sensitivity (Simpson on
    every sub-interval between table nodes and band edges; S·λ is quadratic there)."""
    wl, s = _relative_sensitivity(camera)
    edges = np.asarray(edges_nm, float)
    out = np.zeros((3, edges.size - 1))
    for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        a_in, b_in = max(a, wl[0]), min(b, wl[-1])  # S = 0 outside the table (a jump at its ends)
        if a_in >= b_in:
            continue
        x = np.unique(np.concatenate([[a_in, b_in], wl[(wl > a_in) & (wl < b_in)]]))
        lo, hi, mid = x[:-1], x[1:], 0.5 * (x[:-1] + x[1:])
        for c in range(3):
            f_lo, f_mid, f_hi = (np.interp(z, wl, s[c], left=0.0, right=0.0) * z for z in (lo, mid, hi))
            out[c, k] = np.sum((hi - lo) / 6 * (f_lo + 4 * f_mid + f_hi)) / (b - a)
    return out * peak_qe * 1e-9 / (H_PLANCK_J_S * C_LIGHT_M_S)


def checked_nonnegative(a: np.ndarray, what: str) -> tuple[np.ndarray, int]:
    """Reject NaN/inf and real negatives; clamp round-off negatives. Returns (array, n_clamped)."""
    lo, hi = (float(a.min()), float(a.max())) if a.size else (0.0, 0.0)
    if not (np.isfinite(lo) and np.isfinite(hi)):  # a NaN or an infinity makes the min or the max one
        bad = ~np.isfinite(a)
        raise SensorError(f"{what}: {int(bad.sum())} NaN or infinite values (first at index "
                          f"{tuple(int(i) for i in np.argwhere(bad)[0])}); the sensor needs finite input")
    if lo >= 0:
        return a, 0
    scale = max(-lo, hi)  # max |x|
    if lo < -NEGATIVE_TOLERANCE_REL * scale:
        raise SensorError(f"{what}: negative value {lo:g} (max |x| {scale:g}); only round-off negatives "
                          f"≥ −{NEGATIVE_TOLERANCE_REL:g} × max|x| are accepted (clamped to 0)")
    neg = a < 0
    return np.where(neg, 0, a), int(neg.sum())


def _bin(a: np.ndarray, input_pitch_um: float | None, pitch_um: float, what: str) -> tuple[np.ndarray, int]:
    """Block-mean of a render at pitch/s to the sensor pitch (s integer)."""
    if input_pitch_um is None:
        return a, 1
    s = pitch_um / input_pitch_um
    if not (input_pitch_um > 0 and abs(s - round(s)) < 1e-6 and round(s) >= 1):
        raise SensorError(f"{what}: input_pitch_um = {input_pitch_um!r}: must be the sensor pitch "
                          f"{pitch_um} µm divided by an integer")
    s = int(round(s))
    if s == 1:
        return a, 1
    if a.shape[-1] % s or a.shape[-2] % s:
        raise SensorError(f"{what}: shape {a.shape} not divisible by the binning factor {s}")
    k, h, w = a.shape
    return a.reshape(k, h // s, s, w // s, s).mean(axis=(2, 4), dtype=np.float64), s


def cos4_map(height_px: int, width_px: int, pitch_um: float, focal_length_um: float) -> np.ndarray:
    """cos⁴θ = 1 / (1 + r²/f²)² at pixel centres, r from the mosaic centre."""
    y = (np.arange(height_px) + 0.5 - height_px / 2) * pitch_um
    x = (np.arange(width_px) + 0.5 - width_px / 2) * pitch_um
    return 1.0 / (1.0 + (y[:, None] ** 2 + x[None, :] ** 2) / focal_length_um ** 2) ** 2


def band_electron_weights(edges_nm, sensor: SensorConfig) -> np.ndarray:
    """[3, K] electrons per pixel per unit band radiance (W·sr⁻¹·m⁻²·nm⁻¹) of band k in channel c:
    π/(4N²) · A · t · Δλ_k · q_ck (on-axis, no cos⁴)."""
    edges = np.asarray(edges_nm, float)
    area_m2 = (sensor.pitch_um * 1e-6) ** 2
    const = math.pi / (4 * sensor.f_number ** 2) * area_m2 * sensor.exposure_s
    return photon_weights(edges, sensor.camera, sensor.peak_qe) * np.diff(edges)[None, :] * const


def electrons_rgb(radiance_bands: np.ndarray, edges_nm, sensor: SensorConfig) -> np.ndarray:
    """[3, H, W] mean electrons that an R, G and B pixel would collect at every pixel (the
    demosaic-free camera RGB used as ground truth; no noise, no full well, cos⁴ if enabled)."""
    L = np.asarray(radiance_bands)
    L, _ = checked_nonnegative(L, "radiance_bands")
    w = band_electron_weights(edges_nm, sensor)
    e = np.einsum("ck,khw->chw", w, L, dtype=np.float64, optimize=True)
    if sensor.cos4_falloff:
        e *= cos4_map(*e.shape[1:], sensor.pitch_um, sensor.focal_length_um)
    return e


def electrons_spectral(radiance_bands: np.ndarray, edges_nm, sensor: SensorConfig,
                       input_pitch_um: float | None = None) -> np.ndarray:
    """Mean collected electrons [H, W] (float64, no noise, no full well) of an RGGB mosaic from
    band-mean radiance [K, H, W] (W·sr⁻¹·m⁻²·nm⁻¹): e = Σ_k π L_k/(4N²) [cos⁴θ] A t Δλ_k q_ck."""
    L = np.asarray(radiance_bands)
    edges = np.asarray(edges_nm, float)
    if L.ndim != 3 or edges.ndim != 1 or edges.size != L.shape[0] + 1:
        raise SensorError(f"radiance_bands: shape {L.shape} with {edges.size} edges: expected [K, H, W] and K + 1 "
                          "edges")
    if not (np.all(np.isfinite(edges)) and np.all(edges > 0) and np.all(np.diff(edges) > 0)):
        raise SensorError(f"edges_nm = {edges.tolist()}: expected increasing positive finite wavelengths")
    L, _ = checked_nonnegative(L, "radiance_bands")
    L, _ = _bin(L, input_pitch_um, sensor.pitch_um, "radiance_bands")
    check_even(L.shape, "radiance_bands")
    w = band_electron_weights(edges, sensor)
    h, wd = L.shape[1:]
    e = np.zeros((h, wd))
    for c, (i, j) in enumerate(SITES):
        acc = e[i::2, j::2]
        for k in np.nonzero(w[SITE_COLOUR[c]])[0]:
            acc += w[SITE_COLOUR[c], k] * L[k, i::2, j::2]
    if sensor.cos4_falloff:
        e *= cos4_map(h, wd, sensor.pitch_um, sensor.focal_length_um)
    return e


def electrons_per_channel(rgb: np.ndarray, sensor: SensorConfig) -> np.ndarray:
    """The paper's form y = γ_c x_c: electrons [H, W] = γ_c x_c · R / conversion_gain from a linear
    [3, H, W] image (x = 1 at γ = 1 fills the full well with the default conversion gain)."""
    x = np.asarray(rgb)
    if x.ndim != 3 or x.shape[0] != 3:
        raise SensorError(f"rgb: shape {x.shape}: expected [3, H, W] (R, G, B) for the per-channel form")
    x, _ = checked_nonnegative(x, "rgb")
    check_even(x.shape, "rgb")
    per_e = sensor.dn_per_electron / sensor.gain / sensor.range_dn  # normalised units per e⁻ at gain 1
    e = np.empty(x.shape[1:])
    for c, (i, j) in enumerate(SITES):
        e[i::2, j::2] = sensor.gamma_rggb[c] * x[SITE_COLOUR[c], i::2, j::2] / per_e
    if sensor.cos4_falloff:
        e *= cos4_map(*e.shape, sensor.pitch_um, sensor.focal_length_um)
    return e


