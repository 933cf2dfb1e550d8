"""A dataset pool's worker processes: forked from the process that runs the job, which has imported what an item
needs, so that a worker starts in milliseconds instead of a fresh interpreter's ~1.2 s of imports (spawn).

Fork copies one thread: the libraries' thread pools are rebuilt in the child by their own fork handlers (OpenBLAS,
scipy.fft's pocketfft), the Python threads of this process (a progress bar's monitor) are not copied. Dr.Jit's
threads have no such handler: a process that has loaded it (Mitsuba: an XML scene's camera) spawns its workers.
A worker's BLAS thread count is set by start_worker (threadpoolctl), in a forked worker as in a spawned one.
"""
from __future__ import annotations

import multiprocessing
import sys

from threadpoolctl import threadpool_limits

from udc_render.dataset.threads import set_worker_threads


def worker_context() -> multiprocessing.context.BaseContext:
    """fork where the platform has it and Dr.Jit is not loaded in this process; spawn otherwise."""
    if "fork" in multiprocessing.get_all_start_methods() and "drjit" not in sys.modules:
        return multiprocessing.get_context("fork")
    return multiprocessing.get_context("spawn")


def start_worker(threads: int, blas: int | None) -> None:
    """A worker's initializer: BLAS and OpenMP at `blas` threads (threadpoolctl; a spawned worker has them from
    the environment already, a forked one has its parent's pools), then the item's threads (set_worker_threads)."""
    if blas:
        threadpool_limits(limits=int(blas))
    set_worker_threads(threads)
