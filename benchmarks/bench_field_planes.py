#!/usr/bin/env python
"""The field blend through the monitor's planes, error against run time (issue 46): SynthConfig.field_planes_rank
(J, the shared weight maps: optics.field_planes) against the band path at the same field rank.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_field_planes.py [--images builtin:astronaut,builtin:coffee]
        [--ranks 1,2,3,4,6,8] [--out out/bench_field_planes] [--figure docs/figures/field_planes.png]

The physical profile's job on the paper's frame (2048 × 1024, 30 bands, T-OLED and P-OLED at 2 mm), each image's
render: per d > 0 display, the electrons of its view (views.channel_electrons, one thread, as a dataset worker
has its kernels: prepare_kernels, from the kernel cache) through the band path (the reference: rank-4 bases, their
spectra from the cache) and through the planes at each J, with the CPU seconds (the least of two runs: the summed
kernels' spectra are made on a worker's first item, then kept; 'first' is that item's). The error: the largest
change of any pixel's electrons in σ of the read noise, the RMS over each pixel's own noise √(E + σ_read²), and the
recorded bound (optics.field_planes.planes_bound). Writes a markdown table, a JSON and the figure.
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from udc_render.io.files import save_text


def timed(band_image, view, sensor, cfg, primaries) -> tuple[np.ndarray, dict, float, float]:
    """(electrons, record, the first run's CPU s, the least of two)."""
    from udc_render.views import channel_electrons
    times, out = [], None
    for _ in range(2):
        t0 = time.process_time()
        out = channel_electrons(band_image, view, sensor, cfg, None, None, {}, primaries)
        times.append(time.process_time() - t0)
    return out[0], out[1], times[0], min(times)


def cases(image: str, ranks: list[int]) -> list[dict]:
    from udc_render.cli import build_parser
    from udc_render.cli.dataset import dataset_job
    from udc_render.dataset import _shared
    from udc_render.optics import field_planes
    from udc_render.pipeline import auto_exposure_s, capture_views, prepare_kernels, sensor_for_scene
    from udc_render.render import render_scene
    from udc_render.views import shared_primaries
    out = Path("out/bench_field_planes/job")
    shared = _shared(dataset_job(build_parser().parse_args(["dataset", "--builtin", "--display", "toled,poled",
                                                            "--count", "1", "--out", str(out), "--quiet"])), out)
    scene = replace(shared.scene, content=replace(shared.scene.content, image=image))
    cfg = replace(shared.cfg, field_print_sigma=None)  # every d > 0 view blended
    kernels = prepare_kernels(shared.scene, shared.displays, cfg)
    band_image = render_scene(scene, progress=False)
    sensor = sensor_for_scene(cfg.sensor, scene)
    sensor = replace(sensor, exposure_s=auto_exposure_s(band_image, sensor)[0])
    views = [v for v in capture_views(kernels, shared.displays, band_image.edges_nm) if v.field_planes is not None]
    primaries = shared_primaries(band_image, views + [replace(views[0], field_print={"prints": False})], cfg)
    rows = []
    for view in views:
        ref, _, _, ref_s = timed(band_image, view, sensor, replace(cfg, field_planes_rank=None), primaries)
        sigma = np.sqrt(np.maximum(ref, 0) + sensor.read_noise_e ** 2)
        rows.append({"image": image, "display": view.name, "knob": f"band path, rank {cfg.field_rank}",
                     "seconds": ref_s, "first_seconds": ref_s, "max_sigma_read": 0.0, "rms_sigma": 0.0, "bound": 0.0})
        for J in ranks:
            field_planes._SPECTRA.clear()  # each J's first item makes its summed kernels' spectra
            e, record, first, best = timed(band_image, view, sensor, replace(cfg, field_planes_rank=J), primaries)
            d = np.abs(e - ref)
            rows.append({"image": image, "display": view.name, "knob": f"planes, J = {J}", "seconds": best,
                         "first_seconds": first, "max_sigma_read": float(d.max() / sensor.read_noise_e),
                         "rms_sigma": float(np.sqrt(np.mean((d / sigma) ** 2))),
                         "bound": record["field_planes"]["bound_e"] / sensor.read_noise_e})
    return rows


def table(rows) -> str:
    lines = ["| image | display | knob | CPU s (kept spectra) | CPU s (first item) | max change / σ_read | "
             "RMS change / σ | bound / σ_read |", "|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r['image']} | {r['display']} | {r['knob']} | {r['seconds']:.2f} | {r['first_seconds']:.2f} | "
              f"{r['max_sigma_read']:.3g} | {r['rms_sigma']:.3g} | {r['bound']:.3g} |" for r in rows]
    return "\n".join(lines) + "\n"


def plot(rows, default_rank: int, path: Path) -> None:
    from udc_render.io.plots import pyplot, save_plot
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for (image, display), marker in zip(sorted({(r["image"], r["display"]) for r in rows}), "osd^v<>"):
        pts = [r for r in rows if (r["image"], r["display"]) == (image, display) and r["knob"].startswith("planes")]
        ref = next(r for r in rows if (r["image"], r["display"]) == (image, display) and r["knob"].startswith("band"))
        line = ax.plot([r["seconds"] for r in pts], [max(r["max_sigma_read"], 1e-6) for r in pts], marker=marker,
                       label=f"{display}, {image.split(':')[-1]}: J = 1, 2, … (band path {ref['seconds']:.1f} s)")[0]
        for r in pts:
            if r["knob"].endswith(f"= {default_rank}"):
                ax.annotate(f"J = {default_rank} (default)", (r["seconds"], r["max_sigma_read"]), fontsize=7,
                            xytext=(4, 4), textcoords="offset points", color=line.get_color())
    ax.set_yscale("log")
    ax.set_xlabel("CPU seconds of the view (one thread, the summed kernels' spectra kept)")
    ax.set_ylabel("largest change of a pixel / σ_read (vs the band path)")
    ax.set_title("Field blend through the monitor's planes: error against run time, paper's frame, 2 mm")
    ax.legend(fontsize=7)
    save_plot(fig, path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", default="builtin:astronaut,builtin:coffee")
    ap.add_argument("--ranks", default="1,2,3,4,6,8")
    ap.add_argument("--out", type=Path, default=Path("out/bench_field_planes"))
    ap.add_argument("--figure", type=Path, default=Path("docs/figures/field_planes.png"))
    a = ap.parse_args()
    from udc_render.dataset.threads import set_worker_threads
    from udc_render.pipeline import SynthConfig
    set_worker_threads(1)
    ranks = [int(r) for r in a.ranks.split(",")]
    rows = [row for image in a.images.split(",") for row in cases(image, ranks)]
    save_text(a.out / "field_planes.json", json.dumps(rows, indent=1))
    text = table(rows)
    save_text(a.out / "field_planes.md", text)
    plot(rows, SynthConfig.field_planes_rank, a.figure)
    print(text)


if __name__ == "__main__":
    main()
