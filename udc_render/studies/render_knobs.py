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
estimate, relative to the noise-free image like rel_error) is 1 for an unbiased run.
``rel_error_xyz``: the same on the CIE XYZ image (spectra.band_xyz), what a trichromatic camera
sees (colour noise between neighbouring bands averages out there).
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
    """Every render in order: per series an untimed 2-spp warm-up, the reference halves, the sweep."""
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



def _render_timed(scene: Scene, repeats: int):
    """render_scene timed by its meta['seconds'], repeated (up to `repeats`) only while under REPEAT_BELOW_S."""
    return timed(lambda: render_scene(scene, progress=False), repeats, seconds_of=lambda b: b.meta["seconds"],
                 repeat_below_s=REPEAT_BELOW_S)


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


def _reference_row(run: Run, scene: Scene, h1, h2, ref: Reference) -> dict:
    """The reference's row: both halves' spp and seconds, its noise from their difference."""
    return _row(run, scene, h2, [h1.meta["seconds"] + h2.meta["seconds"]], []) | {
        "spp": 2 * run.spp, "seed": "1+2", "noise_rel": ref.noise, "ref_noise_rel": ref.noise,
        "ref_noise_xyz": ref.noise_xyz, "ref_noise_meta": ref.noise_from_meta}


def _sweep_row(run: Run, scene: Scene, b, t, ref: Reference, cfg: Config) -> dict:
    """A sweep run's row: its time and its errors against the scene's reference (err_over_noise = net / noise)."""
    row = _row(run, scene, b, t.seconds, t.cpu_seconds) | ref.compare(b.bands)
    row["ref_spp"] = 2 * (cfg.rgb_ref_spp // 2 if run.scene == "monitor" else cfg.room_ref_spp // 2)
    if row["noise_rel"]:
        row["err_over_noise"] = row["rel_error_net"] / row["noise_rel"]
    return row


def measure(runs: list[Run], scenes: dict[str, Scene], cfg: Config, bar) -> list[dict]:
    """Render every run in order; warm-ups are not recorded, the two reference halves make one row."""
    refs: dict[str, Reference] = {}
    halves: dict[str, list] = {}
    rows: list[dict] = []
    for run in runs:
        bar.set_postfix_str(f"{run.scene} {run.path} bpr={run.bpr} spp={run.spp} {run.role}")
        scene = _scene_for(run, scenes)
        t = _render_timed(scene, cfg.repeats if run.role == "sweep" else 1)
        bar.update(1)
        b = t.result
        if run.role == "reference":
            halves.setdefault(run.scene, []).append(b)
            if len(halves[run.scene]) == 2:
                h1, h2 = halves.pop(run.scene)
                refs[run.scene] = Reference(h1, h2, scene.bands.edges_nm)
                rows.append(_reference_row(run, scene, h1, h2, refs[run.scene]))
        elif run.role == "sweep":
            rows.append(_sweep_row(run, scene, b, t, refs[run.scene], cfg))
        elif run.role == "check":
            rows.append(_row(run, scene, b, t.seconds, t.cpu_seconds))
        del b, t
    return rows


def run_study(out_dir, quick: bool = False, progress: bool = True) -> list[dict]:
    """Run the sweeps, write study_render.{csv,md,png,json} into out_dir and return the rows."""
    from tqdm.auto import tqdm

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
