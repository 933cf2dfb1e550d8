"""Error-versus-run-time study of the renderer's knobs: samples per pixel, render path, bands per render.

    udc-render study render --out DIR [--quick]

Two scenes at reduced resolution, same framing as the full 2048 × 1024 × 1.55 µm sensor (the
sensor's physical size is kept: fewer, larger pixels):

- **monitor** (scenes/monitor.toml, 512 × 256 px of 6.2 µm): the ``rgb_matrix`` path over
  spp = 1, 2, 4, …, 256, and the ``spectral`` path (llvm spectral variant, the panel texture) at a
  few spp with 4 and 30 bands per render.
- **room** (scenes/room.toml, 128 × 64 px of 24.8 µm): the ``spectral`` path for bands_per_render
  1, 2, 4, 8, 30 (30 = all bands of 400:700:10 in one render). The spp of each render is chosen so
  that every bands_per_render line spends the same sample budget (renders × spp = 16, 64, 256):
  the lines then overlap in run time and can be compared at equal cost.

Error = relative L2 ‖x − ref‖₂ / ‖ref‖₂ over all bands and all pixels of the render grid (margin
included, the same norm as the renderer's ``noise_rel``). The reference is the mean of two renders
with other seeds (1 and 2) at high spp; its own noise, ‖h₁ − h₂‖ / (2 ‖ref‖), is subtracted in
quadrature (``rel_error_net`` = sqrt(rel_error² − ref_noise²)), so that rel_error_net estimates the
run's true error. ``err_over_noise`` = rel_error_net / noise_rel (the renderer's own noise
estimate, relative to the noise-free image like rel_error) is 1 for an unbiased run. ``rel_error_xyz``: the same on the CIE XYZ image (spectra.band_xyz), what a
trichromatic camera sees (colour noise between neighbouring bands averages out there).
``band_mean_dev`` = max over bands of |Σ x_k / Σ ref_k − 1|: a bias check (noise averages out over
the ~10⁵ pixels). The monitor's spectral runs are compared with the rgb_matrix reference: a bias
between the two paths shows up as an error floor and in band_mean_dev.

Time = the renderer's ``meta['seconds']`` (the whole render_scene call: scene set-up, every pass
and band group; no depth pass), median of 3 runs when a run takes under REPEAT_BELOW_S (the image
of a seed is bit-identical, so repeats only refine the time). Every series is preceded by an
untimed 2-spp render of the same settings so that Dr.Jit's kernels are compiled and cached
(the first compile of a new kernel costs about 0.6 s per band group; it is a one-time cost).

Outputs in DIR: study_render.csv (one row per run), study_render.md (tables, fits and the
recommended defaults derived from the data), study_render.png (error vs time, log-log, annotated
with spp) and study_render.json (the rows, fits and recommendations). Every file is written atomically.
``quick=True``: tiny images, 3 spp values and 2 bands_per_render values (a smoke test, < 40 s).
"""
from __future__ import annotations

import math
import os
import platform
import statistics
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from udc_render.content import spectra
from udc_render.io.files import csv_text, save_figure, save_json, save_text
from udc_render.render import render_scene
from udc_render.scene import scenes_dir, Scene, Sensor, load_scene

FULL_SENSOR = (2048, 1024, 1.55)  # the scene files' sensor, for the extrapolations
REPEAT_BELOW_S = 4.0
TARGETS = (0.05, 0.02, 0.01)

COLUMNS = ["scene", "path", "variant", "spp", "bands_per_render", "seconds", "rel_error", "noise_rel",
           "rel_error_net", "rel_error_xyz", "rel_error_xyz_net", "band_mean_dev", "err_over_noise",
           "role", "groups", "renders_x_spp", "sensor_px", "pitch_um", "grid_px", "seconds_min", "cpu_seconds",
           "repeats", "seed",
           "ref_spp", "ref_noise_rel", "ref_noise_xyz"]


@dataclass(frozen=True)
class Config:
    quick: bool
    repeats: int
    monitor_sensor: tuple  # (width_px, height_px, pitch_um)
    monitor_panel_px: tuple | None  # None: the scene's panel (3840 × 2160)
    rgb_spp: tuple
    rgb_ref_spp: int  # total over the two reference halves
    spectral_bpr: tuple
    spectral_spp: tuple
    room_sensor: tuple
    room_bpr: tuple
    room_budgets: tuple  # renders × spp per render, the same for every bands_per_render line
    room_ref_bpr: int
    room_ref_spp: int
    checks: bool  # resolution checks: noise_rel at higher resolution (no reference)


FULL = Config(quick=False, repeats=3, monitor_sensor=(512, 256, 6.2), monitor_panel_px=None,
              rgb_spp=(1, 2, 4, 8, 16, 32, 64, 128, 256), rgb_ref_spp=1024, spectral_bpr=(4, 30),
              spectral_spp=(2, 8, 32), room_sensor=(128, 64, 24.8), room_bpr=(1, 2, 4, 8, 30),
              room_budgets=(16, 64, 256), room_ref_bpr=2, room_ref_spp=128, checks=True)

QUICK = Config(quick=True, repeats=1, monitor_sensor=(128, 64, 24.8), monitor_panel_px=(960, 540),
               rgb_spp=(4, 16, 64), rgb_ref_spp=256, spectral_bpr=(30,), spectral_spp=(4, 16),
               room_sensor=(64, 32, 49.6), room_bpr=(8, 30), room_budgets=(8, 32, 128), room_ref_bpr=8,
               room_ref_spp=64, checks=False)


# ----------------------------------------------------------------------------------------------
# Scenes and metrics


