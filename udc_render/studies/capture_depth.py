"""The depth and dynamic-range knobs of `study capture`: depth layers (defocus tolerance) and bright sources.

- ``layers``: a near square whose distance ramps from 0.6 to 1.2 m over a far textured plane at 3 m, focus
  at 3 m (blur diameters 0 … 17 px), 3 bands of 100 nm, glass; the layered synthesis at defocus tolerances
  from 4 to 0.25 px, and with defocus off, against the per-pixel brute-force reference
  (studies.layers_reference). Error: relative L2 of the electrons within 8 px of the near object's outline
  (the frame's is in the markdown too). kernel_s: the layers' kernels (each distance computed once, cache
  off); apply_s: the layered optics.
- ``bright``: a dim room with the sun in frame (10⁹ times brighter, a 7-px disc), T-OLED at the physical
  profile's d and glass: float32 FFTs with and without the bright pixels convolved apart, and float64,
  against float64 with them apart. Error: the largest |Δe| over the pixel's own noise √(σ_read² + e)
  (the round-off must stay below the noise floor; the default aims at 0.1).
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from udc_render.optics import displays as D
from udc_render.optics.layers import DefocusGeometry
from udc_render.pipeline import (
    SynthConfig,
    capture_views,
    depth_layers,
    display_kernels,
    plan_kernels,
    sensor_for_scene,
)
from udc_render.render import BandImage
from udc_render.scene import Bands, load_scene
from udc_render.scene.geometry import camera_geometry, psf_lens, render_grid
from udc_render.sensor import SensorConfig
from udc_render.studies.layers_reference import edge_region, near_over_far, reference_electrons, with_focus
from udc_render.views import View, bright_pixels, layered_electrons

FULL = {"layers_sensor": (160, 96), "tolerances": (4.0, 2.0, 1.0, 0.5, 0.25), "reference_step": 0.02,
        "bright_sensor": (256, 128)}
QUICK = {"layers_sensor": (48, 32), "tolerances": (2.0, 0.5), "reference_step": 0.1, "bright_sensor": (64, 32)}
NOISELESS = SynthConfig(sensor=SensorConfig(noise="none"), use_cache=False)


def _small(name: str, size: tuple[int, int], margin_um: float | None = None):
    s = load_scene(name)
    s = replace(s, sensor=replace(s.sensor, width_px=size[0], height_px=size[1]), bands=Bands((400.0, 700.0), 100.0))
    return s if margin_um is None else s.with_render(margin_um=margin_um)


class _TimedKernels:
    """Glass kernels by object distance, each computed once (cache off) and its seconds kept."""

    def __init__(self, scene):
        self.scene, self.grid, self.sets, self.seconds = scene, render_grid(scene), {}, {}

    def __call__(self, z: float):
        if z not in self.sets:
            t0 = time.perf_counter()
            self.sets[z] = display_kernels(D.preset("glass"), self.scene, self.grid, NOISELESS, object_distance_m=z)
            self.seconds[z] = time.perf_counter() - t0
        return self.sets[z]


def layer_rows(cfg: dict) -> list[dict]:
    """The `layers` knob (module doc): one row per tolerance, and defocus off."""
    s = with_focus(_small("room", cfg["layers_sensor"], margin_um=62.0), 3.0)
    bi = near_over_far(s, 3.0, (0.6, 1.2))
    lens, grid = psf_lens(s), render_grid(s)
    geo = DefocusGeometry(lens.aperture_um, lens.image_distance_um, 3.0, grid.pitch_um)
    sensor = replace(sensor_for_scene(NOISELESS.sensor, s), exposure_s=1e-3)
    kernels = _TimedKernels(s)
    ref = reference_electrons(bi, geo, kernels, sensor, cfg["reference_step"])
    ring = edge_region(bi.depth_m, 3.0, grid.margin_px, 8)
    rows = []
    for tol in cfg["tolerances"] + (None,):
        layers = depth_layers(bi, s, grid, replace(NOISELESS, defocus_tolerance_px=tol))
        for z in layers.depths_m:
            kernels(z)
        t0 = time.perf_counter()
        e = layered_electrons(bi, layers, lambda i: [View("gt", kernels(layers.depths_m[i]), None)], sensor,
                              NOISELESS)["gt"][0]
        apply_s = time.perf_counter() - t0
        edge = float(np.linalg.norm((e - ref)[:, ring]) / np.linalg.norm(ref[:, ring]))
        frame = float(np.linalg.norm(e - ref) / np.linalg.norm(ref))
        label = "off (in focus)" if tol is None else f"{tol:g} px ({layers.count} layers)"
        rows.append({"study": "layers", "display": "glass", "setting": label, "reference":
                     f"per pixel (β to {cfg['reference_step']:g} px)", "rel_error": edge, "frame_error": frame,
                     "kernel_s": round(sum(kernels.seconds[z] for z in layers.depths_m), 3),
                     "apply_s": round(apply_s, 3), "metric": "rel. L2 at the edge"})
    return rows


def sun_room(scene, sun_ratio: float = 1e9, seed: int = 0) -> BandImage:
    """A dim textured room (0.01–0.03 W sr⁻¹ m⁻² nm⁻¹) with a sun disc of radius 3 px sun_ratio times brighter,
    every pixel at the focus distance."""
    g = camera_geometry(scene)
    rng = np.random.default_rng(seed)
    room = 0.02 * (0.5 + rng.random((g.height_px, g.width_px)))
    yy, xx = np.mgrid[0:g.height_px, 0:g.width_px]
    sun = (yy - g.height_px * 0.4) ** 2 + (xx - g.width_px * 0.6) ** 2 <= 9.0
    radiance = np.where(sun, 0.02 * sun_ratio, room)
    k = len(scene.bands.edges_nm) - 1
    return BandImage(np.repeat(radiance[None], k, axis=0).astype(np.float32), np.asarray(scene.bands.edges_nm, float),
                     g.pitch_um, g.margin_px, np.full(radiance.shape, g.focus_distance_m, np.float32))


def bright_rows(cfg: dict) -> list[dict]:
    """The `bright` knob (module doc)."""
    from udc_render.profiles import PHYSICAL_DISTANCE_MM
    s = _small("hdr", cfg["bright_sensor"])
    bi = sun_room(s)
    displays = [D.preset("toled").with_distance(PHYSICAL_DISTANCE_MM)]
    t0 = time.perf_counter()
    kernels = plan_kernels(s, displays, NOISELESS)
    kernel_s = time.perf_counter() - t0
    layers = depth_layers(bi, s, kernels.grid, NOISELESS)
    sensor = replace(sensor_for_scene(NOISELESS.sensor, s), exposure_s=2e-4)
    bright = bright_pixels(bi, sensor)

    def electrons(precision, split):
        t0 = time.perf_counter()
        out = layered_electrons(bi, layers, lambda _layer: capture_views(kernels, displays, bi.edges_nm), sensor,
                                replace(NOISELESS, precision=precision), bright if split else None)
        return {k: v[0] for k, v in out.items()}, time.perf_counter() - t0

    ref, _ = electrons("float64", True)
    rows = []
    for precision, split in (("float32", False), ("float32", True), ("float64", False)):
        e, apply_s = electrons(precision, split)
        for view, name in (("gt", "glass"), ("toled", "toled")):
            noise = np.sqrt(sensor.read_noise_e ** 2 + np.clip(ref[view], 0, None))
            rows.append({"study": "bright", "display": name,
                         "setting": f"{precision}{', sun apart' if split else ''}"
                                    f"{' (default)' if split and precision == 'float32' else ''}",
                         "reference": "float64, sun apart",
                         "rel_error": float(np.max(np.abs(e[view] - ref[view]) / noise)),
                         "kernel_s": round(kernel_s, 3), "apply_s": round(apply_s, 3),
                         "metric": f"max abs Δe over the noise "
                                   f"({0 if bright is None else int(bright.mask.sum())} px apart)"})
    return rows
