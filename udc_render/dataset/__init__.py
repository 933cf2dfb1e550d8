"""Datasets: many capture pairs, one monitor image or one view of a 3D scene per item through every
display; sharded, resumable, on a process pool or a Dask cluster.

    job = DatasetJob(scene, displays, SynthConfig(), out=Path("out/ds"), split=(200, 40, 60))
    summary = run_dataset(job, workers=2)

A monitor scene: item i shows image i of the list (cycling when there are more items than images; the
built-in list is scikit-image's samples, the procedural charts, then dead-leaves charts with seeds 1,
2, … so every item differs). A 3D scene (room, hdr, a Mitsuba XML scene, any scene file of those):
item i sees the scene from its own camera pose (plan.Views): item 0 from the scene's pose (an XML
scene's: its sensor's, render.resolve_xml_camera), item i > 0 with the camera origin moved by
u[0:3] · origin_jitter_m and the target by u[3:6] · target_jitter_m per world axis (metres; defaults
plan.DEFAULT_ORIGIN_JITTER_M = ±(0.15, 0.1, 0.15), DEFAULT_TARGET_JITTER_M = ±(0.3, 0.2, 0)), u =
streams.stream(render seed, 'pose', i).uniform(−1, 1, 6); the up vector is kept. The focus distance
is the base pose's for every item (lens.focus_distance_m set to it once), so the lens-to-sensor distance,
the field of view and the in-focus kernels are the same for all items. Every item is rendered with seed
SeedSequence([render seed, i]).generate_state(1)[0] and has sensor noise SeedSequence([noise seed, i,
crc32(display)]) (pipeline.noise_seed). Layout:

    OUT/job.json                 the job's parameters; a re-run with other parameters is refused
    OUT/manifest.jsonl           one line per complete item, by item id (rewritten atomically)
    OUT/timing.jsonl             per-item run times (appended; kept out of the item files)
    OUT/<split>/shard_<k>/item_<i>/  item.json + io.capture.write_synthesis's files: gt.exr,
                                 <display>/raw.dng and capture.json, synth.json, summary.json/.md;
                                 gt_preview.png and <display>/preview.png with previews only,
                                 side_by_side.png with side_by_side only

item.json (and its manifest line) records the item's image (a monitor scene: "image", the path relative
to --images or the spec) or its camera ("pose": origin_m, target_m, up; a 3D scene); job.json records the
image list or the views (base pose, jitters, the draw), the scene (its fixed focus distance included).

Items go to train, val and test in id order; shard k of a split holds its items k·shard_size …
(k+1)·shard_size − 1 (by position in the split). An item is written into a hidden temporary folder
beside its final one and renamed into place when complete, so a folder named item_<i> is always
whole: a re-run removes stale temporary folders and makes only the missing items, with the same
bytes as an uninterrupted run (every file is deterministic).

A randomized job (randomized.py; --randomize, --panels N) draws N panels once and records them in
job.json; item i sees panel capture_panel(N, seed, i) with its own sensor and exposure, its panel's
capture in <item>/random/; the items are dispatched sorted by panel.

Kernels are planned once in this process (pipeline.prepare_kernels, into the kernel cache folder, with what
is made of them: far fields, rank-r field bases and exact-power maps) before items are dispatched, and each
worker loads them once (memory-mapped, psf.cache): the monitor plane's, or a 3D scene's
in-focus kernels; the synthesis plans the other depth layers' kernels of each item itself, through
the same cache (executors.cache_layer_kernels plans them into the cache first, with this process's
BLAS thread count, so they are loaded, never used straight from their computation: the same bits on
any worker and in any run order). With a Dask scheduler the cache and OUT must be on a file system
the cluster's workers share.

    plan.py       Task, the image list, Views (a 3D scene's poses), render seeds, the split
    store.py      lock, job.json, stale folders, manifest
    executors.py  make_item; in-process, process pool or Dask
    randomized.py a randomized job's panels, their kernels, each item's draws and their records
"""
from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

from tqdm import tqdm

from psf.cache import ENGINE_VERSION
from udc_render.dataset.executors import Shared, executor
from udc_render.dataset.plan import (
    BUILTIN_THEN,
    DEFAULT_ORIGIN_JITTER_M,
    DEFAULT_TARGET_JITTER_M,
    SPLITS,
    DatasetError,
    Task,
    Views,
    image_list,
    plan_tasks,
)
from udc_render.dataset.randomize import PANEL_NAME, capture_panel
from udc_render.dataset.randomized import Randomization, plan_panels
from udc_render.dataset.store import check_job, clean_stale, locked, write_manifest
from udc_render.dataset.threads import parent_blas_threads
from udc_render.optics.displays import Display
from udc_render.optics.field_planes import PAYBACK_ITEMS as PLANES_PAYBACK_ITEMS
from udc_render.pipeline import SynthConfig, prepare_kernels
from udc_render.scene import Monitor, Scene
from udc_render.scene.geometry import camera_geometry

