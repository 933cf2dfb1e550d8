"""StrayLight: the knobs of the stray light the diffraction model leaves out (optics.stray; issue 29).

Each effect is off at 0 or None, so `dataclasses.replace(cfg.stray_light, <knob>=0 or None)` switches it
off and ON_VALUES names the value a study switches it on with. The defaults are on only where the
evidence gives a magnitude (docs/concepts/defaults.md: the evidence, the choice, what is uncertain):

========================  =======================  ===============  ==========================================
effect                    knob (off)               default          on-value (ON_VALUES)
========================  =======================  ===============  ==========================================
a. room light on the      room_illuminance_lux     None (off)       500 lx (EN 12464-1 office), the screen's
   monitor's screen       (None)                                    reflectance 0.044 (DisplayMate 2014)
b. ghost between display  lens_reflectance (0)     0 (off)          0.005 (a multilayer AR coating), with the
   and lens                                                         underside's reflectance (glass 2 × 4 %)
c. lens veiling glare     lens_glare (0)           0 (off)          0.02 (ISO 9358 veiling glare index, a
                                                                    typical figure; the paper's lens unmeasured)
d. haze of the display    haze (None or {})        P-OLED 0.015     the same: the median ASTM D1003 haze of six
   stack                                                            polyimide films (0.6–2.8 %)
e. the active display's   display_luminance_cd_m2  None (off)       1 cd/m² (1 % of a 100 cd/m² region; no
   own light              (None)                                    measured value of what reaches the lens)
========================  =======================  ===============  ==========================================
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Mapping

from udc_render.content.spectra import SpectrumError, illuminant
from udc_render.errors import UdcError

SCREEN_REFLECTANCE = 0.044  # DisplayMate (Soneira 2014): 2.2 % the lowest screen reflectance measured, 4.4 % before
GLASS_UNDERSIDE = 0.08  # the thin glass of the ground truth: two uncoated faces of 4 % (n ≈ 1.5, normal incidence)
GHOST_BLUR_UM = 2000.0  # D · s / z_g for a virtual ghost source z_g ≈ 10 mm before a 6 mm lens at f/1.8 (module apply)
GLARE_INNER_DEG = 1.0  # the veiling glare tail starts ~1° from the image point (ISO 9358's black spot: a few degrees)
HAZE_INNER_DEG = 2.5  # ASTM D1003 / ISO 14782: haze is the transmitted light deviated by more than 2.5°
POLED_HAZE = 0.015  # median of six colourless polyimide films' haze, 0.6–2.8 % (Polymers 2023, 15, 3408, Table 4)
ON_VALUES = {"room_illuminance_lux": 500.0, "lens_reflectance": 0.005, "lens_glare": 0.02,
             "haze": {"poled": POLED_HAZE}, "display_luminance_cd_m2": 1.0}


class StrayLightError(UdcError):
    """A stray-light knob out of range; one line."""


def _number(name: str, v, lo: float, hi: float, hi_open: bool = False, lo_open: bool = False) -> float:
    ok = (not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)
          and (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi))
    if not ok:
        span = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
        raise StrayLightError(f"stray_light.{name} = {v!r}: expected a number in {span}")
    return float(v)


def _mapping(name: str, m, hi: float) -> tuple[tuple[str, float], ...]:
    """A {display name: value} mapping (None or {}: none), stored as sorted pairs (hashable)."""
    if m is None:
        return ()
    items = m.items() if isinstance(m, Mapping) else m
    try:
        pairs = [(k, v) for k, v in items]
    except (TypeError, ValueError):
        raise StrayLightError(f"stray_light.{name} = {m!r}: expected a mapping of display name to number, "
                              "or None") from None
    for k, v in pairs:
        if not isinstance(k, str) or not k:
            raise StrayLightError(f"stray_light.{name}: key {k!r}: expected a display name (glass, toled, poled, …)")
        _number(f"{name}[{k!r}]", v, 0.0, hi, hi_open=True)
    return tuple(sorted((k, float(v)) for k, v in pairs))


@dataclass(frozen=True)
class StrayLight:
    """The stray light of a synthesis (module doc; optics.stray.apply for the formulas)."""
    # a. room light reflected by the monitor's screen: L = R E / π, through every view (ground truth too)
    room_illuminance_lux: float | None = None
    screen_reflectance: float = SCREEN_REFLECTANCE
    room_illuminant: str = "LED-B3"  # a colour-science illuminant (CIE LED-B3, 4100 K)
    # b. ghost: lens front face → display underside → lens, a disc of ghost_blur_um, share R_lens · R_under
    lens_reflectance: float = 0.0
    underside_reflectance: Mapping[str, float] | None = field(default_factory=lambda: {"glass": GLASS_UNDERSIDE})
    ghost_blur_um: float = GHOST_BLUR_UM
    # c. the lens's veiling glare: a θ⁻² tail from glare_inner_deg, in every view (ground truth too)
    lens_glare: float = 0.0
    glare_inner_deg: float = GLARE_INNER_DEG
    # d. haze of each display's stack (by display name): a θ⁻² tail from haze_inner_deg
    haze: Mapping[str, float] | None = field(default_factory=lambda: {"poled": POLED_HAZE})
    haze_inner_deg: float = HAZE_INNER_DEG
    # e. the driven display's own light reaching the lens (luminance of its underside, cd/m²)
    display_luminance_cd_m2: float | None = None

    def __post_init__(self):
        if self.room_illuminance_lux is not None:
            _number("room_illuminance_lux", self.room_illuminance_lux, 0.0, math.inf, hi_open=True)
        _number("screen_reflectance", self.screen_reflectance, 0.0, 1.0)
        if not isinstance(self.room_illuminant, str):
            raise StrayLightError(f"stray_light.room_illuminant = {self.room_illuminant!r}: expected a "
                                  "colour-science illuminant name such as LED-B3, FL2, D65")
        _number("lens_reflectance", self.lens_reflectance, 0.0, 1.0, hi_open=True)
        _number("ghost_blur_um", self.ghost_blur_um, 0.0, math.inf, lo_open=True, hi_open=True)
        _number("lens_glare", self.lens_glare, 0.0, 1.0, hi_open=True)
        _number("glare_inner_deg", self.glare_inner_deg, 0.0, 90.0, lo_open=True, hi_open=True)
        _number("haze_inner_deg", self.haze_inner_deg, 0.0, 90.0, lo_open=True, hi_open=True)
        if self.display_luminance_cd_m2 is not None:
            _number("display_luminance_cd_m2", self.display_luminance_cd_m2, 0.0, math.inf, hi_open=True)
        object.__setattr__(self, "underside_reflectance", _mapping("underside_reflectance",
                                                                    self.underside_reflectance, 1.0))
        object.__setattr__(self, "haze", _mapping("haze", self.haze, 1.0))
        if self.room_on:
            try:
                illuminant(self.room_illuminant)
            except SpectrumError as e:
                raise StrayLightError(f"stray_light.room_illuminant: {e}") from None

    @classmethod
    def off(cls) -> "StrayLight":
        """Every effect off (the paper profile)."""
        return cls(haze=None)

    @property
    def room_on(self) -> bool:
        return bool(self.room_illuminance_lux) and self.screen_reflectance > 0

    @property
    def emission_on(self) -> bool:
        return bool(self.display_luminance_cd_m2)

    def haze_of(self, display: str) -> float:
        """The haze of a display (0 when it has none)."""
        return dict(self.haze).get(display, 0.0)

    def underside_of(self, display: str) -> float:
        """The reflectance of a display's underside toward the lens; a display without its own value has the
        glass's (its outer face is at least a glass or polyimide interface), 0 without either."""
        u = dict(self.underside_reflectance)
        return u.get(display, u.get("glass", 0.0))

    def is_off(self) -> bool:
        return not (self.room_on or self.lens_reflectance or self.lens_glare or self.emission_on
                    or any(v > 0 for _, v in self.haze))

    def describe(self) -> dict:
        """The knobs as plain JSON values (capture.json, synth.json)."""
        d = asdict(self)
        d["underside_reflectance"] = dict(self.underside_reflectance)
        d["haze"] = dict(self.haze)
        return d
