"""A randomized dataset (--randomize default|FILE.toml --panels N; issue 31, udc_render.dataset.randomize).

The job draws N panels once (draw_panels: a display named 'random', its lens, its haze), recorded in
job.json; their kernels are planned in the parent before any item (plan_panels: each panel's scene, its
lens focused by the drawn focus error at the drawn f-number, through glass and the panel, into the kernel
cache), and a worker loads a panel's kernels on its first item of that panel (executors.worker_kernels).
Item i draws its panel and its own sensor and exposure (draw_capture: seeded by the randomization seed
and i alone, so neither the worker count nor a resume changes them): the panel's display at the drawn
gain, the drawn read noise, defect pixels and fixed-pattern noise (their maps drawn per item), the
exposure (auto or --exposure-s) × exposure.scale, the render's radiance × exposure.brightness (the
exposure chosen before the scaling: a dimmer scene, not a shorter exposure). Everything drawn goes into
synth.json and each capture.json under "randomized"; item.json and the manifest name the panel.

Layout: the glass capture and the ground truth as in any dataset, the panel's capture in
<item>/random/ (raw.dng, capture.json).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from udc_render.dataset.randomize import (
    CaptureDraw,
    Distributions,
    PanelDraw,
    as_record,
    capture_config,
    capture_display,
    draw_capture,
    panel_scene,
    scaled_exposure_s,
)
from udc_render.optics.displays import Display
from udc_render.pipeline import SynthConfig, SynthResult, auto_exposure_s, prepare_kernels, sensor_for_scene
from udc_render.render import BandImage
from udc_render.scene import Scene

DRAW_RULE = ("panel i: draw_panel(distributions, i, seed); item i: draw_capture(distributions, panels, seed, i) "
             "(udc_render/dataset/randomize/draws.py: one stream SeedSequence([seed, crc32(what), index, "
             "crc32(key)]) per parameter)")


@dataclass(frozen=True)
class Randomization:
    """A job's randomization: the distributions, the seed and the panels drawn once."""
    dists: Distributions
    seed: int
    panels: tuple[PanelDraw, ...]

    def describe(self) -> dict:
        """job.json's record: what decides every draw, and the panels as drawn."""
        return {**self.dists.describe(), "seed": self.seed, "panels": len(self.panels), "draw": DRAW_RULE,
                "panel_draws": [as_record(p) for p in self.panels]}


@dataclass(frozen=True)
class ItemSetup:
    """One item's draws made concrete: its panel and capture draws, the scene (the panel's lens), the
    displays (glass, the panel at the drawn gain) and the synthesis settings (the drawn sensor)."""
    panel: PanelDraw
    capture: CaptureDraw
    scene: Scene
    displays: list[Display]
    cfg: SynthConfig


def panel_setup(scene: Scene, glass: Display, panel: PanelDraw) -> tuple[Scene, list[Display]]:
    """A panel's scene (its lens) and displays (glass, the panel): what its kernels are planned for."""
    return panel_scene(scene, panel.lens), [glass, panel.display]


def plan_panels(rand: Randomization, scene: Scene, glass: Display, cfg: SynthConfig) -> list[float]:
    """Plan every panel's kernels into the cache (in the parent, before the items); seconds per panel."""
    seconds = []
    for p in rand.panels:
        t0 = time.perf_counter()
        prepare_kernels(*panel_setup(scene, glass, p), cfg)
        seconds.append(time.perf_counter() - t0)
    return seconds


def item_setup(rand: Randomization, scene: Scene, glass: Display, cfg: SynthConfig, item: int) -> ItemSetup:
    """Item `item`'s draws (module doc) on the item's scene (its image or pose already set)."""
    cap = draw_capture(rand.dists, len(rand.panels), rand.seed, item)
    panel = rand.panels[cap.panel]
    return ItemSetup(panel, cap, panel_scene(scene, panel.lens), [glass, capture_display(panel, cap)],
                     capture_config(cfg, cap, panel))


def exposed(setup: ItemSetup, band_image: BandImage) -> tuple[BandImage, SynthConfig, dict]:
    """The render × brightness and the settings at the drawn exposure (module doc), and their record."""
    cfg, cap = setup.cfg, setup.capture
    if cfg.exposure_s is not None:
        base, how = cfg.exposure_s, "--exposure-s"
    else:
        base, how = auto_exposure_s(band_image, sensor_for_scene(cfg.sensor, setup.scene))
    t = scaled_exposure_s(base, cap)
    if cap.brightness != 1.0:
        band_image = replace(band_image, bands=(band_image.bands * np.float32(cap.brightness)).astype(np.float32))
    return band_image, replace(cfg, exposure_s=t), {"exposure_s": t, "exposure_rule": f"{how} × exposure.scale",
                                                    "base_exposure_s": float(base)}


def recorded(result: SynthResult, setup: ItemSetup, exposure: dict) -> SynthResult:
    """The synthesis with everything drawn in synth.json and every capture.json ('randomized')."""
    record = {"panel": as_record(setup.panel), "capture": as_record(setup.capture), **exposure,
              "brightness": setup.capture.brightness,
              "note": "the profile's defect pixels and fixed-pattern noise are replaced by the drawn ones"}
    meta = {**result.meta, "randomized": record}
    display_meta = {k: {**v, "randomized": record} for k, v in result.display_meta.items()}
    return replace(result, meta=meta, display_meta=display_meta)
