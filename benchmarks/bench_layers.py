#!/usr/bin/env python
"""What the depth layers and the bright-source split cost: the optics of the built-in room and HDR scene at
the paper's 2048 × 1024 with their default layers, against the same optics with defocus off (one layer, the
cost before issue 14), and the layers' kernels.

For each scene: one render (its own spp here: the optics' cost does not depend on the render's noise), the
physical profile's views (ground truth, T-OLED and P-OLED at d = 2 mm, 30 bands), then, interleaved, R
rounds of views.layered_electrons with the default layers and with defocus off (kernels planned and
loaded before the clock starts; the kernels' own seconds reported apart, from a cold cache when --cold).
Median seconds, the ratio in the same run (the machine is shared), the layer count and blur range, and the
number of bright pixels convolved apart.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_layers.py [--scenes room,hdr] [--spp 4] [--repeats 3]
        [--tolerance-px 1.0 0.5] [--cache-dir DIR] [--out out/bench/layers.md]
"""
from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import replace
from pathlib import Path

from udc_render.io.files import save_text
from udc_render.optics.displays import load_displays
from udc_render.pipeline import (
    DEFAULT_DEFOCUS_TOLERANCE_PX,
    SynthConfig,
    auto_exposure_s,
    capture_views,
    compact_kernels,
    depth_layers,
    layer_kernels,
    plan_kernels,
    sensor_for_scene,
)
from udc_render.profiles import resolve_profile
from udc_render.render import render_scene
from udc_render.scene import load_scene
from udc_render.views import bright_pixels, layered_electrons


def setup(name: str, spp: int, cache_dir: str | None, tolerance_px: float):
    """(scene, render, displays, cfg, kernels per layer with and without defocus, layers, seconds of kernels)."""
    scene = load_scene(name).with_render(spp=spp)
    cfg, displays = resolve_profile("physical", SynthConfig(kernel_cache=cache_dir, defocus_tolerance_px=tolerance_px),
                                    load_displays("toled,poled"))
    t0 = time.perf_counter()
    band_image = render_scene(scene, progress=True)
    render_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    base = compact_kernels(plan_kernels(scene, displays, cfg, progress=True), scene, cfg)
    off = replace(cfg, defocus_tolerance_px=None)
    base_off = compact_kernels(plan_kernels(scene, displays, off, progress=True), scene, off)
    layers = depth_layers(band_image, scene, base.grid, cfg)
    per_layer = layer_kernels(layers, base, scene, displays, cfg, progress=True)
    kernel_s = time.perf_counter() - t0
    return scene, band_image, displays, cfg, per_layer, base_off, layers, render_s, kernel_s


def optics_seconds(band_image, scene, displays, cfg, per_layer, layers, bright) -> float:
    sensor = sensor_for_scene(cfg.sensor, scene)
    sensor = replace(sensor, exposure_s=auto_exposure_s(band_image, sensor)[0])
    t0 = time.perf_counter()
    layered_electrons(band_image, layers, lambda i: capture_views(per_layer[i], displays, band_image.edges_nm),
                      sensor, cfg, bright)
    return time.perf_counter() - t0


def bench(name: str, spp: int, repeats: int, cache_dir: str | None, tolerance_px: float) -> dict:
    scene, bi, displays, cfg, per_layer, base_off, layers, render_s, kernel_s = setup(name, spp, cache_dir,
                                                                                      tolerance_px)
    off = replace(cfg, defocus_tolerance_px=None)
    single = depth_layers(bi, scene, base_off.grid, off)
    sensor = sensor_for_scene(cfg.sensor, scene)
    bright = bright_pixels(bi, replace(sensor, exposure_s=auto_exposure_s(bi, sensor)[0]))
    t_layers, t_single = [], []
    for _ in range(repeats):
        t_layers.append(optics_seconds(bi, scene, displays, cfg, per_layer, layers, bright))
        t_single.append(optics_seconds(bi, scene, displays, off, [base_off], single, bright))
    d = layers.describe()
    return {"scene": name, "tolerance_px": tolerance_px, "layers": layers.count, "blur_px": d["blur_diameter_px"],
            "share": d["pixel_share"],
            "bright_px": 0 if bright is None else int(bright.mask.sum()), "layered_s": statistics.median(t_layers),
            "single_s": statistics.median(t_single), "render_s": render_s, "kernel_s": kernel_s}


def table(rows: list[dict], repeats: int) -> str:
    lines = ["# Depth layers and bright sources: optics cost at 2048 × 1024", "",
             f"Physical profile (ground truth, T-OLED and P-OLED at d = 2 mm, 30 bands), median of {repeats} "
             "interleaved rounds of views.layered_electrons; `kernels s` is every kernel these runs needed "
             "(the layers' included; cold or cached as the cache was). Target: layered ≤ 3 × one layer.", "",
             "| scene | tolerance px | layers | blur diameters (px) | pixel share | bright px | one layer s "
             "| layered s | ratio | kernels s |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['tolerance_px']:g} | {r['layers']} | "
                     f"{', '.join(f'{b:.2f}' for b in r['blur_px'])} | "
                     f"{', '.join(f'{s:.2f}' for s in r['share'])} | {r['bright_px']} | {r['single_s']:.2f} | "
                     f"{r['layered_s']:.2f} | {r['layered_s'] / r['single_s']:.2f} | {r['kernel_s']:.0f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument("--scenes", default="room,hdr")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--cache-dir", default=None)
    ap.add_argument("--tolerance-px", type=float, nargs="+", default=[DEFAULT_DEFOCUS_TOLERANCE_PX],
                    help="defocus tolerances to time (each its own render of the scene)")
    ap.add_argument("--out", type=Path, default=Path("out/bench/layers.md"))
    args = ap.parse_args()
    rows = [bench(n, args.spp, args.repeats, args.cache_dir, t)
            for n in args.scenes.split(",") for t in args.tolerance_px]
    text = table(rows, args.repeats)
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_text(args.out, text)


if __name__ == "__main__":
    main()
