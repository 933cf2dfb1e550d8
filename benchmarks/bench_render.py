#!/usr/bin/env python
"""Megapixels per second of each render path and Mitsuba variant at the 2048 × 1024 sensor.

Cases (scenes/monitor.toml and scenes/room.toml as shipped, sensor 2048 × 1024 px of 1.55 µm; the
render grid adds the 396 µm margin on every side, 2560 × 1536 px):

- monitor, rgb_matrix (one RGB render, bands by the 3 × 30 primary matrix), at 4 and 16 spp;
- monitor, spectral (render.path = "spectral": the panel texture Σ_c drive_c(uv) · S_c(λ), 4 bands per
  render, 8 renders), at 2 spp;
- room, spectral (max_depth 6) at 1 spp, with the scene's 4 bands per render (8 renders) and with all
  30 bands in one render; no depth pass.

Each case runs in its own subprocess, because the Mitsuba variant is chosen once per process: the
llvm variants (`llvm_ad_rgb` / `llvm_ad_spectral`, the renderer's default when a working libLLVM is
found) and the scalar ones (`UDC_RENDER_VARIANT=scalar`): monitor rgb_matrix at 4 spp; the monitor's
spectral path (a Python texture in scalar variants) at 1 spp on 512 × 256 px of 6.2 µm; the room
(30 bands per render) at 1 spp on 1024 × 512 px of 3.1 µm. These smaller sensors keep the framing (fewer, larger
pixels: 1/16 and 1/4 of the pixels); the table marks them "scaled": their throughput is what is
compared, and the 2048 × 1024 time is scaled from it.

Times: the renderer's meta['seconds'] (the whole render_scene call, scene set-up included), median of
--repeats runs after one untimed warm-up (imports, kernel compile); a warm-up over 20 s is kept as a
timed run, and a case stops repeating once its median passes --stop-after-s (40 s), so the dearest
cases are one run whose time may include Dr.Jit's compile of kernels not yet in its disk cache
(~0.6 s per render). Throughput: sensor Mpx / s, render-grid Mpx / s, and grid Mpx · spp / s (the
spp of the final band image, whatever the number of renders); "M samples/s (× renders)" counts every
render's samples (grid Mpx · spp · renders / s), the path tracer's raw rate.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_render.py --out out/bench
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
import time

FULL = (2048, 1024, 1.55)

# name, scene, path, spp, variant, sensor (None: the scene's 2048 × 1024 × 1.55 µm), bands per render
# (None: the scene's)
CASES = [
    ("monitor-rgb-4", "monitor", "rgb_matrix", 4, "llvm", None, None),
    ("monitor-rgb-16", "monitor", "rgb_matrix", 16, "llvm", None, None),
    ("monitor-spectral-2", "monitor", "spectral", 2, "llvm", None, 4),
    ("room-spectral-1", "room", "spectral", 1, "llvm", None, 4),
    ("room-spectral-1-bpr30", "room", "spectral", 1, "llvm", None, 30),
    ("monitor-rgb-4", "monitor", "rgb_matrix", 4, "scalar", None, None),
    ("monitor-spectral-1", "monitor", "spectral", 1, "scalar", (512, 256, 6.2), 4),
    ("room-spectral-1-bpr30", "room", "spectral", 1, "scalar", (1024, 512, 3.1), 30),
]
QUICK_SENSOR = (512, 256, 6.2)
EXPENSIVE_S = 20.0  # no untimed warm-up above this (the first timed run includes the compile)

COLUMNS = ["case", "scene", "path", "variant", "bands_per_render", "renders", "sensor_px", "pitch_um",
           "grid_px", "spp", "repeats", "seconds", "seconds_min", "sensor_mpx_per_s", "grid_mpx_per_s",
           "grid_mpx_spp_per_s", "grid_msamples_per_s", "seconds_full", "noise_rel", "peak_rss_gib", "scaled"]


# ----------------------------------------------------------------------------------------------
# Worker (one case, in its own process)


def worker(spec: dict) -> dict:
    import resource
    from dataclasses import replace

    from udc_render.render import render_scene
    from udc_render.scene import Sensor, load_scene, scenes_dir
    from udc_render.scene.geometry import camera_geometry

    scene = load_scene(scenes_dir() / f"{spec['scene']}.toml")
    if spec["sensor"]:
        scene = replace(scene, sensor=Sensor(*spec["sensor"]))
    scene = scene.with_render(spp=spec["spp"], noise=None, path=spec["path"], depth=False)
    if spec["bpr"]:
        scene = scene.with_render(bands_per_render=spec["bpr"])
    g = camera_geometry(scene)
    times, first = [], None
    warm = spec["warmup"]
    while len(times) < spec["repeats"]:
        b = render_scene(scene, progress=False)
        if warm:
            warm = False
            if b.meta["seconds"] > EXPENSIVE_S:  # too dear to throw away: keep it as a timed run
                times.append(b.meta["seconds"])
                first = b.meta
            continue
        times.append(b.meta["seconds"])
        first = first or b.meta
        if statistics.median(times) > spec["stop_after_s"]:
            break
        del b
    k = scene.bands.count
    bpr = scene.render.bands_per_render if first["render_path"] == "spectral" else None
    return {"variant": first["variant"], "backend_reason": first["backend_reason"], "times": times,
            "spp": first["spp"], "noise_rel": first["noise_rel"], "grid": [g.width_px, g.height_px],
            "sensor": [scene.sensor.width_px, scene.sensor.height_px, scene.sensor.pitch_um],
            "bands_per_render": bpr, "renders": -(-k // bpr) if bpr else 1,
            "peak_rss_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20}


def run_case(case, repeats: int, quick: bool, stop_after_s: float) -> dict:
    name, scene, path, spp, variant, sensor, bpr = case
    if quick:
        sensor = QUICK_SENSOR
    spec = {"scene": scene, "path": path, "spp": spp, "sensor": sensor, "repeats": repeats, "bpr": bpr,
            "warmup": True, "stop_after_s": stop_after_s}
    env = dict(os.environ)
    env.pop("UDC_RENDER_VARIANT", None)
    if variant == "scalar":
        env["UDC_RENDER_VARIANT"] = "scalar"
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    r = subprocess.run([sys.executable, os.path.abspath(__file__), "--worker", json.dumps(spec)], env=env,
                       capture_output=True, text=True)
    line = next((ln for ln in r.stdout.splitlines() if ln.startswith("RESULT ")), None)
    if r.returncode != 0 or line is None:
        tail = (r.stderr or r.stdout).strip().splitlines()[-1:] or ["no output"]
        raise RuntimeError(f"{name} ({variant}) failed (exit {r.returncode}): {tail[0]}")
    out = json.loads(line[len("RESULT "):])
    w, h = out["grid"]
    sec = statistics.median(out["times"])
    gw, gh = _full_grid(scene)
    mpx_spp = w * h * out["spp"] / 1e6 / sec
    row = {"case": name, "scene": scene, "path": path, "variant": out["variant"],
           "bands_per_render": out["bands_per_render"] or "", "renders": out["renders"],
           "sensor_px": f"{out['sensor'][0]}x{out['sensor'][1]}", "pitch_um": out["sensor"][2],
           "grid_px": f"{w}x{h}", "spp": out["spp"], "repeats": len(out["times"]), "seconds": sec,
           "seconds_min": min(out["times"]), "sensor_mpx_per_s": out["sensor"][0] * out["sensor"][1] / 1e6 / sec,
           "grid_mpx_per_s": w * h / 1e6 / sec, "grid_mpx_spp_per_s": mpx_spp,
           "seconds_full": gw * gh * out["spp"] / 1e6 / mpx_spp,
           "grid_msamples_per_s": mpx_spp * out["renders"], "noise_rel": out["noise_rel"],
           "peak_rss_gib": out["peak_rss_gib"], "scaled": (w * h) != (gw * gh), "times": out["times"]}
    return row


def _full_grid(scene: str) -> tuple[int, int]:
    from udc_render.scene import load_scene, scenes_dir
    from udc_render.scene.geometry import camera_geometry
    g = camera_geometry(load_scene(scenes_dir() / f"{scene}.toml"))
    return g.width_px, g.height_px


# ----------------------------------------------------------------------------------------------
# Report


def _g(v, digits=3) -> str:
    if v is None or v == "":
        return ""
    if isinstance(v, bool):
        return "yes" if v else ""
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    return str(v)


def markdown(rows: list[dict]) -> str:
    cols = [("scene", "scene"), ("path", "path"), ("variant", "variant"), ("bands_per_render", "bands/render"),
            ("renders", "renders"), ("sensor_px", "sensor px"), ("pitch_um", "pitch µm"), ("grid_px", "grid px"),
            ("spp", "spp"), ("repeats", "runs"), ("seconds", "seconds (median)"), ("sensor_mpx_per_s", "sensor Mpx/s"),
            ("grid_mpx_per_s", "grid Mpx/s"), ("grid_mpx_spp_per_s", "grid Mpx·spp/s"),
            ("grid_msamples_per_s", "M samples/s (× renders)"),
            ("seconds_full", "seconds at 2048×1024"), ("noise_rel", "noise_rel"), ("peak_rss_gib", "peak RSS GiB"),
            ("scaled", "scaled")]
    out = ["| " + " | ".join(h for _, h in cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for r in rows:
        out.append("| " + " | ".join(_g(r.get(k)) for k, _ in cols) + " |")
    return "\n".join(out)


def ratios(rows: list[dict], study: dict | None) -> list[str]:
    def find(scene, path, variant_kind, spp=None, bpr=None):
        for r in rows:
            if r["scene"] == scene and r["path"] == path and r["variant"].startswith(variant_kind) and \
                    (spp is None or r["spp"] == spp) and (bpr is None or r["bands_per_render"] == bpr):
                return r
        return None

    lines = []
    for scene, path, bpr in (("monitor", "rgb_matrix", None), ("monitor", "spectral", 4), ("room", "spectral", 30)):
        a, b = find(scene, path, "llvm", bpr=bpr), find(scene, path, "scalar", bpr=bpr)
        if a and b:
            lines.append(f"- {scene} {path}: llvm / scalar throughput (grid Mpx·spp/s) = "
                         f"{a['grid_mpx_spp_per_s'] / b['grid_mpx_spp_per_s']:.1f}× "
                         f"({a['variant']} at {a['grid_px']}, {b['variant']} at {b['grid_px']}"
                         f"{', scaled' if b['scaled'] else ''}).")
    rgb, spec = find("monitor", "rgb_matrix", "llvm", 16), find("monitor", "spectral", "llvm")
    if rgb and spec:
        lines.append(f"- monitor, equal spp (llvm, {rgb['sensor_px'].replace('x', '×')}): "
                     f"spectral ({spec['bands_per_render']} bands per render) "
                     f"/ rgb_matrix time per spp = {rgb['grid_mpx_spp_per_s'] / spec['grid_mpx_spp_per_s']:.0f}× "
                     f"({spec['seconds'] / spec['spp']:.1f} s vs {rgb['seconds'] / rgb['spp']:.2f} s per spp, set-up "
                     "included).")
        if rgb["noise_rel"] and spec["noise_rel"]:
            nr, ns = rgb["noise_rel"], spec["noise_rel"]
            eq = (spec["seconds"] * ns ** 2) / (rgb["seconds"] * nr ** 2)
            lines.append(f"- monitor, equal per-band error (llvm; cost ∝ seconds · noise², noise from these runs' "
                         f"passes): spectral / rgb_matrix = {eq:.0f}× (spectral {spec['spp']} spp: noise {ns:.3g}; "
                         f"rgb {rgb['spp']} spp: noise {nr:.3g}; set-up included in both).")
    r4, r30 = find("room", "spectral", "llvm", bpr=4), find("room", "spectral", "llvm", bpr=30)
    if r4 and r30:
        lines.append(f"- room, 4 vs 30 bands per render (llvm, 1 spp): {r4['seconds'] / r30['seconds']:.1f}× the time "
                     f"for {r4['renders']} renders instead of 1; per render and sample: "
                     f"{r4['grid_msamples_per_s']:.3g} vs {r30['grid_msamples_per_s']:.3g} M/s.")
    if study:
        for r in study.get("analysis", {}).get("recommend", {}).get("monitor_spectral_vs_rgb", []):
            lines.append(f"- monitor, equal error from the study (study_render.json, {r['bands_per_render']} bands per "
                         f"render, fitted per-spp cost × error², set-up excluded): spectral / rgb_matrix = "
                         f"{r['equal_error_cost_ratio']:.0f}× per band"
                         + (f", {r['equal_error_cost_ratio_xyz']:.0f}× on the XYZ image"
                            if r.get("equal_error_cost_ratio_xyz") else "") + ".")
    return lines


def environment(load0: float, seconds: float) -> str:
    from importlib.metadata import version

    from udc_render.render.variants import choose_backend
    llvm = choose_backend().libllvm or "none working (llvm cases fell back to scalar)"
    return (f"Python {sys.version.split()[0]}, mitsuba {version('mitsuba')}, drjit {version('drjit')}, libLLVM "
            f"{llvm}; {os.cpu_count()} CPUs; 1-min load average {load0:.1f} at start, {os.getloadavg()[0]:.1f} at "
            f"end; run {seconds:.0f} s. Times: render_scene's meta['seconds'] (set-up included), median of the "
            f"runs; each case in its own process.")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", help="also write bench_render.md and bench_render.csv to this folder")
    ap.add_argument("--repeats", type=int, default=3, help="timed runs per case (median)")
    ap.add_argument("--quick", action="store_true", help=f"every case at {QUICK_SENSOR[0]}×{QUICK_SENSOR[1]} px, 1 run")
    ap.add_argument("--stop-after-s", type=float, default=40.0,
                    help="stop repeating a case once its median run exceeds this (s)")
    ap.add_argument("--study", help="study_render.json (udc-render study render) for the equal-error ratio")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print("RESULT " + json.dumps(worker(json.loads(args.worker))), flush=True)
        return
    if args.repeats < 1:
        ap.error("--repeats must be ≥ 1")
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    rows = []
    for case in CASES:
        print(f"# {case[0]} ({case[4]}) ...", file=sys.stderr, flush=True)
        rows.append(run_case(case, 1 if args.quick else args.repeats, args.quick, args.stop_after_s))
        r = rows[-1]
        print(f"#   {r['variant']}: {r['seconds']:.2f} s median of {r['repeats']} "
              f"({', '.join(f'{t:.2f}' for t in r['times'])}), {r['grid_mpx_spp_per_s']:.3g} grid Mpx·spp/s",
              file=sys.stderr, flush=True)
    study = None
    if args.study and os.path.exists(args.study):
        with open(args.study) as fh:
            study = json.load(fh)
    text = (environment(load0, time.perf_counter() - t0) + "\n\n" + markdown(rows) + "\n\nRatios:\n\n"
            + "\n".join(ratios(rows, study)))
    if args.quick:
        text = f"QUICK run: every case at {QUICK_SENSOR[0]}×{QUICK_SENSOR[1]} px, one run (smoke test).\n\n" + text
    print(text)
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        with open(os.path.join(args.out, "bench_render.md"), "w") as fh:
            fh.write(text + "\n")
        with open(os.path.join(args.out, "bench_render.csv"), "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=COLUMNS, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)
        print(f"# wrote {args.out}/bench_render.md, .csv in {time.perf_counter() - t0:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
