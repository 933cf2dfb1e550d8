"""Stray light the diffraction model leaves out: the effects the paper names as open or as real-data gaps
(l.412: environment light; l.429: an active display, reflections, lens flare) and the display's haze.

    settings.py   StrayLight (the knobs, each off at 0 or None), ON_VALUES, StrayLightError
    spread.py     the wide spreads on the sensor (a θ⁻² scatter tail, a ghost's disc) and their convolution
    apply.py      each view's electrons with the stray light (stray_electrons, apply_view, StrayContext)
"""
from udc_render.optics.stray.apply import (
    StrayContext,
    apply_view,
    stray_electrons,
    synthesis_stray_light,
    uniform_electrons,
)
from udc_render.optics.stray.settings import ON_VALUES, StrayLight, StrayLightError
from udc_render.optics.stray.spread import Spread, convolve

__all__ = ["ON_VALUES", "Spread", "StrayContext", "StrayLight", "StrayLightError", "apply_view", "convolve",
           "stray_electrons", "synthesis_stray_light", "uniform_electrons"]
