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

The arithmetic is sensor.readout's, shared with the online degradation in torch (restore.degrade_sensor); this
module draws its random numbers from one numpy Generator over the whole mosaic.
"""
from __future__ import annotations

import numpy as np

from udc_render.sensor import readout
from udc_render.sensor.bayer import SITES, check_even
from udc_render.sensor.config import SensorConfig
from udc_render.sensor.fpn import FpnConfig, fpn_maps, fpn_record, mean_charge_e


def sample_brooks(rng: np.random.Generator, size=None) -> tuple[np.ndarray, np.ndarray]:
    """(λ_read, λ_shot) from Brooks et al. 2019: log λ_shot ~ U(log 1e-4, log 1.2e-2),
    log λ_read ~ N(2.18 log λ_shot + 1.20, 0.26²) (natural logs; normalised [0, 1] units; sensor.readout:
    a uniform, then a standard normal, from rng)."""
    u = rng.random(size)
    return readout.brooks_lambdas(np.asarray(u), np.asarray(rng.standard_normal(size)))


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


def site_map(values, shape: tuple[int, int]) -> np.ndarray:
    """[H, W] of the four RGGB sites' values (R, Gr, Gb, B) at their sites."""
    out = np.empty(shape)
    for v, (i, j) in zip(values, SITES):
        out[i::2, j::2] = v
    return out


def expose(electrons: np.ndarray, sensor: SensorConfig, rng: np.random.Generator,
           fpn: FpnConfig | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """Mean electrons [H, W] ──► (mosaic uint16, clean float32 (FPN-free), sampled-noise params). See
    module doc (the arithmetic: sensor.readout); fpn: the sensor's fixed-pattern noise (None: none), its maps
    drawn from fpn.seed, not rng. The draws from rng, in order: Poisson counts, then the read noise's normals
    (poisson); the λ when 'brooks', then the normals (gaussian)."""
    e = np.asarray(electrons, dtype=np.float64)
    if not np.all(np.isfinite(e)):  # overflow of huge but finite radiance: saturate, never NaN
        e = readout.finite_electrons(e)
    check_even(e.shape, "electrons")
    g, black, rng_dn = sensor.dn_per_electron, sensor.black_level_dn, sensor.range_dn
    fw = sensor.full_well_e
    clean = np.clip(black + g * np.minimum(e, fw), 0, sensor.white_level_dn).astype(np.float32)
    info: dict = {"noise": sensor.noise, "fpn": None}
    off = None
    if fpn is not None:
        maps = fpn_maps(*e.shape, fpn)
        e, off = mean_charge_e(e, maps, fpn, sensor.exposure_s), maps.offset_e
        info["fpn"] = fpn_record(fpn, maps, sensor)
    if sensor.noise == "poisson":
        n = rng.poisson(np.minimum(e, readout.poisson_cap_e(fw, sensor.read_noise_e))).astype(np.float64)
        normal = rng.standard_normal(n.shape) if sensor.read_noise_e > 0 else None
        sig = readout.read_poisson(n, normal, sensor.read_noise_e, off, fw, g, black)
        info.update(read_noise_e=sensor.read_noise_e, full_well_e=fw)
    elif sensor.noise == "gaussian":
        lam_read, lam_shot = noise_lambdas(sensor, rng)
        cap = readout.gaussian_cap(g * fw / rng_dn, max(lam_read), max(lam_shot))
        sig = readout.read_gaussian(e, rng.standard_normal(e.shape), site_map(lam_read, e.shape),
                                    site_map(lam_shot, e.shape), off, g, rng_dn, fw, black, cap)
        info.update(lambda_source=sensor.lambda_source, lambda_read=list(lam_read), lambda_shot=list(lam_shot))
    else:
        sig = readout.read_noiseless(e, off, fw, g, black)
    return readout.quantised(sig, sensor.white_level_dn).astype(np.uint16), clean, info
