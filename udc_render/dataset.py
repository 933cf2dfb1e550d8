"""`udc-render dataset`: many capture pairs, one monitor image per item through every display.

    udc-render dataset --images DIR | --builtin --display glass,toled,poled --count N --out DIR
                       [--split 200,40,60] [--shard-size 1000] [--workers N | --scheduler ADDRESS]

Item i shows image i of the list (cycling when there are more items than images; --builtin lists
scikit-image's samples, the procedural charts, then dead-leaves charts with seeds 1, 2, … so every
item differs), is rendered with seed SeedSequence([render seed, i]).generate_state(1)[0] and has
sensor noise SeedSequence([noise seed, i, crc32(display)]) (synth.noise_seed). Layout:

    OUT/job.json                 the job's parameters; a re-run with other parameters is refused
    OUT/manifest.jsonl           one line per complete item, by item id (rewritten atomically)
    OUT/timing.jsonl             per-item run times (appended; kept out of the item files)
    OUT/<split>/shard_<k>/item_<i>/  item.json + capture_io.write_synthesis's files

Items go to train, val and test in id order (--split); shard k of a split holds its items
k·shard_size … (k+1)·shard_size − 1 (by position in the split). An item is written into a hidden
temporary folder beside its final one and renamed into place when complete, so a folder named
item_<i> is always whole: a re-run removes stale temporary folders and makes only the missing
items, with the same bytes as an uninterrupted run (every file is deterministic).

Kernels are computed once in this process (psf.cache on disk, $UDC_RENDER_CACHE) before items are
dispatched, so workers only load them; with --scheduler the cache and OUT must be on a file system
the cluster's workers share.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import shutil
import socket
import tempfile
import time
from dataclasses import dataclass, replace
from itertools import islice
from pathlib import Path

import numpy as np

from udc_render.cli import UserError, _float_pair, _positive, scene_from_args
from udc_render.synth_cli import add_capture_arguments, parse_displays, synth_config

SPLITS = ("train", "val", "test")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".webp")
BUILTIN_CHARTS = ("pattern:slanted_edge", "pattern:sine_x", "pattern:sine_y", "pattern:siemens",
                  "pattern:dead_leaves:0")
TMP_PREFIX = ".tmp-"
JOB_VERSION = 1
CONNECT_TIMEOUT_S = 10.0  # reaching a Dask scheduler and waiting for its first worker


@dataclass(frozen=True)
class Shared:
    """What every item needs (sent once per worker): the scene without its image, the displays,
    the synthesis knobs and the output folder (absolute)."""
    scene: object
    displays: list
    cfg: object
    out: Path
    side_by_side: bool
    kernel_cache: str | None  # the kernel cache folder workers must use (None: --no-cache)


@dataclass(frozen=True)
class Task:
    """One item: its id, split, folder (relative to OUT), image (spec and label) and render seed."""
    item: int
    split: str
    folder: str
    image: str  # what the monitor shows: an absolute file path, builtin:NAME or pattern:NAME
    label: str  # the image as recorded: a path relative to --images, or the spec
    render_seed: int


def _split(text: str) -> tuple[int, int, int]:
    try:
        counts = tuple(int(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--split must be TRAIN,VAL,TEST counts, got '{text}'") from None
    if len(counts) != 3 or min(counts) < 0 or sum(counts) < 1:
        raise argparse.ArgumentTypeError(f"--split must be three counts ≥ 0 (TRAIN,VAL,TEST) summing to ≥ 1, got '{text}'")
    return counts


def register(sub) -> dict:
    p = sub.add_parser("dataset", help="many capture pairs: one image per item through every display "
                                       "(sharded, resumable, parallel)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--images", type=Path, help="a folder of images (searched recursively, sorted by path)")
    src.add_argument("--builtin", action="store_true",
                     help="scikit-image's samples and the procedural charts, then dead-leaves charts")
    p.add_argument("--count", type=_positive("--count", int), help="number of items [the sum of --split]")
    p.add_argument("--split", type=_split, help="TRAIN,VAL,TEST item counts, assigned in id order [all train]")
    p.add_argument("--out", type=Path, default=Path("out/dataset"), help="output folder [out/dataset]")
    p.add_argument("--shard-size", type=_positive("--shard-size", int), default=1000,
                   help="items per shard folder [1000]")
    run = p.add_mutually_exclusive_group()
    run.add_argument("--workers", type=_positive("--workers", int), default=1,
                     help="1: in this process; N > 1: a local pool of N processes [1]")
    run.add_argument("--scheduler", help="address of a Dask distributed scheduler (tcp://HOST:PORT) to run items on")
    p.add_argument("--side-by-side", action="store_true", help="also write each item's side_by_side.png")
    p.add_argument("--scene", default="monitor", help="a monitor scene file or name [monitor]")
    samples = p.add_mutually_exclusive_group()
    samples.add_argument("--spp", type=_positive("--spp", int), help="samples per pixel [the scene's]")
    samples.add_argument("--noise", type=_positive("--noise"), help="target relative RMS noise per item")
    p.add_argument("--bands-nm", help="LOW:HIGH:STEP in nm [the scene's]")
    p.add_argument("--seed", type=int, help="base render seed [the scene's render.seed]")
    p.add_argument("--sensor-px", type=_float_pair("--sensor-px"), help="sensor width,height in pixels")
    p.add_argument("--pitch-um", type=_positive("--pitch-um"), help="sensor pixel pitch in µm")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_capture_arguments(p)
    return {"dataset": run_dataset}


def item_count(args) -> tuple[int, tuple[int, int, int]]:
    """(count, split counts) from --count and --split."""
    if args.split is None:
        if args.count is None:
            raise UserError("--count N is required (or --split TRAIN,VAL,TEST)")
        return args.count, (args.count, 0, 0)
    total = sum(args.split)
    if args.count is not None and args.count != total:
        raise UserError(f"--split {','.join(map(str, args.split))} sums to {total}, but --count is {args.count}")
    return total, args.split


def image_list(args) -> tuple[list[tuple[str, str]], str]:
    """[(spec, label)] of the images to cycle through, and their source (the folder or 'builtin')."""
    from udc_render.display_image import BUILTIN_IMAGES
    if args.builtin:
        return [(s, s) for s in [f"builtin:{n}" for n in BUILTIN_IMAGES] + list(BUILTIN_CHARTS)], "builtin"
    folder = args.images.resolve()
    if not folder.is_dir():
        raise UserError(f"--images {args.images}: no such folder")
    files = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*")
                   if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()
                   and not any(part.startswith(".") for part in p.relative_to(folder).parts))
    if not files:
        raise UserError(f"--images {args.images}: no images ({', '.join(IMAGE_SUFFIXES)}) in the folder")
    return [(str(folder / f), f) for f in files], str(folder)


def image_of(images: list[tuple[str, str]], builtin: bool, i: int) -> tuple[str, str]:
    """Item i's image: the list cycled, or (builtin) new dead-leaves seeds after the list."""
    if builtin and i >= len(images):
        spec = f"pattern:dead_leaves:{i - len(images) + 1}"
        return spec, spec
    return images[i % len(images)]


