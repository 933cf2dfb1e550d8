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
  dither the quantiser: the N frames drawn one by one in expose's arithmetic. A dark pixel's N Poisson
  counts come as T ~ Poisson(N e) electrons each put in a uniform frame (thinning: the same law, fewer
  draws); the read noise is drawn frame by frame.

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
# Frame by frame, a pixel of mean below this many electrons draws its n counts as one Poisson(n e) spread over the
# frames (_thinned_counts), above it n Poisson draws: the faster of the two at n = 16 (benchmarks/bench_gt_frames.py:
# thinned 0.35-0.6 of the time up to 4 e⁻, 0.76-0.92 at 8-12, 1.6 at 16, 6 at 64; the T small integers grow with e)
THIN_BELOW_E = 12.0
BLOCK_ELEMENTS = 65536  # pixel-frames a block of the thinned draws: its [⌈65536 / n⌉, n] float64 (0.5 MB) stay in cache


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
    """The mean of n frames of expose for the pixels e [m], each frame drawn. Poisson noise (module doc): below
    THIN_BELOW_E the frames' counts thinned from one draw (_thinned_counts) in blocks of BLOCK_ELEMENTS, above
    it frame after frame (_frame_after_frame); then each frame's read noise, full well, gain, rounding and clips
    in expose's arithmetic (_frames_sum). Other noise, or a non-finite e: n frames of expose on the zero-padded
    [2, 2⌈m/4⌉] layout."""
    m = e.size
    if sensor.noise != "poisson" or not np.all(np.isfinite(e)):
        grid = np.zeros(4 * max(1, -(-m // 4)))
        grid[:m] = e
        grid = grid.reshape(2, -1)
        total = np.zeros(grid.shape)
        for _ in range(n):
            total += expose(grid, sensor, rng)[0]
        return total.ravel()[:m] / n
    mean = np.minimum(e, readout.poisson_cap_e(sensor.full_well_e, sensor.read_noise_e))
    out = np.empty(m)
    thin = mean < THIN_BELOW_E
    pixels, step = np.flatnonzero(thin), -(-BLOCK_ELEMENTS // n)
    for a in range(0, pixels.size, step):
        block = pixels[a:a + step]
        out[block] = _frames_sum(_thinned_counts(mean[block], n, rng), sensor, rng)
    out[~thin] = _frame_after_frame(mean[~thin], sensor, n, rng)
    return out / n


def _thinned_counts(mean_e: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """[c, n] counts of n frames, iid Poisson(mean_e) along each row, as T ~ Poisson(n · mean_e) electrons each put
    in a uniform frame: given T, n iid Poisson counts are multinomial with equal shares (exact). One Poisson draw
    and T small integers a pixel in place of n Poisson draws."""
    total = rng.poisson(n * mean_e)
    slots = np.repeat(np.arange(0, mean_e.size * n, n), total) + rng.integers(0, n, total.sum(), dtype=np.uint16)
    return np.bincount(slots, minlength=mean_e.size * n).reshape(mean_e.size, n)


def _frame_after_frame(mean_e: np.ndarray, sensor: SensorConfig, n: int, rng: np.random.Generator) -> np.ndarray:
    """Σ_f DN_f of n frames of the pixels mean_e [c], frame after frame over all of them: one Poisson and one
    normal draw a pixel and frame."""
    total = np.zeros(mean_e.size)
    for _ in range(n):
        total += _read_out(rng.poisson(mean_e).astype(np.float64), sensor, rng)
    return total


def _frames_sum(counts: np.ndarray, sensor: SensorConfig, rng: np.random.Generator) -> np.ndarray:
    """Σ_f DN_f over the frames (axis 1) of the counts [c, n] (_read_out); sums of integers, exact in float64."""
    return _read_out(counts.astype(np.float64), sensor, rng).sum(axis=1)


def _read_out(dn: np.ndarray, sensor: SensorConfig, rng: np.random.Generator) -> np.ndarray:
    """Counts n_f (float64) to DN_f = clip(rint(black + g · min(n_f + σ_read N_f, FW)), 0, white) in place:
    expose's arithmetic."""
    if sensor.read_noise_e > 0:
        dn += sensor.read_noise_e * rng.standard_normal(dn.shape)
    np.minimum(dn, sensor.full_well_e, out=dn)
    dn *= sensor.dn_per_electron
    dn += sensor.black_level_dn
    np.round(dn, out=dn)
    return np.clip(dn, 0.0, sensor.white_level_dn, out=dn)