JOB_VERSION = 2  # 2: raw.dng replaces raw.png and packed.tiff; previews optional

__all__ = ["DatasetError", "DatasetJob", "Randomization", "Task", "Views", "run_dataset", "SPLITS",
           "DEFAULT_ORIGIN_JITTER_M", "DEFAULT_TARGET_JITTER_M"]


@dataclass(frozen=True)
class DatasetJob:
    """What decides a dataset's bytes: a monitor scene or a 3D scene (its render seed is the job's base
    seed), the displays (glass first), the synthesis knobs, the images of a monitor scene (None: the
    built-in list; a 3D scene takes none), the camera jitters of a 3D scene (metres per world axis,
    plan.Views), the split (train, val, test item counts), the shard size, the output folder, whether to
    plot (side_by_side.png) and whether to write the sRGB previews (gt_preview.png, <display>/preview.png;
    the plot draws them either way), and a randomization (randomized.py: the displays are then glass alone,
    each item adds its panel; spectral form)."""
    scene: Scene
    displays: list[Display]
    cfg: SynthConfig
    out: Path
    split: tuple[int, int, int]
    images_dir: Path | None = None
    shard_size: int = 1000
    side_by_side: bool = False
    previews: bool = False
    origin_jitter_m: tuple[float, float, float] = DEFAULT_ORIGIN_JITTER_M
    target_jitter_m: tuple[float, float, float] = DEFAULT_TARGET_JITTER_M
    randomize: Randomization | None = None

    def __post_init__(self):
        if self.randomize is not None:
            names = [d.name for d in self.displays]
            if names != ["glass"]:
                raise DatasetError(f"--randomize with --display {','.join(n for n in names if n != 'glass')}: the "
                                   f"drawn panel ('{PANEL_NAME}') is the item's display; leave --display out")
            if self.cfg.form != "spectral":
                raise DatasetError(f"--randomize with form {self.cfg.form}: the drawn panels need the spectral form "
                                   "(their distance, T(λ) and haze); use --profile physical or --form spectral")
        if not self.is_monitor and self.images_dir is not None:
            raise DatasetError(f"--scene {self.scene.source}: a {self.scene.content_type} scene's items are views of "
                               f"the scene (--pose-jitter-m, --target-jitter-m); --images and --builtin are for a "
                               f"monitor scene")
        for name, v in (("--pose-jitter-m", self.origin_jitter_m), ("--target-jitter-m", self.target_jitter_m)):
            if len(v) != 3 or not all(math.isfinite(x) and x >= 0 for x in v):
                raise DatasetError(f"{name} = {v}: expected three distances ≥ 0 in metres (X,Y,Z)")
        if len(self.split) != 3 or min(self.split) < 0 or sum(self.split) < 1:
            raise DatasetError(f"--split = {self.split}: expected three counts ≥ 0 (TRAIN,VAL,TEST) summing to ≥ 1")

    @property
    def is_monitor(self) -> bool:
        return isinstance(self.scene.content, Monitor)

    @property
    def count(self) -> int:
        return sum(self.split)


def job_params(job: DatasetJob, shared: Shared, source: str | None, images, views: Views | None = None) -> dict:
    """Everything that decides the items' bytes (not how they are run), as plain JSON values."""
    cfg = {k: v for k, v in dataclasses.asdict(shared.cfg).items() if k not in ("use_cache", "kernel_cache")}
    images_then = {"then": BUILTIN_THEN} if source == "builtin" else {}
    what = ({"images": {"source": source, "list": [label for _, label in images], **images_then}} if views is None
            else {"views": views.describe()})
    params = {"version": JOB_VERSION, "count": job.count, "split": dict(zip(SPLITS, job.split)),
              "shard_size": job.shard_size, **what,
              "render_seed": job.scene.render.seed, "scene": dataclasses.asdict(shared.scene),
              "displays": [d.describe() for d in shared.displays], "synth": cfg, "side_by_side": shared.side_by_side,
              "previews": shared.previews, "psf_engine": ENGINE_VERSION}  # other kernels: a new job, not a resume
    if job.randomize is not None:
        params["randomize"] = job.randomize.describe()
    return json.loads(json.dumps(params, default=str))


