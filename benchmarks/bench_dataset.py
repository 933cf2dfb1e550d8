#!/usr/bin/env python
"""Dataset throughput: captures per minute at 1 and 2 workers, each worker's set-up before its first item, the
per-stage split, peak memory per worker, and the FFTs an item needs beside its synthesis time.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_dataset.py --out out/bench_dataset [--count 6]
        [--workers 1,2] [--profiles physical,paper] [--display toled,poled] [--one-thread 1]

Each (profile, workers) case runs `udc-render dataset --builtin --display toled,poled --count N` at the
monitor scene's 2048 × 1024 frame, 30 bands (glass + T-OLED + P-OLED: 3 captures per item) into a fresh
folder, after one warm-up job of the profile (the kernel cache then holds the kernels and what is made of them:
far fields, field bases, power maps, kernel spectra; their first cost is benchmarks/bench_kernels.py's).
Figures:

- threads: per worker, cores // workers (udc_render.dataset.threads); a last row pins 1 worker to 1 thread;
- wall: the whole run_dataset call (pool start-up, every worker's set-up and the parent's check of the cache);
- set-up: per worker, its process's age at its first item plus that item's kernel load (timing.jsonl's
  process_age_s + kernels_s: imports and kernels), the largest over the workers;
- per item: medians over the items of timing.jsonl (render, synth, write; seconds in one worker), and its CPU
  seconds (cpu_s: every thread of the worker's process); cpu_captures_per_min = cores · 60 · 3 / cpu_s, what
  the item's core-seconds allow when the cores do nothing else (a machine shared with other work shows its
  wall figures below it; this one does not depend on the others' load as much);
- speedup_vs_1: captures/min over the first case's (1 worker, all cores);
- peak RSS per worker: the largest ru_maxrss any item's process reported (MB; the memory-mapped cache entries'
  pages count in it, though every worker shares them);
- FFTs per item, from the first item's capture.json records (fft_counts): 'now' as the synthesis made them
  (large: the frame's FFT shape; small: the far field's), 'before' as the same item at today's defaults would
  have made them before issue 46 (every band transformed, every display's field blend, kernel spectra per
  item); the bound = large FFTs now × one FFT of that shape at the worker's thread count (the mean of an
  rfft2 and an irfft2), and the synthesis time over it.
The machine is shared: the load average is written beside each case; compare ratios within one run.
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


def fft_counts(item: Path, bands: int, rank: int) -> dict:
    """FFTs of one item (module doc) from its records: per view, blend or not (optics.model), through the
    monitor's planes or the bands (optics.primaries; a blend through them: optics.field_planes, 3J forward FFTs),
    the far field's bands (far_field.bands_added)."""
    views = {"gt": json.loads((item / "synth.json").read_text())["gt_optics"]}
    for folder in sorted(p.parent for p in item.glob("*/capture.json")):
        optics = json.loads((folder / "capture.json").read_text()).get("optics")
        if optics and folder.name != "glass":
            views[folder.name] = optics
    now, small, before, small_before = 0, 0, 0, 0
    planes = any("primaries" in o and o["model"] != "field-dependent" for o in views.values())
    plain_bands = sum(o["model"] != "field-dependent" and "primaries" not in o for o in views.values())
    now += 3 if planes else bands if plain_bands else 0  # forward: the planes, or the bands shared by plain views
    for name, o in views.items():
        blend = o["model"] == "field-dependent"
        r = o.get("field_rank", rank)
        through = o.get("field_planes", {}).get("forward_ffts")  # the blend through the planes: 3J of its own
        now += (through if through else bands * r if blend else 0) + 3  # kernel spectra kept by the worker; 3 inverse
        far = o.get("far_field")
        if far:
            small += (9 + 3 if "primaries" in o else 2 * far["bands_added"]) + 3
            small_before += 2 * far["bands_added"] + 3
        before += (2 * bands * rank if name != "gt" else 2 * bands) + 3  # every display blended (d > 0)
    return {"ffts_now": now, "small_ffts_now": small + (3 if planes else 0), "ffts_before": before,
            "small_ffts_before": small_before}


