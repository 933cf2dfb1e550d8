"""The mean of N frames of one exposure: the paper's ground truth, 16 glass frames averaged (l.235).

Frame f of a pixel with mean electrons e is the capture of sensor.noise (expose) at the sensor's gain:

    poisson:  DN_f = clip(rint(black + g · min(n_f, FW)), 0, white),  n_f = Poisson(e) + N(0, σ_read²)
    gaussian: DN_f = clip(rint(black + R · min(y_f, g FW / R)), 0, white),  y_f = w + N(0, λ_read + λ_shot w)

and the result is the mean of N frames, (1/N) Σ_f DN_f: its temporal noise is the single frame's σ/√N.
It is drawn exactly in distribution, with one draw per pixel instead of N where no frame can clip:

- a pixel whose frames stay inside the DN range and below the full well (the mean ± CLIP_SIGMAS σ_f,
  σ_f the frame's noise in DN) sums without clipping: Σ_f n_f = Poisson(N e) + N(0, N σ_read²)
  (gaussian: N w + N(0, N (λ_read + λ_shot w))), exactly; the N roundings add Σ_f q_f, each
  q_f ~ U(−½, ½) independent of the signal when the noise dithers the quantiser (σ_f ≥ DITHER_DN:
  Widrow & Kollár 2008, the quantisation theorem), drawn as N(0, N / 12) (the Irwin–Hall sum: the same
  variance, excess kurtosis −1.2 / N; it is 0.02 % of the read noise's variance at the defaults);
- the others (near black with black level 0, near saturation) and every pixel when the noise does not
  dither the quantiser: the N frames drawn one by one (expose).

The noise model's λ (gaussian, 'brooks') are drawn once for the burst: one camera, N frames. noise
'none': every frame is the same, the mean is one frame. What averaging does not remove (fixed-pattern
noise, dead and hot pixels: the same in every frame) is the caller's (pipeline: the ground truth).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from udc_render.sensor import readout
from udc_render.sensor.config import SensorConfig, SensorError
from udc_render.sensor.noise import expose, noise_lambdas

# A frame clips with probability < 1e-15 beyond this many σ_f (Gaussian tail; Poisson's is lighter below)
CLIP_SIGMAS = 8.0
DITHER_DN = 1.0  # σ_f ≥ 1 DN: the rounding error is uniform and independent of the signal to < 1e-8 (Widrow)
MAX_FRAMES = 4096


def check_frames(frames) -> int:
    """N as an int in [1, MAX_FRAMES]; a SensorError naming the value otherwise."""
    if isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or not 1 <= frames <= MAX_FRAMES:
        raise SensorError(f"frames = {frames!r}: expected a whole number of frames from 1 to {MAX_FRAMES}")
    return int(frames)


def burst_sensor(sensor: SensorConfig, rng: np.random.Generator) -> SensorConfig:
    """The sensor with its Gaussian-model λ fixed for the burst (drawn once from rng when 'brooks')."""
    if sensor.noise != "gaussian":
        return sensor
    lam_read, lam_shot = noise_lambdas(sensor, rng)
    return replace(sensor, lambda_source="fixed", lambda_read=tuple(lam_read), lambda_shot=tuple(lam_shot))


def mean_of_frames(electrons: np.ndarray, sensor: SensorConfig, frames: int, rng: np.random.Generator,
                   site: int = 0) -> tuple[np.ndarray, int]:
    """(the mean DN of `frames` captures of electrons [H, W] (float64), how many pixels were drawn frame by
    frame) under sensor (module doc). Every pixel has the noise of RGGB site `site` (0 R, 1 Gr, 2 Gb, 3 B:
    its λ in the gaussian model; fix 'brooks' λ first with burst_sensor). H, W even."""
    n = check_frames(frames)
    e = np.asarray(electrons, dtype=np.float64)
    if sensor.noise == "gaussian" and sensor.lambda_source == "brooks":
        raise SensorError("mean_of_frames: lambda_source 'brooks' draws λ per capture: fix them first "
                          "(burst_sensor)")
    if sensor.noise == "gaussian":  # every site of the plane with `site`'s λ (the frames go through expose)
        sensor = replace(sensor, lambda_read=(sensor.lambda_read[site],) * 4,
                         lambda_shot=(sensor.lambda_shot[site],) * 4)
    if sensor.noise == "none":
        return expose(e, sensor, rng)[0].astype(np.float64), 0
    mean_dn, sigma_dn, var_read_dn2, shot = _moments(e, sensor)
    g, fw = sensor.dn_per_electron, sensor.full_well_e
    safe = ((mean_dn - CLIP_SIGMAS * sigma_dn >= -0.5)
            & (mean_dn + CLIP_SIGMAS * sigma_dn <= sensor.white_level_dn - 0.5)
            & (mean_dn + CLIP_SIGMAS * sigma_dn <= sensor.black_level_dn + g * fw))
    if math.sqrt(var_read_dn2) < DITHER_DN:
        safe[:] = False
    out = np.empty_like(e)
    ok = e[safe]
    if sensor.noise == "poisson":
        sums = g * rng.poisson(n * ok).astype(np.float64)
    else:
        w = ok * g / sensor.range_dn
        sums = n * w * sensor.range_dn + rng.standard_normal(ok.shape) * np.sqrt(n * shot[safe])
    sums += rng.standard_normal(ok.shape) * math.sqrt(n * (var_read_dn2 + 1.0 / 12.0))
    out[safe] = sensor.black_level_dn + sums / n
    rest = ~safe
    count = int(rest.sum())
    if count:
        out[rest] = _frame_by_frame(e[rest], sensor, n, rng)
    return out, count


def _moments(e: np.ndarray, sensor: SensorConfig) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """(unclipped mean DN, frame σ in DN, read variance in DN², the signal-dependent variance in DN²)."""
    g, r = sensor.dn_per_electron, sensor.range_dn
    if sensor.noise == "poisson":
        shot, read = g * g * np.maximum(e, 0.0), (g * sensor.read_noise_e) ** 2
    else:  # gaussian: λ per site, all sites equal here (mean_of_frames)
        shot, read = r * r * sensor.lambda_shot[0] * (g * np.maximum(e, 0.0) / r), r * r * sensor.lambda_read[0]
    return sensor.black_level_dn + g * e, np.sqrt(shot + read), read, shot


def _frame_by_frame(e: np.ndarray, sensor: SensorConfig, n: int, rng: np.random.Generator) -> np.ndarray:
    """The mean of n frames of expose for the pixels e [m], each frame drawn (laid out [2, 2⌈m/4⌉], zero-padded).
    Poisson noise takes expose's draws and arithmetic in place, without its noise-free image and uint16 copy: the
    same bits at 0.6 of its time (tests/udc_render/test_sensor_frames.py)."""
    m = e.size
    grid = np.zeros(4 * max(1, -(-m // 4)))
    grid[:m] = e
    if sensor.noise != "poisson" or not np.all(np.isfinite(grid)):
        grid = grid.reshape(2, -1)
        total = np.zeros(grid.shape)
        for _ in range(n):
            total += expose(grid, sensor, rng)[0]
        return total.ravel()[:m] / n
    fw, sigma, g = sensor.full_well_e, sensor.read_noise_e, sensor.dn_per_electron
    mean = np.minimum(grid, readout.poisson_cap_e(fw, sigma))
    total = np.zeros(grid.shape)
    for _ in range(n):
        dn = rng.poisson(mean).astype(np.float64)
        if sigma > 0:
            dn += sigma * rng.standard_normal(dn.shape)
        np.minimum(dn, fw, out=dn)
        dn *= g
        dn += sensor.black_level_dn
        np.round(dn, out=dn)
        total += np.clip(dn, 0.0, sensor.white_level_dn, out=dn)
    return total[:m] / n
