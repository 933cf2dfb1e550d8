#!/usr/bin/env python
"""The d > 0 field blend's knobs, error against run time (issue 46): SynthConfig.field_print_sigma (a view's blend
left out when it cannot print: views.field_print) and SynthConfig.field_rank (the rank of each band's phase basis).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_field_knobs.py [--image builtin:astronaut] [--ranks 1,2,3,4,6]
        [--out out/bench_field_knobs] [--figure docs/figures/field_knobs.png] [--from-json FILE]

The physical profile's job on the paper's frame (2048 × 1024, 30 bands, T-OLED and P-OLED at 2 mm, its monitor
image), one item's render: per display, the electrons of its view (views.channel_electrons as the synthesis calls
it, one thread, the exact-power maps and a rank's basis spectra made beforehand as a dataset worker has them)
through every phase kernel (the reference), through a rank-r basis and through the mean kernel (the blend left
out), with the CPU seconds of each (the least of two runs). The error of each:
the largest change of any pixel's electrons against the reference, in σ of the read noise (the least noise of
any pixel, field_print's unit), and the RMS of the change over each pixel's own noise σ = √(E + σ_read²); beside
the mean kernel, field_print's bound on that change. Writes a table (markdown) and the figure: error against
seconds, one line per display, the threshold field_print_sigma drawn across.
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from udc_render.io.files import save_text


def setup(image: str):
    """(shared, kernels with every phase kernel and their power maps stored, band image, sensor at its exposure)."""
    from udc_render.cli import build_parser
    from udc_render.cli.dataset import dataset_job
    from udc_render.dataset import _shared
    from udc_render.pipeline import auto_exposure_s, plan_kernels, sensor_for_scene, store_power_maps
    from udc_render.render import render_scene
    job = dataset_job(build_parser().parse_args(["dataset", "--builtin", "--display", "toled,poled", "--count", "1",
                                                 "--out", "out/bench_field_knobs/job", "--quiet"]))
    shared = _shared(job, Path("out/bench_field_knobs/job"))
    scene = replace(shared.scene, content=replace(shared.scene.content, image=image))
    kernels = store_power_maps(plan_kernels(shared.scene, shared.displays, shared.cfg), shared.scene,
                               shared.cfg.kernel_cache)
    band_image = render_scene(scene, progress=False)
    sensor = sensor_for_scene(shared.cfg.sensor, scene)
    return shared, kernels, band_image, replace(sensor, exposure_s=auto_exposure_s(band_image, sensor)[0])


def timed_electrons(band_image, view, sensor, cfg, primaries) -> tuple[np.ndarray, float]:
    """(electrons, the least CPU seconds of two runs) of one view, as the synthesis makes them (views.py: the
    monitor's planes and their spectra shared, made beforehand)."""
    from udc_render.views import channel_electrons
    best, e = np.inf, None
    for _ in range(2):
        t0 = time.process_time()
        e = channel_electrons(band_image, view, sensor, cfg, None, None, {}, primaries)[0]
        best = min(best, time.process_time() - t0)
    return e, best


def cases(shared, kernels, band_image, sensor, ranks) -> list[dict]:
    """Per d > 0 display: every phase (the reference; its phase kernels' spectra made per call), each rank (its
    bases' spectra made beforehand, as a dataset worker has them from the kernel cache) and the mean kernel."""
    from udc_render.optics import fft_shape, field_basis, field_weights, live_phases
    from udc_render.optics.convolution import kernel_spectra
    from udc_render.pipeline import capture_views, field_prints
    from udc_render.views import shared_primaries
    cfg = shared.cfg
    prints = field_prints(band_image, kernels, shared.displays, sensor, cfg)
    views = [v for v in capture_views(kernels, shared.displays, band_image.edges_nm) if v.name in prints]
    primaries = shared_primaries(band_image, views + [replace(views[0], field_print={"prints": False})], cfg)
    shape = fft_shape(band_image.bands.shape[1:], kernels.grid.kernel_size_px, band_image.margin_px)
    rows = []
    for view in views:
        ks, verdict = view.kernel_set, prints[view.name]
        blend = replace(view, field_print=verdict | {"prints": True}, spectra=None)
        ref, ref_s = timed_electrons(band_image, blend, sensor, replace(cfg, field_rank=None), primaries)
        sigma = np.sqrt(np.maximum(ref, 0) + sensor.read_noise_e ** 2)

        def row(knob, e, seconds, bound=None):
            d = np.abs(e - ref)
            return {"display": view.name, "knob": knob, "seconds": seconds, "max_sigma_read": float(d.max() /
                    sensor.read_noise_e), "rms_sigma": float(np.sqrt(np.mean((d / sigma) ** 2))), "bound": bound}
        rows.append(row("every phase", ref, ref_s))
        wy, wx, _ = field_weights(ks, band_image.bands.shape[1:], band_image.pitch_um, ks.distance_mm)
        for r in ranks:
            basis = field_basis(ks.field_kernels, live_phases(wy, wx), r)
            made = [kernel_spectra(b, shape, cfg.precision) for b in basis.bases]
            rank_view = replace(blend, field_basis=basis, spectra=lambda *_, made=made: made)
            rows.append(row(f"rank {r}", *timed_electrons(band_image, rank_view, sensor, replace(cfg, field_rank=r),
                                                          primaries)))
            del made, rank_view
        mean = replace(view, field_print=verdict | {"prints": False})
        rows.append(row("mean kernel (left out)", *timed_electrons(band_image, mean, sensor, cfg, primaries),
                        bound=verdict["bound_e"] / sensor.read_noise_e))
    return rows


def table(rows) -> str:
    lines = ["| display | knob | CPU s | max change / σ_read | RMS change / σ | field_print bound / σ_read |",
             "|---|---|---|---|---|---|"]
    lines += [f"| {r['display']} | {r['knob']} | {r['seconds']:.2f} | {r['max_sigma_read']:.3g} | {r['rms_sigma']:.3g} "
              f"| {'' if r['bound'] is None else format(r['bound'], '.3g')} |" for r in rows]
    return "\n".join(lines) + "\n"


def plot(rows, threshold: float, path: Path) -> None:
    from udc_render.io.plots import pyplot, save_plot
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for name, marker in (("toled", "o"), ("poled", "s")):
        pts = [r for r in rows if r["display"] == name and r["knob"] != "every phase"]
        pts.sort(key=lambda r: r["seconds"])
        ax.plot([r["seconds"] for r in pts], [max(r["max_sigma_read"], 1e-6) for r in pts], marker=marker, ls="-",
                label=f"{name}: the mean kernel, then rank 1, 2, …")
        for r in pts:
            if r["bound"] is not None:  # what field_print judged by
                ax.plot(r["seconds"], r["bound"], marker="x", color=ax.lines[-1].get_color(), ls="none")
                ax.annotate("its bound", (r["seconds"], r["bound"]), fontsize=7, xytext=(3, -9),
                            textcoords="offset points")
            ax.annotate(r["knob"].replace(" (left out)", ""), (r["seconds"], max(r["max_sigma_read"], 1e-6)),
                        fontsize=7, xytext=(3, 3), textcoords="offset points")
    ax.axhline(threshold, color="grey", ls="--", lw=1,
               label=f"field_print_sigma = {threshold:g}: a bound below it leaves the blend out")
    ax.set_yscale("log")
    ax.set_xlabel("CPU seconds of the view (one thread)")
    ax.set_ylabel("largest change of a pixel / σ_read (vs every phase)")
    ax.set_title("d > 0 field blend: error against run time, paper's frame, 2 mm")
    ax.legend(fontsize=8)
    save_plot(fig, path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--image", default="builtin:astronaut")
    ap.add_argument("--ranks", default="1,2,3,4,6")
    ap.add_argument("--out", type=Path, default=Path("out/bench_field_knobs"))
    ap.add_argument("--figure", type=Path, default=Path("docs/figures/field_knobs.png"))
    ap.add_argument("--from-json", type=Path, help="plot the rows of an earlier run's field_knobs.json only")
    a = ap.parse_args()
    from udc_render.pipeline import SynthConfig
    if a.from_json is not None:
        rows = json.loads(a.from_json.read_text())
    else:
        from udc_render.dataset.threads import set_worker_threads
        set_worker_threads(1)
        shared, kernels, band_image, sensor = setup(a.image)
        rows = cases(shared, kernels, band_image, sensor, [int(r) for r in a.ranks.split(",")])
        save_text(a.out / "field_knobs.json", json.dumps(rows, indent=1))
    text = table(rows)
    save_text(a.out / "field_knobs.md", text)
    plot(rows, SynthConfig.field_print_sigma, a.figure)
    print(text)


if __name__ == "__main__":
    main()
