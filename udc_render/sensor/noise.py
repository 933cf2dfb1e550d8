"""Noise, full well and quantisation: mean electrons ──► DN (defect pixels: sensor.defects).

With fixed-pattern noise (sensor.fpn, FpnConfig) the mean electrons e become the mean charge
q = e · (1 + PRNU map) + dark current × exposure before the noise below, and the offset map o (DSNU,
rows, columns; e⁻) is added to the read-out charge before the full-well cap: Poisson(q) + N + o,
w + noise + g·o/R, or q + o. Without it (fpn None) every line below runs exactly as written.


    noise = "poisson":  DN = black + g · min(Poisson(e) + N(0, σ_read²), FW)
    noise = "gaussian": w = g · e / R,   DN = black + R · min(w + N(0, λ_read + λ_shot · w), g FW / R)
    noise = "none":     DN = black + g · min(e, FW)

(noise is drawn around the unsaturated signal and the full well then caps the read-out signal, as
in Yang & Sankaranarayanan 2021, so a saturated pixel reads exactly black + g · FW: the white level
at gain 1 with the default conversion gain)
then DN is rounded to an integer, clipped to [0, white] (never wraps) and stored as uint16. The
clean mosaic is black + g · min(e, FW) clipped to [0, white], unquantised (float32).
Brooks et al. 2019 ("Unprocessing images for learned raw denoising") sampling, natural logs:
    log λ_shot ~ U(log 1e-4, log 1.2e-2),  log λ_read ~ N(2.18 log λ_shot + 1.20, 0.26²).
"""
from __future__ import annotations

import math

import numpy as np

from udc_render.sensor.bayer import SITES, check_even
from udc_render.sensor.config import SensorConfig
from udc_render.sensor.fpn import FpnConfig, fpn_maps, fpn_record, mean_charge_e

BROOKS_LOG_SHOT_RANGE = (math.log(1e-4), math.log(1.2e-2))
BROOKS_READ_SLOPE, BROOKS_READ_INTERCEPT, BROOKS_READ_SIGMA = 2.18, 1.20, 0.26



def sample_brooks(rng: np.random.Generator, size=None) -> tuple[np.ndarray, np.ndarray]:
    """(λ_read, λ_shot) from Brooks et al. 2019: log λ_shot ~ U(log 1e-4, log 1.2e-2),
    log λ_read ~ N(2.18 log λ_shot + 1.20, 0.26²) (natural logs; normalised [0, 1] units)."""
    log_shot = rng.uniform(*BROOKS_LOG_SHOT_RANGE, size=size)
    log_read = rng.normal(BROOKS_READ_SLOPE * log_shot + BROOKS_READ_INTERCEPT, BROOKS_READ_SIGMA)
    return np.exp(log_read), np.exp(log_shot)


def sensor_lambdas(sensor: SensorConfig) -> tuple[float, float]:
    """(λ_read, λ_shot) of the Gaussian model equivalent to the photon model in normalised units:
    λ_shot = g / R, λ_read = (g σ_read / R)² (quantisation excluded)."""
    u = sensor.dn_per_electron / sensor.range_dn
    return (u * sensor.read_noise_e) ** 2, u


def noise_lambdas(sensor: SensorConfig, rng: np.random.Generator) -> tuple[tuple, tuple]:
    """Per-channel (λ_read[4], λ_shot[4]) for the Gaussian model, drawn from rng when 'brooks'."""
    if sensor.lambda_source == "fixed":
        return sensor.lambda_read, sensor.lambda_shot
    if sensor.lambda_source == "sensor":
        r, s = sensor_lambdas(sensor)
        return (r,) * 4, (s,) * 4
    r, s = sample_brooks(rng, 4 if sensor.brooks_per_channel else 1)
    r, s = (np.repeat(r, 4), np.repeat(s, 4)) if r.size == 1 else (r, s)
    return tuple(float(v) for v in r), tuple(float(v) for v in s)


def _to_dn(signal_dn: np.ndarray, sensor: SensorConfig) -> np.ndarray:
    """Round to integer DN, clip to [0, white] (no wrap) and cast to uint16 (in place on float64)."""
    np.rint(signal_dn, out=signal_dn)
    np.clip(signal_dn, 0, sensor.white_level_dn, out=signal_dn)
    return signal_dn.astype(np.uint16)


def expose(electrons: np.ndarray, sensor: SensorConfig, rng: np.random.Generator,
           fpn: FpnConfig | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """Mean electrons [H, W] ──► (mosaic uint16, clean float32 (FPN-free), sampled-noise params). See
    module doc; fpn: the sensor's fixed-pattern noise (None: none), its maps drawn from fpn.seed, not rng."""
    e = np.asarray(electrons, dtype=np.float64)
    if not np.all(np.isfinite(e)):  # overflow of huge but finite radiance: saturate, never NaN
        e = np.nan_to_num(e, nan=0.0, posinf=np.finfo(np.float64).max)
    check_even(e.shape, "electrons")
    g, black, rng_dn = sensor.dn_per_electron, sensor.black_level_dn, sensor.range_dn
    fw = sensor.full_well_e
    charge = np.minimum(e, fw)
    clean = np.clip(black + g * charge, 0, sensor.white_level_dn).astype(np.float32)
    info: dict = {"noise": sensor.noise, "fpn": None}
    off = None
    if fpn is not None:
        maps = fpn_maps(*e.shape, fpn)
        e, off = mean_charge_e(e, maps, fpn, sensor.exposure_s), maps.offset_e
        info["fpn"] = fpn_record(fpn, maps, sensor)
    if sensor.noise == "poisson":
        # Poisson(λ) + read noise ≥ FW for λ ≥ cap with probability 1 − e^(−hundreds): the cap only
        # avoids numpy's limit on λ (and overflow); the clipped result is the same.
        cap = 2 * fw + 100 + 40 * sensor.read_noise_e
        n = rng.poisson(np.minimum(e, cap)).astype(np.float64)
        if sensor.read_noise_e > 0:
            n += rng.normal(0.0, sensor.read_noise_e, size=n.shape)
        if off is not None:
            n += off
        np.minimum(n, fw, out=n)
        sig = black + g * n
        info.update(read_noise_e=sensor.read_noise_e, full_well_e=fw)
    elif sensor.noise == "gaussian":
        lam_read, lam_shot = noise_lambdas(sensor, rng)
        # Noise around the unsaturated signal, then the full-well clip (as in the photon model), so a
        # saturated pixel reads exactly g·FW. The cap keeps w finite and lies ≥ 40 σ above g·FW / R.
        w_fw = g * fw / rng_dn
        cap = 2 * w_fw + 1600 * max(lam_shot) + 40 * math.sqrt(max(lam_read))
        w = np.minimum(g * e / rng_dn, cap)
        var = np.empty_like(w)
        for c, (i, j) in enumerate(SITES):
            var[i::2, j::2] = lam_read[c] + lam_shot[c] * w[i::2, j::2]
        y = w + rng.standard_normal(w.shape) * np.sqrt(var)
        if off is not None:
            y += (g / rng_dn) * off
        sig = black + rng_dn * np.minimum(y, g * fw / rng_dn, out=y)
        info.update(lambda_source=sensor.lambda_source, lambda_read=list(lam_read), lambda_shot=list(lam_shot))
    else:
        sig = black + g * (charge if off is None else np.minimum(e + off, fw))
    return _to_dn(sig, sensor), clean, info


