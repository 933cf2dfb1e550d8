"""Error-versus-run-time study of the renderer's knobs: samples per pixel, Mitsuba's sampler, render path,
bands per render.

    udc-render study render --out DIR [--quick]

Two scenes at reduced resolution, same framing as the full 2048 × 1024 × 1.55 µm sensor (the
sensor's physical size is kept: fewer, larger pixels):

- **monitor** (scenes/monitor.toml, 512 × 256 px of 6.2 µm). Reference: the ``analytic`` path (the
  exact pixel-area means of the panel, render.analytic: noise 0), whose row gives its run time (error 0
  by construction). That it is exact is checked, not assumed: an ``exact_check`` row compares an
  ldsampler rgb_matrix render at high spp with it (error / that render's own noise ≈ 1). The
  ``rgb_matrix`` path (Mitsuba) is swept over spp for every sampler (render.sampler: independent
  1, 2, 4, …, 256; stratified, multijitter, orthogonal, ldsampler 8, 32, 128, 512 requested, which
  are exact counts for all but orthogonal), and the ``spectral`` path (independent sampler, the panel
  texture) at a few spp with 4 and 30 bands per render. At the **full** 2048 × 1024 frame, where the
  analytic reference costs a second, every sampler is also run at 8, 32, 128 spp (role ``full``):
  the monitor's sampler table (time to 1 % and 0.1 %) is read from these runs.
- **room** (scenes/room.toml, 128 × 64 px of 24.8 µm): the ``spectral`` path for bands_per_render
  1, 2, 4, 8, 30 (30 = all bands of 400:700:10 in one render) with the independent sampler, and every
  other sampler at the scene's 30 bands per render. The spp of each render is chosen so that every
  line spends the same sample budget (renders × spp = 16, 64, 256): the lines then overlap in run
  time and can be compared at equal cost. Samplers round their counts up (ldsampler to a power of 4 per
  pass: a 3D pass has at most 8 spp, so ldsampler renders 16 per pass, twice the request); the rows
  record the spp rendered and the spp requested.

Error = relative L2 ‖x − ref‖₂ / ‖ref‖₂ over all bands and all pixels of the render grid (margin
included, the same norm as the renderer's ``noise_rel``). The room's reference is the mean of two
renders with other seeds (1 and 2, independent sampler) at high spp; its own noise,
‖h₁ − h₂‖ / (2 ‖ref‖), is subtracted in quadrature (``rel_error_net`` = sqrt(rel_error² −
ref_noise²)), so that rel_error_net estimates the run's true error (the monitor's reference has no
noise: rel_error_net = rel_error). ``err_over_noise`` = rel_error_net / noise_rel (the renderer's own
noise estimate from the spread of its passes, relative to the noise-free image like rel_error) is 1 for
an unbiased run whose noise estimate is honest, whatever the sampler.
``rel_error_xyz``: the same on the CIE XYZ image (spectra.band_xyz), what a trichromatic camera
sees (colour noise between neighbouring bands averages out there).
``band_mean_dev`` = max over bands of |Σ x_k / Σ ref_k − 1|: a bias check (noise averages out over
the ~10⁵ pixels). The monitor's spectral runs are compared with the analytic reference too: a bias
between the paths shows up as an error floor and in band_mean_dev.

Correlated samplers converge faster than 1/√spp, so the time to reach a target error is read from the
measured points: log-log interpolation between the two runs that bracket the target, and only beyond
the last run an extrapolation along the local slope through the series' last two points (its errors are
norms over 10⁵–10⁶ values: precise) and the time fit a + b · spp (render_analysis.time_to; the tables say
which). The recommended sampler is the one reaching the
targets in the least time (render_analysis.sampler_tables).

What the committed run (docs/figures/render/) found: the pass noise estimate is honest for every sampler
(err_over_noise 0.97–1.03); on the monitor's rgb_matrix path the correlated samplers converge as
spp^−0.75 (stratified) to spp^−1 (multijitter, orthogonal, ldsampler) within a pass, and at 2048 × 1024
reach 0.1 % in ~20 s of CPU (multijitter, ldsampler) against ~7 min for independent; in the room every
sampler falls as spp^−0.5 (a 3D pass holds at most 8 spp) but the stratified ones start lower, and
multijitter reaches the room's targets in the least CPU time (ldsampler the most: its 8-spp passes are
rounded up to 16 samples that buy nothing per band). Hence render.sampler = "multijitter" by default;
the monitor alone renders by the analytic path.

Time = the renderer's ``meta['seconds']`` (the whole render_scene call: scene set-up, every pass
and band group; no depth pass), median of 3 runs when a run takes under REPEAT_BELOW_S (the image
of a seed is bit-identical, so repeats only refine the time). Every series is preceded by an
untimed 2-spp render of the same settings so that Dr.Jit's kernels are compiled and cached
(the first compile of a new kernel costs about 0.6 s per band group; it is a one-time cost).

Outputs in DIR: study_render.csv (one row per run), study_render.md (tables, fits, the sampler tables
and the recommended defaults derived from the data), study_render.png (error vs CPU time, log-log,
annotated with spp, one line per scene, path and sampler) and study_render.json (the rows, fits and
recommendations). Every file is written atomically.
``quick=True``: tiny images, two samplers (independent, ldsampler), 3 spp values and 2 bands_per_render
values, no full-frame runs (a smoke test, well under a minute).
The grids: render_config.py; the fits and recommendations: render_analysis.py; the outputs:
render_report.py.
"""
from __future__ import annotations

