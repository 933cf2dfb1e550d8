#!/usr/bin/env python
"""CPU seconds of a dataset worker's set-up and of its items, one thread (issue 46): a figure that other work on a
shared machine moves far less than the wall's.

    PYTHONPATH=TREE .venv/bin/python benchmarks/bench_item_cpu.py [--images builtin:astronaut,builtin:camera]
        [--profile physical] [--display toled,poled]

TREE is this checkout, or an older one to compare (`git archive COMMIT udc_render psf | tar -x -C DIR`; the same
kernel cache: run a one-item `udc-render dataset` job of the same settings first, so both trees find their
kernels there). As executors.make_item runs them at one thread (BLAS, FFTs, Dr.Jit): the imports a worker makes,
its kernels (worker_kernels: loading, and whatever it computes), then per image the render, the synthesis
(`pipeline.synthesize`) and the files (`io.capture.write_synthesis` into a temporary folder, as a dataset item
without previews), and the item's page faults and system CPU (getrusage: memory faulted in afresh).
"""
from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time

os.environ.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")  # before numpy loads

CPU_START = time.process_time()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", default="builtin:astronaut,builtin:camera")
    ap.add_argument("--profile", default="physical")
    ap.add_argument("--display", default="toled,poled")
    a = ap.parse_args()
    from dataclasses import replace
    from pathlib import Path

    import udc_render
    from udc_render.cli import build_parser
    from udc_render.cli.dataset import dataset_job
    from udc_render.dataset import _shared
    from udc_render.dataset.executors import worker_kernels
    from udc_render.dataset.threads import set_worker_threads
    from udc_render.io.capture import write_synthesis
    from udc_render.pipeline import synthesize
    from udc_render.render import render_scene
    set_worker_threads(1)
    imports = time.process_time() - CPU_START
    out = Path("out/bench_item_cpu")
    job = dataset_job(build_parser().parse_args(["dataset", "--builtin", "--display", a.display, "--profile",
                                                 a.profile, "--count", "1", "--out", str(out), "--quiet"]))
    shared = _shared(job, out)
    c0 = time.process_time()
    kernels = worker_kernels(shared)
    print(f"code: {Path(udc_render.__file__).parent}\nimports {imports:.2f} CPU s, kernels "
          f"{time.process_time() - c0:.2f} CPU s")
    for image in a.images.split(","):
        scene = replace(shared.scene, content=replace(shared.scene.content, image=image))
        u0 = resource.getrusage(resource.RUSAGE_SELF)
        c0 = time.process_time()
        band_image = render_scene(scene, progress=False)
        c1 = time.process_time()
        result = synthesize(band_image, scene, shared.displays, shared.cfg, 0, kernels=kernels)
        c2 = time.process_time()
        with tempfile.TemporaryDirectory() as tmp:  # the files as a dataset item writes them (no previews)
            write_synthesis(Path(tmp), result, shared.cfg.sensor.camera, side_by_side=False, previews=False)
        u1 = resource.getrusage(resource.RUSAGE_SELF)
        print(f"{image}: render {c1 - c0:.2f} CPU s, synthesis {c2 - c1:.2f} CPU s, files "
              f"{time.process_time() - c2:.2f} CPU s; {u1.ru_minflt - u0.ru_minflt} page faults, "
              f"{u1.ru_stime - u0.ru_stime:.2f} s of it system CPU", flush=True)


if __name__ == "__main__":
    main()
