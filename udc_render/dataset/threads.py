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
import os

BLAS_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def threads_per_worker(workers: int, cores: int | None = None) -> int:
    """max(1, cores // workers); cores: the CPUs this process may use."""
    cores = cores or len(os.sched_getaffinity(0))
    return max(1, cores // max(1, workers))


def set_worker_threads(threads: int) -> None:
    """In a worker process: the optics' and psf's FFT threads and Dr.Jit's thread pool."""
    import psf.fourier
    import udc_render.optics.convolution as convolution
    convolution.FFT_WORKERS = threads
    psf.fourier.WORKERS = threads
    import drjit
    drjit.set_thread_count(threads)


_OPENBLAS_GET = ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads", "openblas_get_num_threads64_",
                 "openblas_get_num_threads")


def _openblas_libs() -> list:
    """The OpenBLAS libraries loaded in this process (ctypes handles), numpy's first."""
    import ctypes
    import numpy  # noqa: F401  (loads its BLAS)
    try:
        with open("/proc/self/maps") as f:
            paths = {line.split()[-1] for line in f if "openblas" in line.lower() and ".so" in line}
    except OSError:
        return []
    libs = []
    for path in sorted(paths, key=lambda p: ("numpy" not in p, p)):
        try:
            libs.append(ctypes.CDLL(path))
        except OSError:
            pass
    return libs


def _symbol(lib, verb: str):
    for name in _OPENBLAS_GET:
        name = name.replace("_get_", f"_{verb}_")
        if hasattr(lib, name):
            return getattr(lib, name)
    return None


def parent_blas_threads() -> int | None:
    """The thread count of numpy's OpenBLAS in this process (read from the loaded library: the environment
    may have changed since it was loaded, e.g. by a Dask LocalCluster), or None when it cannot be read."""
    for lib in _openblas_libs():
        get = _symbol(lib, "get")
        if get is not None:
            n = int(get())
            return n if n >= 1 else None
    return None


@contextlib.contextmanager
def blas_threads(threads: int | None):
    """Every loaded OpenBLAS at `threads` threads inside the block (None: unchanged), restored after:
    kernels computed on a worker (a Dask worker's BLAS count is its cluster's) get the parent's bits."""
    if not threads:
        yield
        return
    saved = []
    for lib in _openblas_libs():
        get, put = _symbol(lib, "get"), _symbol(lib, "set")
        if get is not None and put is not None:
            saved.append((put, int(get())))
            put(int(threads))
    try:
        yield
    finally:
        for put, n in saved:
            put(n)


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
