#!/usr/bin/env python
"""A randomized dataset against the same count through one fixed display: the panels' kernel planning
per panel, the items' wall time and their per-stage medians.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_randomize.py --out out/bench_randomize [--count 8]
        [--panels 4] [--sensor-px 512,256] [--workers 1] [--display toled]

Both cases run `udc-render dataset --builtin --count N` on the monitor scene (30 bands, 513-px kernels at
1.55 µm, the physical profile: d = 2 mm for the fixed preset, d drawn from 0.5–5 mm for the panels, so
both have field-phase kernels) with a fresh kernel cache each, so that the planning is cold:

- fixed: `--display DISPLAY` (glass + the preset: 2 captures per item);
- randomized: `--randomize default --panels P` (glass + the drawn panel: 2 captures per item).

Figures: plan_s, the kernels planned in the parent before any item (the fixed case: glass + the display
once; randomized: every panel's glass + panel under its lens, per panel too); wall_s, run_dataset's item
phase (each worker's kernel load, the compact bases and power maps of every panel it meets included);
per item, medians of timing.jsonl; ratio, the randomized wall over the fixed one. The machine is shared:
compare ratios within one run.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

from udc_render.io.files import csv_text, save_text

COLUMNS = ["case", "items", "panels", "plan_s", "plan_s_per_panel", "wall_s", "s_per_item", "item_render_s",
           "item_synth_s", "item_write_s", "wall_ratio_vs_fixed"]


def run_case(name: str, extra: list[str], a, root: Path) -> dict:
    from udc_render.cli import build_parser
    from udc_render.cli.dataset import dataset_job
    from udc_render.dataset import run_dataset
    out, cache = root / name, root / f"cache_{name}"
    shutil.rmtree(out, ignore_errors=True)
    shutil.rmtree(cache, ignore_errors=True)
    argv = ["dataset", "--builtin", "--count", str(a.count), "--sensor-px", a.sensor_px, "--out", str(out),
            "--cache-dir", str(cache), "--quiet", *extra]
    job = dataset_job(build_parser().parse_args(argv))
    t0 = time.perf_counter()
    s = run_dataset(job, a.workers, progress=False)
    total = time.perf_counter() - t0
    log = [json.loads(line) for line in (out / "timing.jsonl").read_text().splitlines()]
    med = {k: statistics.median(r[k] for r in log) for k in ("render_s", "synth_s", "write_s")}
    plan = s["panels_plan_s"] or [total - s["wall_s"]]
    return {"case": name, "items": a.count, "panels": len(s["panels_plan_s"]) or 1, "plan_s": sum(plan),
            "plan_s_per_panel": statistics.median(plan), "wall_s": s["wall_s"], "s_per_item": s["wall_s"] / a.count,
            **{f"item_{k}": v for k, v in med.items()}}


def table(rows: list[dict]) -> str:
    def fmt(v):
        return f"{v:.3g}" if isinstance(v, float) else str(v)
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    return "\n".join(lines + ["| " + " | ".join(fmt(r.get(c, "")) for c in COLUMNS) + " |" for r in rows]) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/bench_randomize"))
    ap.add_argument("--count", type=int, default=8)
    ap.add_argument("--panels", type=int, default=4)
    ap.add_argument("--sensor-px", default="512,256")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--display", default="toled")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory(dir=a.out) as tmp:
        for name, extra in (("fixed", ["--display", a.display]),
                            ("randomized", ["--randomize", "default", "--panels", str(a.panels)])):
            rows.append(run_case(name, extra, a, Path(tmp)))
            print(table(rows[-1:]).splitlines()[-1], flush=True)
    for r in rows:
        r["wall_ratio_vs_fixed"] = r["wall_s"] / rows[0]["wall_s"]
    head = (f"bench_randomize: {a.count} items, sensor {a.sensor_px} px, {a.workers} worker(s), fixed display "
            f"{a.display}, {a.panels} panels; {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} "
            "at the end\n\n")
    save_text(a.out / "bench_randomize.md", head + table(rows))
    save_text(a.out / "bench_randomize.csv", csv_text([{c: r.get(c) for c in COLUMNS} for r in rows], COLUMNS))
    print(head + table(rows))


if __name__ == "__main__":
    main()
