#!/usr/bin/env python
"""Light is conserved: what the far field (optics.far_field) adds and costs on the paper's rig.

1. lost: each preset's share of the transmitted power outside the default 513-px core window (1.55 µm, the
   monitor scene's margin of 396 µm; 450/550/650 nm), the far share the far field lays on the sensor and
   the share beyond the acceptance.
2. invariant: P-OLED, d = 0, spectral, 2048 × 1024 (the monitor scene, bands of --bands): the electrons of
   the P-OLED view over the frame for a small bright patch (a 32 × 32 white square of the 3840 × 2160
   panel) and a flat field (every render pixel 1), at render.margin_um 396 and 1200, far field off and on.
3. time: views.layered_electrons of the P-OLED view (and the ground truth), 2048 × 1024, 30 bands, d = 0 and
   the physical profile's d = 2 mm, far field off and at the default threshold, median of --repeats
   interleaved rounds (kernels planned and cached before the clock starts), and the P-OLED's far field
   alone (optics.apply.far_field_images into the 3 camera channels; the difference of the two medians is
   within a loaded machine's noise).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_far_field.py [--parts lost,invariant,time] [--bands 400:700:50]
        [--repeats 3] [--out out/bench/far_field.md]
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from udc_render.io.files import save_text
from udc_render.optics.apply import far_field_images
from udc_render.optics.displays import load_displays
from udc_render.pipeline import (
    SynthConfig,
    auto_exposure_s,
    capture_views,
    depth_layers,
    plan_kernels,
    sensor_for_scene,
)
from udc_render.render import render_scene
from udc_render.scene import load_scene, parse_bands
from udc_render.sensor import SensorConfig, band_electron_weights
from udc_render.views import layered_electrons

OFF = SynthConfig(sensor=SensorConfig(noise="none"), far_field_threshold=None)
ON = replace(OFF, far_field_threshold=SynthConfig.far_field_threshold)


def _shares(a) -> str:
    return " / ".join(f"{v:.2%}" for v in a)


def lost_part() -> list[str]:
    scene = replace(load_scene("monitor"), bands=parse_bands("400:700:100"))
    k = plan_kernels(scene, load_displays("toled,poled"), replace(ON, far_field_threshold=0.0))
    lines = ["## Lost share at the 513-px window and the far field (450 / 550 / 650 nm)", "",
             "| view | lost share o | far share added | beyond the acceptance |", "|---|---|---|---|"]
    for name, ks in k.band.items():
        f = k.far[name]
        lines.append(f"| {name} | {_shares(ks.energy_outside)} | {_shares(f.added)} | {_shares(f.beyond)} |")
    return lines + [""]


def _patch_image(folder: Path) -> str:
    code = np.zeros((2160, 3840, 3), np.uint8)
    code[1064:1096, 1904:1936] = 255
    path = folder / "patch.png"
    iio.imwrite(path, code)
    return str(path)


def _electrons(scene, band_image, cfg) -> float:
    """The P-OLED view's electrons over the frame (d = 0, exposure 1 s, no noise, no clipping)."""
    poled = load_displays("poled")[1:]
    kernels = plan_kernels(scene, poled, cfg)
    sensor = replace(sensor_for_scene(cfg.sensor, scene), exposure_s=1.0)
    layers = depth_layers(band_image, scene, kernels.grid, cfg)
    e = layered_electrons(band_image, layers, lambda _layer: capture_views(kernels, poled, band_image.edges_nm),
                          sensor, cfg)
    return float(e["poled"][0].sum())


def invariant_part(bands: str) -> list[str]:
    lines = [f"## Total light of the P-OLED view, 2048 × 1024, d = 0, bands {bands} nm", "",
             "| scene | margin µm | far field off | far field on |", "|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        base = replace(load_scene("monitor"), bands=parse_bands(bands))
        base = replace(base, content=replace(base.content, image=_patch_image(Path(tmp))))
        totals = {}
        for margin in (396.0, 1200.0):
            scene = base.with_render(margin_um=margin)
            b = render_scene(scene, progress=False)
            for kind, bi in (("patch", b), ("flat", replace(b, bands=np.ones_like(b.bands)))):
                totals[kind, margin] = [_electrons(scene, bi, cfg) for cfg in (OFF, ON)]
        for kind in ("patch", "flat"):
            for margin in (396.0, 1200.0):
                off, on = totals[kind, margin]
                ref_off, ref_on = totals[kind, 1200.0]
                lines.append(f"| {kind} | {margin:g} | {off:.6g} ({off / ref_off - 1:+.2%}) "
                             f"| {on:.6g} ({on / ref_on - 1:+.2%}) |")
    return lines + ["", "(in brackets: against margin 1200 µm)", ""]


def time_part(repeats: int) -> list[str]:
    lines = [f"## Optics seconds, P-OLED view and ground truth, 2048 × 1024, 30 bands (median of {repeats})", "",
             "| d mm | far field off s | far field on s | added s | the P-OLED's far field alone s |",
             "|---|---|---|---|---|"]
    scene = load_scene("monitor")
    b = render_scene(scene, progress=False)
    for d_mm in (0.0, 2.0):
        poled = [d.with_distance(d_mm) for d in load_displays("poled")[1:]]
        runs = {}
        for cfg in (OFF, ON):
            kernels = plan_kernels(scene, poled, cfg)
            sensor = sensor_for_scene(cfg.sensor, scene)
            sensor = replace(sensor, exposure_s=auto_exposure_s(b, sensor)[0])
            layers = depth_layers(b, scene, kernels.grid, cfg)
            runs[cfg.far_field_threshold] = (kernels, sensor, layers, cfg)
        times = {k: [] for k in runs}
        for _ in range(repeats):
            for key, (kernels, sensor, layers, cfg) in runs.items():
                t0 = time.perf_counter()
                layered_electrons(b, layers, lambda _layer: capture_views(kernels, poled, b.edges_nm), sensor, cfg)
                times[key].append(time.perf_counter() - t0)
        off, on = statistics.median(times[None]), statistics.median(times[ON.far_field_threshold])
        kernels, sensor = runs[ON.far_field_threshold][:2]
        w = band_electron_weights(b.edges_nm, sensor)
        far = kernels.far["poled"]
        gains = poled[0].transmission.band_means(b.edges_nm) * kernels.band["poled"].transmittance
        alone = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            far_field_images(b.bands, far, b.margin_px, gains, w)
            alone.append(time.perf_counter() - t0)
        lines.append(f"| {d_mm:g} | {off:.2f} | {on:.2f} | {on - off:+.2f} | {statistics.median(alone):.2f} |")
    return lines + [""]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default="lost,invariant,time")
    ap.add_argument("--bands", default="400:700:50", help="bands of the invariant part (range:step nm)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path("out/bench/far_field.md"))
    args = ap.parse_args()
    parts = args.parts.split(",")
    lines = ["# The far field: lost light, invariance, cost", ""]
    if "lost" in parts:
        lines += lost_part()
    if "invariant" in parts:
        lines += invariant_part(args.bands)
    if "time" in parts:
        lines += time_part(args.repeats)
    text = "\n".join(lines) + "\n"
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_text(args.out, text)


if __name__ == "__main__":
    main()
