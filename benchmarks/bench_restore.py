#!/usr/bin/env python
"""Milliseconds per megapixel of output RGB for the full-size restoration models on this CPU, at 1 and
2 torch threads, in contiguous and channels_last memory layout; optionally DeP.

- Models: the paper's UNet (8.93 M parameters, restore.models.UNET_CONFIG) and ResNet (EDSR 16 × 64,
  RESNET_CONFIG), random weights (time does not depend on them), float32, eval mode,
  torch.inference_mode; input 1 × 4 × 256 × 512 packed RAW (--size), output 3 × 512 × 1024
  (0.52 Mpx). The paper's T is ms/Mpx on a Titan X at 512 × 1024 × 4 (UNet 21.37, ResNet 92.92).
- channels_last: model and input converted with `.to(memory_format=torch.channels_last)`.
- Times: median of --repeats forward passes after one warm-up, per case; ms/Mpx = ms / output Mpx.
  Ratios: against the same model, contiguous, 1 thread; and the ResNet against the UNet in the
  same layout and threads. The machine is shared: read the ratios.
- --dep: restore.dep.dep_restore on the same packed size (numpy/scikit-image: torch's thread
  setting does not apply), its default denoiser ('nlm'), a Gaussian 33² kernel (σ = 3 px), a smooth
  random scene + noise σ = 0.01; skipped with a line if restore.dep cannot be imported.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_restore.py --json out/bench_restore.json
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

from bench_capture import _timed  # benchmarks/ is on sys.path when a benchmark runs as a script
from restore.models import RESNET_CONFIG, UNET_CONFIG, build_model


def _timed_ms(fn, repeats: int) -> float:
    """Median wall time in ms after a warm-up (bench_capture's timer)."""
    return 1e3 * _timed(fn, repeats)


def model_cases(size: tuple[int, int], repeats: int) -> list[dict]:
    torch.manual_seed(0)
    x = torch.rand(1, 4, *size)
    mpx = 4 * size[0] * size[1] / 1e6
    rows = []
    for name, config in (("UNet", UNET_CONFIG), ("ResNet", RESNET_CONFIG)):
        model = build_model(config).eval()
        for layout, fmt in (("contiguous", torch.contiguous_format), ("channels_last", torch.channels_last)):
            m, xi = model.to(memory_format=fmt), x.to(memory_format=fmt)
            for threads in (1, 2):
                torch.set_num_threads(threads)
                with torch.inference_mode():
                    ms = _timed_ms(lambda: m(xi), repeats)
                rows.append({"method": name, "layout": layout, "threads": threads, "ms": round(ms, 1),
                             "ms_per_mpx": round(ms / mpx, 1), "repeats": repeats})
                print(f"{name:<7} {layout:<14} {threads} thread(s): {ms:9.1f} ms  {ms / mpx:9.1f} ms/Mpx", flush=True)
    base = {r["method"]: r["ms"] for r in rows if r["layout"] == "contiguous" and r["threads"] == 1}
    unet = {(r["layout"], r["threads"]): r["ms"] for r in rows if r["method"] == "UNet"}
    for r in rows:
        r["speed-up vs contiguous 1 thread"] = round(base[r["method"]] / r["ms"], 2)
        r["time / UNet"] = round(r["ms"] / unet[(r["layout"], r["threads"])], 2)
    return rows


def dep_cases(size: tuple[int, int], repeats: int) -> list[dict]:
    try:
        from restore.dep import dep_restore
    except ImportError as e:
        print(f"--dep: restore.dep not importable ({e}); DeP rows skipped")
        return []
    from scipy.ndimage import gaussian_filter
    rng = np.random.default_rng(0)
    scene = gaussian_filter(rng.random((4, *size)), (0, 4, 4))
    packed = scene + 0.01 * rng.standard_normal(scene.shape)
    r = np.arange(33) - 16
    k = np.exp(-(r[:, None] ** 2 + r[None, :] ** 2) / (2 * 3.0 ** 2))
    kernels = np.repeat((k / k.sum())[None], 4, axis=0)
    mpx = 4 * size[0] * size[1] / 1e6
    ms = _timed_ms(lambda: dep_restore(packed, 1.0, kernels, rng=0), repeats)
    print(f"DeP (nlm): {ms:9.1f} ms  {ms / mpx:9.1f} ms/Mpx", flush=True)
    return [{"method": "DeP (nlm)", "layout": "numpy", "threads": "n/a", "ms": round(ms, 1),
             "ms_per_mpx": round(ms / mpx, 1), "repeats": repeats}]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, nargs=2, default=(256, 512), metavar=("H", "W"),
                    help="packed RAW height and width (output is 2H × 2W)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--dep", action="store_true", help="add DeP rows (restore.dep)")
    ap.add_argument("--json", type=Path, help="write the rows and the machine description here")
    args = ap.parse_args()
    size = tuple(args.size)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    rows = model_cases(size, args.repeats) + (dep_cases(size, args.repeats) if args.dep else [])
    machine = {"python": platform.python_version(), "torch": torch.__version__, "cpus": os.cpu_count(),
               "load_avg_1min_start": round(load0, 2), "load_avg_1min_end": round(os.getloadavg()[0], 2),
               "run_s": round(time.perf_counter() - t0, 1), "input": [1, 4, *size],
               "output_mpx": 4 * size[0] * size[1] / 1e6}
    cols = ["method", "layout", "threads", "ms", "ms_per_mpx", "speed-up vs contiguous 1 thread", "time / UNet"]
    md = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    md += ["| " + " | ".join("" if r.get(c) is None else str(r[c]) for c in cols) + " |" for r in rows]
    print("\n" + json.dumps(machine) + "\n\n" + "\n".join(md))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"machine": machine, "rows": rows}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