def render_seed(base: int, item: int) -> int:
    """Mitsuba's uint32 base seed of item `item`."""
    return int(np.random.SeedSequence([base, item]).generate_state(1)[0])


def plan(count: int, split: tuple[int, int, int], shard_size: int, images, builtin: bool, base_seed: int) -> list[Task]:
    tasks = []
    for name, n in zip(SPLITS, split):
        for pos in range(n):
            i = len(tasks)
            spec, label = image_of(images, builtin, i)
            tasks.append(Task(i, name, f"{name}/shard_{pos // shard_size:04d}/item_{i:06d}", spec, label,
                              render_seed(base_seed, i)))
    return tasks


def make_item(shared: Shared, task: Task) -> dict:
    """Render and synthesise one item into a temporary folder, then rename it into place.
    Runs in this process, a pool process or a Dask worker; returns run times (s) for the log."""
    from udc_render.capture_io import write_synthesis
    from udc_render.fileio import current_umask, save_json
    from udc_render.render import render_scene
    from udc_render.synth import synthesize
    if shared.kernel_cache is not None:  # load the parent's kernels: computed here they could differ in the last bits
        os.environ["UDC_RENDER_CACHE"] = shared.kernel_cache
    t0 = time.perf_counter()
    scene = shared.scene
    scene = replace(scene, content=replace(scene.content, image=task.image),
                    render=replace(scene.render, seed=task.render_seed))
    band_image = render_scene(scene, progress=False)
    t1 = time.perf_counter()
    result = synthesize(band_image, scene, shared.displays, shared.cfg, item=task.item)
    t2 = time.perf_counter()
    final = shared.out / task.folder
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}{final.name}-", dir=final.parent))
    try:
        write_synthesis(tmp, result, shared.cfg.sensor.camera, side_by_side=shared.side_by_side)
        save_json(tmp / "item.json", item_record(task, shared))
        os.chmod(tmp, 0o777 & ~current_umask())  # mkdtemp makes 0700
        os.rename(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return {"item": task.item, "folder": task.folder, "render_s": round(t1 - t0, 3), "synth_s": round(t2 - t1, 3),
            "write_s": round(time.perf_counter() - t2, 3), "host": socket.gethostname(), "pid": os.getpid()}


def item_record(task: Task, shared: Shared) -> dict:
    """item.json and the manifest's line (less the file list): nothing that depends on where OUT is."""
    return {"item": task.item, "split": task.split, "folder": task.folder, "image": task.label,
            "render_seed": task.render_seed, "noise_seed": f"SeedSequence([{shared.cfg.seed}, {task.item}, crc32(display)])",
            "displays": [d.name for d in shared.displays]}


def job_params(shared: Shared, count: int, split, shard_size: int, source: str, images, base_seed: int) -> dict:
    """Everything that decides the items' bytes (not how they are run), as plain JSON values."""
    cfg = {k: v for k, v in dataclasses.asdict(shared.cfg).items() if k != "use_cache"}
    params = {"version": JOB_VERSION, "count": count, "split": dict(zip(SPLITS, split)), "shard_size": shard_size,
              "images": {"source": source, "list": [label for _, label in images]},
              "render_seed": base_seed, "scene": dataclasses.asdict(shared.scene),
              "displays": [d.describe() for d in shared.displays], "synth": cfg, "side_by_side": shared.side_by_side}
    return json.loads(json.dumps(params, default=str))


@contextlib.contextmanager
def locked(out: Path):
    """Hold an exclusive lock on OUT/.lock: one run at a time per folder."""
    import fcntl
    out.mkdir(parents=True, exist_ok=True)
    with open(out / ".lock", "w") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise UserError(f"--out {out}: another udc-render dataset run is writing there") from None
        yield


def check_job(out: Path, params: dict) -> None:
    """Write OUT/job.json, or refuse when it holds a different job."""
    from udc_render.fileio import save_json
    path = out / "job.json"
    if path.exists():
        try:
            old = json.loads(path.read_text())
        except (OSError, ValueError):
            raise UserError(f"{path}: unreadable; use another --out or delete the folder") from None
        if old != params:
            keys = sorted(k for k in params.keys() | old.keys() if old.get(k) != params.get(k))
            raise UserError(f"--out {out} holds a different job (differs in {', '.join(keys)}); "
                            "use another --out or delete the folder")
        return
    save_json(path, params)


def clean_stale(out: Path) -> int:
    """Remove temporary item folders left by an interrupted run; returns how many."""
    stale = [p for p in out.glob(f"*/shard_*/{TMP_PREFIX}*") if p.is_dir()]
    for p in stale:
        shutil.rmtree(p)
    return len(stale)


def warm_kernels(shared: Shared) -> None:
    """Compute (or load) every kernel set the items will need, into the on-disk cache."""
    from udc_render.render import BandImage
    from udc_render.rig import camera_geometry
    from udc_render.synth import display_channel_kernels, display_kernels
    from udc_render.displays import Display
    scene, cfg = shared.scene, shared.cfg
    geom = camera_geometry(scene)
    edges = np.asarray(scene.bands.edges_nm, float)
    grid = BandImage(np.zeros((edges.size - 1, 0, 0), np.float32), edges, geom.pitch_um, geom.margin_px, None)
    display_kernels(Display("glass", None), scene, grid, cfg)
    for d in shared.displays:
        if cfg.form == "spectral" or d.source != "preset":  # per_channel: analytic γ needs them
            display_kernels(d, scene, grid, cfg)
        if cfg.form == "per_channel":
            display_channel_kernels(d, scene, grid, cfg)


def write_manifest(out: Path, tasks: list[Task], shared: Shared) -> int:
    """OUT/manifest.jsonl: the complete items by id, each with its files; returns their number."""
    from udc_render.fileio import save_text
    lines = []
    for t in tasks:
        folder = out / t.folder
        if folder.is_dir():
            files = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())
            lines.append(json.dumps({**item_record(t, shared), "files": files}, sort_keys=True))
    save_text(out / "manifest.jsonl", "".join(line + "\n" for line in lines))
    return len(lines)


