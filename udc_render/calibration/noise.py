"""(λ_read, λ_shot) per RGGB channel of the display capture.

A random pattern of 16 × 9 grey blocks (sRGB code values uniform in 0..255), captured `noise_frames`
times at exposures geometrically spaced from NOISE_SPAN · E_max to E_max (linear scaling of the
irradiance; the short exposures give the dark pixels that pin λ_read), E_max putting the dimmest
channel's brightest pixel at NOISE_FILL of white (brighter channels then clip in the upper frames and
those pixels are left out). Residual noisy − clean in normalised units w = (DN − black)/(white −
black), variance in quantile bins of the clean w (a censored-Gaussian maximum-likelihood variance:
with a black level of 0 the noise of dark pixels is clipped), weighted least-squares line var =
λ_read + λ_shot · w; pixels within CLIP_SIGMAS σ of the black or white clip are left out. λ do not
depend on the exposure. Truth: sensor_lambdas at the display's gain (photon model; quantisation
excluded) or the λ the Gaussian model drew.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.special import log_ndtr

from udc_render.calibration.rig import CHANNELS, Rig, check
from udc_render.pipeline import SynthError
from udc_render.sensor import pack_rggb, sensor_lambdas

NOISE_TOL = 0.10
NOISE_BINS = 40
NOISE_FILL, NOISE_SPAN = 0.9, 1e-3  # exposure series: brightest frame, and shortest / longest exposure
CLIP_SIGMAS = 0.25  # noise bins this many σ clear of the black and white clips (censored fit below)


def censored_variance(r: np.ndarray, low: np.ndarray, high: np.ndarray) -> float:
    """Maximum-likelihood variance of zero-mean Gaussian residuals r, where r ≤ low (a pixel read at
    the black clip) or r ≥ high (at the white clip) is only known to lie beyond the clip (Tobit)."""
    lo, hi = r <= low, r >= high
    mid = r[~lo & ~hi]

    def nll(log_s):
        sd = math.exp(log_s)
        return (mid.size * log_s + float(np.sum(mid ** 2)) / (2 * sd * sd)
                - float(np.sum(log_ndtr(low[lo] / sd))) - float(np.sum(log_ndtr(-high[hi] / sd))))
    s0 = math.log(max(float(np.std(r)), 1e-12))
    return math.exp(2 * minimize_scalar(nll, bounds=(s0 - 3, s0 + 3), method="bounded").x)


def noise_fit(w: np.ndarray, resid: np.ndarray, bins: int = NOISE_BINS) -> dict:
    """var = λ_read + λ_shot · w from residuals `resid` = noisy − clean at clean intensities `w`
    (normalised units; the clips at w + r = 0 and 1 are treated as censoring, censored_variance).

    Pixels whose clean w lies within CLIP_SIGMAS σ of the black (0) or white (1) clip are left out,
    with σ(w) from 200 fine quantile bins; the rest go into `bins` quantile bins, and a weighted
    least-squares line is fitted to the bin variances (weights n_b / var_b², var_b from the
    previous line; first pass unweighted)."""
    def binned(sel, n):
        groups = np.array_split(sel[np.argsort(w[sel])], n)
        return (np.array([w[g].mean() for g in groups]),
                np.array([censored_variance(resid[g], -w[g], 1 - w[g]) for g in groups]),
                np.array([g.size for g in groups]))
    wf, vf, _ = binned(np.arange(w.size), 200)
    ok = (wf > CLIP_SIGMAS * np.sqrt(vf)) & (wf + CLIP_SIGMAS * np.sqrt(vf) < 1)
    if ok.sum() < 3:
        raise SynthError("noise calibration: fewer than 3 intensity bins clear of the black and white clips")
    sel = np.nonzero((w >= wf[ok].min()) & (w <= wf[ok].max()))[0]
    wb, vb, nb = binned(sel, bins)
    A = np.stack([np.ones_like(wb), wb], 1)
    coef = np.linalg.lstsq(A, vb, rcond=None)[0]
    for _ in range(2):
        sw = np.sqrt(nb) / np.maximum(A @ coef, 1e-30)
        coef = np.linalg.lstsq(A * sw[:, None], vb * sw, rcond=None)[0]
    return {"w": wb, "var": vb, "w_range": [float(wf[ok].min()), float(wf[ok].max())],
            "lambda_read": float(coef[0]), "lambda_shot": float(coef[1])}


def _truth(s, cap) -> tuple[list, list, str]:
    """(λ_read, λ_shot per channel, where they come from) of sensor `s` (cap: a capture, for the Gaussian λ)."""
    if s.noise == "poisson":
        lr, ls = sensor_lambdas(s)
        return [lr] * 4, [ls] * 4, f"sensor_lambdas at gain {s.gain:g} (photon model)"
    return cap.params["lambda_read"], cap.params["lambda_shot"], f"the Gaussian model's λ ({s.lambda_source})"


def calibrate_noise(rig: Rig) -> dict:
    """(λ_read, λ_shot) per RGGB channel of the display capture (module doc)."""
    if rig.cfg.sensor.noise == "none":
        return {"skipped": "noise model 'none': no noise to calibrate", "checks": []}
    code = np.kron(rig.rng(7).integers(0, 256, (9, 16)), np.ones((30, 30)))
    b = rig.render(rig.pattern_file("noise_blocks.png", code))
    s = rig.sensors[rig.display.name]
    img = rig.optics(b, rig.display)
    preview = pack_rggb(rig.capture(img, b, rig.display, 1999).clean_dn - s.black_level_dn).reshape(4, -1).max(axis=1)
    top = NOISE_FILL * s.range_dn / preview.min()  # exposure scale: the dimmest channel's brightest pixel at NOISE_FILL
    w, r = [], []
    for i, scale in enumerate(np.geomspace(NOISE_SPAN * top, top, rig.spec.noise_frames)):
        cap = rig.capture(img * np.float32(scale), b, rig.display, 2000 + i)
        w.append(pack_rggb((cap.clean_dn.astype(np.float64) - s.black_level_dn) / s.range_dn).reshape(4, -1))
        r.append(pack_rggb((cap.mosaic_dn.astype(np.float64) - cap.clean_dn) / s.range_dn).reshape(4, -1))
    w, r = np.concatenate(w, 1), np.concatenate(r, 1)
    fits = [noise_fit(w[c], r[c]) for c in range(4)]
    truth_r, truth_s, how = _truth(s, cap)
    checks = [check(f"lambda_read {c}", f["lambda_read"], truth_r[k], NOISE_TOL)
              for k, (c, f) in enumerate(zip(CHANNELS, fits))]
    checks += [check(f"lambda_shot {c}", f["lambda_shot"], truth_s[k], NOISE_TOL)
               for k, (c, f) in enumerate(zip(CHANNELS, fits))]
    return {"model": s.noise, "gain": s.gain, "frames": rig.spec.noise_frames, "exposure_scale_max": float(top),
            "truth_from": how, "fits": fits, "truth_read": truth_r, "truth_shot": truth_s, "checks": checks}
