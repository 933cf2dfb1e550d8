#!/usr/bin/env python
"""CPU seconds of a dataset worker's set-up and of its items, one thread (issue 46): a figure that other work on a
shared machine moves far less than the wall's.

    PYTHONPATH=TREE .venv/bin/python benchmarks/bench_item_cpu.py [--images builtin:astronaut,builtin:camera]
        [--profile physical] [--display toled,poled]

TREE is this checkout, or an older one to compare (`git archive COMMIT udc_render psf | tar -x -C DIR`; the same
kernel cache: run a one-item `udc-render dataset` job of the same settings first, so both trees find their
kernels there). As a dataset worker makes them, at one thread (BLAS, FFTs, Dr.Jit): the imports a worker makes, its
kernels (worker_kernels: loading, and whatever it computes), then per image one item through executors.make_item
(render, synthesis, files as a dataset item writes them, in out/bench_item_cpu): its CPU seconds, the stages' wall
seconds (at one thread on a quiet machine, their CPU), and its page faults and system CPU (getrusage: memory
faulted in afresh). Items after the first are a worker's steady state.
"""
from __future__ import annotations

import argparse
import os
import time

os.environ.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")  # before numpy loads

CPU_START = time.process_time()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", default="builtin:astronaut,builtin:camera")
    ap.add_argument("--profile", default="physical")
    ap.add_argument("--display", default="toled,poled")
    a = ap.parse_args()
    import resource
    import shutil
    from pathlib import Path

    import udc_render
    from udc_render.cli import build_parser
    from udc_render.cli.dataset import dataset_job
    from udc_render.dataset import _shared
    from udc_render.dataset.executors import make_item, worker_kernels
    from udc_render.dataset.plan import Task
    from udc_render.dataset.threads import set_worker_threads
    set_worker_threads(1)
    imports = time.process_time() - CPU_START
    out = Path("out/bench_item_cpu")
    shutil.rmtree(out, ignore_errors=True)
    job = dataset_job(build_parser().parse_args(["dataset", "--builtin", "--display", a.display, "--profile",
                                                 a.profile, "--count", "1", "--out", str(out), "--quiet"]))
    shared = _shared(job, out)
    c0 = time.process_time()
    worker_kernels(shared)
    print(f"code: {Path(udc_render.__file__).parent}\nimports {imports:.2f} CPU s, kernels "
          f"{time.process_time() - c0:.2f} CPU s")
    for i, image in enumerate(a.images.split(",")):
        u0 = resource.getrusage(resource.RUSAGE_SELF)
        r = make_item(shared, Task(item=i, split="train", folder=f"items/{i:04d}", image=image, label=image,
                                   render_seed=i))
        u1 = resource.getrusage(resource.RUSAGE_SELF)
        print(f"{image}: {r['cpu_s']:.2f} CPU s (render {r['render_s']:.2f} s, synthesis {r['synth_s']:.2f} s, files "
              f"{r['write_s']:.2f} s); {u1.ru_minflt - u0.ru_minflt} page faults, {u1.ru_stime - u0.ru_stime:.2f} s of "
              "it system CPU", flush=True)
    shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    main()
