#!/usr/bin/env python
"""How much light each stray-light effect (udc_render.optics.stray) moves on the default monitor capture.

The default monitor scene (the astronaut on the 27-inch panel, 2048 × 1024, 30 bands), the physical
profile's views (ground truth through glass, T-OLED and P-OLED at its display-to-lens distance), noise-free;
the views' electrons are taken where the pipeline hands them to the stray light, then each effect alone at
its on-value (settings.ON_VALUES; the P-OLED's haze is its default) is applied to each view. Per view:
moved = Σ|e_on − e_off| / Σ e_off and net = Σ(e_on − e_off) / Σ e_off over the RGGB mosaic (the gap study's
share of light moved), and the seconds the effect took.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_stray_light.py [--distance-mm D] [--out out/bench/stray_light.md]
"""
from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import udc_render.pipeline as pipeline
from udc_render.io.files import save_text
from udc_render.optics.displays import load_displays
from udc_render.optics.stray import ON_VALUES, StrayContext, StrayLight, apply_view, synthesis_stray_light
from udc_render.profiles import resolve_profile
from udc_render.scene import load_scene
from udc_render.sensor import SensorConfig, mosaic_of

OFF = StrayLight.off()
EFFECTS = {
    "a. room light on the screen (500 lx, R 0.044)":
        replace(OFF, room_illuminance_lux=ON_VALUES["room_illuminance_lux"]),
    "b. ghost (R_lens 0.005 × R_under 0.08, 2 mm disc)": replace(OFF, lens_reflectance=ON_VALUES["lens_reflectance"]),
    "c. lens veiling glare 0.02 (θ⁻², ≥ 1°)": replace(OFF, lens_glare=ON_VALUES["lens_glare"]),
    "d. haze, P-OLED 0.015 (θ⁻², ≥ 2.5°; the default)": replace(OFF, haze=StrayLight().haze),
    "e. display's own light 1 cd/m²": replace(OFF, display_luminance_cd_m2=ON_VALUES["display_luminance_cd_m2"]),
}


def views_electrons(distance_mm: float | None) -> tuple[dict, object, object]:
    """(the views' electrons before the stray light, the sensor, the band image) of the default monitor."""
    cfg, displays = resolve_profile("physical", pipeline.SynthConfig(sensor=SensorConfig(noise="none")),
                                    load_displays("toled,poled"), distance_mm=distance_mm)
    cfg = replace(cfg, stray_light=OFF, defects=None, **{k: None for k in ("fpn", "gt_frames") if hasattr(cfg, k)})
    seen = {}

    def grab(stray, electrons, band_image, sensor, form, glass_names=()):
        seen.update(electrons=electrons, sensor=sensor, band_image=band_image)
        return synthesis_stray_light(stray, electrons, band_image, sensor, form, glass_names)

    pipeline.synthesis_stray_light = grab
    pipeline.capture_scene(load_scene("monitor"), displays, cfg)
    return seen["electrons"], seen["sensor"], seen["band_image"]


def measure(distance_mm: float | None) -> list[dict]:
    electrons, sensor, band_image = views_electrons(distance_mm)
    ctx = StrayContext(np.asarray(band_image.edges_nm, float), sensor, True, np.asarray(electrons["gt"][1]["gains"]))
    rows = []
    for effect, stray in EFFECTS.items():
        for name, (e, rec) in electrons.items():
            t0 = time.perf_counter()
            on, _ = apply_view(stray, e, "glass" if name == "gt" else name, name == "gt", rec["gains"], ctx)
            seconds = time.perf_counter() - t0
            a, b = mosaic_of(e), mosaic_of(on)
            rows.append({"effect": effect, "view": name, "moved": float(np.abs(b - a).sum() / a.sum()),
                         "net": float((b - a).sum() / a.sum()), "seconds": seconds})
    return rows


def table(rows: list[dict], distance_mm) -> str:
    d = "the physical profile's" if distance_mm is None else f"{distance_mm:g} mm"
    lines = [f"# Stray light on the default monitor capture (2048 × 1024, 30 bands, display-to-lens distance {d})", "",
             "moved = Σ|e_on − e_off| / Σ e_off, net = Σ(e_on − e_off) / Σ e_off over the noise-free RGGB mosaic; "
             "each effect alone at its on-value.", "",
             "| effect | view | moved | net | s |", "|---|---|---|---|---|"]
    lines += [f"| {r['effect']} | {r['view']} | {r['moved']:.2e} | {r['net']:+.2e} | {r['seconds']:.2f} |"
              for r in rows]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument("--distance-mm", type=float, default=None, help="display-to-lens distance (default: the profile's)")
    ap.add_argument("--out", type=Path, default=Path("out/bench/stray_light.md"))
    args = ap.parse_args()
    text = table(measure(args.distance_mm), args.distance_mm)
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_text(args.out, text)


if __name__ == "__main__":
    main()
