"""A drawn panel as a Display: the family's layout (optionally a disordered supercell), T(λ) and gain.

T(λ): the T-OLED's flat T (optics.displays.TOLED_T, fitted to the paper's γ) × transmission_scale; the
P-OLED's polyimide edge × silver cathode at the drawn Urbach width w, its (scale, edge, cathode) fitted
to the paper's γ (0.34/0.34/0.34/0.20) at each width (POLED_T_TABLE, every 2 nm from 8 to 30 nm:
optics.displays.fit_poled_transmission on the default rig, as `udc-render study realism` does) and
interpolated linearly in w (γ within 0.25 % of the paper's at every width, 0.25 nm steps), then
× transmission_scale. The gain is the paper's for the family (6, 25).
"""
from __future__ import annotations

import numpy as np

from psf import layouts
from udc_render.optics.displays import PAPER_GAIN, TOLED_T, Display, Transmission, poled_transmission

PANEL_NAME = "random"  # the drawn display's name: its capture's folder in an item

# w (nm): (scale, edge_nm, cathode_nm), the fit at each Urbach width (module doc; 20 nm: the preset's constants;
# tests/udc_render/test_randomize.py re-fits two rows from the default rig's kernels, -m slow)
POLED_T_TABLE = {
    8.0: (0.0829717, 455.463, 7.04651), 10.0: (0.0849655, 453.119, 7.49275), 12.0: (0.0874161, 450.907, 8.00738),
    14.0: (0.0904635, 448.847, 8.60423), 16.0: (0.0942937, 446.957, 9.29936), 18.0: (0.0991251, 445.245, 10.1066),
    20.0: (0.105223, 443.714, 11.0389), 22.0: (0.112937, 442.363, 12.1124), 24.0: (0.122759, 441.196, 13.3506),
    26.0: (0.135424, 440.213, 14.7895), 28.0: (0.152088, 439.419, 16.4861), 30.0: (0.174683, 438.818, 18.5326),
}
# The largest transmission_scale that keeps T ≤ 1 at every wavelength, per family
MAX_TRANSMISSION_SCALE = {"toled": 1.0 / TOLED_T, "poled": 1.0 / max(v[0] for v in POLED_T_TABLE.values())}


def poled_fit(urbach_width_nm: float) -> tuple[float, float, float]:
    """(scale, edge_nm, cathode_nm) of the P-OLED's T(λ) at Urbach width w: POLED_T_TABLE interpolated."""
    w = np.array(sorted(POLED_T_TABLE))
    rows = np.array([POLED_T_TABLE[x] for x in w])
    return tuple(float(np.interp(urbach_width_nm, w, rows[:, j])) for j in range(3))


def panel_transmission(family: str, values: dict) -> Transmission:
    """The family's T(λ) at the drawn values (module doc)."""
    s = values["transmission_scale"]
    if family == "toled":
        return Transmission("flat", TOLED_T * s)
    w = values["urbach_width_nm"]
    scale, edge, cathode = poled_fit(w)
    return poled_transmission(scale * s, edge, cathode, w)


def panel_layout(family: str, values: dict, seed: int):
    """The family's layout at the drawn values; a disordered supercell (psf.layouts.disordered, its own
    `seed`) when either disorder σ is > 0."""
    if family == "toled":
        base = layouts.toled(values["pitch_um"], values["open_fraction"], values["slit_height_fraction"])
    else:
        base = layouts.poled(values["pitch_um"], values["open_fraction"], values["small_to_large"])
    if values["disorder_position_um"] > 0 or values["disorder_size_sd"] > 0:
        return layouts.disordered(base, int(values["disorder_cells"]), values["disorder_position_um"],
                                  values["disorder_size_sd"], seed)
    return base


def panel_display(family: str, values: dict, distance_mm: float, seed: int, source: str) -> Display:
    """The drawn panel, named PANEL_NAME."""
    return Display(PANEL_NAME, panel_layout(family, values, seed), panel_transmission(family, values),
                   PAPER_GAIN[family], float(distance_mm), source=source)