def fft_seconds(shape, threads: int) -> float:
    """Median of one rfft2 and one irfft2 of `shape` (float32), averaged: one FFT's cost."""
    x = np.random.default_rng(0).random(shape, dtype=np.float32)
    spec = sfft.rfft2(x, workers=threads)
    fwd = median_time(lambda: sfft.rfft2(x, workers=threads))
    inv = median_time(lambda: sfft.irfft2(spec, s=shape, workers=threads))
    return (fwd + inv) / 2


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
    load = os.getloadavg()[0]
    summary = run_dataset(job, workers, progress=False)
    log = [json.loads(line) for line in (out / "timing.jsonl").read_text().splitlines()]
    med = {k: statistics.median(r[k] for r in log) for k in ("render_s", "synth_s", "write_s", "seconds", "cpu_s")}
    first = {}
    for r in sorted(log, key=lambda r: r["process_age_s"]):
        first.setdefault(r["pid"], r)
    in_process = workers == 1  # the age of this process is not a worker's start-up: its kernel load only
    setup_s = max(r["kernels_s"] + (0 if in_process else r["process_age_s"]) for r in first.values())
    return {"profile": profile, "workers": workers, "threads": threads or threads_per_worker(workers), "items": count,
            "wall_s": summary["wall_s"], "captures_per_min": 60 * count * CAPTURES_PER_ITEM / summary["wall_s"],
            "setup_s": setup_s, **{f"item_{k}": v for k, v in med.items()},
            "cpu_captures_per_min": os.cpu_count() * 60 * CAPTURES_PER_ITEM / med["cpu_s"],
            "peak_rss_mb": max(r["peak_rss_mb"] for r in log), "item_mb": item_bytes(out) / 1e6, "out": out,
            "load_start": load, "load_end": os.getloadavg()[0]}


def bounds(profile: str, display: str, threads: int, out: Path) -> dict:
    """The FFTs of the case's first item and its synthesis bound (module doc), at the worker's thread count."""
    from udc_render.optics import fft_shape
    from udc_render.scene.geometry import camera_geometry, render_grid
    job, cfg = setup(dataset_args(profile, display, 1, 1, out))
    g, cam = render_grid(job.scene), camera_geometry(job.scene)
    shape = fft_shape((cam.height_px, cam.width_px), g.kernel_size_px, g.margin_px)
    item = sorted(out.glob("train/shard_*/item_*"))[0]
    counts = fft_counts(item, g.centres_nm.size, cfg.field_rank or 16)
    one = fft_seconds(shape, threads)
    return {**counts, "fft_shape": f"{shape[0]}x{shape[1]}", "one_fft_ms": 1e3 * one,
            "bound_synth_s": counts["ffts_now"] * one}


COLUMNS = ["profile", "workers", "threads", "items", "wall_s", "captures_per_min", "speedup_vs_1", "setup_s",
           "item_cpu_s", "cpu_captures_per_min", "item_render_s", "item_synth_s", "bound_synth_s", "synth_over_bound",
           "ffts_now", "small_ffts_now", "ffts_before", "one_fft_ms", "item_write_s", "item_mb", "peak_rss_mb",
           "load_start", "load_end"]


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
            run_case(profile, a.display, 1, 1, root / "warm-up")  # the cache's kernels and what is made of them
            base = None
            cases = [(int(w), None) for w in a.workers.split(",")] + [(1, 1)] * a.one_thread
            for w, threads in cases:
                r = run_case(profile, a.display, a.count, w, root, threads)
                r |= bounds(profile, a.display, r["threads"], r["out"])
                r["synth_over_bound"] = r["item_synth_s"] / r["bound_synth_s"] if r["bound_synth_s"] else None
                base = base or r["captures_per_min"]
                r["speedup_vs_1"] = r["captures_per_min"] / base
                rows.append(r)
                print(table([r]).splitlines()[-1], flush=True)
    head = (f"bench_dataset: {a.count} items per case, displays glass,{a.display}, {os.cpu_count()} CPUs, "
            f"load average (1 min) at each case's start and end in its row\n\n")
    save_text(a.out / "bench_dataset.md", head + table(rows))
    save_text(a.out / "bench_dataset.csv", csv_text([{c: r.get(c) for c in COLUMNS} for r in rows], COLUMNS))
    print(head + table(rows))


if __name__ == "__main__":
    main()
