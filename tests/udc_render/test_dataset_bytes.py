"""Every file a dataset job writes, records included, has the same bytes with 1 and 2 workers and after a
resume (issue 45): the two mechanisms that broke it, then whole randomized jobs (slow) where they showed.

- The rank-r field bases (optics.field.phase_basis, in pipeline.compact_kernels) were made on a worker's BLAS
  threads (a share of the cores), and their kernel residual, recorded in capture.json, changed in its last
  digits with the thread count (kernels of S ≥ 29 px over 16 phases: numpy's norm is a threaded BLAS dot above
  10⁴ elements).
- Without the kernel cache (--no-cache) each worker computed its kernels with its own BLAS thread count, and
  psf's kernels change in their last bits with it: raw.dng and gt.exr differed.
"""
import shutil

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from tests.conftest import monitor_doc, write_scene
from tests.udc_render.test_dataset import assert_same_files
from tests.udc_render.test_dataset_randomize import FOLDERS, args
from udc_render.cli import main
from udc_render.dataset.executors import Shared, worker_kernels
from udc_render.optics.displays import load_display
from udc_render.optics.field import phase_basis
from udc_render.pipeline import Kernels, SynthConfig, plan_kernels
from udc_render.scene import load_scene

pytestmark = pytest.mark.usefixtures("render_cache")


def blas_count() -> int:
    return [i["num_threads"] for i in threadpool_info() if i.get("user_api") == "blas"][0]


def test_a_worker_prepares_its_kernels_at_the_parents_blas_threads(tiny_dataset_scene, tmp_path, monkeypatch):
    """The kernels, their rank-r field bases (whose residual capture.json records), the exact-power maps and the
    plane bases (a Gram matrix's eigenvectors) are made at the parent's BLAS thread count in a worker that has
    fewer."""
    import udc_render.pipeline as pipeline
    seen = {}

    def spy(name):
        def made(*args, **kwargs):
            seen[name] = blas_count()
            return Kernels(None, {})
        return made
    for name in ("plan_kernels", "compact_kernels", "store_power_maps", "store_field_planes"):
        monkeypatch.setattr(pipeline, name, spy(name))
    shared = Shared(load_scene(tiny_dataset_scene), [load_display("glass")], SynthConfig(), tmp_path, False, False,
                    blas_threads=2)
    with threadpool_limits(limits=1, user_api="blas"):
        worker_kernels(shared)
        assert blas_count() == 1
    assert seen == {"plan_kernels": 2, "compact_kernels": 2, "store_power_maps": 2, "store_field_planes": 2}


def test_the_field_basis_residual_depends_on_the_blas_threads():
    """Why the bases are made at one thread count: 16 phase kernels of 33 px at rank 2, the residual (a
    Frobenius ratio, ≈ 0.0046) read 0.004599089615468634 at 1 BLAS thread and …635 at 2 (OpenBLAS; another BLAS
    may agree, then there is nothing to show)."""
    rng = np.random.default_rng(1)
    base = rng.random((33, 33))
    kernels = np.stack([base + 0.01 * rng.random((33, 33)) for _ in range(16)])
    kernels /= kernels.sum(axis=(1, 2), keepdims=True)
    residuals = []
    for threads in (1, 2):
        with threadpool_limits(limits=threads, user_api="blas"):
            residuals.append(phase_basis(kernels, 2)[2])
    if residuals[0] == residuals[1]:
        pytest.skip("this BLAS sums the residual alike at 1 and 2 threads")
    assert residuals[0] == pytest.approx(residuals[1], rel=1e-12) and 0 < residuals[0] < 0.05


def test_a_worker_plans_its_kernels_at_the_parents_blas_threads(tiny_dataset_scene, tmp_path):
    """Without the cache a worker computes its kernels: at one BLAS thread (a pool worker's share) with a
    parent of two, they are the bits the parent would compute."""
    scene = load_scene(tiny_dataset_scene)
    glass = [load_display("glass")]
    cfg = SynthConfig(use_cache=False)

    def planned(threads):
        with threadpool_limits(limits=threads, user_api="blas"):
            return plan_kernels(scene, glass, cfg).band["glass"].kernels.tobytes()
    at_two = planned(2)
    if planned(1) == at_two:
        pytest.skip("this BLAS computes psf's kernels with the same bits at 1 and 2 threads")
    shared = Shared(scene, glass, cfg, tmp_path, False, False, blas_threads=2)
    with threadpool_limits(limits=1, user_api="blas"):
        worker = worker_kernels(shared).band["glass"].kernels.tobytes()
    assert worker == at_two


@pytest.mark.slow
def test_without_the_cache_two_workers_give_the_same_bytes(tiny_dataset_scene, tmp_path):
    """--no-cache: each of 2 workers plans its panels' kernels; every file as a 1-worker run with the cache."""
    reference, two = tmp_path / "one", tmp_path / "two"
    assert main(args(tiny_dataset_scene, reference)) == 0
    assert main(args(tiny_dataset_scene, two, "--workers", "2", "--no-cache")) == 0
    assert_same_files(two, reference)


@pytest.mark.slow
def test_records_have_the_same_bytes_with_kernels_of_31_px(tmp_path):
    """A 700 µm margin (31 px kernels) and 16 field phases: the field basis's residual, recorded in every
    random/capture.json, is the same with 2 workers and after a resume (it was not, on main)."""
    scene = tmp_path / "mon.toml"
    write_scene(scene, monitor_doc(sensor_px=(64, 32), pitch_um=49.6, render={"spp": 2, "margin_um": 700},
                                   bands={"range_nm": [400, 700], "step_nm": 100}))
    reference, two, resumed = tmp_path / "one", tmp_path / "two", tmp_path / "resumed"

    def run(out, *extra):  # every panel's blend made (a faint one is left out by default: field_print)
        return main(args(scene, out, "--field-phases", "4", "--field-print-sigma", "off", *extra))
    assert run(reference) == 0
    assert all('"field_rank_kernel_residual"' in (reference / f / "random/capture.json").read_text()
               for f in FOLDERS)
    assert '"kernel_px": 31' in (reference / FOLDERS[0] / "random/capture.json").read_text()
    assert run(two, "--workers", "2") == 0
    assert_same_files(two, reference)
    shutil.copytree(reference, resumed)
    for f in FOLDERS[::2]:
        shutil.rmtree(resumed / f)
    assert run(resumed, "--workers", "2") == 0
    assert_same_files(resumed, reference)