def _shared(job: DatasetJob, out: Path) -> Shared:
    """What every item shares: a 3D scene at its base pose (an XML scene's resolved) with the focus distance
    fixed at the base pose's (lens.focus_distance_m), so every item has the same in-focus kernels."""
    from psf.cache import cache_dir
    from udc_render.render import resolve_xml_camera
    cfg = job.cfg
    if cfg.use_cache and cfg.kernel_cache is None:  # workers must load the parent's kernels: pin the folder
        cfg = replace(cfg, kernel_cache=str(cache_dir().resolve()))
    rand = job.randomize
    if rand is not None and job.count < PLANES_PAYBACK_ITEMS * len(rand.panels):  # the blend through the planes
        cfg = replace(cfg, field_planes_rank=None)  # pays its basis back over PLANES_PAYBACK_ITEMS items a panel
    if job.is_monitor:
        scene = replace(job.scene, content=replace(job.scene.content, image="(per item)"))
        return Shared(scene, job.displays, cfg, out, job.side_by_side, job.previews, parent_blas_threads(),
                      job.randomize)
    scene = resolve_xml_camera(job.scene)
    g = camera_geometry(scene)
    scene = replace(scene, camera=replace(scene.camera, origin_m=g.origin_m, target_m=g.target_m, up=g.up),
                    lens=replace(scene.lens, focus_distance_m=g.focus_distance_m))
    return Shared(scene, job.displays, cfg, out, job.side_by_side, job.previews, parent_blas_threads(), job.randomize)


def _views(job: DatasetJob, shared: Shared) -> Views | None:
    """A 3D scene's items' poses around the base pose of `shared` (None: a monitor scene)."""
    if job.is_monitor:
        return None
    c = shared.scene.camera
    return Views(tuple(c.origin_m), tuple(c.target_m), tuple(c.up), tuple(map(float, job.origin_jitter_m)),
                 tuple(map(float, job.target_jitter_m)))


def run_dataset(job: DatasetJob, workers: int = 1, scheduler: str | None = None, progress: bool = True,
                splits: tuple[str, ...] | None = None) -> dict:
    """Make the missing items of `job` (resuming an earlier run), only those of `splits` when given (the
    items keep their ids, images and seeds; the manifest lists the complete ones); returns counts and the
    wall time of the whole call (the pool's start, the cache's preparation and the items)."""
    t0 = time.perf_counter()  # the wall: the pool's start and the cache's preparation included
    images, source = image_list(job.images_dir) if job.is_monitor else (None, None)
    out = Path(job.out).resolve()
    shared = _shared(job, out)
    views = _views(job, shared)
    tasks = plan_tasks(job.count, job.split, job.shard_size, images, job.images_dir is None, job.scene.render.seed,
                       views)
    rand = job.randomize
    if rand is not None:
        tasks = [replace(t, panel=capture_panel(len(rand.panels), rand.seed, t.item)) for t in tasks]
    names = [d.name for d in job.displays] + ([PANEL_NAME] if rand is not None else [])
    with executor(workers, scheduler, shared) as run_all, locked(out):
        check_job(out, job_params(job, shared, source, images, views))
        stale = clean_stale(out)
        todo = [t for t in tasks if not (out / t.folder).is_dir() and (splits is None or t.split in splits)]
        plan_s = []
        if todo and shared.cfg.use_cache:
            # once, into the cache, before dispatching (a 3D scene: the in-focus ones; the synthesis plans
            # each item's other depth layers through the same cache); a randomized job: every panel's
            if rand is None:  # the kernels and what the workers make of them (far fields, bases, power maps)
                prepare_kernels(shared.scene, shared.displays, shared.cfg)
            else:
                plan_s = plan_panels(rand, shared.scene, shared.displays[0], shared.cfg)
        if rand is not None:  # a worker keeps few panels' kernels: one panel's items after another
            todo.sort(key=lambda t: (t.panel, t.item))
        wanted = sum(1 for t in tasks if splits is None or t.split in splits)
        bar = tqdm(total=wanted, initial=wanted - len(todo), desc="dataset", unit="item",
                   disable=not progress)  # also into a log file: a job run in the background shows where it is
        try:
            with open(out / "timing.jsonl", "a") as log:
                for r in run_all(todo):
                    seconds = r["render_s"] + r["kernels_s"] + r["synth_s"] + r["write_s"]
                    log.write(json.dumps({**r, "seconds": round(seconds, 3),
                                          "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z")}) + "\n")
                    log.flush()
                    bar.update()
        finally:
            bar.close()
            complete = write_manifest(out, tasks, names, shared.cfg.seed)
    return {"out": str(out), "count": job.count, "complete": complete, "made": len(todo), "stale_removed": stale,
            "wall_s": time.perf_counter() - t0, "panels_plan_s": plan_s}