def _windowed(submit, wait_any, tasks, window: int):
    """Results of submit(task) for every task, as they finish, with at most `window` in flight."""
    it = iter(tasks)
    pending = {submit(t) for t in islice(it, window)}
    while pending:
        done, pending = wait_any(pending)
        for f in done:
            pending |= {submit(t) for t in islice(it, 1)}
            yield f.result()


@contextlib.contextmanager
def executor(workers: int, scheduler: str | None, shared: Shared):
    """A function tasks -> iterator of make_item's results: in process, a spawn pool, or Dask."""
    if scheduler is not None:
        with _dask_client(scheduler) as client:
            import distributed
            shared_f = client.scatter(shared, broadcast=True, hash=False)
            window = 2 * max(1, sum(client.nthreads().values()))

            def wait_any(fs):
                r = distributed.wait(fs, return_when="FIRST_COMPLETED")
                return r.done, r.not_done
            yield lambda tasks: _windowed(lambda t: client.submit(make_item, shared_f, t, pure=False), wait_any,
                                          tasks, window)
        return
    if workers == 1:
        yield lambda tasks: (make_item(shared, t) for t in tasks)
        return
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"))  # Dr.Jit threads and fork do not mix
    try:
        yield lambda tasks: _windowed(lambda t: pool.submit(make_item, shared, t),
                                      lambda fs: wait(fs, return_when=FIRST_COMPLETED), tasks, 2 * workers)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


