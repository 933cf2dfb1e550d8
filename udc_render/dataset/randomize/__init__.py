"""Randomized panels, sensors and exposures (issue 31): a TOML of distributions (distributions.py, the
shipped default.toml: the documented ranges), N panels drawn once per job and each capture's own draws
(draws.py), a drawn panel as a Display (panels.py). docs/guides/randomize.md has the format and ranges.
"""
from udc_render.dataset.randomize.distributions import (
    DEFAULT,
    SCHEMA,
    Dist,
    Distributions,
    RandomizeError,
    default_distributions,
    load_distributions,
    parse,
)
from udc_render.dataset.randomize.draws import (
    CaptureDraw,
    LensDraw,
    PanelDraw,
    as_record,
    capture_config,
    capture_display,
    capture_panel,
    draw_capture,
    draw_panel,
    draw_panels,
    panel_scene,
    scaled_exposure_s,
)
from udc_render.dataset.randomize.panels import PANEL_NAME, POLED_T_TABLE, poled_fit

__all__ = ["DEFAULT", "SCHEMA", "Dist", "Distributions", "RandomizeError", "default_distributions",
           "load_distributions", "parse", "CaptureDraw", "LensDraw", "PanelDraw", "as_record", "capture_config",
           "capture_display", "capture_panel", "draw_capture", "draw_panel", "draw_panels", "panel_scene",
           "scaled_exposure_s", "PANEL_NAME", "POLED_T_TABLE", "poled_fit"]
