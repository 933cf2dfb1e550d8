#!/usr/bin/env python
"""The flat field's first harmonic against the field rank and the field phases (issue 29): study banding's
rig (udc_render.studies.banding, FULL: 1024 × 128 px, 15 bands of 20 nm; --quick: its quick rig), one display,
bands along x, the blend's power from the exact series. For each distance d and phase count P the kernels are
made once (through a kernel cache when --cache-dir is given), then each field rank is synthesised and measured
(banding.measure: first harmonic / the exact series P(s), the phase-averaged kernel's MTF), and timed:
rounds alternate the ranks, median wall and process-CPU seconds of --repeats syntheses (the machine is shared:
compare ratios within one run).

--weights fourier replaces the bilinear phase weights of every axis whose phases span a whole display period
by trigonometric interpolation, w_i(s) = (1/P) [1 + 2 Σ_{h<P/2} cos(2πh(s − s_i)/p) (+ cos(πP(s − s_i)/p), P
even)]: no sinc²(h/P) loss of the kernels' phase harmonics below P/2 (a diagnostic: the weights go negative,
the synthesis keeps the bilinear ones).

--full-frame instead times a synthesis of the default monitor scene (2048 × 1024, 30 bands; glass and the
display at the first distance) at each integer rank, with the exact-power map made per capture and made once
beforehand (pipeline.store_power_maps, what a dataset worker keeps): median of --repeats alternating rounds.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_banding_rank.py [--display toled] [--distances 2,4,8,16]
        [--phases 4] [--ranks 2,3,4,all] [--repeats 3] [--weights bilinear|fourier] [--far-field]
        [--quick] [--full-frame] [--cache-dir DIR] [--out out/bench/banding_rank.jsonl]
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from udc_render.optics import displays as D, field as field_module
from udc_render.pipeline import SynthConfig
from udc_render.studies import banding as B

BILINEAR = field_module.phase_weights


def fourier_weights(positions_um, shifts_um, distance_um, image_distance_um, period_um, periodic):
    """Trigonometric interpolation weights [P, N] over P phases spanning a period (module doc); the bilinear
    ones (optics.field.phase_weights) on an axis whose phases do not span a period."""
    if not periodic or len(shifts_um) < 2:
        return BILINEAR(positions_um, shifts_um, distance_um, image_distance_um, period_um, periodic)
    s = np.asarray(positions_um, float) * distance_um / image_distance_um
    shifts = np.asarray(shifts_um, float)
    P = shifts.size
    phase = 2 * np.pi * (s[None, :] - shifts[:, None]) / period_um
    w = np.ones_like(phase) + sum(2 * np.cos(h * phase) for h in range(1, (P - 1) // 2 + 1))
    if P % 2 == 0:
        w += np.cos(P // 2 * phase)
    return w / P


def run(args) -> list[dict]:
    if args.weights == "fourier":
        field_module.phase_weights = fourier_weights
    rig = B.Rig(B.QUICK if args.quick else B.FULL, "x")
    base = SynthConfig(use_cache=args.cache_dir is not None, kernel_cache=args.cache_dir)
    rig.base = base if args.far_field else replace(base, far_field_threshold=None)
    ranks = [r if r == "all" else int(r) for r in args.ranks.split(",")]
    out = []
    for d in (float(v) for v in args.distances.split(",")):
        display = D.preset(args.display).with_distance(d)
        for P in (int(v) for v in args.phases.split(",")):
            rows = {r: B.measure(rig, args.display, d, P, "series", r)[0] for r in ranks}
            wall, cpu = {r: [] for r in ranks}, {r: [] for r in ranks}
            for _ in range(args.repeats):
                for r in ranks:
                    c0, t0 = time.process_time(), time.perf_counter()
                    rig.synthesis(display, P, "series", r)
                    wall[r].append(time.perf_counter() - t0)
                    cpu[r].append(time.process_time() - c0)
            for r in ranks:
                row = rows[r]
                rec = {"display": args.display, "distance_mm": d, "field_phases": P, "field_rank": r,
                       "weights": args.weights, "far_field": args.far_field,
                       "ratio_to_series": row.get("ratio_measured_analytic"), "psf_mtf": row.get("psf_mtf"),
                       "harmonic_order": row.get("harmonic_order"), "a1_measured_rel": row.get("a1_measured_rel"),
                       "kernel_s": row["kernel_s"], "synth_wall_s": float(np.median(wall[r])),
                       "synth_cpu_s": float(np.median(cpu[r])), "repeats": args.repeats}
                print(json.dumps(rec), flush=True)
                out.append(rec)
    return out


def full_frame(args) -> list[dict]:
    """Seconds of a full-frame synthesis per rank, the power map per capture ('fresh') or stored ('stored')."""
    from udc_render.pipeline import compact_kernels, plan_kernels, store_power_maps, synthesize
    from udc_render.render import render_scene
    from udc_render.scene import load_scene
    scene = load_scene("monitor")
    band_image = render_scene(scene, progress=False)
    displays = [D.preset("glass"), D.preset(args.display).with_distance(float(args.distances.split(",")[0]))]
    base = SynthConfig(use_cache=args.cache_dir is not None, kernel_cache=args.cache_dir)
    base = base if args.far_field else replace(base, far_field_threshold=None)
    t0 = time.perf_counter()
    kernels = plan_kernels(scene, displays, base)
    kernel_s = time.perf_counter() - t0
    runs = {}
    for r in (int(v) for v in args.ranks.split(",") if v != "all"):
        cfg = replace(base, field_rank=r)
        compact = compact_kernels(kernels, scene, cfg)
        t0 = time.perf_counter()
        stored = store_power_maps(compact, scene)
        runs[(r, "fresh")], runs[(r, "stored")] = (cfg, compact, 0.0), (cfg, stored, time.perf_counter() - t0)
    seconds = {key: [] for key in runs}
    for _ in range(args.repeats):
        for key, (cfg, k, _) in runs.items():
            t0 = time.perf_counter()
            synthesize(band_image, scene, displays, cfg, kernels=k)
            seconds[key].append(time.perf_counter() - t0)
    out = [{"display": args.display, "distance_mm": displays[1].distance_mm, "field_rank": r, "power_map": m,
            "store_s": runs[(r, m)][2], "kernel_s": kernel_s, "synth_wall_s": float(np.median(v)),
            "repeats": args.repeats, "far_field": args.far_field} for (r, m), v in seconds.items()]
    for rec in out:
        print(json.dumps(rec), flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--display", default="toled", choices=("toled", "poled"))
    ap.add_argument("--distances", default="2,4,8,16", help="mm, comma-separated")
    ap.add_argument("--phases", default="4", help="field phases per axis, comma-separated")
    ap.add_argument("--ranks", default="2,3,4,all", help="field ranks (or all), comma-separated")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--weights", default="bilinear", choices=("bilinear", "fourier"))
    ap.add_argument("--far-field", action="store_true", help="keep SynthConfig's far field (default: off)")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--full-frame", action="store_true", help="time the default scene's synthesis (module doc)")
    ap.add_argument("--cache-dir", default=None)
    ap.add_argument("--out", type=Path, default=Path("out/bench/banding_rank.jsonl"))
    args = ap.parse_args()
    rows = full_frame(args) if args.full_frame else run(args)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "a") as f:
        f.writelines(json.dumps(r) + "\n" for r in rows)


if __name__ == "__main__":
    main()
