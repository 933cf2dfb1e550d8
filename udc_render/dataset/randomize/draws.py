"""Draws from the randomization's distributions: N panels per job, and each capture's own sensor and
exposure; typed, frozen, JSON-able (as_record).

    dists = load_distributions("default")
    panels = draw_panels(dists, n=8, seed=0)          # PanelDraw: display (named 'random'), lens
    cap = draw_capture(dists, len(panels), seed=0, item=17)   # CaptureDraw: panel index, sensor, exposure
    scene = panel_scene(scene, panels[cap.panel].lens)
    cfg = capture_config(cfg, cap); display = capture_display(panels[cap.panel], cap)

Streams: every parameter has a generator of its own, SeedSequence([seed, crc32('panel'), i,
crc32(key)]) for panel i and SeedSequence([seed, crc32('capture'), item, crc32(key)]) for a capture
(distributions.stream), so a draw depends on the seed, the index and the key's own distribution alone:
panel i is the same for any N, and editing one key's distribution leaves every other key's draws.
"""
from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field, replace

import numpy as np

from udc_render.dataset.randomize.distributions import Distributions, RandomizeError, stream
from udc_render.dataset.randomize.panels import panel_display
from udc_render.optics.displays import Display
from udc_render.scene import Scene
from udc_render.sensor.defects import DefectConfig
from udc_render.sensor.fpn import FpnConfig
from udc_render.synth_config import SynthConfig
from udc_render.synth_kernels import scene_object_distance_m

SENSOR_KEYS = ("gain_scale", "read_noise_e", "dead_fraction", "hot_fraction", "hot_dark_e_per_s", "prnu", "dsnu_e",
               "row_offset_e", "column_offset_e", "dark_current_e_per_s")
EXPOSURE_KEYS = ("scale", "brightness")


@dataclass(frozen=True)
class LensDraw:
    """The lens of a panel: focus error δ = 1/z_focus − 1/z_object (m⁻¹; > 0: focused nearer than the
    object) and the f-number."""
    focus_error_per_m: float
    f_number: float


@dataclass(frozen=True)
class PanelDraw:
    """Panel i of a job: its display (panels.panel_display, named 'random'), its lens, its stack's haze
    (optics.stray: the share scattered past 2.5°), and every drawn value by key (display.*, lens.*)."""
    index: int
    seed: int
    family: str
    display: Display
    lens: LensDraw
    haze: float
    values: dict = field(hash=False)


@dataclass(frozen=True)
class CaptureDraw:
    """One capture's own draws: which panel (0 … N−1), the sensor (gain × the family's, read noise, defect
    pixels and fixed-pattern noise with their maps' seeds) and the exposure (× the exposure; × the scene's
    radiance), and every drawn value by key (sensor.*, exposure.*)."""
    item: int
    seed: int
    panel: int
    gain_scale: float
    read_noise_e: float
    defects: DefectConfig
    fpn: FpnConfig
    exposure_scale: float
    brightness: float
    values: dict = field(hash=False)


def _seed_of(rng: np.random.Generator) -> int:
    return int(rng.integers(0, 2 ** 63 - 1))


def draw_panel(dists: Distributions, index: int, seed: int) -> PanelDraw:
    """Panel `index` of the job with this seed (module doc: its streams)."""
    def draw(key):
        return dists[key].sample(stream(seed, "panel", index, key))
    family = draw("display.family")
    prefix = f"display.{family}."
    values = {"display.family": family, "display.distance_mm": draw("display.distance_mm"),
              **{k: draw(k) for k in sorted(dists.dists) if k.startswith(prefix)},
              "lens.focus_error_per_m": draw("lens.focus_error_per_m"), "lens.f_number": draw("lens.f_number")}
    own = {k[len(prefix):]: v for k, v in values.items() if k.startswith(prefix)}
    disorder_seed = _seed_of(stream(seed, "panel", index, "disorder"))
    display = panel_display(family, own, values["display.distance_mm"], disorder_seed,
                            f"randomize: panel {index} of seed {seed} ({dists.source})")
    return PanelDraw(index, int(seed), family, display,
                     LensDraw(values["lens.focus_error_per_m"], values["lens.f_number"]), own["haze"], values)