@contextlib.contextmanager
def _dask_client(address: str):
    try:
        import distributed
    except ImportError:
        raise UserError("--scheduler needs the 'distributed' package: pip install 'udc-render[dist]'") from None
    try:
        client = distributed.Client(address, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError) as e:
        raise UserError(f"--scheduler {address}: cannot reach the scheduler ({type(e).__name__}: "
                        f"{str(e).splitlines()[0] if str(e) else 'no answer'})") from None
    try:
        try:
            client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        except TimeoutError:
            raise UserError(f"--scheduler {address}: no workers joined within {CONNECT_TIMEOUT_S:g} s") from None
        yield client
    finally:
        client.close()


def run_dataset(args) -> int:
    from psf.cache import cache_dir
    from tqdm import tqdm
    from udc_render.scene import Monitor
    count, split = item_count(args)
    images, source = image_list(args)
    ns = argparse.Namespace(scene=args.scene, spp=args.spp, noise=args.noise, seed=args.seed, path=None,
                            bands_nm=args.bands_nm, image=None, sensor_px=args.sensor_px, pitch_um=args.pitch_um)
    scene = scene_from_args(ns)
    if not isinstance(scene.content, Monitor):
        raise UserError(f"--scene {args.scene}: a dataset needs a monitor scene; {scene.source} has "
                        f"{scene.content_type} content")
    base_seed = scene.render.seed
    scene = replace(scene, content=replace(scene.content, image="(per item)"))
    out = args.out.resolve()
    cfg = synth_config(args)
    shared = Shared(scene, parse_displays(args.display, args.distance_mm), cfg, out, args.side_by_side,
                    str(cache_dir().resolve()) if cfg.use_cache else None)
    tasks = plan(count, split, args.shard_size, images, args.builtin, base_seed)
    params = job_params(shared, count, split, args.shard_size, source, images, base_seed)
    with executor(args.workers, args.scheduler, shared) as run_all, locked(out):
        check_job(out, params)
        stale = clean_stale(out)
        todo = [t for t in tasks if not (out / t.folder).is_dir()]
        if todo and shared.cfg.use_cache:
            warm_kernels(shared)
        t0 = time.perf_counter()
        bar = tqdm(total=count, initial=count - len(todo), desc="dataset", unit="item",
                   disable=True if args.quiet else None)
        try:
            with open(out / "timing.jsonl", "a") as log:
                for r in run_all(todo):
                    log.write(json.dumps({**r, "seconds": round(r["render_s"] + r["synth_s"] + r["write_s"], 3),
                                          "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z")}) + "\n")
                    log.flush()
                    bar.update()
        finally:
            bar.close()
            complete = write_manifest(out, tasks, shared)
    wall = time.perf_counter() - t0
    rate = f", {wall / len(todo):.2f} s/item wall" if todo else ""
    print(f"{complete}/{count} items in {out} ({len(todo)} made now{rate}, {count - len(todo)} already there"
          f"{f', {stale} stale temporary folders removed' if stale else ''}); manifest.jsonl, job.json, timing.jsonl")
    return 0
