"""Threads per dataset worker: N workers on C cores each get max(1, C // N) threads, so that the pool
does not oversubscribe the cores (the FFTs of the optics, Dr.Jit's pool for Mitsuba renders, and the
BLAS/OpenMP libraries numpy loads). benchmarks/bench_dataset.py measures the scaling.

Threads decide how fast, never what: every item's bytes are the same at any thread count (tests).
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
