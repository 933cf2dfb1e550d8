"""Where an online batch's time goes (torch.profiler): 4 crops of 256 px through the synthetic panels of
bench_degrade.py (d = 0 and d > 0, 513-px kernels), cut from two 2048 × 1024 clean images on the device.

    .venv/bin/python benchmarks/profile_online.py [--device cuda|cpu]

Prints, for the degradation crop by crop and as one batch (Degrader.batched), the mean time of an online
batch (8 batches after 4 of warm-up) and the kernel launches over 4 more; then the profiler's tables of the
batched run, by CPU time and by device time. On the H100 of benchmarks/README.md: 905 kernel launches, 26.8 ms CPU
and 4.4 ms GPU over the 4 batches (the degradation is launch-bound there).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
from torch.profiler import ProfilerActivity, profile

from bench_degrade import synthetic_panels
from restore.degrade import Degrader
from restore.online import CleanImage, OnlineBatches
from udc_render.dataset.bank import Bank


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    dev = torch.device(ap.parse_args().device)
    panels = synthetic_panels(513, 4)
    rng = np.random.default_rng(0)
    images = [CleanImage(f"noise {i}", rng.random((3, 1024, 2048), dtype=np.float32)) for i in range(2)]
    for batched in (False, True):
        profile_batches(dev, OnlineBatches(images, Bank(Path("."), {}, panels), Degrader(panels, dev, batched=batched),
                                           256, 4, 0, 40, 0).epoch(0)[1], "one batch" if batched else "crop by crop",
                        tables=batched)


def profile_batches(dev: torch.device, batches, name: str, tables: bool) -> None:
    """The mean time of 8 batches after 4 of warm-up, then the profiler's count of kernel launches (and, with
    tables, its tables) over 4 more."""
    def sync():
        if dev.type == "cuda":
            torch.cuda.synchronize()
    for _ in range(4):
        next(batches)
    sync()
    t = time.perf_counter()
    for _ in range(8):
        next(batches)
    sync()
    mean_ms = (time.perf_counter() - t) / 8 * 1e3
    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if dev.type == "cuda" else [])
    with profile(activities=activities) as prof:
        for _ in range(4):
            next(batches)
        sync()
    events = prof.key_averages()
    launches = sum(e.count for e in events if e.key in ("cudaLaunchKernel", "cuLaunchKernel", "cudaLaunchKernelExC"))
    print(f"device {dev}, the degradation {name}: an online batch of 4 crops {mean_ms:.1f} ms; over 4 batches "
          f"{launches} kernel launches")
    if tables:
        print(events.table(sort_by="cpu_time_total", row_limit=20))
        if dev.type == "cuda":
            print(events.table(sort_by="cuda_time_total", row_limit=12))


if __name__ == "__main__":
    main()
