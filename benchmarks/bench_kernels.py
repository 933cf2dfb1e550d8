#!/usr/bin/env python
"""Seconds to compute the d > 0 kernel set of the default monitor scene: this engine against the engine of
another checkout (--baseline, e.g. the one before issue 13), with the error between them.

The set `udc-render demo` needs per display: 30 bands (400–700 nm, 10 nm, centres 405…695 nm) × 4 × 4
field phases, 513-px kernels of 1.55 µm pixels, d = 2 mm, the paper's 2048 × 1024 sensor, the monitor
scene's lens, T-OLED and P-OLED, kernel cache off (psf.compute_kernels called directly).

- ``this``: compute_kernels of this checkout;
- ``baseline``: compute_kernels of the checkout --baseline DIR (git worktree add DIR 831aa6e: before issue 13).

Every run is a fresh subprocess (PYTHONPATH = this checkout or DIR), the two interleaved within a round,
times the median over --repeats rounds; the machine is shared, so compare ratios taken in one run. Errors of
the baseline against this engine (kernels are unit-sum): L1 = Σ|k − k_this|, max = max|k − k_this| / max k_this,
the worst over bands (and phases for field kernels); field_power and transmittance as the largest absolute
difference. --quick: 3 bands (405, 545, 695 nm).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_kernels.py [--quick] [--baseline DIR] [--repeats R] [--out DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

DISTANCE_MM = 2.0
SENSOR_UM = (2048 * 1.55, 1024 * 1.55)
QUICK_BANDS = (0, 14, 29)  # 405, 545, 695 nm
ROOT = Path(__file__).resolve().parents[1]
FIELDS = ("kernels", "field_kernels", "field_power", "transmittance")


def _request(quick: bool) -> dict:
    """compute_kernels' arguments (JSON) for the monitor scene's band grid (all 30 bands, or 3 with quick)."""
    from udc_render.scene import load_scene
    from udc_render.scene.geometry import psf_lens, render_grid
    scene = load_scene("monitor")
    grid = render_grid(scene)
    wl = grid.centres_nm[list(QUICK_BANDS)] if quick else grid.centres_nm
    return dict(lens=psf_lens(scene).describe(), wavelengths_nm=[float(v) for v in wl], pixel_um=grid.pitch_um,
                size_px=grid.kernel_size_px, distance_mm=DISTANCE_MM, sensor_um=list(SENSOR_UM))


def child(display: str, request: str, out: str) -> None:
    """Run one kernel set with the psf on sys.path; write its arrays and seconds to `out` (.npz)."""
    from psf import Lens, compute_kernels, layouts
    kw = json.loads(request)
    kw["lens"] = Lens(**kw["lens"])
    t0 = time.perf_counter()
    ks = compute_kernels(getattr(layouts, display)(), **kw)
    seconds = time.perf_counter() - t0
    np.savez(out, seconds=seconds, **{f: getattr(ks, f) for f in FIELDS})


def _spawn(label: str, tree: Path, display: str, request: dict, folder: str) -> dict:
    out = Path(folder) / f"{display}-{label}.npz"
    env = dict(os.environ, PYTHONPATH=str(tree))
    subprocess.run([sys.executable, __file__, "--child", display, json.dumps(request), str(out)], env=env,
                   check=True, cwd=tree)
    with np.load(out) as f:
        return {k: f[k] for k in f.files}


def _l1_max(k: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """Worst Σ|k − ref| and worst max|k − ref| / max ref over the leading axes of [..., S, S]."""
    diff = np.abs(k.astype(np.float64) - ref)
    return float(diff.sum(axis=(-1, -2)).max()), float((diff.max(axis=(-1, -2)) / ref.max(axis=(-1, -2))).max())


def _errors(res: dict, ref: dict) -> dict:
    fl1, fmax = _l1_max(res["field_kernels"], ref["field_kernels"])
    ml1, mmax = _l1_max(res["kernels"], ref["kernels"])
    return {"field L1": fl1, "field max": fmax, "mean L1": ml1, "mean max": mmax,
            "field_power": float(np.abs(res["field_power"] - ref["field_power"]).max()),
            "transmittance": float(np.abs(res["transmittance"] - ref["transmittance"]).max())}


def run(displays, engines: dict[str, Path], repeats: int, quick: bool) -> list[dict]:
    """engines: label → checkout; 'this' is the error reference."""
    request = _request(quick)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for display in displays:
            times = {label: [] for label in engines}
            results = {}
            for _ in range(repeats):
                for label, tree in engines.items():  # interleaved: each round runs every engine once
                    results[label] = _spawn(label, tree, display, request, folder)
                    times[label].append(float(results[label]["seconds"]))
                    print(f"  {display} {label}: {times[label][-1]:.1f} s", flush=True)
            this = statistics.median(times["this"])
            for label in engines:
                t = statistics.median(times[label])
                rows.append({"display": display, "engine": label, "bands": len(request["wavelengths_nm"]),
                             "time_s": t, "time / this": t / this, **_errors(results[label], results["this"])})
    return rows


def table(rows: list[dict]) -> str:
    cols = ["display", "engine", "bands", "time_s", "time / this", "field L1", "field max", "mean L1", "mean max",
            "field_power", "transmittance"]
    fmt = {"time_s": "{:.1f}", "time / this": "{:.2f}"}
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for row in rows:
        cells = [fmt.get(c, "{:.1e}").format(row[c]) if isinstance(row[c], float) else str(row[c]) for c in cols]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="3 bands instead of 30")
    ap.add_argument("--baseline", type=Path, default=None, help="a checkout whose engine is timed too")
    ap.add_argument("--displays", default="toled,poled")
    ap.add_argument("--repeats", type=int, default=None, help="rounds (default 3 with --quick, else 1)")
    ap.add_argument("--out", type=Path, default=None, help="also write bench_kernels.md here")
    ap.add_argument("--child", nargs=3, metavar=("DISPLAY", "REQUEST", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(*args.child)
        return
    repeats = args.repeats or (3 if args.quick else 1)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    engines = {"this": ROOT} | ({"baseline": args.baseline.resolve()} if args.baseline else {})
    rows = run(args.displays.split(","), engines, repeats, args.quick)
    head = (f"Python {platform.python_version()}, numpy {np.__version__}; {os.cpu_count()} CPUs; 1-min load "
            f"{load0:.1f} at start, {os.getloadavg()[0]:.1f} at end; run {time.perf_counter() - t0:.0f} s; "
            f"median of {repeats} round(s), each run a fresh process.")
    text = head + "\n\n" + table(rows) + "\n"
    print(text)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "bench_kernels.md").write_text(text)


if __name__ == "__main__":
    main()
