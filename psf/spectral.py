"""Spectral kernels: wavelength bands integrated over a weight spectrum, and channel-effective
kernels for camera sensitivities.

A band kernel is the power-weighted mean of monochromatic kernels (midpoint rule, step δλ):
    k_band = Σ_i w(λ_i) T(λ_i) (1 − e_out(λ_i)) k(λ_i)  /  Σ_i w(λ_i) T(λ_i) (1 − e_out(λ_i))
with T the transmittance and e_out the energy outside the window, so the result is exactly what a
sensor integrating w(λ) sees. The default step is δλ = λ_lo / S (S the kernel size in pixels): the kernel's
outer orders move by δλ/λ · S/2 pixels between samples, so this keeps that shift at half a pixel. Measured
(`udc-render study psf`, T-OLED, 100 nm bands, worst band): S = 127 at 3 nm (≈ 400/127) 1.1e-3 L1;
S = 255 at 3 nm 7.3e-3, at 1.5 nm (≈ 400/255) 3.9e-4.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from . import colour_tables
from .engine import KernelSet, PSFError, compute_kernels

__all__ = ["CAMERAS", "band_samples", "combine", "auto_step_nm", "band_kernels", "load_sensitivities", "load_weight",
           "channel_kernels", "channel_weights"]

CAMERAS = ("Nikon 5100 (NPL)", "Sigma SDMerill (NPL)")


def band_samples(lo_nm: float, hi_nm: float, step_nm: float) -> tuple[np.ndarray, np.ndarray]:
    """Midpoint-rule wavelengths and widths (nm) covering [lo, hi] with at most step_nm spacing."""
    if not (0 < lo_nm < hi_nm and step_nm > 0):
        raise PSFError(f"band [{lo_nm}, {hi_nm}] nm with step {step_nm} nm: need 0 < lo < hi and step > 0")
    n = max(1, math.ceil((hi_nm - lo_nm) / step_nm - 1e-9))
    width = (hi_nm - lo_nm) / n
    return lo_nm + (np.arange(n) + 0.5) * width, np.full(n, width)


def combine(ks: KernelSet, weights: np.ndarray, centres_nm, extra_params: dict) -> KernelSet:
    """Collapse K monochromatic kernels into C weighted ones; weights is [C, K] (e.g. S_c(λ)·E(λ)·δλ)."""
    w = np.asarray(weights, dtype=np.float64)
    trans, inside = ks.transmittance, 1.0 - ks.energy_outside
    ww, wt = w * (trans * inside)[None, :], w * trans[None, :]
    if np.any(ww.sum(axis=1) <= 0):
        raise PSFError("a band or channel has zero total weight over the sampled wavelengths")
    kern = np.einsum("ck,kij->cij", ww, ks.kernels.astype(np.float64)) / ww.sum(axis=1)[:, None, None]
    field_k = field_p = None
    if ks.field_kernels is not None:
        field_k = np.einsum("ck,kpqij->cpqij", ww, ks.field_kernels.astype(np.float64))
        field_k /= field_k.sum(axis=(-2, -1), keepdims=True)
        field_p = np.einsum("ck,kpq->cpq", wt, ks.field_power) / wt.sum(axis=1)[:, None, None]
    series = None
    if ks.field_series is not None:  # linear in the weights, as field_power
        series = np.einsum("ck,kyx->cyx", wt, ks.field_series) / wt.sum(axis=1)[:, None, None]
    params = dict(ks.params, **extra_params, sample_wavelengths_nm=ks.wavelengths_nm.tolist())
    return KernelSet(kern.astype(ks.kernels.dtype), np.asarray(centres_nm, dtype=np.float64), ks.pixel_um,
                     1.0 - ww.sum(axis=1) / wt.sum(axis=1), wt.sum(axis=1) / w.sum(axis=1),
                     np.einsum("ck,k->c", w, ks.ratio_r) / w.sum(axis=1), params,
                     None if field_k is None else field_k.astype(ks.kernels.dtype), field_p,
                     ks.field_shifts_um, list(ks.notes), ks.period_um, ks.distance_mm, ks.image_distance_um, series)


def auto_step_nm(lo_nm: float, size_px: int) -> float:
    """Default wavelength step for a band starting at lo_nm and kernels of size_px: λ_lo / S."""
    return lo_nm / size_px


def band_kernels(display, lens, bands_nm, step_nm: float | None = None, weight=None, weight_name: str | None = None,
                 **kwargs) -> KernelSet:
    """One kernel per band [(lo, hi), …] nm, integrated over weight(λ) (flat when None; see
    load_weight), with wavelength step step_nm (None: auto_step_nm per band)."""
    samples, rows = [], []
    size_px = kwargs.get("size_px", 255)
    steps = [step_nm or auto_step_nm(lo, size_px) for lo, _ in bands_nm]
    for (lo, hi), step in zip(bands_nm, steps):
        lam, dl = band_samples(lo, hi, step)
        samples.append(lam)
        rows.append(dl * (1.0 if weight is None else np.asarray(weight(lam), dtype=np.float64)))
    allwl = np.concatenate(samples)
    W = np.zeros((len(rows), allwl.size))
    start = 0
    for c, r in enumerate(rows):
        W[c, start:start + r.size] = r
        start += r.size
    ks = compute_kernels(display, lens, allwl, **kwargs)
    centres = [0.5 * (lo + hi) for lo, hi in bands_nm]
    return combine(ks, W, centres, {"bands_nm": [list(b) for b in bands_nm], "band_step_nm": steps,
                                        "weight": weight_name or ("E" if weight is None else "callable")})


def load_sensitivities(camera: str) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """(wavelengths_nm [M], sensitivities [C, M], channel names) from colour-science or a CSV.

    CSV: a header row, first column wavelength in nm, then one column per channel.
    """
    if camera in CAMERAS:
        wavelengths, values = colour_tables.spectrum("camera_sensitivities", camera)
        return (np.array(wavelengths, float), np.array(values, float).T,  # copies: the tables are read-only
                list(colour_tables.labels("camera_sensitivities", camera)))
    path = Path(camera)
    if not path.is_file():
        raise PSFError(f"sensitivities '{camera}': neither a built-in camera ({', '.join(CAMERAS)}) nor a CSV file")
    try:
        header = path.read_text().splitlines()[0].split(",")
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    except (OSError, ValueError, IndexError) as exc:
        raise PSFError(f"sensitivities {path}: cannot be read as CSV (wavelength_nm, channels...): {exc}") from None
    if data.shape[1] < 2 or np.any(np.diff(data[:, 0]) <= 0) or np.any(data[:, 1:] < 0):
        raise PSFError(f"sensitivities {path}: need increasing wavelengths and ≥ 1 non-negative channel column")
    return data[:, 0], data[:, 1:].T, [h.strip() for h in header[1:]]


def load_weight(spec: str = "E"):
    """A weight spectrum w(λ) as a callable: 'E' (flat), a colour-science illuminant, or a CSV
    (header row; wavelength_nm, weight), linearly interpolated and 0 outside its range."""
    if spec == "E":
        return lambda lam: np.ones_like(np.asarray(lam, dtype=np.float64))
    key = colour_tables.key("illuminants", spec)
    if key is not None:
        wl, values = (np.asarray(a, float) for a in colour_tables.spectrum("illuminants", key))
    else:
        path = Path(spec)
        if not path.is_file():
            raise PSFError(f"weight spectrum '{spec}': neither 'E', a colour-science illuminant (e.g. D65) "
                           "nor a CSV file")
        try:
            data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        except ValueError as exc:
            raise PSFError(f"weight spectrum {path}: cannot be read as CSV (wavelength_nm, weight): {exc}") from None
        if data.shape[1] != 2 or np.any(np.diff(data[:, 0]) <= 0) or np.any(data[:, 1] < 0):
            raise PSFError(f"weight spectrum {path}: need two columns, increasing wavelengths, weights ≥ 0")
        wl, values = data[:, 0], data[:, 1]
    return lambda lam: np.interp(lam, wl, values, left=0.0, right=0.0)


def channel_kernels(display, lens, camera: str = "Nikon 5100 (NPL)", illuminant: str = "E",
                    step_nm: float | None = None, relative_cutoff: float = 1e-3, **kwargs) -> KernelSet:
    """Channel-effective kernels: weights S_c(λ) E(λ) δλ over the wavelengths the channels reach.

    Wavelengths where every channel's weight is below relative_cutoff × its maximum are left out
    (and listed in notes). illuminant: a weight spectrum for load_weight ('E', 'D65', a CSV).
    """
    step_nm = step_nm or auto_step_nm(float(load_sensitivities(camera)[0][0]), kwargs.get("size_px", 255))
    lam, W, names, skipped = channel_weights(camera, illuminant, step_nm, relative_cutoff)
    ks = compute_kernels(display, lens, lam, **kwargs)
    centres = (W * lam).sum(axis=1) / W.sum(axis=1)
    out = combine(ks, W, centres, {"camera": camera, "illuminant": illuminant, "channel_step_nm": step_nm,
                                   "channels": names})
    out.notes.append(f"{skipped} of {lam.size + skipped} wavelengths skipped: every channel weight "
                     f"< {relative_cutoff:g} × its peak")
    return out


def channel_weights(camera: str, illuminant: str, step_nm: float, relative_cutoff: float = 1e-3
                    ) -> tuple[np.ndarray, np.ndarray, list[str], int]:
    """(wavelengths_nm [K], weights S_c(λ) E(λ) δλ [C, K], channel names, wavelengths skipped): channel_kernels'
    midpoint samples of the camera's band at step_nm, those where every channel's weight is below relative_cutoff ×
    its maximum left out."""
    wl_s, sens, names = load_sensitivities(camera)
    lam, dl = band_samples(float(wl_s[0]), float(wl_s[-1]), step_nm)
    S = np.stack([np.interp(lam, wl_s, s, left=0.0, right=0.0) for s in sens])
    W = S * load_weight(illuminant)(lam)[None, :] * dl[None, :]
    keep = np.any(W >= relative_cutoff * W.max(axis=1, keepdims=True), axis=0)
    return lam[keep], W[:, keep], names, int((~keep).sum())