def draw_panels(dists: Distributions, n: int, seed: int) -> list[PanelDraw]:
    """Panels 0 … n−1 (each as draw_panel: the first k are the same for any n ≥ k)."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise RandomizeError(f"--panels = {n!r}: expected a whole number of panels ≥ 1")
    return [draw_panel(dists, i, seed) for i in range(n)]


def capture_panel(panels: int, seed: int, item: int) -> int:
    """Which of the `panels` panels capture `item` sees (uniform; its own stream): draw_capture's panel."""
    return int(stream(seed, "capture", item, "panel").integers(panels))


def draw_capture(dists: Distributions, panels: int, seed: int, item: int) -> CaptureDraw:
    """Capture `item`'s panel (uniform over 0 … panels−1), sensor and exposure (module doc: its streams)."""
    def draw(key):
        return dists[key].sample(stream(seed, "capture", item, key))
    s = {k: draw(f"sensor.{k}") for k in SENSOR_KEYS}
    e = {k: draw(f"exposure.{k}") for k in EXPOSURE_KEYS}
    panel = capture_panel(panels, seed, item)
    defects = DefectConfig(s["dead_fraction"], s["hot_fraction"], s["hot_dark_e_per_s"],
                           _seed_of(stream(seed, "capture", item, "defect map")))
    fpn = FpnConfig(s["prnu"], s["dsnu_e"], s["row_offset_e"], s["column_offset_e"], s["dark_current_e_per_s"],
                    _seed_of(stream(seed, "capture", item, "fpn maps")))
    values = {**{f"sensor.{k}": v for k, v in s.items()}, **{f"exposure.{k}": v for k, v in e.items()}}
    return CaptureDraw(int(item), int(seed), panel, s["gain_scale"], s["read_noise_e"], defects, fpn, e["scale"],
                       e["brightness"], values)


def as_record(draw) -> dict:
    """A draw (PanelDraw, CaptureDraw, LensDraw) as plain JSON values: a Display by its describe(),
    nested dataclasses as dicts."""
    def plain(v):
        if isinstance(v, Display):
            return v.describe()
        if dataclasses.is_dataclass(v):
            return {f.name: plain(getattr(v, f.name)) for f in dataclasses.fields(v)}
        return v
    return json.loads(json.dumps(plain(draw), default=float))


def panel_scene(scene: Scene, lens: LensDraw) -> Scene:
    """The scene with the panel's lens: focused at 1 / (1/z + δ), z the object distance the scene fixes
    (synth_kernels.scene_object_distance_m: the monitor's plane, a 3D scene's focus), and its f-number."""
    z = scene_object_distance_m(scene)
    vergence = 1.0 / z + lens.focus_error_per_m
    if not vergence > 0:
        raise RandomizeError(f"lens.focus_error_per_m = {lens.focus_error_per_m:g}: expected more than −1/z = "
                             f"{-1.0 / z:.4g} m⁻¹ for the scene's object at z = {z:.4g} m (focus beyond infinity)")
    return replace(scene, lens=replace(scene.lens, focus_distance_m=1.0 / vergence, f_number=float(lens.f_number)))


def capture_display(panel: PanelDraw, cap: CaptureDraw) -> Display:
    """The panel's display at the capture's gain (the family's × gain_scale)."""
    return replace(panel.display, gain=panel.display.gain * cap.gain_scale)


def capture_config(cfg: SynthConfig, cap: CaptureDraw, panel: PanelDraw | None = None) -> SynthConfig:
    """The synthesis settings with the capture's sensor (read noise, defect pixels, fixed-pattern noise) and,
    with `panel`, its haze (unless the job's stray light has no haze: --stray-light off)."""
    cfg = replace(cfg, sensor=replace(cfg.sensor, read_noise_e=float(cap.read_noise_e)), defects=cap.defects,
                  fpn=cap.fpn)
    stray = cfg.stray_light
    if panel is None or not stray.haze:
        return cfg
    return replace(cfg, stray_light=replace(stray, haze={**dict(stray.haze), panel.display.name: panel.haze}))


def scaled_exposure_s(auto_or_set_s: float, cap: CaptureDraw) -> float:
    """The capture's exposure: the job's (auto or --exposure-s) × exposure.scale."""
    t = float(auto_or_set_s) * cap.exposure_scale
    if not (t > 0 and math.isfinite(t)):
        raise RandomizeError(f"exposure.scale = {cap.exposure_scale:g}: gives an exposure of {t!r} s")
    return t
