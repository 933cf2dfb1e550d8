"""Datasets: many capture pairs, one monitor image per item through every display; sharded,
resumable, on a process pool or a Dask cluster.

    job = DatasetJob(scene, displays, SynthConfig(), out=Path("out/ds"), split=(200, 40, 60))
    summary = run_dataset(job, workers=2)

Item i shows image i of the list (cycling when there are more items than images; the built-in list is
scikit-image's samples, the procedural charts, then dead-leaves charts with seeds 1, 2, … so every
item differs), is rendered with seed SeedSequence([render seed, i]).generate_state(1)[0] and has
sensor noise SeedSequence([noise seed, i, crc32(display)]) (pipeline.noise_seed). Layout:

    OUT/job.json                 the job's parameters; a re-run with other parameters is refused
    OUT/manifest.jsonl           one line per complete item, by item id (rewritten atomically)
    OUT/timing.jsonl             per-item run times (appended; kept out of the item files)
    OUT/<split>/shard_<k>/item_<i>/  item.json + io.capture.write_synthesis's files: gt.exr,
                                 <display>/raw.dng and capture.json, synth.json, summary.json/.md;
                                 gt_preview.png and <display>/preview.png with previews only,
                                 side_by_side.png with side_by_side only

Items go to train, val and test in id order; shard k of a split holds its items k·shard_size …
(k+1)·shard_size − 1 (by position in the split). An item is written into a hidden temporary folder
beside its final one and renamed into place when complete, so a folder named item_<i> is always
whole: a re-run removes stale temporary folders and makes only the missing items, with the same
bytes as an uninterrupted run (every file is deterministic).

Kernels are planned once in this process (pipeline.plan_kernels, into the kernel cache folder)
before items are dispatched, and each worker loads them once; with a Dask scheduler the cache and
OUT must be on a file system the cluster's workers share.

    plan.py       Task, the image list, render seeds, the split
    store.py      lock, job.json, stale folders, manifest
    executors.py  make_item; in-process, process pool or Dask
"""
from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

from udc_render.dataset.executors import Shared, executor
from udc_render.dataset.plan import SPLITS, DatasetError, Task, image_list, plan_tasks
from udc_render.dataset.store import check_job, clean_stale, locked, write_manifest
from udc_render.optics.displays import Display
from udc_render.pipeline import SynthConfig, plan_kernels
from udc_render.scene import Monitor, Scene

JOB_VERSION = 2  # 2: raw.dng replaces raw.png and packed.tiff; previews optional

__all__ = ["DatasetError", "DatasetJob", "Task", "run_dataset", "SPLITS"]


@dataclass(frozen=True)
class DatasetJob:
    """What decides a dataset's bytes: a monitor scene (its render seed is the job's base seed),
    the displays (glass first), the synthesis knobs, the images (None: the built-in list), the split
    (train, val, test item counts), the shard size, the output folder, whether to plot (side_by_side.png)
    and whether to write the sRGB previews (gt_preview.png, <display>/preview.png; the plot draws them either way)."""
    scene: Scene
    displays: list[Display]
    cfg: SynthConfig
    out: Path
    split: tuple[int, int, int]
    images_dir: Path | None = None
    shard_size: int = 1000
    side_by_side: bool = False
    previews: bool = False

    def __post_init__(self):
        if not isinstance(self.scene.content, Monitor):
            raise DatasetError(f"--scene {self.scene.source}: a dataset needs a monitor scene; it has "
                               f"{self.scene.content_type} content")
        if len(self.split) != 3 or min(self.split) < 0 or sum(self.split) < 1:
            raise DatasetError(f"--split = {self.split}: expected three counts ≥ 0 (TRAIN,VAL,TEST) summing to ≥ 1")

    @property
    def count(self) -> int:
        return sum(self.split)


def job_params(job: DatasetJob, shared: Shared, source: str, images) -> dict:
    """Everything that decides the items' bytes (not how they are run), as plain JSON values."""
    cfg = {k: v for k, v in dataclasses.asdict(shared.cfg).items() if k not in ("use_cache", "kernel_cache")}
    params = {"version": JOB_VERSION, "count": job.count, "split": dict(zip(SPLITS, job.split)),
              "shard_size": job.shard_size, "images": {"source": source, "list": [label for _, label in images]},
              "render_seed": job.scene.render.seed, "scene": dataclasses.asdict(shared.scene),
              "displays": [d.describe() for d in shared.displays], "synth": cfg, "side_by_side": shared.side_by_side,
              "previews": shared.previews}
    return json.loads(json.dumps(params, default=str))


def _shared(job: DatasetJob, out: Path) -> Shared:
    from psf.cache import cache_dir
    cfg = job.cfg
    if cfg.use_cache and cfg.kernel_cache is None:  # workers must load the parent's kernels: pin the folder
        cfg = replace(cfg, kernel_cache=str(cache_dir().resolve()))
    scene = replace(job.scene, content=replace(job.scene.content, image="(per item)"))
    return Shared(scene, job.displays, cfg, out, job.side_by_side, job.previews)


def run_dataset(job: DatasetJob, workers: int = 1, scheduler: str | None = None, progress: bool = True) -> dict:
    """Make the missing items of `job` (resuming an earlier run); returns counts and the wall time."""
    from tqdm import tqdm
    images, source = image_list(job.images_dir)
    out = Path(job.out).resolve()
    shared = _shared(job, out)
    tasks = plan_tasks(job.count, job.split, job.shard_size, images, job.images_dir is None, job.scene.render.seed)
    names = [d.name for d in job.displays]
    with executor(workers, scheduler, shared) as run_all, locked(out):
        check_job(out, job_params(job, shared, source, images))
        stale = clean_stale(out)
        todo = [t for t in tasks if not (out / t.folder).is_dir()]
        if todo and shared.cfg.use_cache:
            plan_kernels(shared.scene, shared.displays, shared.cfg)  # once, into the cache, before dispatching
        t0 = time.perf_counter()
        bar = tqdm(total=job.count, initial=job.count - len(todo), desc="dataset", unit="item",
                   disable=None if progress else True)
        try:
            with open(out / "timing.jsonl", "a") as log:
                for r in run_all(todo):
                    log.write(json.dumps({**r, "seconds": round(r["render_s"] + r["synth_s"] + r["write_s"], 3),
                                          "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z")}) + "\n")
                    log.flush()
                    bar.update()
        finally:
            bar.close()
            complete = write_manifest(out, tasks, names, shared.cfg.seed)
    return {"out": str(out), "count": job.count, "complete": complete, "made": len(todo), "stale_removed": stale,
            "wall_s": time.perf_counter() - t0}