def study_scenes(cfg: Config) -> dict[str, Scene]:
    """The monitor and room scene files at the study's reduced resolution (same physical sensor)."""
    mon = load_scene(scenes_dir() / "monitor.toml")
    mon = replace(mon, sensor=Sensor(*cfg.monitor_sensor)).with_render(depth=False)
    if cfg.monitor_panel_px is not None:
        mon = replace(mon, content=replace(mon.content, resolution_px=tuple(cfg.monitor_panel_px)))
    room = load_scene(scenes_dir() / "room.toml")
    room = replace(room, sensor=Sensor(*cfg.room_sensor)).with_render(depth=False, path="spectral")
    return {"monitor": mon, "room": room}


def n_groups(bands: int, bpr: int) -> int:
    return math.ceil(bands / bpr)


def budget_spp(budget: int, groups: int) -> int:
    """The power of two nearest (in log) to budget / groups, at least 1."""
    return max(1, 2 ** round(math.log2(budget / groups)))


def rel_l2(x: np.ndarray, ref: np.ndarray) -> float:
    x, ref = np.asarray(x, np.float64), np.asarray(ref, np.float64)
    return float(np.linalg.norm(x - ref) / np.linalg.norm(ref))


def net(err: float, floor: float) -> float:
    """err with an independent reference noise `floor` taken out in quadrature (0 if below it)."""
    return math.sqrt(max(err * err - floor * floor, 0.0))


class Reference:
    """Mean of two independent renders (seeds 1, 2); its noise from their difference."""

    def __init__(self, h1, h2, edges_nm):
        self.xyz_m = spectra.band_xyz(edges_nm)  # [3, K]
        a, b = h1.bands.astype(np.float64), h2.bands.astype(np.float64)
        self.bands = (a + b) / 2
        self.xyz = np.einsum("ck,khw->chw", self.xyz_m, self.bands)
        d = a - b
        self.noise = float(np.linalg.norm(d) / 2 / np.linalg.norm(self.bands))
        self.noise_xyz = float(np.linalg.norm(np.einsum("ck,khw->chw", self.xyz_m, d)) / 2 / np.linalg.norm(self.xyz))
        n1, n2 = h1.meta.get("noise_rel"), h2.meta.get("noise_rel")
        self.noise_from_meta = 0.5 * math.hypot(n1, n2) if n1 is not None and n2 is not None else None
        self.band_sums = self.bands.sum(axis=(1, 2))

    def compare(self, bands: np.ndarray) -> dict:
        x = bands.astype(np.float64)
        err = rel_l2(x, self.bands)
        exyz = rel_l2(np.einsum("ck,khw->chw", self.xyz_m, x), self.xyz)
        sums = x.sum(axis=(1, 2))
        ok = self.band_sums > 0
        dev = float(np.max(np.abs(sums[ok] / self.band_sums[ok] - 1))) if ok.any() else float("nan")
        return {"rel_error": err, "rel_error_net": net(err, self.noise), "rel_error_xyz": exyz,
                "rel_error_xyz_net": net(exyz, self.noise_xyz), "band_mean_dev": dev,
                "ref_noise_rel": self.noise, "ref_noise_xyz": self.noise_xyz}


# ----------------------------------------------------------------------------------------------
# The runs


@dataclass
class Run:
    scene: str
    path: str
    bpr: int | None  # None for rgb_matrix
    spp: int
    role: str  # sweep, reference, warmup, check
    seed: int = 0
    sensor: tuple | None = None  # override (checks)


