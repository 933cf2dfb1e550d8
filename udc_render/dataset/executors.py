"""Where items run: in this process, a process pool (forked: workers.py), or a Dask distributed cluster. No home-made
scheduler: a window of submitted items, results as they finish."""
from __future__ import annotations

import contextlib
import os
import resource
import shutil
import socket
import tempfile
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, replace
from itertools import islice
from pathlib import Path

from udc_render.dataset.plan import DatasetError, Task
from udc_render.dataset.randomized import Randomization, exposed, item_setup, panel_setup, recorded
from udc_render.dataset.store import TMP_PREFIX, item_record
from udc_render.dataset.threads import (
    blas_threads,
    blas_threads_env,
    keep_freed_memory,
    process_age_s,
    threads_per_worker,
)
from udc_render.dataset.workers import start_worker, worker_context
from udc_render.io.capture import write_synthesis
from udc_render.io.files import current_umask, save_json
from udc_render.optics.displays import Display
from udc_render.optics.kept import on_disk
from udc_render.pipeline import Kernels, SynthConfig
from udc_render.scene import Monitor, Scene

CONNECT_TIMEOUT_S = 10.0  # reaching a Dask scheduler and waiting for its first worker


@dataclass(frozen=True)
class Shared:
    """What every item needs: the scene without its image (a monitor) or at its base pose with the focus
    distance fixed (a 3D scene: every item uses the same in-focus kernels), the displays, the synthesis
    knobs (with the kernel cache folder the parent filled: workers load those kernels and never recompute
    them, so every worker uses the same bits), the output folder (absolute), whether to plot, whether to
    write the sRGB previews, and the parent's BLAS thread count (worker_kernels, cache_layer_kernels)."""
    scene: Scene
    displays: list[Display]
    cfg: SynthConfig
    out: Path
    side_by_side: bool
    previews: bool
    blas_threads: int | None = None  # the parent's BLAS threads: kernels a worker computes are computed with them
    randomize: Randomization | None = None  # --randomize: the panels drawn once (dataset.randomized)


_WORKER_KERNELS: dict[tuple, Kernels] = {}  # per process: the job's kernels (a panel's), loaded once per worker
KEEP_PANELS = 2  # a randomized job's panels whose kernels a worker keeps (the items come sorted by panel)


def worker_kernels(shared: Shared, panel: int | None = None) -> Kernels:
    """The job's kernels (with --randomize, panel `panel`'s: randomized.panel_setup), loaded from the cache
    on a worker's first item and kept for the next ones (KEEP_PANELS panels, the first loaded dropped first), the
    d > 0 phase kernels reduced to their rank-r bases (pipeline.compact_kernels: same numbers, 1/8 the memory)
    and their exact-power maps made once (pipeline.store_power_maps: same numbers, not remade per item).
    All made with the parent's BLAS thread count (Shared.blas_threads), the bits of a 1-worker run: a pool
    worker has a share of the cores' threads, and the bits change with the BLAS thread count (threads.py):
    without the kernel cache (--no-cache) the kernels themselves (raw.dng differed between 1 and 2 workers),
    and the rank-r bases' residual, which capture.json records (field_rank_kernel_residual differed in its
    last digits with 31-px kernels over 16 phases)."""
    from udc_render.pipeline import compact_kernels, plan_kernels, store_field_planes, store_power_maps
    key = (str(shared.out), panel)
    if key not in _WORKER_KERNELS:
        for old in [k for k in _WORKER_KERNELS if k[0] != key[0]]:  # another job's
            del _WORKER_KERNELS[old]
        while len(_WORKER_KERNELS) >= KEEP_PANELS:
            del _WORKER_KERNELS[next(iter(_WORKER_KERNELS))]  # the first loaded
        scene, displays = (shared.scene, shared.displays) if panel is None else \
            panel_setup(shared.scene, shared.displays[0], shared.randomize.panels[panel])
        with blas_threads(shared.blas_threads):
            kernels = compact_kernels(plan_kernels(scene, displays, shared.cfg), scene, shared.cfg)
            kernels = store_field_planes(store_power_maps(kernels, scene, shared.cfg.kernel_cache), scene, shared.cfg)
            _WORKER_KERNELS[key] = replace(kernels, cache_spectra=True)  # their spectra: made once, into the cache
    return _WORKER_KERNELS[key]


def cache_layer_kernels(band_image, scene: Scene, shared: Shared, kernels: Kernels,
                        displays: list[Display] | None = None) -> None:
    """Plan the kernels of the item's depth layers other than the job's (a 3D scene's depth away from
    the focus) into the kernel cache before the synthesis, which then loads them from there: computed
    here with the parent's BLAS thread count (Shared.blas_threads; a pool worker has it already, a Dask
    worker has its cluster's), since psf's kernels differ in the last bits with the BLAS thread count
    (threads.py), so an item's bytes do not depend on which process computed a layer's kernels. Costs
    one extra load per such layer; nothing without the cache (then the synthesis computes them with this
    process's BLAS threads) or for a monitor (one layer, the job's). `displays`: the item's [shared.displays]."""
    from udc_render.pipeline import depth_layers, plan_kernels
    if not shared.cfg.use_cache or isinstance(scene.content, Monitor):
        return
    with blas_threads(shared.blas_threads):  # the bits of the parent's kernels (threads.py)
        for z in depth_layers(band_image, scene, kernels.grid, shared.cfg).depths_m:
            if z != kernels.object_distance_m:
                plan_kernels(scene, displays or shared.displays, shared.cfg, object_distance_m=z)