import math
import statistics
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from udc_render.content import spectra
from udc_render.render import render_scene
from udc_render.scene import Scene, Sensor
from udc_render.studies.render_analysis import analyse
from udc_render.studies.render_config import FULL, FULL_SENSOR, QUICK, REPEAT_BELOW_S, Config, grid_px, study_scenes
from udc_render.studies.render_report import write_report
from udc_render.studies.report import load_average, timed

# ----------------------------------------------------------------------------------------------
# Metrics


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
    """Mean of two independent renders h1, h2 (seeds 1, 2), its noise from their difference; with
    h2 = None the exact image h1 (the analytic render), noise 0."""

    def __init__(self, h1, h2, edges_nm):
        self.xyz_m = spectra.band_xyz(edges_nm)  # [3, K]
        self.path = h1.meta.get("render_path")
        if h2 is None:
            self.bands = h1.bands.astype(np.float64)
            self.xyz = np.einsum("ck,khw->chw", self.xyz_m, self.bands)
            self.noise = self.noise_xyz = 0.0
            self.noise_from_meta = h1.meta.get("noise_rel")
            self.spp = None
        else:
            a, b = h1.bands.astype(np.float64), h2.bands.astype(np.float64)
            self.bands = (a + b) / 2
            self.xyz = np.einsum("ck,khw->chw", self.xyz_m, self.bands)
            d = a - b
            self.noise = float(np.linalg.norm(d) / 2 / np.linalg.norm(self.bands))
            self.noise_xyz = float(np.linalg.norm(np.einsum("ck,khw->chw", self.xyz_m, d)) / 2
                                   / np.linalg.norm(self.xyz))
            n1, n2 = h1.meta.get("noise_rel"), h2.meta.get("noise_rel")
            self.noise_from_meta = 0.5 * math.hypot(n1, n2) if n1 is not None and n2 is not None else None
            self.spp = (h1.meta.get("spp") or 0) + (h2.meta.get("spp") or 0)
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
                "ref_noise_rel": self.noise, "ref_noise_xyz": self.noise_xyz, "ref_path": self.path,
                "ref_spp": self.spp if self.spp else ""}


# ----------------------------------------------------------------------------------------------
# The runs


@dataclass
class Run:
    scene: str
    path: str
    bpr: int | None  # None for rgb_matrix and analytic
    spp: int  # requested (0 for analytic)
    role: str  # warmup, reference, exact_check, sweep, full (full-frame sweep), check (resolution)
    seed: int = 0
    sensor: tuple | None = None  # override (full-frame runs, checks)
    sampler: str = "independent"


def _warm(run: Run) -> list[Run]:
    """An untimed 2-spp render with run's settings, then run."""
    return [replace(run, spp=2, role="warmup", seed=0), run]