def plan(cfg: Config, scenes: dict[str, Scene]) -> list[Run]:
    runs: list[Run] = []
    k = scenes["room"].bands.count
    runs.append(Run("monitor", "rgb_matrix", None, 2, "warmup"))
    runs += [Run("monitor", "rgb_matrix", None, cfg.rgb_ref_spp // 2, "reference", seed=s) for s in (1, 2)]
    runs += [Run("monitor", "rgb_matrix", None, spp, "sweep") for spp in cfg.rgb_spp]
    for bpr in cfg.spectral_bpr:
        runs.append(Run("monitor", "spectral", bpr, 2, "warmup"))
        runs += [Run("monitor", "spectral", bpr, spp, "sweep") for spp in cfg.spectral_spp]
    runs.append(Run("room", "spectral", cfg.room_ref_bpr, 2, "warmup"))
    runs += [Run("room", "spectral", cfg.room_ref_bpr, cfg.room_ref_spp // 2, "reference", seed=s) for s in (1, 2)]
    for bpr in cfg.room_bpr:
        if bpr != cfg.room_ref_bpr:
            runs.append(Run("room", "spectral", bpr, 2, "warmup"))
        g = n_groups(k, bpr)
        runs += [Run("room", "spectral", bpr, budget_spp(b, g), "sweep") for b in cfg.room_budgets]
    if cfg.checks:
        w, h, _ = FULL_SENSOR
        runs.append(Run("monitor", "rgb_matrix", None, 2, "warmup", sensor=FULL_SENSOR))
        runs.append(Run("monitor", "rgb_matrix", None, 16, "check", sensor=FULL_SENSOR))
        room_check = (w // 4, h // 4, FULL_SENSOR[2] * 4)
        runs.append(Run("room", "spectral", 30, 2, "warmup", sensor=room_check))
        runs.append(Run("room", "spectral", 30, 16, "check", sensor=room_check))
    return runs


def _scene_for(run: Run, scenes: dict[str, Scene]) -> Scene:
    s = scenes[run.scene]
    if run.sensor is not None:
        s = replace(s, sensor=Sensor(*run.sensor))
    changes = dict(spp=run.spp, noise=None, seed=run.seed, path=run.path)
    if run.bpr is not None:
        changes["bands_per_render"] = run.bpr
    return s.with_render(**changes)


def _timed(scene: Scene, repeats: int):
    """(first BandImage, wall seconds (meta) of every repeat, CPU seconds of this process, all threads)."""
    c0 = time.process_time()
    first = render_scene(scene, progress=False)
    times, cpu = [first.meta["seconds"]], [time.process_time() - c0]
    while len(times) < repeats and times[0] < REPEAT_BELOW_S:
        c0 = time.process_time()
        again = render_scene(scene, progress=False)
        times.append(again.meta["seconds"])
        cpu.append(time.process_time() - c0)
        del again
    return first, times, cpu


def run_study(out_dir, quick: bool = False, progress: bool = True) -> list[dict]:
    """Run the sweeps, write study_render.{csv,md,png,json} into out_dir and return the rows."""
    from tqdm.auto import tqdm

    cfg = QUICK if quick else FULL
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    load_start = os.getloadavg() if hasattr(os, "getloadavg") else None
    scenes = study_scenes(cfg)
    runs = plan(cfg, scenes)
    refs: dict[str, Reference] = {}
    halves: dict[str, list] = {}
    rows: list[dict] = []
    with tqdm(total=len(runs), disable=not progress, desc="study render", unit="run", dynamic_ncols=True) as bar:
        for run in runs:
            bar.set_postfix_str(f"{run.scene} {run.path} bpr={run.bpr} spp={run.spp} {run.role}")
            scene = _scene_for(run, scenes)
            repeats = cfg.repeats if run.role == "sweep" else 1
            b, times, cpu = _timed(scene, repeats)
            bar.update(1)
            if run.role == "warmup":
                continue
            if run.role == "reference":
                halves.setdefault(run.scene, []).append(b)
                if len(halves[run.scene]) == 2:
                    h1, h2 = halves.pop(run.scene)
                    refs[run.scene] = Reference(h1, h2, scene.bands.edges_nm)
                    ref_seconds = h1.meta["seconds"] + h2.meta["seconds"]
                    rows.append(_row(run, scene, b, [ref_seconds], []) | {
                        "spp": 2 * run.spp, "seed": "1+2", "noise_rel": refs[run.scene].noise,
                        "ref_noise_rel": refs[run.scene].noise, "ref_noise_xyz": refs[run.scene].noise_xyz,
                        "ref_noise_meta": refs[run.scene].noise_from_meta})
                continue
            row = _row(run, scene, b, times, cpu)
            if run.role == "sweep":
                row.update(refs[run.scene].compare(b.bands))
                row["ref_spp"] = 2 * (cfg.rgb_ref_spp // 2 if run.scene == "monitor" else cfg.room_ref_spp // 2)
                if row["noise_rel"]:
                    row["err_over_noise"] = row["rel_error_net"] / row["noise_rel"]
            rows.append(row)
            del b

    elapsed = time.perf_counter() - t_start
    analysis = analyse(rows, cfg, scenes)
    meta = {"elapsed_s": elapsed, "load_start": load_start,
            "load_end": os.getloadavg() if hasattr(os, "getloadavg") else None, "cfg": asdict(cfg),
            "variant_rgb": next((r["variant"] for r in rows if r["path"] == "rgb_matrix"), None),
            "variant_spectral": next((r["variant"] for r in rows if r["path"] == "spectral"), None),
            "grid": {name: _grid_px(s) for name, s in scenes.items()}}
    save_text(out_dir / "study_render.csv", csv_text(rows, COLUMNS))
    save_text(out_dir / "study_render.md", markdown(rows, analysis, meta, cfg))
    save_json(out_dir / "study_render.json", {"meta": meta, "analysis": analysis, "rows": rows})
    plot(rows, analysis, out_dir / "study_render.png", cfg)
    return rows


def _grid_px(scene: Scene) -> list[int]:
    from udc_render.scene.geometry import camera_geometry
    g = camera_geometry(scene)
    return [g.width_px, g.height_px]


def _row(run: Run, scene: Scene, b, times: list[float], cpu: list[float]) -> dict:
    gw, gh = b.bands.shape[2], b.bands.shape[1]
    k = scene.bands.count
    groups = 1 if run.path == "rgb_matrix" else n_groups(k, run.bpr)
    return {"scene": run.scene, "path": run.path, "variant": b.meta["variant"], "spp": b.meta["spp"],
            "bands_per_render": run.bpr if run.path == "spectral" else "", "seconds": statistics.median(times),
            "seconds_min": min(times), "cpu_seconds": statistics.median(cpu) if cpu else None,
            "repeats": len(times), "noise_rel": b.meta["noise_rel"], "role": run.role,
            "groups": groups, "renders_x_spp": groups * b.meta["spp"],
            "sensor_px": f"{scene.sensor.width_px}x{scene.sensor.height_px}", "pitch_um": scene.sensor.pitch_um,
            "grid_px": f"{gw}x{gh}", "grid_mpx": gw * gh / 1e6, "seed": run.seed}


# ----------------------------------------------------------------------------------------------
# Analysis: fits and recommendations


def _series_key(r: dict) -> tuple:
    return (r["scene"], r["path"], r["bands_per_render"])


def series_label(key: tuple) -> str:
    scene, path, bpr = key
    return f"{scene} {path}" + (f", {bpr} bands/render" if bpr != "" else "")


def fit_series(rs: list[dict], metric: str = "rel_error_net") -> dict:
    """Error ∝ spp^slope (free slope) and error = c / sqrt(spp) (fixed slope); time = a + b · spp."""
    out: dict = {"n": len(rs)}
    pts = [(r["spp"], r[metric]) for r in rs if r.get(metric)]
    if len(pts) >= 2:
        s, e = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
        out["slope"] = float(np.polyfit(s, e, 1)[0]) if np.ptp(s) > 0 else None
        out["c"] = float(np.exp(np.mean(e + 0.5 * s)))
    spp = np.array([r["spp"] for r in rs], float)
    if len(rs) >= 2 and np.ptp(spp) > 0:
        for col, (ka, kb) in (("seconds", ("a", "b")), ("cpu_seconds", ("a_cpu", "b_cpu"))):
            sec = np.array([r.get(col, np.nan) for r in rs], float)
            if np.all(np.isfinite(sec)):
                b, a = np.polyfit(spp, sec, 1)
                out[ka], out[kb] = float(max(a, 0.0)), float(max(b, 1e-9))
    return out


def spp_for(fit: dict, target: float) -> float | None:
    return (fit["c"] / target) ** 2 if fit.get("c") else None


def seconds_for(fit: dict, spp: float, scale: float = 1.0) -> float | None:
    """Fitted run time at `spp`, the per-spp cost scaled by `scale` (render-grid pixel ratio)."""
    if fit.get("b") is None or spp is None:
        return None
    return fit["a"] + fit["b"] * scale * spp


def _tk(t: float) -> str:
    """A target's key in the analysis dicts (JSON keys must be strings)."""
    return f"{t:g}"


def _pow2_at_least(x: float) -> int:
    return 1 if x <= 1 else 2 ** math.ceil(math.log2(x) - 1e-9)


def analyse(rows: list[dict], cfg: Config, scenes: dict[str, Scene]) -> dict:
    sweep = [r for r in rows if r["role"] == "sweep"]
    series: dict = {}
    for r in sweep:
        series.setdefault(_series_key(r), []).append(r)
    full_grid = {name: _grid_px(replace(s, sensor=Sensor(*FULL_SENSOR))) for name, s in scenes.items()}
    study_grid = {name: _grid_px(s) for name, s in scenes.items()}
    px = lambda wh: wh[0] * wh[1]  # noqa: E731
    scale = {name: px(full_grid[name]) / px(study_grid[name]) for name in scenes}
    fits = {}
    for key, rs in series.items():
        f, fx = fit_series(rs), fit_series(rs, "rel_error_xyz_net")
        fits[key] = {"label": series_label(key), "band": f, "xyz": fx, "groups": rs[0]["groups"],
                     "scale_to_full": scale[key[0]], "targets": {}}
        for t in TARGETS:
            entry = {}
            for name, fit, col in (("band", f, "rel_error_net"), ("xyz", fx, "rel_error_xyz_net")):
                spp = spp_for(fit, t)
                reached = [r for r in rs if r.get(col) is not None and r[col] <= t]
                entry[name] = {"spp_fit": spp, "seconds_fit": seconds_for(f, spp),
                               "smallest_spp_in_grid": min((r["spp"] for r in reached), default=None)}
            fits[key]["targets"][_tk(t)] = entry

    # Resolution checks: noise_rel at a higher resolution against the study's run at the same settings.
    checks = []
    for c in (r for r in rows if r["role"] == "check"):
        twin = next((r for r in sweep if _series_key(r) == _series_key(c) and r["spp"] == c["spp"]), None)
        w, h = (int(v) for v in c["grid_px"].split("x"))
        fit = fits.get(_series_key(c), {}).get("band", {})
        checks.append({"scene": c["scene"], "path": c["path"], "bands_per_render": c["bands_per_render"],
                       "spp": c["spp"], "groups": c["groups"], "sensor_px": c["sensor_px"], "grid_px": [w, h],
                       "noise_rel": c["noise_rel"], "seconds": c["seconds"],
                       "seconds_pred": seconds_for(fit, c["spp"], w * h / px(study_grid[c["scene"]])),
                       "study_noise_rel": twin["noise_rel"] if twin else None,
                       "noise_factor": (c["noise_rel"] / twin["noise_rel"])
                       if twin and twin["noise_rel"] and c["noise_rel"] else None})

    def check(scene):
        return next((c for c in checks if c["scene"] == scene and c["noise_factor"]), None)

    rec: dict = {}
    # Monitor: rgb_matrix spp for 2 % and 1 %, at study resolution and at the full sensor.
    rgb = fits.get(("monitor", "rgb_matrix", ""))
    if rgb and rgb["band"].get("c") and rgb["band"].get("b") is not None:
        chk = check("monitor")
        fct = chk["noise_factor"] if chk else 1.0
        a = rgb["band"]["a"]
        if chk:  # full-size time per spp from the full-size run itself
            per_spp_full = max(chk["seconds"] - a, 0.0) / chk["spp"] * px(full_grid["monitor"]) / px(chk["grid_px"])
        else:
            per_spp_full = rgb["band"]["b"] * rgb["scale_to_full"]
        m = {"noise_factor_full": chk["noise_factor"] if chk else None, "setup_s": a, "per_spp_full_s": per_spp_full}
        for t in (0.02, 0.01):
            spp_full = spp_for({"c": rgb["band"]["c"] * fct}, t)
            m[_tk(t)] = {"spp_study_fit": spp_for(rgb["band"], t),
                         "smallest_spp_in_grid": rgb["targets"][_tk(t)]["band"]["smallest_spp_in_grid"],
                         "spp_full_est": spp_full, "spp_full_pow2": _pow2_at_least(spp_full),
                         "seconds_full_est": a + per_spp_full * _pow2_at_least(spp_full)}
        m["recommended_spp"] = m["0.01"]["spp_full_pow2"]
        m["recommended_error_full"] = rgb["band"]["c"] * fct / math.sqrt(m["recommended_spp"])
        rec["monitor"] = m
        # rgb_matrix vs spectral: run time per spp, and at equal error (asymptotic b · c², set-up excluded).
        def cost(fit, c, b="b"):  # time per unit 1/error²
            return fit["band"][b] * fit[c]["c"] ** 2 if fit["band"].get(b) and fit[c].get("c") else None

        def ratio(x, y):
            return x / y if x is not None and y else None

        ratios = []
        for key, f in fits.items():
            if key[0] == "monitor" and key[1] == "spectral" and f["band"].get("c") and f["band"].get("b"):
                top = max(series[key], key=lambda r: r["spp"])
                same = next((r for r in series[("monitor", "rgb_matrix", "")] if r["spp"] == top["spp"]), None)
                ratios.append({
                    "bands_per_render": key[2],
                    "seconds_ratio_same_spp": top["seconds"] / same["seconds"] if same else None,
                    "per_spp_cost_ratio": ratio(f["band"]["b"], rgb["band"]["b"]),
                    "per_spp_cost_ratio_cpu": ratio(f["band"].get("b_cpu"), rgb["band"].get("b_cpu")),
                    "equal_error_cost_ratio": ratio(cost(f, "band"), cost(rgb, "band")),
                    "equal_error_cost_ratio_xyz": ratio(cost(f, "xyz"), cost(rgb, "xyz")),
                    "equal_error_cost_ratio_cpu": ratio(cost(f, "band", "b_cpu"), cost(rgb, "band", "b_cpu")),
                    "equal_error_cost_ratio_xyz_cpu": ratio(cost(f, "xyz", "b_cpu"), cost(rgb, "xyz", "b_cpu")),
                    "max_spp": top["spp"], "rel_error_net_at_max_spp": top["rel_error_net"],
                    "noise_rel_at_max_spp": top["noise_rel"], "err_over_noise_at_max_spp": top.get("err_over_noise"),
                    "band_mean_dev_at_max_spp": top["band_mean_dev"]})
        rec["monitor_spectral_vs_rgb"] = ratios
    # Room: samples (renders × spp) needed per unit 1/error² for each bands_per_render, per band and on XYZ.
    room = {key: f for key, f in fits.items() if key[0] == "room" and f["band"].get("c") and f["xyz"].get("c")}
    if room:
        chk = check("room")
        fct = chk["noise_factor"] if chk else 1.0
        table = []
        for key, f in sorted(room.items(), key=lambda kv: kv[0][2]):
            g = f["groups"]
            table.append({"bands_per_render": key[2], "groups": g, "slope": f["band"].get("slope"),
                          "slope_xyz": f["xyz"].get("slope"), "c": f["band"]["c"], "c_xyz": f["xyz"]["c"],
                          "samples_band": g * f["band"]["c"] ** 2, "samples_xyz": g * f["xyz"]["c"] ** 2,
                          "time_band": f["band"].get("b_cpu", 0) * f["band"]["c"] ** 2,
                          "time_xyz": f["band"].get("b_cpu", 0) * f["xyz"]["c"] ** 2,
                          "render_spp_s": f["band"].get("b", 0) / g})
        for m in ("band", "xyz"):
            lo = min(e[f"samples_{m}"] for e in table)
            lo_t = min(e[f"time_{m}"] for e in table)
            for e in table:
                e[f"samples_{m}_rel"] = e[f"samples_{m}"] / lo
                e[f"time_{m}_rel"] = e[f"time_{m}"] / lo_t
        best_band = min(table, key=lambda e: e["samples_band"])
        best_xyz = min(table, key=lambda e: e["samples_xyz"])
        if chk:  # seconds per render × spp at full size, from the larger check render
            rs_full = chk["seconds"] / (chk["groups"] * chk["spp"]) * px(full_grid["room"]) / px(chk["grid_px"])
        else:
            rs_full = best_xyz["render_spp_s"] * scale["room"]
        r = {"noise_factor_full": chk["noise_factor"] if chk else None, "table": table,
             "fastest_bpr_band": best_band["bands_per_render"], "fastest_bpr_xyz": best_xyz["bands_per_render"],
             "render_spp_full_s": rs_full, "recommended_bpr": best_xyz["bands_per_render"]}

        def predict(e, spp):
            return {"spp": spp, "band_error": e["c"] * fct / math.sqrt(spp),
                    "xyz_error": e["c_xyz"] * fct / math.sqrt(spp), "seconds_full": e["groups"] * spp * rs_full}
        for t in (0.05, 0.02):
            r[f"xyz_{_tk(t)}"] = predict(best_xyz, _pow2_at_least((best_xyz["c_xyz"] * fct / t) ** 2))
        r["recommended_spp"] = r["xyz_0.05"]["spp"]
        default = scenes["room"].render
        e_def = next((e for e in table if e["bands_per_render"] == default.bands_per_render), None)
        if e_def and default.spp:
            r["scene_default"] = {"bands_per_render": default.bands_per_render, **predict(e_def, default.spp)}
        r["per_band_best"] = {"bands_per_render": best_band["bands_per_render"],
                              **predict(best_band, _pow2_at_least((best_band["c"] * fct / 0.05) ** 2))}
        rec["room"] = r
    return {"fits": {series_label(k): v for k, v in fits.items()}, "checks": checks, "recommend": rec,
            "full_grid_px": full_grid, "study_grid_px": study_grid}


# ----------------------------------------------------------------------------------------------
# Output


def _g(v, digits=3) -> str:
    if v is None or v == "":
        return ""
    if isinstance(v, (float, np.floating)):
        if not math.isfinite(v):
            return str(v)
        return f"{v:.{digits}g}"
    return str(v)


def _pct(v) -> str:
    return "" if v is None or v == "" else f"{100 * v:.3g} %"


def _table(rows: list[dict], cols: list[tuple[str, str]], fmt=None) -> list[str]:
    fmt = fmt or {}
    out = ["| " + " | ".join(h for _, h in cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for r in rows:
        out.append("| " + " | ".join(fmt.get(k, _g)(r.get(k)) for k, _ in cols) + " |")
    return out


def _duration(s) -> str:
    if s is None:
        return "?"
    if s < 90:
        return f"{s:.2g} s"
    if s < 5400:
        return f"{s / 60:.2g} min"
    return f"{s / 3600:.2g} h"


def markdown(rows: list[dict], an: dict, meta: dict, cfg: Config) -> str:
    la, lb = meta["load_start"], meta["load_end"]
    mon_w, mon_h, mon_p = cfg.monitor_sensor
    room_w, room_h, room_p = cfg.room_sensor
    grid = an["study_grid_px"]
    full = an["full_grid_px"]
    ref = {r["scene"]: r for r in rows if r["role"] == "reference"}
    lines = [
        "# Rendering: error versus run time (spp, render path, bands per render)",
        "",
        ("QUICK smoke-test grid (not for decisions). " if cfg.quick else "")
        + f"Total study time {meta['elapsed_s']:.0f} s on {os.cpu_count()} CPU cores "
        f"({platform.processor() or platform.machine()})"
        + (f"; load average {la[0]:.1f} at start, {lb[0]:.1f} at end (a shared machine: times are noisy, read "
           "them as ratios)." if la else "."),
        f"Variants: {meta['variant_rgb']} (rgb_matrix), {meta['variant_spectral']} (spectral).",
        "",
        f"Scenes: scenes/monitor.toml with the sensor at {mon_w} × {mon_h} px of {mon_p:g} µm "
        f"(render grid with margin {grid['monitor'][0]} × {grid['monitor'][1]})"
        + (f", panel reduced to {cfg.monitor_panel_px[0]} × {cfg.monitor_panel_px[1]}" if cfg.monitor_panel_px else "")
        + f"; scenes/room.toml at {room_w} × {room_h} px of {room_p:g} µm (grid {grid['room'][0]} × "
        f"{grid['room'][1]}), no depth pass. The same physical sensor as the full {FULL_SENSOR[0]} × "
        f"{FULL_SENSOR[1]} px of {FULL_SENSOR[2]} µm (grid {full['monitor'][0]} × {full['monitor'][1]}), "
        "so the framing is unchanged.",
        "",
        "**rel_error** = ‖x − ref‖₂ / ‖ref‖₂ over all 30 bands and all grid pixels (margin included). "
        "**rel_error_net** = sqrt(rel_error² − ref_noise²): the reference's own noise taken out. "
        "**noise_rel**: the run's own noise estimate (spread of its passes, the renderer's meta; none at 1 spp); "
        "relative to the noise-free image, like rel_error. "
        "err/noise = rel_error_net / noise_rel: 1 when the error is all noise, above 1 with a bias. "
        "**rel_error_xyz**: the same error on the CIE XYZ image (bands weighted by the colour-matching "
        "functions), what a three-channel camera sees. band_mean_dev = max over bands of "
        "|Σ x_k / Σ ref_k − 1| (bias check). seconds = the renderer's meta['seconds'] for the whole "
        f"render_scene call (set-up included), median of up to {cfg.repeats} runs when under "
        f"{REPEAT_BELOW_S:g} s; kernels warmed by an untimed 2-spp render of each series. CPU s = this process's "
        "CPU time over the same call (all threads: about 2× the wall time while both cores render; less "
        "sensitive than wall time to other processes on the machine, so the cost ratios below use it).",
        "",
        "References (mean of two renders with seeds 1 and 2; ref_noise from their difference, noise_meta "
        "from the halves' own noise_rel):",
        "",
    ]
    for name, r in ref.items():
        bpr = f", {r['bands_per_render']} bands per render" if r["bands_per_render"] != "" else ""
        meta_n = r.get("ref_noise_meta")
        lines.append(f"- {name}: {r['path']}{bpr}, {r['spp']} spp in all, {r['seconds']:.1f} s; "
                     f"ref_noise {_pct(r['ref_noise_rel'])} (bands), {_pct(r['ref_noise_xyz'])} (XYZ)"
                     + (f"; noise_meta {_pct(meta_n)}" if meta_n else "") + ".")
    lines.append("")
    cols = [("spp", "spp"), ("seconds", "seconds"), ("cpu_seconds", "CPU s"), ("rel_error", "rel_error"),
            ("rel_error_net", "rel_error_net"), ("noise_rel", "noise_rel"),
            ("err_over_noise", "err/noise"), ("rel_error_xyz", "rel_error_xyz"),
            ("rel_error_xyz_net", "xyz_net"), ("band_mean_dev", "band_mean_dev"), ("repeats", "repeats")]
    pct = {k: _pct for k in ("rel_error", "rel_error_net", "noise_rel", "rel_error_xyz",
                             "rel_error_xyz_net", "band_mean_dev")}
    sweep = [r for r in rows if r["role"] == "sweep"]
    lines += ["## Monitor, rgb_matrix path", ""]
    lines += _table([r for r in sweep if r["scene"] == "monitor" and r["path"] == "rgb_matrix"], cols, pct)
    lines += ["", "## Monitor, spectral path (against the rgb_matrix reference)", ""]
    lines += _table([r for r in sweep if r["scene"] == "monitor" and r["path"] == "spectral"],
                    [("bands_per_render", "bands/render"), ("groups", "renders")] + cols, pct)
    lines += ["", "## Room, spectral path", "",
              "Each bands_per_render line spends the same budget renders × spp (columns 'renders', 'spp'), "
              f"{', '.join(str(b) for b in cfg.room_budgets)} (spp rounded to a power of two).", ""]
    lines += _table([r for r in sweep if r["scene"] == "room"],
                    [("bands_per_render", "bands/render"), ("groups", "renders"), ("renders_x_spp", "renders×spp")]
                    + cols, pct)
    lines += ["", "## Fits", "",
              "Per line: error ∝ spp^slope (least squares in log-log; −0.5 for pure Monte Carlo noise), "
              "c = error · sqrt(spp) (slope fixed at −1/2, geometric mean), wall time = a + b · spp (b_cpu: "
              "the same fit on CPU time). Cost at equal error ∝ b · c².", ""]
    fit_rows = []
    for label, f in an["fits"].items():
        fit_rows.append({"line": label, "slope": f["band"].get("slope"), "c": f["band"].get("c"),
                         "slope_xyz": f["xyz"].get("slope"), "c_xyz": f["xyz"].get("c"), "a": f["band"].get("a"),
                         "b": f["band"].get("b"), "b_cpu": f["band"].get("b_cpu"),
                         "spp2": f["targets"]["0.02"]["band"]["spp_fit"],
                         "spp1": f["targets"]["0.01"]["band"]["spp_fit"],
                         "s2": f["targets"]["0.02"]["band"]["seconds_fit"]})
    lines += _table(fit_rows, [("line", "line"), ("slope", "slope"), ("c", "c"), ("slope_xyz", "slope (XYZ)"),
                               ("c_xyz", "c (XYZ)"), ("a", "a (s)"), ("b", "b (s/spp)"), ("b_cpu", "b_cpu (CPU s/spp)"),
                               ("spp2", "spp for 2 %"), ("spp1", "spp for 1 %"), ("s2", "seconds for 2 %")])
    if an["checks"]:
        lines += ["", "## Resolution checks (noise_rel only: no reference at that size)", ""]
        lines += _table(an["checks"], [("scene", "scene"), ("path", "path"), ("bands_per_render", "bands/render"),
                                       ("spp", "spp"), ("sensor_px", "sensor"), ("seconds", "seconds"),
                                       ("seconds_pred", "seconds predicted"),
                                       ("noise_rel", "noise_rel"), ("study_noise_rel", "study noise_rel"),
                                       ("noise_factor", "factor")],
                        {"noise_rel": _pct, "study_noise_rel": _pct})
        lines += ["", "factor = noise at the higher resolution / noise at the study's resolution, same spp: "
                  "used below to carry the study's spp over to the full sensor. seconds predicted = the "
                  "study's fit a + b · spp with b scaled by the render grid's pixel count (the rule used for "
                  "the full-size times below)."]
    lines += ["", "## Recommended defaults (derived from the data above)", ""]
    lines += _recommendations(an, cfg)
    return "\n".join(lines) + "\n"


def _recommendations(an: dict, cfg: Config) -> list[str]:
    rec = an["recommend"]
    out = []
    m = rec.get("monitor")
    if m:
        f = m.get("noise_factor_full")
        out.append(
            f"- **Monitor (rgb_matrix): spp = {m['recommended_spp']}** (the smallest power of two reaching 1 % "
            f"at the full sensor: ≈ {_pct(m['recommended_error_full'])}, ≈ {_duration(m['0.01']['seconds_full_est'])}). "
            f"In the study ({cfg.monitor_sensor[0]} × {cfg.monitor_sensor[1]} px) the smallest spp of the grid "
            f"reaching 2 % is {m['0.02']['smallest_spp_in_grid'] or 'none'} and 1 %: "
            f"{m['0.01']['smallest_spp_in_grid'] or 'none'} (fit: {_g(m['0.02']['spp_study_fit'])} and "
            f"{_g(m['0.01']['spp_study_fit'])} spp). "
            + (f"At the full sensor the noise at equal spp is {f:.2f}× the study's (resolution check: each pixel "
               f"covers fewer panel pixels, so less of the image's detail is averaged by Monte Carlo), so 2 % needs "
               f"≈ {_g(m['0.02']['spp_full_est'])} spp and 1 % ≈ {_g(m['0.01']['spp_full_est'])} spp. "
               if f else "Without a resolution check the study's spp is used as is. ")
            + f"Time at full size: ≈ {m['setup_s']:.1f} s of scene set-up (panel image, primaries) + "
            f"{m['per_spp_full_s']:.2g} s per spp.")
    for r in rec.get("monitor_spectral_vs_rgb", []):
        same = (f"{r['seconds_ratio_same_spp']:.2g}× the wall time at {r['max_spp']} spp (set-up included), "
                if r.get("seconds_ratio_same_spp") else "")
        if r.get("equal_error_cost_ratio_cpu"):
            cost = (f"{r['per_spp_cost_ratio_cpu']:.0f}× the CPU time per additional spp (wall: "
                    f"{r['per_spp_cost_ratio']:.0f}×); **at equal per-band error {r['equal_error_cost_ratio_cpu']:.0f}×** "
                    f"(wall: {r['equal_error_cost_ratio']:.0f}×)"
                    + (f", on the XYZ image {r['equal_error_cost_ratio_xyz_cpu']:.0f}×"
                       if r.get("equal_error_cost_ratio_xyz_cpu") else ""))
        else:
            cost = (f"{r['per_spp_cost_ratio']:.0f}× per additional spp; **at equal per-band error "
                    f"{r['equal_error_cost_ratio']:.0f}×**")
        out.append(
            f"- **Monitor, spectral vs rgb_matrix** ({r['bands_per_render']} bands per render): {same}{cost} "
            f"(fitted b · c², set-up excluded). At {r['max_spp']} spp its error against the rgb_matrix "
            f"reference is {_pct(r['rel_error_net_at_max_spp'])}, err/noise {_g(r.get('err_over_noise_at_max_spp'))}, "
            f"band means within {_pct(r['band_mean_dev_at_max_spp'])}: no bias between the paths is visible. "
            "Keep path = auto (rgb_matrix) for the monitor alone.")
    room = rec.get("room")
    if room:
        t = room["table"]
        per_band = ", ".join(f"{e['bands_per_render']}: {e['samples_band_rel']:.2g}" for e in t)
        per_xyz = ", ".join(f"{e['bands_per_render']}: {e['samples_xyz_rel']:.2g}" for e in t)
        time_band = ", ".join(f"{e['bands_per_render']}: {e['time_band_rel']:.2g}" for e in t)
        time_xyz = ", ".join(f"{e['bands_per_render']}: {e['time_xyz_rel']:.2g}" for e in t)
        f = room.get("noise_factor_full")
        x5, x2 = room["xyz_0.05"], room["xyz_0.02"]
        out.append(
            f"- **Room: bands_per_render = {room['recommended_bpr']}** (the cheapest at equal error on the XYZ "
            f"image, i.e. for what a camera records). Samples (renders × spp) needed for equal error, relative to "
            f"the cheapest — per band: {per_band}; on XYZ: {per_xyz}. CPU time at equal error "
            f"(b_cpu · c², study size, per-render overheads included) — per band: {time_band}; on XYZ: {time_xyz}. "
            f"Per band, {room['fastest_bpr_band']} bands per render is cheapest: a render's 4 wavelengths per "
            "path then all land in its few bands; with all bands in one render a band gets a wavelength on only "
            "a few paths, but every path covers the whole spectrum, which is what the camera's broad channels "
            f"integrate. If per-band images are the product, use {room['fastest_bpr_band']}.")
        d = room.get("scene_default")
        out.append(
            f"- **Room spp = {room['recommended_spp']}** (with {room['recommended_bpr']} bands per render: the "
            f"smallest power of two reaching 5 % on XYZ at the full sensor"
            + (f", noise factor {f:.2f} from the resolution check" if f else "")
            + f"): XYZ ≈ {_pct(x5['xyz_error'])}, per band ≈ {_pct(x5['band_error'])}, ≈ "
            f"{_duration(x5['seconds_full'])} at 2048 × 1024 ({room['render_spp_full_s']:.2g} s per render × spp "
            f"there). 2 % on XYZ needs {x2['spp']} spp (≈ {_duration(x2['seconds_full'])}). "
            + (f"The scene file's current {d['bands_per_render']} bands per render × {d['spp']} spp gives XYZ ≈ "
               f"{_pct(d['xyz_error'])}, per band ≈ {_pct(d['band_error'])} in ≈ {_duration(d['seconds_full'])}. "
               if d else "")
            + f"Per band, 5 % needs {room['per_band_best']['spp']} spp with {room['per_band_best']['bands_per_render']} "
            f"bands per render (≈ {_duration(room['per_band_best']['seconds_full'])}). Noise falls as 1/sqrt(spp) "
            "and a 3D scene costs hours at 2048 × 1024 on 2 cores for per-band errors of a few %: pick spp by "
            "the time available, or use render.noise (spp from pilot renders).")
    return out or ["(not enough data)"]


def plot(rows: list[dict], an: dict, path: Path, cfg: Config) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    sweep = [r for r in rows if r["role"] == "sweep"]
    panels = [("monitor", "rel_error_net", "monitor: per-band error"),
              ("room", "rel_error_net", "room: per-band error"),
              ("room", "rel_error_xyz_net", "room: XYZ error")]
    fig, axes = plt.subplots(1, 3, figsize=(18, 5.5))
    for ax, (scene, metric, title) in zip(axes, panels):
        series: dict = {}
        for r in sweep:
            if r["scene"] == scene:
                series.setdefault(_series_key(r), []).append(r)
        for key, rs in series.items():
            pts = [(r["seconds"], r[metric], r["spp"]) for r in rs if r.get(metric)]
            if not pts:
                continue
            line, = ax.loglog([p[0] for p in pts], [p[1] for p in pts], marker="o", ms=5, lw=1.2,
                              label=series_label(key).replace(f"{scene} ", ""))
            for t, e, spp in pts:
                ax.annotate(str(spp), (t, e), textcoords="offset points", xytext=(4, 3), fontsize=7,
                            color=line.get_color())
        ref = next((r for r in rows if r["role"] == "reference" and r["scene"] == scene), None)
        if ref:
            floor = ref["ref_noise_xyz"] if metric == "rel_error_xyz_net" else ref["ref_noise_rel"]
            ax.axhline(floor, color="k", ls=":", lw=0.8, label=f"reference noise ({_pct(floor)}, subtracted)")
        for t in (0.02, 0.01):
            ax.axhline(t, color="grey", ls="--", lw=0.6)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_title(title + " (labels: spp)", fontsize=10)
        ax.set_xlabel("run time (s, render_scene, median)")
        ax.set_ylabel("relative L2 error, reference noise removed")
        ax.grid(True, which="both", alpha=0.25)
        ax.legend(fontsize=7, loc="best")
    fig.suptitle(("QUICK grid — " if cfg.quick else "") + "Rendering: error vs run time (dashed: 2 % and 1 %)",
                 fontsize=12)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
