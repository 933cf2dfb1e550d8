"""The effects `udc-render study gap` switches (udc_render.studies.gap), each with the evidence for its size,
and the DeP candidates it tries on the shipped profile's captures.

An Effect switches one mechanism of the physical profile on (its shipped default, or for an effect that is
off by default for want of a magnitude, the on-value named in `evidence`) or off, on a gap.Setup.
"""
from __future__ import annotations

import importlib.util
from dataclasses import dataclass, replace
from typing import Callable

from udc_render.optics.stray.settings import ON_VALUES
from udc_render.sensor import SensorConfig
from udc_render.sensor.defects import DefectConfig
from udc_render.sensor.fpn import FpnConfig
from udc_render.synth_config import DEFAULT_FAR_FIELD_THRESHOLD


@dataclass(frozen=True)
class Effect:
    """One mechanism beyond the paper's model; switch(setup, on) → the setup with it on or off."""
    name: str
    evidence: str  # where its size comes from (one line)
    default_on: bool  # on in the physical profile
    switch: Callable
    # what 'light moved' compares: 'clean' (the noise-free captures), 'packed' (the recorded ones: effects on
    # the recorded values alone, e.g. defect pixels) or 'gt' (an effect on the ground truth alone)
    compare: str = "clean"


def _cfg(setup, **changes):
    return replace(setup, cfg=replace(setup.cfg, **changes))


def _distance(setup, on: bool):
    from udc_render.profiles import PHYSICAL_DISTANCE_MM
    d = PHYSICAL_DISTANCE_MM if on else 0.0
    return replace(setup, displays=tuple(x.with_distance(d) for x in setup.displays))


def _defects(setup, on: bool):
    return _cfg(setup, defects=DefectConfig() if on else None)


def _fpn(setup, on: bool):
    return _cfg(setup, fpn=FpnConfig() if on else None)


def _stray(knob: str):
    """Switch one stray-light knob (optics.stray): its ON_VALUES value, or off (None for a mapping or a
    level, 0 for a fraction)."""
    def switch(setup, on: bool):
        off = None if knob in ("room_illuminance_lux", "haze", "display_luminance_cd_m2") else 0.0
        return _cfg(setup, stray_light=replace(setup.cfg.stray_light, **{knob: ON_VALUES[knob] if on else off}))
    return switch


def _gt_frames(setup, on: bool):
    from udc_render.profiles import PAPER_GT_FRAMES
    return _cfg(setup, gt_frames=PAPER_GT_FRAMES if on else None)


ABERRATION = ((4, 0, 0.07),)  # spherical, waves RMS at 550 nm: Maréchal's diffraction limit (Strehl 0.82)


def _aberration(setup, on: bool):
    scene = setup.scene
    return replace(setup, scene=replace(scene, lens=replace(scene.lens, zernike_waves=ABERRATION if on else ())))


def _far_field(setup, on: bool):
    return _cfg(setup, far_field_threshold=DEFAULT_FAR_FIELD_THRESHOLD if on else None)


def _read_noise(setup, on: bool):
    e = 2 * SensorConfig().read_noise_e if on else SensorConfig().read_noise_e
    return _cfg(setup, sensor=replace(setup.cfg.sensor, read_noise_e=e))


EFFECTS: tuple[Effect, ...] = (
    Effect("display-to-lens distance 2 mm (bands)",
           "the paper's real data shows bands of low to moderate visibility (l.498); d from `study realism`", True,
           _distance),
    Effect("far field (light past the kernel window)", "diffraction: the display's orders past the 513-px window "
           "(P-OLED 6–10 %, T-OLED 1.1–1.6 %) within the lens's acceptance; psf.far, optics.far_field", True,
           _far_field),
    Effect("dead and hot pixels", "impulse noise 'widely exists' in the real data (l.412); densities: "
           "Chapman et al. 2011–2022 (sensor.defects)", True, _defects, compare="packed"),
    Effect("fixed-pattern noise (PRNU, DSNU, rows/columns, dark current)", "EMVA 1288 nonuniformities; PRNU 0.7 % "
           "from ISETCam's Sony IMX363 model, the rest stated choices (sensor.fpn)", True, _fpn, compare="packed"),
    Effect("haze of the display stack (P-OLED 1.5 %)", "median ASTM D1003 haze of six polyimide films, 0.6–2.8 % "
           "(Polymers 15, 3408, 2023); 'hazy' (l.122); optics.stray", True, _stray("haze")),
    Effect("room light on the monitor (500 lx)", "environment light (l.412): EN 12464-1 office 500 lx × screen "
           "reflectance 4.4 % (DisplayMate 2014) / π; the rig's room unknown: off by default", False,
           _stray("room_illuminance_lux")),
    Effect("ghost between display and lens (0.5 %)", "reflections (l.429): a multilayer AR coating 0.4–0.5 % × the "
           "underside's reflectance; off by default", False, _stray("lens_reflectance")),
    Effect("lens veiling glare (2 %)", "lens flare (l.429): ISO 9358 veiling glare index, a typical figure; the "
           "paper's lens unmeasured: off by default", False, _stray("lens_glare")),
    Effect("the display's own light (1 cd/m²)", "an active display (l.429); the paper's panels were not driven "
           "(l.200–235): off by default", False, _stray("display_luminance_cd_m2")),
    Effect("ground truth of 16 averaged frames", "the paper averaged 16 glass frames at gain 1 (l.235); its residual "
           "noise σ/4 (sensor.frames)", True, _gt_frames, compare="gt"),
    Effect("lens aberration (spherical 0.07 wave RMS)", "Maréchal's diffraction limit, Strehl 0.82; phone lenses "
           "0.07–0.12 wave (MTF 0.2–0.25 at Nyquist); the paper's lens unmeasured: off by default", False, _aberration),
    Effect("read noise 2× (9.7 e⁻)", "the noise at gain 25: a sensitivity, not evidence (the default 4.87 e⁻ is a "
           "peer's; 1.55 µm Sony sensors read 1.5–5 e⁻, sensor.fpn's sources)", False, _read_noise),
)


@dataclass(frozen=True)
class DepVariant:
    """A way the paper's DeP could have run: its kernels ('paper', 'exact'), denoiser, a γ error."""
    name: str
    evidence: str
    kernels: str = "paper"
    denoiser: str = "nlm"
    gamma_scale: float = 1.0
    images: int | None = None  # run on the first `images` of each content group (None: all)
    content: str | None = None  # run on this content group only (None: every group)

    def available(self) -> bool:
        return self.denoiser != "bm3d" or importlib.util.find_spec("bm3d") is not None


DEP_VARIANTS: tuple[DepVariant, ...] = (
    DepVariant("exact kernel", "the upper bound a perfect PSF gives (restore.known 'exact')", kernels="exact"),
    DepVariant("γ 5 % high", "an inaccurate transmission (l.412): the paper prints γ to two digits (±1.5 % on "
               "0.34, ±2.5 % on 0.20) from a 256-px white square; 5 % stands for that and a field-dependent T",
               gamma_scale=1.05),
    DepVariant("BM3D denoiser", "the paper's DeP denoised with BM3D (l.277); needs the optional bm3d package; "
               "the first dead-leaves image (BM3D takes minutes per frame)", denoiser="bm3d", images=1,
               content="dead leaves"),
)
