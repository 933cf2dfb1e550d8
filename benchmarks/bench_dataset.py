#!/usr/bin/env python
"""Dataset throughput: items and captures per minute at 1 and 2 workers, the per-stage split, peak
memory per worker, and a lower bound beside each stage.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_dataset.py --out out/bench_dataset [--count 6]
        [--workers 1,2] [--profiles physical,paper] [--display toled,poled]

Each (profile, workers) case runs `udc-render dataset --builtin --display toled,poled --count N` at the
monitor scene's 2048 × 1024 frame, 30 bands (glass + T-OLED + P-OLED: 3 captures per item) into a fresh
folder, with the job's kernels planned and cached beforehand (their cost is the kernel benchmark's:
benchmarks/bench_kernels.py). Figures:

- threads: per worker, cores // workers (udc_render.dataset.threads); a last row pins 1 worker to
  1 thread, so that the pool's scaling per process shows beside the threads' (--one-thread 0: skip);
- wall: the whole run_dataset call (pool start-up and each worker's kernel load included);
- per item: medians over the items of timing.jsonl (render, synth, write; seconds in one worker);
- steady captures/min = workers · 60 / (median item seconds) · 3: what a long run approaches;
- speedup_vs_1: captures/min over the first case's (1 worker, all cores);
- peak RSS per worker: the largest ru_maxrss any item's process reported (MB);
- lower bounds, per item: synth = (FFT count) × (median time of one FFT of that shape at the worker's
  thread count); render = bytes of the band image at the measured copy bandwidth (the K band images
  must be written at least once); write = bytes of the item's files at the measured file write speed.

The FFT count per item (pipeline.synthesize, spectral form): ground truth K forward + K kernel +
3 inverse; a d = 0 display K kernel + 3 inverse (the band spectra are shared); a d > 0 display with
field rank r: K·r forward + K·r kernel + 3 inverse. The machine is shared: compare ratios in one run.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import tempfile
from pathlib import Path

import numpy as np
import scipy.fft as sfft

from udc_render.io.files import csv_text, save_text

CAPTURES_PER_ITEM = 3  # glass, T-OLED, P-OLED


def dataset_args(profile: str, display: str, count: int, workers: int, out: Path) -> list[str]:
    return ["dataset", "--builtin", "--display", display, "--profile", profile, "--count", str(count),
            "--workers", str(workers), "--out", str(out), "--quiet"]


def setup(argv: list[str]):
    """(DatasetJob, SynthConfig) exactly as the CLI builds them (cli.dataset.dataset_job)."""
    from udc_render.cli import build_parser
    from udc_render.cli.dataset import dataset_job
    job = dataset_job(build_parser().parse_args(argv))
    return job, job.cfg


def median_time(fn, repeats: int = 5) -> float:
    """Median wall seconds of `repeats` runs after one warm-up (studies.report.timed)."""
    from udc_render.studies.report import timed
    fn()
    return statistics.median(timed(fn, repeats).seconds)


def fft_count(job, kernels) -> int:
    """FFTs per item of pipeline.synthesize (module doc)."""
    K = kernels.grid.centres_nm.size
    if job.cfg.form != "spectral":
        return 2 * K + 3 + 9 * sum(not d.is_glass for d in job.displays)  # per-channel: 3 channel kernels each
    count = 2 * K + 3  # ground truth
    for d in job.displays:
        ks = kernels.band[d.name]
        if d.is_glass:
            continue  # the ground truth's electrons
        if ks.field_kernels is None:
            count += K + 3
        else:
            r = job.cfg.field_rank or ks.field_kernels.shape[1] * ks.field_kernels.shape[2]
            count += 2 * K * r + 3
    return count


def fft_seconds(shape, threads: int) -> float:
    """Median of one rfft2 and one irfft2 of `shape` (float32), averaged: one FFT's cost."""
    x = np.random.default_rng(0).random(shape, dtype=np.float32)
    spec = sfft.rfft2(x, workers=threads)
    fwd = median_time(lambda: sfft.rfft2(x, workers=threads))
    inv = median_time(lambda: sfft.irfft2(spec, s=shape, workers=threads))
    return (fwd + inv) / 2


