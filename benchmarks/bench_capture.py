#!/usr/bin/env python
"""Seconds per 2048 × 1024 capture for each optics path, against naive per-band convolution, and the
dataset throughput with 1 and 2 workers.

Optics cases (render grid 2560 × 1536 = the 2048 × 1024 frame + the 256-px margin of 396 µm at
1.55 µm; 513-px kernels; the time of the optics does not depend on the pixel values, so the band
image and the kernels are random, positive and normalised):

- ``3 kernels``: the paper's per-channel form, convolve_bands on 3 camera-RGB planes;
- ``30 band kernels``: the spectral form, apply_kernels with one kernel per 10 nm band (d = 0);
- ``field-varying``: 30 bands × 4 × 4 field phases (d > 0), blend 'source';
- ``naive``: scipy.signal.fftconvolve(x_k, k_k, mode='same') per band, then the margin cropped
  (what a first implementation would write; float64, one thread);
- each in float32 (default) and float64; plus the sensor stage (30 bands → RGGB, Poisson noise).

Times: median of --repeats runs after a warm-up; the machine is shared, so compare ratios.
Dataset throughput: `udc-render dataset --builtin --display toled,poled` at the full 2048 × 1024
sensor, --count N items with 1 and 2 workers, in a subprocess each (kernels cached beforehand, so
items are render + glass/T-OLED/P-OLED captures + files); captures per minute counts the three views.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_capture.py --out out/bench_capture
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.signal

from psf.engine import KernelSet
from udc_render.io.files import csv_text, save_text
from udc_render.optics import apply_kernels, convolve_bands
from udc_render.render import BandImage
from udc_render.sensor import SensorConfig, capture

H, W, M, S, K = 1024, 2048, 256, 513, 30


def _timed(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _kernels(rng, n, phases=None) -> np.ndarray:
    shape = (n,) + ((phases, phases) if phases else ()) + (S, S)
    k = rng.random(shape, dtype=np.float32)
    return k / k.sum(axis=(-1, -2), keepdims=True)


def optics_cases(repeats: int) -> list[dict]:
    rng = np.random.default_rng(0)
    bands = rng.random((K, H + 2 * M, W + 2 * M), dtype=np.float32)
    edges = np.arange(400.0, 701.0, 10.0)
    bi = BandImage(bands, edges, 1.55, M, None, {})
    wl = 0.5 * (edges[1:] + edges[:-1])
    ones = np.ones(K)
    flat = KernelSet(_kernels(rng, K), wl, 1.55, 0 * ones, ones, ones, {"distance_mm": 0.0})
    field = KernelSet(flat.kernels, wl, 1.55, 0 * ones, ones, ones,
                      {"distance_mm": 1.0}, field_kernels=_kernels(rng, K, 4), field_power=np.ones((K, 4, 4)),
                      field_shifts_um=np.stack(np.meshgrid(np.arange(4) * 15.0, np.arange(4) * 15.0), -1),
                      period_um=(60.0, 60.0), distance_mm=1.0, image_distance_um=6028.0)
    rgb = bands[:3]
    rows = []

    def naive():
        out = np.empty((K, H, W))
        for k in range(K):
            out[k] = scipy.signal.fftconvolve(bands[k].astype(np.float64), flat.kernels[k].astype(np.float64),
                                              mode="same")[M:-M, M:-M]
        return out

    cases = [("naive per-band fftconvolve", "float64", naive)]
    for prec in ("float32", "float64"):
        cases += [("3 kernels (per-channel form)", prec,
                   lambda p=prec: convolve_bands(rgb, flat.kernels[:3], M, None, p)),
                  ("30 band kernels (d = 0)", prec, lambda p=prec: apply_kernels(bi, flat, None, p)),
                  ("field-varying, 30 bands x 16 phases", prec,
                   lambda p=prec: apply_kernels(bi, field, None, p, period_um=(60.0, 60.0)))]
    frame = bands[:, M:-M, M:-M]
    sensor = SensorConfig(exposure_s=0.03)
    cases.append(("sensor: 30 bands -> RGGB + Poisson", "float64",
                  lambda: capture(frame, edges, sensor, np.random.default_rng(1))))
    for name, prec, fn in cases:
        reps = 1 if "field" in name or "naive" in name else repeats
        t = _timed(fn, reps)
        rows.append({"case": name, "precision": prec, "seconds": round(t, 3), "repeats": reps})
        print(f"{name:<40} {prec:<8} {t:8.2f} s", flush=True)
    naive_t = rows[0]["seconds"]
    for r in rows:
        r["speed-up vs naive"] = round(naive_t / r["seconds"], 2)
    return rows


def dataset_cases(count: int) -> list[dict]:
    rows = []
    exe = str(Path(sys.executable).with_name("udc-render"))
    with tempfile.TemporaryDirectory() as tmp:
        warm = [exe, "dataset", "--builtin", "--display", "toled,poled", "--count", "1", "--out", f"{tmp}/warm",
                "--workers", "1", "--quiet"]
        subprocess.run(warm, check=True)  # kernels into the cache
        for workers in (1, 2):
            cmd = [exe, "dataset", "--builtin", "--display", "toled,poled", "--count", str(count),
                   "--out", f"{tmp}/w{workers}", "--workers", str(workers), "--quiet"]
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True)
            t = time.perf_counter() - t0
            rows.append({"case": f"dataset, {workers} worker(s), {count} items", "precision": "float32",
                         "seconds": round(t, 2), "items/min": round(60 * count / t, 2),
                         "captures/min": round(3 * 60 * count / t, 2)})
            print(f"dataset {workers} worker(s): {t:.1f} s for {count} items, {60 * count / t:.2f} items/min",
                  flush=True)
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/bench_capture"))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--dataset-count", type=int, default=4)
    ap.add_argument("--skip-dataset", action="store_true")
    args = ap.parse_args()
    rows = optics_cases(args.repeats)
    if not args.skip_dataset:
        rows += dataset_cases(args.dataset_count)
    cols = ["case", "precision", "seconds", "repeats", "speed-up vs naive", "items/min", "captures/min"]
    save_text(args.out / "bench_capture.csv", csv_text(rows, cols))
    md = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    md += ["| " + " | ".join("" if r.get(c) is None else str(r.get(c)) for c in cols) + " |" for r in rows]
    save_text(args.out / "bench_capture.md", "\n".join(md) + "\n")
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    sys.exit(main())
