#!/usr/bin/env python
"""The averaged ground truth's frame-by-frame pixels (sensor.frames._frame_by_frame): CPU time per pixel against
the pixel's mean electrons, for the two ways of drawing its N frames' Poisson counts, beside the naive loop.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_gt_frames.py [--pixels 262144] [--frames 16] [--repeats 5]

For each mean e (a flat field of `--pixels` pixels at the paper's sensor, gain 1, black level 0):
- thinned: T ~ Poisson(N e), each electron in a uniform frame (frames._thinned_counts), then frames._frames_sum,
  in blocks of frames.BLOCK_ELEMENTS pixel-frames;
- frame after frame: one Poisson and one normal draw a pixel and frame over all the pixels
  (frames._frame_after_frame: the loop before the thinning, which frames keeps above THIN_BELOW_E).
Times are medians of `--repeats` runs, one thread, in ns a pixel (all N frames). frames.THIN_BELOW_E is where
thinned stops being the faster. A last row mixes the means as a
dark-surround frame has them (half below 1 e⁻, a tail to 80 e⁻) through _frame_by_frame itself.
"""
from __future__ import annotations

import argparse
import os
import statistics
import time
from dataclasses import replace

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from udc_render.sensor import (
    SensorConfig,  # noqa: E402
    frames,  # noqa: E402
)
from udc_render.sensor.readout import poisson_cap_e  # noqa: E402

MEANS_E = (0.0, 0.05, 0.2, 0.5, 1.0, 2.0, 4.0, 8.0, 12.0, 16.0, 24.0, 32.0, 64.0)


def thinned(e: np.ndarray, s: SensorConfig, n: int, rng) -> np.ndarray:
    out, step = np.empty(e.size), -(-frames.BLOCK_ELEMENTS // n)
    for a in range(0, e.size, step):
        out[a:a + step] = frames._frames_sum(frames._thinned_counts(e[a:a + step], n, rng), s, rng)
    return out / n


def naive(e: np.ndarray, s: SensorConfig, n: int, rng) -> np.ndarray:
    """Frame after frame over every pixel, whatever its mean (the loop before the thinning)."""
    return frames._frame_after_frame(np.minimum(e, poisson_cap_e(s.full_well_e, s.read_noise_e)), s, n, rng) / n


def cpu_ns(fn, pixels: int, repeats: int) -> float:
    times = []
    for r in range(repeats):
        t0 = time.process_time()
        fn(np.random.default_rng(r))
        times.append(time.process_time() - t0)
    return 1e9 * statistics.median(times) / pixels


def dark_surround(pixels: int) -> np.ndarray:
    """Means as the frame-by-frame pixels of a monitor capture have them: half below 1 e⁻ (exponential, mean 0.5),
    a quarter 1–10 e⁻, a quarter 10–80 e⁻ (log-uniform)."""
    rng = np.random.default_rng(0)
    q = pixels // 4
    return np.concatenate([rng.exponential(0.5, pixels - 2 * q), np.exp(rng.uniform(0, np.log(10), q)),
                           np.exp(rng.uniform(np.log(10), np.log(80), q))])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pixels", type=int, default=1 << 18)
    ap.add_argument("--frames", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    s, n, px = replace(SensorConfig(), gain=1.0), args.frames, args.pixels
    print(f"bench_gt_frames: {px} pixels, {n} frames, ns a pixel (CPU, median of {args.repeats}); "
          f"THIN_BELOW_E = {frames.THIN_BELOW_E:g}, BLOCK_ELEMENTS = {frames.BLOCK_ELEMENTS}\n")
    print("| mean e⁻ | thinned | frame after frame | thinned / frame after frame |\n|---|---|---|---|")
    for mean in MEANS_E:
        e = np.full(px, mean)
        thin = cpu_ns(lambda rng: thinned(e, s, n, rng), px, args.repeats)
        each = cpu_ns(lambda rng: naive(e, s, n, rng), px, args.repeats)
        print(f"| {mean:g} | {thin:.0f} | {each:.0f} | {thin / each:.2f} |")
    e = dark_surround(px)
    now = cpu_ns(lambda rng: frames._frame_by_frame(e, s, n, rng), px, args.repeats)
    slow = cpu_ns(lambda rng: naive(e, s, n, rng), px, args.repeats)
    print(f"\ndark-surround mix: _frame_by_frame {now:.0f} ns a pixel, frame after frame {slow:.0f}: "
          f"{slow / now:.2f}× faster")


if __name__ == "__main__":
    main()
