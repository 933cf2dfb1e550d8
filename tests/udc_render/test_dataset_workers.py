"""A dataset pool's workers (udc_render.dataset.workers): forked from the job's process unless it has loaded
Dr.Jit, and at the BLAS thread count the job gives them, not their parent's. The items' bytes with 1 and 2
workers: tests/udc_render/test_dataset.py, test_dataset_bytes.py, test_dataset_3d.py."""
import multiprocessing
import sys
from concurrent.futures import ProcessPoolExecutor

import pytest
from threadpoolctl import threadpool_limits

import udc_render.dataset.workers as workers
from tests.udc_render.test_dataset_bytes import blas_count
from udc_render.dataset.workers import start_worker, worker_context

FORK = "fork" in multiprocessing.get_all_start_methods()


def marker() -> object:
    return getattr(workers, "MARKER", None)


@pytest.mark.skipif(not FORK, reason="no fork on this platform")
def test_workers_fork_unless_drjit_is_loaded(monkeypatch):
    monkeypatch.delitem(sys.modules, "drjit", raising=False)
    assert worker_context().get_start_method() == "fork"
    monkeypatch.setitem(sys.modules, "drjit", object())
    assert worker_context().get_start_method() == "spawn"


@pytest.mark.skipif(not FORK, reason="no fork on this platform")
def test_a_forked_worker_has_its_parents_state_without_importing_it_again(monkeypatch):
    """What this process holds at the fork (here a value set at run time, which no import would make) is the
    worker's: its modules are not imported afresh."""
    monkeypatch.delitem(sys.modules, "drjit", raising=False)
    monkeypatch.setattr(workers, "MARKER", 1234, raising=False)
    with ProcessPoolExecutor(1, mp_context=worker_context(), initializer=start_worker, initargs=(1, 1)) as pool:
        assert pool.submit(marker).result() == 1234


@pytest.mark.parametrize("parent, worker", [(2, 1), (1, 2)])
def test_a_worker_runs_its_blas_at_the_jobs_count_not_its_parents(parent, worker):
    """A forked worker copies its parent's BLAS pool; start_worker sets the job's count (threads.py: the kernels'
    bits depend on it)."""
    with threadpool_limits(limits=parent, user_api="blas"):
        if blas_count() != parent:
            pytest.skip("this BLAS does not take a thread count")
        with ProcessPoolExecutor(1, mp_context=worker_context(), initializer=start_worker,
                                 initargs=(1, worker)) as pool:
            assert pool.submit(blas_count).result() == worker
        assert blas_count() == parent