def copy_bandwidth_b_s(nbytes: int) -> float:
    a = np.ones(nbytes // 4, np.float32)
    b = np.empty_like(a)
    return nbytes / median_time(lambda: np.copyto(b, a), 3)


def write_bandwidth_b_s(folder: Path, nbytes: int = 64 << 20) -> float:
    data = os.urandom(nbytes)
    path = folder / "bandwidth.bin"

    def write():
        with open(path, "wb") as f:
            f.write(data)
    t = median_time(write, 3)
    path.unlink()
    return nbytes / t


def item_bytes(out: Path) -> float:
    sizes = [sum(p.stat().st_size for p in d.rglob("*") if p.is_file()) for d in out.glob("train/shard_*/item_*")]
    return statistics.median(sizes)


def run_case(profile: str, display: str, count: int, workers: int, root: Path, threads: int | None = None) -> dict:
    """One dataset run; threads: pin the in-process worker's thread count (workers = 1 only)."""
    from udc_render.dataset import run_dataset
    from udc_render.dataset.threads import set_worker_threads, threads_per_worker
    out = root / f"{profile}_w{workers}_t{threads}"
    shutil.rmtree(out, ignore_errors=True)
    job, _ = setup(dataset_args(profile, display, count, workers, out))
    if workers == 1:
        set_worker_threads(threads or threads_per_worker(1))
    summary = run_dataset(job, workers, progress=False)
    log = [json.loads(line) for line in (out / "timing.jsonl").read_text().splitlines()]
    med = {k: statistics.median(r[k] for r in log) for k in ("render_s", "synth_s", "write_s", "seconds")}
    return {"profile": profile, "workers": workers, "threads": threads or threads_per_worker(workers), "items": count, "wall_s": summary["wall_s"],
            "items_per_min": 60 * count / summary["wall_s"],
            "captures_per_min": 60 * count * CAPTURES_PER_ITEM / summary["wall_s"],
            "steady_captures_per_min": workers * 60 / med["seconds"] * CAPTURES_PER_ITEM,
            **{f"item_{k}": v for k, v in med.items()},
            "peak_rss_mb": max(r["peak_rss_mb"] for r in log), "item_mb": item_bytes(out) / 1e6, "out": out}


def bounds(profile: str, display: str, workers: int, threads: int, root: Path, item_mb: float) -> dict:
    """Per-item lower bounds (s) of the three stages (module doc), at the worker's thread count."""
    from udc_render.optics import fft_shape
    from udc_render.pipeline import plan_kernels
    from udc_render.scene.geometry import camera_geometry
    job, cfg = setup(dataset_args(profile, display, 1, workers, root / "bounds"))
    kernels = plan_kernels(job.scene, job.displays, cfg)
    g, cam = kernels.grid, camera_geometry(job.scene)
    shape = fft_shape((cam.height_px, cam.width_px), g.kernel_size_px, g.margin_px)
    n = fft_count(job, kernels)
    one = fft_seconds(shape, threads)
    band_bytes = g.centres_nm.size * cam.height_px * cam.width_px * 4
    return {"ffts_per_item": n, "fft_shape": f"{shape[0]}x{shape[1]}", "one_fft_ms": 1e3 * one,
            "bound_synth_s": n * one, "bound_render_s": band_bytes / copy_bandwidth_b_s(band_bytes),
            "bound_write_s": item_mb * 1e6 / write_bandwidth_b_s(root)}


COLUMNS = ["profile", "workers", "threads", "items", "wall_s", "items_per_min", "captures_per_min", "steady_captures_per_min",
           "item_render_s", "bound_render_s", "item_synth_s", "bound_synth_s", "ffts_per_item", "one_fft_ms",
           "item_write_s", "bound_write_s", "item_mb", "peak_rss_mb", "speedup_vs_1"]


def table(rows: list[dict]) -> str:
    def fmt(v):
        return f"{v:.3g}" if isinstance(v, float) else str(v)
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(fmt(r.get(c, "")) for c in COLUMNS) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/bench_dataset"))
    ap.add_argument("--count", type=int, default=6)
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--profiles", default="physical,paper")
    ap.add_argument("--display", default="toled,poled")
    ap.add_argument("--one-thread", type=int, choices=(0, 1), default=1,
                    help="also run 1 worker pinned to 1 thread: the pool's scaling per process [1]")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory(dir=a.out) as tmp:
        root = Path(tmp)
        for profile in a.profiles.split(","):
            from udc_render.pipeline import plan_kernels
            job, cfg = setup(dataset_args(profile, a.display, 1, 1, root / "plan"))
            plan_kernels(job.scene, job.displays, cfg, progress=True)  # cached: the runs load them
            base = None
            cases = [(int(w), None) for w in a.workers.split(",")] + [(1, 1)] * a.one_thread
            for w, threads in cases:
                r = run_case(profile, a.display, a.count, w, root, threads)
                r |= bounds(profile, a.display, w, r["threads"], root, r["item_mb"])
                base = base or r["captures_per_min"]
                r["speedup_vs_1"] = r["captures_per_min"] / base
                rows.append(r)
                print(table([r]).splitlines()[-1], flush=True)
    head = (f"bench_dataset: {a.count} items per case, displays glass,{a.display}, {os.cpu_count()} CPUs, "
            f"load average {os.getloadavg()[0]:.1f} at the end\n\n")
    save_text(a.out / "bench_dataset.md", head + table(rows))
    save_text(a.out / "bench_dataset.csv", csv_text([{c: r.get(c) for c in COLUMNS} for r in rows], COLUMNS))
    print(head + table(rows))


if __name__ == "__main__":
    main()