def kept_spectra(shared: Shared, kernels: Kernels):
    """The block in which an item's summed kernel spectra are kept in the kernel cache too (optics.kept), so that
    every worker of this job and of the next loads what the first made: a job of fixed panels through the cache.
    A randomized job's panels are new each job, and their spectra used by few items: kept in memory only."""
    if shared.randomize is None and shared.cfg.use_cache and kernels.cache_spectra:
        return on_disk(kernels.cache_dir)
    return contextlib.nullcontext()


def make_item(shared: Shared, task: Task) -> dict:
    """Render and synthesise one item into a temporary folder, then rename it into place.
    Runs in this process, a pool process or a Dask worker; returns run times (s) for the log."""
    from udc_render.pipeline import synthesize
    from udc_render.render import render_scene
    age, t0, cpu0 = process_age_s(), time.perf_counter(), time.process_time()
    scene = replace(shared.scene, render=replace(shared.scene.render, seed=task.render_seed))
    if task.pose is None:  # a monitor item: its image
        scene = replace(scene, content=replace(scene.content, image=task.image))
    else:  # a 3D item: its camera pose (the focus distance stays the job's, fixed in shared.scene.lens)
        origin, target, up = task.pose
        scene = replace(scene, camera=replace(scene.camera, origin_m=origin, target_m=target, up=up))
    displays, cfg, setup = shared.displays, shared.cfg, None
    if shared.randomize is not None:  # the item's panel, sensor and exposure (dataset.randomized)
        setup = item_setup(shared.randomize, scene, shared.displays[0], shared.cfg, task.item)
        scene, displays, cfg = setup.scene, setup.displays, setup.cfg
    band_image = render_scene(scene, progress=False)
    if setup is not None:
        band_image, cfg, exposure = exposed(setup, band_image)
    t1 = time.perf_counter()
    kernels = worker_kernels(shared, None if setup is None else setup.panel.index)
    t_kernels = time.perf_counter()
    cache_layer_kernels(band_image, scene, shared, kernels, displays)
    with kept_spectra(shared, kernels):
        result = synthesize(band_image, scene, displays, cfg, task.item, kernels=kernels)
    if setup is not None:
        result = recorded(result, setup, exposure)
    t2 = time.perf_counter()
    final = shared.out / task.folder
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}{final.name}-", dir=final.parent))
    try:
        write_synthesis(tmp, result, shared.cfg.sensor.camera, side_by_side=shared.side_by_side,
                        previews=shared.previews)
        save_json(tmp / "item.json", item_record(task, [d.name for d in displays], shared.cfg.seed))
        os.chmod(tmp, 0o777 & ~current_umask())  # mkdtemp makes 0700
        os.rename(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return {"item": task.item, "folder": task.folder, "render_s": round(t1 - t0, 3),
            "kernels_s": round(t_kernels - t1, 3), "synth_s": round(t2 - t_kernels, 3),
            "write_s": round(time.perf_counter() - t2, 3),
            "cpu_s": round(time.process_time() - cpu0, 3),  # this process's CPU seconds (every thread's)
            "process_age_s": None if age is None else round(age, 3), "host": socket.gethostname(), "pid": os.getpid(),
            "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)}


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
    """A function tasks -> iterator of make_item's results: in process, a process pool (workers.py), or Dask."""
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
        keep_freed_memory()
        yield lambda tasks: (make_item(shared, t) for t in tasks)
        return
    threads = threads_per_worker(workers)
    # BLAS threads change the kernels' bits (psf's matrix products): a monitor's kernels come from this
    # process (or, with --no-cache, from worker_kernels at this process's count, as their field bases), so
    # its workers get a share of the cores; a 3D scene's workers compute their off-focus layers' kernels, so
    # they get this process's BLAS threads (the same bits as a 1-worker run; threads.py)
    blas = threads if isinstance(shared.scene.content, Monitor) else shared.blas_threads
    # forked (workers.py) or spawned inside the environment, held for the whole job
    with blas_threads_env(blas) if blas else contextlib.nullcontext():
        context = worker_context()
        pool = ProcessPoolExecutor(workers, mp_context=context, initializer=start_worker, initargs=(threads, blas))
        if context.get_start_method() == "spawn":  # started now, not waited for: they import while this process
            for _ in range(workers):  # checks the job and prepares the kernels (forked ones start at the first
                pool.submit(os.getpid)  # items' submission, with all of it imported)
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
        raise DatasetError("--scheduler needs the 'distributed' package: pip install 'udc-render[dist]'") from None
    try:
        client = distributed.Client(address, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError) as e:
        raise DatasetError(f"--scheduler {address}: cannot reach the scheduler ({type(e).__name__}: "
                        f"{str(e).splitlines()[0] if str(e) else 'no answer'})") from None
    try:
        try:
            client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        except TimeoutError:
            raise DatasetError(f"--scheduler {address}: no workers joined within {CONNECT_TIMEOUT_S:g} s") from None
        yield client
    finally:
        client.close()
