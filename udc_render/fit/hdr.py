"""Several exposures of one laser spot: each prepared for the photometry, and merged into one HDR image
(the lattice's peaks, the figures).

Per exposure i (d: DN above the black level):
- the plane: a grey image as it is; a colour image's channel with the most signal; a CFA mosaic with every
  site divided by its colour's response at the laser's wavelength (relative to the strongest, G_c: first
  --camera's sensitivities, then the response the orders measure, fit.cfa), so every pixel measures the same
  irradiance;
- saturated pixels (and their neighbours) and hot pixels (inputs.hot_pixels) are masked;
- a residual offset b_i, the median of the frame's dark border, is subtracted (a black level given wrong,
  stray light), and the read noise σ_r (per CFA site) is its border's robust σ;
- its noise: var(d) = σ_r² + κ d / G (κ: DN per electron);
- its factor f_i (its signal relative to the brightest exposure, f ≤ 1): the product of the weighted
  least-squares slopes d_dim ≈ f d_bright between each exposure and the next brighter one, over the pixels
  the brighter one sees unmasked below NEAR_CLIP of its range (its noise is not cut by the clip there) and
  above OVERLAP_SNR σ (selected on the brighter one alone, so the dimmer one's noise does not bias the
  slope), weights 1 / var(f d_bright), pixels beyond OUTLIER_SIGMAS left out; a pixel two exposures disagree
  on by more (a hot pixel the same in every exposure, a cosmic ray) is masked in both. The power fit
  (refine) fits the factors again, with the orders.

κ: from the scatter of each exposure against the next brighter one,
var(d_i / f − d_j) = σ_i² / f² + σ_j² + κ s (1/f + 1) / G at the brighter one's signal s, solved for κ by the
median of the normalised differences (on the sites of the laser's colour); else (one exposure) from
--noise-frames (λ_shot (white − black), assuming the frames were taken at the PSF's gain); else
κ = saturation / ASSUMED_FULL_WELL_E (noted). The merged pixel is the inverse-variance mean of d_i / f_i over
the exposures where it is unmasked: w_i = f_i² / var_i, var = 1 / Σ w_i.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from udc_render.fit.inputs import COLOURS, FitError, Frame, border, hot_pixels, robust_sigma, saturated
from udc_render.sensor import photon_weights

ASSUMED_FULL_WELL_E = 10000.0  # one exposure and no --noise-frames: κ = saturation / this (order of a phone pixel)
OVERLAP_SNR = 5.0
NEAR_CLIP = 0.9
OUTLIER_SIGMAS = 8.0


@dataclass(frozen=True)
class Exposure:
    """One exposure ready for the photometry: d [H, W] (DN above black and offset, colour-balanced), its
    noise variance, the usable pixels, those saturated, the colour gain G of every pixel, its read σ."""
    path: str
    d: np.ndarray
    var: np.ndarray
    usable: np.ndarray
    saturated: np.ndarray
    gain: np.ndarray
    sigma: np.ndarray
    hot: int


@dataclass(frozen=True)
class Plane:
    """The exposures, their factors f_i (brightest 1), the merged image [H, W] in the brightest one's DN and
    its variance, the usable pixels, those saturated in every exposure, κ (DN per electron), the colour
    gains (R, G, B) and notes."""
    exposures: tuple
    factors: tuple
    value: np.ndarray
    var: np.ndarray
    usable: np.ndarray
    clipped: np.ndarray
    dn_per_e: float
    colour_gain: tuple
    notes: tuple


def colour_gains(wavelength_nm: float, camera: str) -> np.ndarray:
    """(R, G, B) response to the laser line relative to the strongest (the camera's spectral sensitivities
    over wavelength ± 5 nm)."""
    r = photon_weights([wavelength_nm - 5.0, wavelength_nm + 5.0], camera)[:, 0]
    return r / r.max()


def _channel(frames: list[Frame]) -> int:
    """The colour channel with the most signal above black (colour images)."""
    f = frames[0]
    return int(np.argmax(np.sum(f.above_black(), axis=(0, 1))))


def _prepare(frame: Frame, channel: int, gains: np.ndarray) -> dict:
    """d (balanced, offset removed), the read σ map, the masks and the colour gain map of one frame."""
    raw, above = frame.dn, frame.above_black()
    if frame.kind == "rgb":
        raw, above = raw[..., channel], above[..., channel]
    sat = saturated(frame, raw)
    gain = gains[frame.colour_map()] if frame.kind == "cfa" else np.ones(raw.shape)
    d = above / gain
    edge = border(raw.shape) & ~sat
    sites = frame.site_map()
    sigma = np.zeros(raw.shape)
    for s in np.unique(sites):
        sel = edge & (sites == s)
        if sel.sum() < 8:
            raise FitError(f"{frame.path}: the frame's border is saturated: expected a dark surround around the spot")
        d[sites == s] -= np.median(d[sel])
        sigma[sites == s] = max(robust_sigma(d[sel]), 0.5 / gain[sites == s].max())
    usable = ~sat & ~hot_pixels(d, sigma)
    return {"path": frame.path, "d": d, "sigma": sigma, "usable": usable, "sat": sat, "gain": gain,
            "top": (frame.saturation_dn - (raw - above)) * NEAR_CLIP}


def _overlap(dim: dict, bright: dict) -> np.ndarray:
    return dim["usable"] & bright["usable"] & (bright["d"] * bright["gain"] < bright["top"]) & \
        (bright["d"] > OVERLAP_SNR * bright["sigma"])


def _pair_residual(dim: dict, bright: dict, f: float, kappa: float) -> np.ndarray:
    """(d_dim − f d_bright) / σ at every pixel (the prediction's noise: both exposures')."""
    pred = f * bright["d"]
    var = dim["sigma"] ** 2 + kappa * np.clip(pred, 0.0, None) / dim["gain"] + \
        f * f * (bright["sigma"] ** 2 + kappa * np.clip(bright["d"], 0.0, None) / bright["gain"])
    return (dim["d"] - pred) / np.sqrt(var)


def _factor(dim: dict, bright: dict, kappa: float) -> float:
    """The weighted slope d_dim ≈ f d_bright of the module doc; pixels beyond OUTLIER_SIGMAS of it (a hot
    pixel the same in both, a cosmic ray) are left out."""
    sel = _overlap(dim, bright)
    if sel.sum() < 5:
        raise FitError(f"--psf {dim['path']}: shares fewer than 5 unsaturated pixels above the noise with the next "
                       "brighter exposure: expected exposures of one spot at most ~30× apart")
    f = float(np.median(dim["d"][sel] / bright["d"][sel]))
    for _ in range(4):  # weights from the prediction f d_bright, not from d_dim (whose noise would bias the slope)
        keep = sel & (np.abs(_pair_residual(dim, bright, f, kappa)) < OUTLIER_SIGMAS)
        a, b = dim["d"][keep], bright["d"][keep]
        w = 1.0 / (dim["sigma"][keep] ** 2 + kappa * f * b / dim["gain"][keep])
        f = float(np.sum(w * a * b) / np.sum(w * b * b))
    return f


def _chain(parts: list[dict], kappa: float) -> tuple[list[float], list[tuple[int, int]], int]:
    """(f_i, the (dim, bright) pairs, the brightest's number): the chain of the module doc."""
    common = np.logical_and.reduce([p["usable"] for p in parts])
    order = list(np.argsort([np.sum(p["d"][common]) for p in parts]))[::-1]  # brightest first
    factors = [1.0] * len(parts)
    pairs = list(zip(order[1:], order[:-1]))
    for dim, bright in pairs:
        factors[dim] = factors[bright] * _factor(parts[dim], parts[bright], kappa)
    return factors, pairs, int(order[0])


def _shot_gain(parts: list[dict], factors: list[float], pairs) -> float | None:
    """κ from the pairs' scaled differences (module doc): the κ with median |Δ| / √(base + κ u) = 0.6745 (the
    Gaussian's, robust to outliers and to the spread of u), by bisection in ln κ; None when no pair has 100
    pixels of the laser's colour or the read noise alone explains the scatter."""
    delta, base, u = [], [], []
    for dim, bright in pairs:
        p, r = parts[dim], parts[bright]
        f = factors[dim] / factors[bright]
        sel = _overlap(p, r) & (r["gain"] >= 0.5)  # the laser's colour: the others' noise is the read noise × 1/G
        if sel.sum() < 100:
            continue
        s = r["d"][sel]
        delta.append(p["d"][sel] / f - s)
        base.append((p["sigma"][sel] / f) ** 2 + r["sigma"][sel] ** 2)
        u.append(s / r["gain"][sel] * (1.0 / f + 1.0))
    if not delta:
        return None
    delta, base, u = np.abs(np.concatenate(delta)), np.concatenate(base), np.concatenate(u)

    def score(k):
        return float(np.median(delta / np.sqrt(base + k * u))) - 0.6745
    lo, hi = -12.0, 12.0
    if score(math.exp(lo)) <= 0:
        return None
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if score(math.exp(mid)) > 0 else (lo, mid)
    return math.exp(0.5 * (lo + hi))


def _merge(exposures: list[Exposure], factors: list[float]):
    num = np.zeros(exposures[0].d.shape)
    wsum = np.zeros_like(num)
    for e, f in zip(exposures, factors):
        w = np.where(e.usable, f * f / e.var, 0.0)
        num += w * e.d / f
        wsum += w
    usable = wsum > 0
    safe = np.where(usable, wsum, 1.0)
    return np.where(usable, num / safe, 0.0), np.where(usable, 1.0 / safe, np.inf), usable


def merge_psf(frames: list[Frame], wavelength_nm: float, camera: str, dn_per_e: float | None = None,
              site_gains=None) -> Plane:
    """The exposures and their HDR merge (module doc). dn_per_e: κ (DN per electron, the same in every
    exposure: they differ by their time) from --noise-frames, used when the exposures cannot measure it;
    site_gains: a CFA's (R, G, B) response measured from the orders (fit.cfa.SiteGains) in place of --camera's."""
    notes = [n for f in frames for n in f.notes]
    channel = _channel(frames) if frames[0].kind == "rgb" else 0
    if frames[0].kind == "rgb":
        notes.append(f"colour images: the {COLOURS[channel]} channel (the most signal) is fitted")
    gains = colour_gains(wavelength_nm, camera) if frames[0].kind == "cfa" else np.ones(3)
    if frames[0].kind == "cfa" and site_gains is not None:
        gains = np.asarray(site_gains.gains)
        notes.append(site_gains.note())
    elif frames[0].kind == "cfa":
        notes.append(f"CFA sites balanced by {camera}'s response at {wavelength_nm:g} nm: R/G/B "
                     f"{gains[0]:.3f}/{gains[1]:.3f}/{gains[2]:.3f}")
    parts = [_prepare(f, channel, gains) for f in frames]
    hot = np.logical_or.reduce([~p["usable"] & ~p["sat"] for p in parts])  # a hot pixel is hot in every frame,
    for p in parts:  # where an order's light around it hides it from the spike test
        p["usable"] &= ~hot
    assumed = frames[0].saturation_dn / ASSUMED_FULL_WELL_E
    factors, pairs, _ = _chain(parts, dn_per_e or assumed)
    kappa = _shot_gain(parts, factors, pairs)
    if kappa is not None:
        factors, pairs, _ = _chain(parts, kappa)
    elif dn_per_e is not None:
        kappa = dn_per_e
        notes.append(f"shot noise from --noise-frames: {kappa:.3g} DN per electron (taken at the PSF's gain)")
    else:
        kappa = assumed
        notes.append(f"shot noise not measured (one exposure, no --noise-frames): {kappa:.3g} DN per electron "
                     f"assumed (a {ASSUMED_FULL_WELL_E:g} e- full well); the uncertainties are scaled by the fit's "
                     "residual")
    for dim, bright in pairs:  # a pixel two exposures disagree on (hot, a cosmic ray) is masked in both
        f = factors[dim] / factors[bright]
        bad = parts[dim]["usable"] & parts[bright]["usable"] & \
            (np.abs(_pair_residual(parts[dim], parts[bright], f, kappa)) > OUTLIER_SIGMAS)
        parts[dim]["usable"] &= ~bad
        parts[bright]["usable"] &= ~bad
    exposures = [Exposure(p["path"], p["d"], p["sigma"] ** 2 + kappa * np.clip(p["d"], 0.0, None) / p["gain"],
                          p["usable"], p["sat"], p["gain"], p["sigma"], int((~p["sat"] & ~p["usable"]).sum()))
                 for p in parts]
    value, var, usable = _merge(exposures, factors)
    hot = max(e.hot for e in exposures)
    if hot:
        notes.append(f"{hot} hot pixel(s) masked")
    clipped = np.logical_and.reduce([e.saturated for e in exposures])
    if clipped.any():
        notes.append(f"{int(clipped.sum())} pixel(s) saturated in every exposure, masked")
    return Plane(tuple(exposures), tuple(factors), value, var, usable, clipped, float(kappa),
                 tuple(float(g) for g in gains), tuple(notes))
