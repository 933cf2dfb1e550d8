"""Threads per dataset worker: N workers on C cores each get max(1, C // N) threads, so that the pool
does not oversubscribe the cores (the FFTs of the optics, Dr.Jit's pool for Mitsuba renders, and the
BLAS/OpenMP libraries numpy loads). benchmarks/bench_dataset.py measures the scaling.

Threads decide how fast, never what: every item's bytes are the same at any thread count (tests).
Except BLAS threads: psf's kernels (its matrix products) differ in the last bits with the BLAS thread
count, so the processes that compute kernels must share it: a monitor's kernels all come from the parent,
but a 3D scene's workers compute their items' off-focus layer kernels, so they get the parent's BLAS
thread count (parent_blas_threads), not a share of the cores.
"""
from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os

from threadpoolctl import threadpool_info, threadpool_limits

BLAS_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
# glibc's malloc for items (mallopt parameter: value): arrays up to 32 MB (a frame's float64 plane is 31.5 MB)
# from the heap, not mmap (M_MMAP_THRESHOLD, -3), freed memory kept up to 1 GB (M_TRIM_THRESHOLD, -1) and the heap
# grown 256 MB at a time (M_TOP_PAD, -2): an item's arrays reuse the last item's pages instead of faulting fresh
# ones in. After a process's first item: 52-58 k page faults an item → 1-2 k, its system CPU 0.95-1.09 → 0.18-0.28 s,
# its CPU 5-8 % less (benchmarks/bench_item_cpu.py; benchmarks/README.md, issue 46). The values are unchanged.
MALLOPT = {-3: 32 << 20, -1: 1 << 30, -2: 256 << 20}


def threads_per_worker(workers: int, cores: int | None = None) -> int:
    """max(1, cores // workers); cores: the CPUs this process may use."""
    cores = cores or len(os.sched_getaffinity(0))
    return max(1, cores // max(1, workers))


def keep_freed_memory() -> bool:
    """MALLOPT in this process through glibc's mallopt; False where the C library is not glibc (nothing done)."""
    try:
        mallopt = ctypes.CDLL(ctypes.util.find_library("c")).mallopt
    except (OSError, AttributeError, TypeError):
        return False
    return all(mallopt(param, value) == 1 for param, value in MALLOPT.items())


def set_worker_threads(threads: int) -> None:
    """In a process that makes items: the optics' and psf's FFT threads, Dr.Jit's thread pool (set when Mitsuba
    loads, render.variants.set_drjit_threads: a monitor's analytic render never loads it) and the allocator
    (keep_freed_memory)."""
    keep_freed_memory()
    import psf.fourier
    import udc_render.optics.convolution as convolution
    from udc_render.render.variants import set_drjit_threads
    convolution.FFT_WORKERS = threads
    psf.fourier.WORKERS = threads
    set_drjit_threads(threads)


def process_age_s() -> float | None:
    """Seconds since this process started (Linux: /proc/self/stat's start time against /proc/uptime), or None
    elsewhere: a worker's start-up before its first item (imports, kernels) in timing.jsonl."""
    try:
        with open("/proc/self/stat") as f:
            start_ticks = int(f.read().rsplit(")", 1)[1].split()[19])  # field 22, starttime
        with open("/proc/uptime") as f:
            uptime_s = float(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return None
    return uptime_s - start_ticks / os.sysconf("SC_CLK_TCK")


def parent_blas_threads() -> int | None:
    """The thread count of the BLAS numpy loaded in this process (threadpoolctl reads the library itself:
    the environment may have changed since it was loaded, e.g. by a Dask LocalCluster), or None."""
    counts = [i["num_threads"] for i in threadpool_info() if i.get("user_api") == "blas"]
    return int(counts[0]) if counts and counts[0] >= 1 else None


@contextlib.contextmanager
def blas_threads(threads: int | None):
    """Every loaded BLAS at `threads` threads inside the block (None: unchanged), restored after
    (threadpoolctl): kernels computed on a worker (a Dask worker's BLAS count is its cluster's) get the
    parent's bits."""
    if not threads:
        yield
        return
    with threadpool_limits(limits=int(threads), user_api="blas"):
        yield


@contextlib.contextmanager
def blas_threads_env(threads: int):
    """BLAS/OpenMP thread counts in the environment while worker processes are spawned (they read it
    when numpy loads, before any initializer runs); restored afterwards."""
    old = {k: os.environ.get(k) for k in BLAS_ENV}
    os.environ.update({k: str(threads) for k in BLAS_ENV})
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