def plan(cfg: Config, scenes: dict[str, Scene]) -> list[Run]:
    """Every render in order: the references first, per series an untimed 2-spp warm-up, then the sweep."""
    runs: list[Run] = []
    k = scenes["room"].bands.count
    # monitor: the exact reference (timed like a sweep run), its check, the rgb_matrix sampler sweeps
    runs += _warm(Run("monitor", "analytic", None, 0, "reference"))
    runs += _warm(Run("monitor", "rgb_matrix", None, cfg.exact_check_spp, "exact_check", seed=1, sampler="ldsampler"))
    for smp in cfg.samplers:
        spps = cfg.rgb_spp if smp == "independent" else cfg.rgb_sampler_spp
        runs += _warm(Run("monitor", "rgb_matrix", None, spps[0], "sweep", sampler=smp))
        runs += [Run("monitor", "rgb_matrix", None, spp, "sweep", sampler=smp) for spp in spps[1:]]
    for bpr in cfg.spectral_bpr:
        runs += _warm(Run("monitor", "spectral", bpr, cfg.spectral_spp[0], "sweep"))
        runs += [Run("monitor", "spectral", bpr, spp, "sweep") for spp in cfg.spectral_spp[1:]]
    # room: the two-half reference, the bands_per_render lines (independent), the samplers at the scene's bpr
    runs.append(Run("room", "spectral", cfg.room_ref_bpr, 2, "warmup"))
    runs += [Run("room", "spectral", cfg.room_ref_bpr, cfg.room_ref_spp // 2, "reference", seed=s) for s in (1, 2)]
    bpr0 = scenes["room"].render.bands_per_render
    lines = [(bpr, "independent") for bpr in cfg.room_bpr]
    lines += [(bpr0, s) for s in cfg.samplers if (bpr0, s) not in {(b, "independent") for b in cfg.room_bpr}]
    for bpr, smp in lines:
        g = n_groups(k, bpr)
        spps = [budget_spp(b, g) for b in cfg.room_budgets]
        if bpr != cfg.room_ref_bpr or smp != "independent":
            runs.append(Run("room", "spectral", bpr, 2, "warmup", sampler=smp))
        runs += [Run("room", "spectral", bpr, spp, "sweep", sampler=smp) for spp in spps]
    # monitor at the full frame: its analytic reference, every sampler against it
    if cfg.full_spp:
        runs += _warm(Run("monitor", "analytic", None, 0, "reference", sensor=FULL_SENSOR))
        for smp in cfg.samplers:
            runs += _warm(Run("monitor", "rgb_matrix", None, cfg.full_spp[0], "full", sensor=FULL_SENSOR, sampler=smp))
            runs += [Run("monitor", "rgb_matrix", None, spp, "full", sensor=FULL_SENSOR, sampler=smp)
                     for spp in cfg.full_spp[1:]]
    if cfg.checks:  # the room's noise at 4× the resolution (16× the pixels), per sampler
        w, h, p = FULL_SENSOR
        room_check = (w // 4, h // 4, p * 4)
        for smp in cfg.samplers:
            runs += _warm(Run("room", "spectral", bpr0, 16, "check", sensor=room_check, sampler=smp))
    return runs


def _scene_for(run: Run, scenes: dict[str, Scene]) -> Scene:
    s = scenes[run.scene]
    if run.sensor is not None:
        s = replace(s, sensor=Sensor(*run.sensor))
    changes = dict(noise=None, seed=run.seed, path=run.path, sampler=run.sampler)
    if run.path != "analytic":
        changes["spp"] = run.spp
    if run.bpr is not None:
        changes["bands_per_render"] = run.bpr
    return s.with_render(**changes)


def _render_timed(scene: Scene, repeats: int):
    """render_scene timed by its meta['seconds'], repeated (up to `repeats`) only while under REPEAT_BELOW_S."""
    return timed(lambda: render_scene(scene, progress=False), repeats, seconds_of=lambda b: b.meta["seconds"],
                 repeat_below_s=REPEAT_BELOW_S)


def _row(run: Run, scene: Scene, b, times: list[float], cpu: list[float]) -> dict:
    gw, gh = b.bands.shape[2], b.bands.shape[1]
    k = scene.bands.count
    exact = run.path == "analytic"
    groups = n_groups(k, run.bpr) if run.path == "spectral" else 1
    spp = b.meta["spp"]
    return {"scene": run.scene, "path": run.path, "sampler": b.meta["sampler"] or "",
            "variant": b.meta["variant"] or b.meta["backend"], "spp": spp if spp is not None else "",
            "spp_requested": "" if exact else run.spp,
            "bands_per_render": run.bpr if run.path == "spectral" else "", "seconds": statistics.median(times),
            "seconds_min": min(times), "cpu_seconds": statistics.median(cpu) if cpu else None,
            "repeats": len(times), "noise_rel": b.meta["noise_rel"], "role": run.role,
            "groups": "" if exact else groups, "renders_x_spp": "" if exact else groups * spp,
            "sensor_px": f"{scene.sensor.width_px}x{scene.sensor.height_px}", "pitch_um": scene.sensor.pitch_um,
            "grid_px": f"{gw}x{gh}", "grid_mpx": gw * gh / 1e6, "seed": "" if exact else run.seed}


def _reference_row(run: Run, scene: Scene, h1, h2, ref: Reference, t=None) -> dict:
    """The reference's row: the analytic render's time (repeats: `t`), error and noise 0; or both halves'
    spp and seconds, the noise from their difference."""
    if h2 is None:
        return _row(run, scene, h1, t.seconds, t.cpu_seconds) | {
            "rel_error": 0.0, "rel_error_net": 0.0, "rel_error_xyz": 0.0, "rel_error_xyz_net": 0.0,
            "band_mean_dev": 0.0, "ref_noise_rel": 0.0, "ref_noise_xyz": 0.0, "ref_path": "analytic"}
    return _row(run, scene, h2, [h1.meta["seconds"] + h2.meta["seconds"]], []) | {
        "spp": ref.spp, "spp_requested": 2 * run.spp, "renders_x_spp": n_groups(scene.bands.count, run.bpr) * ref.spp,
        "seed": "1+2", "noise_rel": ref.noise, "ref_noise_rel": ref.noise, "ref_noise_xyz": ref.noise_xyz,
        "ref_noise_meta": ref.noise_from_meta, "ref_path": ref.path}


def _compared_row(run: Run, scene: Scene, b, t, ref: Reference) -> dict:
    """A run's row: its time and its errors against its reference (err_over_noise = net / noise)."""
    row = _row(run, scene, b, t.seconds, t.cpu_seconds) | ref.compare(b.bands)
    if row["noise_rel"]:
        row["err_over_noise"] = row["rel_error_net"] / row["noise_rel"]
    return row


def measure(runs: list[Run], scenes: dict[str, Scene], cfg: Config, bar) -> list[dict]:
    """Render every run in order; warm-ups are not recorded, the two reference halves make one row.
    References are kept per (scene, sensor): the full-frame runs have their own."""
    refs: dict[tuple, Reference] = {}
    halves: dict[tuple, list] = {}
    rows: list[dict] = []
    for run in runs:
        bar.set_postfix_str(f"{run.scene} {run.path} {run.sampler} bpr={run.bpr} spp={run.spp} {run.role}")
        scene = _scene_for(run, scenes)
        key = (run.scene, run.sensor)
        timed_as_sweep = run.role in ("sweep", "full") or (run.role == "reference" and run.path == "analytic")
        t = _render_timed(scene, cfg.repeats if timed_as_sweep else 1)
        bar.update(1)
        b = t.result
        if run.role == "reference" and run.path == "analytic":
            refs[key] = Reference(b, None, scene.bands.edges_nm)
            rows.append(_reference_row(run, scene, b, None, refs[key], t))
        elif run.role == "reference":
            halves.setdefault(key, []).append(b)
            if len(halves[key]) == 2:
                h1, h2 = halves.pop(key)
                refs[key] = Reference(h1, h2, scene.bands.edges_nm)
                rows.append(_reference_row(run, scene, h1, h2, refs[key]))
        elif run.role in ("sweep", "full", "exact_check"):
            rows.append(_compared_row(run, scene, b, t, refs[key]))
        elif run.role == "check":
            rows.append(_row(run, scene, b, t.seconds, t.cpu_seconds))
        del b, t
    return rows


def run_study(out_dir, quick: bool = False, progress: bool = True) -> list[dict]:
    """Run the sweeps, write study_render.{csv,md,png,json} into out_dir and return the rows."""

    cfg = QUICK if quick else FULL
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    load_start = load_average()
    scenes = study_scenes(cfg)
    runs = plan(cfg, scenes)
    with tqdm(total=len(runs), disable=not progress, desc="study render", unit="run", dynamic_ncols=True) as bar:
        rows = measure(runs, scenes, cfg, bar)
    elapsed = time.perf_counter() - t_start
    analysis = analyse(rows, scenes)
    meta = {"elapsed_s": elapsed, "load_start": load_start, "load_end": load_average(), "cfg": asdict(cfg),
            "variant_rgb": next((r["variant"] for r in rows if r["path"] == "rgb_matrix"), None),
            "variant_spectral": next((r["variant"] for r in rows if r["path"] == "spectral"), None),
            "grid": {name: grid_px(s) for name, s in scenes.items()}}
    write_report(out_dir, rows, analysis, meta, cfg)
    return rows
