#!/usr/bin/env python
"""A 2-worker dataset job with its workers forked (udc_render.dataset.workers, the default) against the same job
with them spawned, alternately (A B, B A, ...), so that the machine's drift falls on both: the whole call's wall
(run_dataset's wall_s) of each, their medians and the ratio spawn / fork pair by pair.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_worker_start.py [--pairs 4] [--count 6]
        [--out out/bench_worker_start]

The job is bench_dataset.py's (`udc-render dataset --builtin --display toled,poled --profile physical`, 2048 × 1024,
30 bands); run one job of it first so that the kernel cache is warm.
"""
from __future__ import annotations

import argparse
import multiprocessing
import shutil
import statistics
from pathlib import Path

from bench_dataset import dataset_args, setup


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=4)
    ap.add_argument("--count", type=int, default=6)
    ap.add_argument("--out", type=Path, default=Path("out/bench_worker_start"))
    a = ap.parse_args()
    import udc_render.dataset.executors as executors
    from udc_render.dataset import run_dataset
    contexts = {"fork": executors.worker_context, "spawn": lambda: multiprocessing.get_context("spawn")}
    walls = {"fork": [], "spawn": []}
    for i in range(a.pairs):
        for mode in ("fork", "spawn") if i % 2 == 0 else ("spawn", "fork"):
            executors.worker_context = contexts[mode]
            out = a.out / mode
            shutil.rmtree(out, ignore_errors=True)
            job, _ = setup(dataset_args("physical", "toled,poled", a.count, 2, out))
            walls[mode].append(run_dataset(job, 2, progress=False)["wall_s"])
            print(f"{mode}: {walls[mode][-1]:.2f} s", flush=True)
    ratios = [s / f for f, s in zip(walls["fork"], walls["spawn"])]
    print("| workers started by | wall, median (s) | min–max (s) |\n|---|---|---|")
    for mode, w in walls.items():
        print(f"| {mode} | {statistics.median(w):.2f} | {min(w):.2f}–{max(w):.2f} |")
    pairs = ", ".join(f"{r:.3f}" for r in ratios)
    print(f"spawn / fork, pair by pair: {pairs} (median {statistics.median(ratios):.3f})")


if __name__ == "__main__":
    main()
