"""A drawn panel as a Display: the family's layout (optionally a disordered supercell), T(λ) and gain.

T(λ): the T-OLED's flat T (optics.displays.TOLED_T, fitted to the paper's γ) × transmission_scale; the
P-OLED's polyimide edge × silver cathode at the drawn Urbach width w, its (scale, edge, cathode) fitted
to the paper's γ (0.34/0.34/0.34/0.20) at each width (POLED_T_TABLE, every 1 nm from 8 to 30 nm:
optics.displays.fit_poled_transmission on the default rig, as `udc-render study realism` does) and
interpolated linearly in w (γ within 0.082 % of the paper's at every width, 0.25 nm steps), then
× transmission_scale. The gain is the paper's for the family (6, 25).

The family 'file' is a user's panel (file_display): a display file (`udc-render fit` writes one) or a micrograph
image, every length of its layout × length_scale (a periodic layout's pitch and openings, a micrograph's pixel
size), its T(λ) × transmission_scale (refused where T would pass 1), its gain, at the drawn distance.
"""
from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np

from psf import layouts
from psf.micrograph import MicrographLayout
from udc_render.errors import UdcError
from udc_render.optics.displays import PAPER_GAIN, TOLED_T, Display, Transmission, load_display, poled_transmission


class RandomizeError(UdcError):
    """A bad randomization file or value; one line naming the file, key, value and what is allowed."""


PANEL_NAME = "random"  # the drawn display's name: its capture's folder in an item

# w (nm): (scale, edge_nm, cathode_nm), the fit at each Urbach width (module doc; 20 nm: the preset's constants;
# tests/udc_render/test_randomize.py re-fits two rows from the default rig's kernels, -m slow)
POLED_T_TABLE = {
    8.0: (0.0870588, 455.94, 8.25635), 9.0: (0.0881316, 454.756, 8.46883), 10.0: (0.0893219, 453.603, 8.69859),
    11.0: (0.0906431, 452.485, 8.94672), 12.0: (0.0921141, 451.404, 9.21513), 13.0: (0.0937585, 450.362, 9.50615),
    14.0: (0.0956034, 449.362, 9.82228), 15.0: (0.0976787, 448.406, 10.1659), 16.0: (0.100017, 447.494, 10.5395),
    17.0: (0.102655, 446.628, 10.9451), 18.0: (0.105631, 445.808, 11.385), 19.0: (0.108992, 445.035, 11.8616),
    20.0: (0.112792, 444.308, 12.3775), 21.0: (0.117094, 443.628, 12.9359), 22.0: (0.121974, 442.994, 13.5405),
    23.0: (0.127527, 442.408, 14.1961), 24.0: (0.13387, 441.868, 14.9085), 25.0: (0.14115, 441.377, 15.685),
    26.0: (0.149558, 440.933, 16.535), 27.0: (0.159339, 440.538, 17.4702), 28.0: (0.170824, 440.192, 18.5062),
    29.0: (0.184457, 439.896, 19.6633), 30.0: (0.200859, 439.651, 20.9689),
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


def micrograph_disorder_error(what: str, where: str = "") -> RandomizeError:
    """The one line refusing disorder on a micrograph (`what`), after `where` (a file) when given."""
    return RandomizeError(f"{where + ': ' if where else ''}display.file.disorder_*: {what} is a micrograph: expected "
                          "disorder_position_um = 0 and disorder_size_sd = 0 (disorder moves the openings of a "
                          "periodic layout)")


def with_disorder(base, values: dict, seed: int, what: str):
    """`base`, or its disordered supercell (psf.layouts.disordered, its own `seed`) when either disorder σ is > 0."""
    if not (values["disorder_position_um"] > 0 or values["disorder_size_sd"] > 0):
        return base
    if not isinstance(base, layouts.PeriodicLayout):
        raise micrograph_disorder_error(what)
    return layouts.disordered(base, int(values["disorder_cells"]), values["disorder_position_um"],
                              values["disorder_size_sd"], seed)


def panel_layout(family: str, values: dict, seed: int):
    """A preset family's layout at the drawn values, disordered where drawn so."""
    if family == "toled":
        base = layouts.toled(values["pitch_um"], values["open_fraction"], values["slit_height_fraction"])
    else:
        base = layouts.poled(values["pitch_um"], values["open_fraction"], values["small_to_large"])
    return with_disorder(base, values, seed, family)


def scaled_layout(layout, s: float):
    """Every length of a layout × s: a periodic layout's pitch and its openings' centres and sizes, or a
    micrograph's pixel size (its tile as it is)."""
    if isinstance(layout, MicrographLayout):
        return replace(layout, pixel_um=layout.pixel_um * s)
    lengths = ("cx_um", "cy_um", "width_um", "height_um", "rx_um", "ry_um")
    openings = tuple(replace(o, **{k: getattr(o, k) * s for k in lengths if hasattr(o, k)}) for o in layout.openings)
    return replace(layout, pitch_x_um=layout.pitch_x_um * s, pitch_y_um=layout.pitch_y_um * s, openings=openings)


def scaled_transmission(t: Transmission, s: float) -> Transmission:
    """T(λ) × s, in the transmission's own parameters (a flat value, an edge's or polyimide's scale, a table)."""
    if t.kind == "flat":
        return replace(t, value=t.value * s)
    if t.kind == "csv":
        return replace(t, table_t=tuple(v * s for v in t.table_t))
    return replace(t, scale=t.scale * s)


T_CHECK_NM = np.arange(350.0, 801.0)  # where a scaled file T(λ) must stay ≤ 1


@lru_cache(maxsize=8)
def _loaded_display(path: str) -> Display:
    """load_display once per path for a job's draws (a micrograph's image is decoded once, not once a panel)."""
    return load_display(path)


def file_base(path: str, where: str = "") -> Display:
    """The family 'file''s display at path (loaded once per path); a load error names the path (after where: …)."""
    try:
        return _loaded_display(path)
    except ValueError as e:  # a DisplayError, or psf's LayoutError of a micrograph
        raise RandomizeError(f"{where}{': ' if where else ''}display.file.path = {path!r}: {e}") from None


def check_file_transmission(path: str, base: Display, scale: float, shown: str, where: str = "") -> None:
    """One line when T(λ) × scale exceeds 1 on T_CHECK_NM (shown: the scale as the message gives it)."""
    top = float(np.max(base.transmission(T_CHECK_NM)))
    if top * scale > 1.0 + 1e-12:
        raise RandomizeError(f"{where}{': ' if where else ''}display.file.transmission_scale = {shown}: puts the T(λ) "
                             f"of {path} at {top * scale:.3g}: expected T ≤ 1 (at most {1.0 / top:.3g})")


def file_display(values: dict, distance_mm: float, seed: int, source: str) -> Display:
    """The family 'file' at the drawn values (module doc)."""
    path, scale = values["path"], values["transmission_scale"]
    base = file_base(path)
    if base.is_glass:
        raise RandomizeError(f"display.file.path = {path!r}: a bare lens (glass): expected a display")
    check_file_transmission(path, base, scale, f"{scale:g}")
    layout = with_disorder(scaled_layout(base.layout, values["length_scale"]), values, seed, path)
    t = scaled_transmission(base.transmission, scale)
    return Display(PANEL_NAME, layout, t, base.gain, float(distance_mm), source=f"{source}; {base.name} from {path}")


def panel_display(family: str, values: dict, distance_mm: float, seed: int, source: str) -> Display:
    """The drawn panel, named PANEL_NAME."""
    if family == "file":
        return file_display(values, distance_mm, seed, source)
    return Display(PANEL_NAME, panel_layout(family, values, seed), panel_transmission(family, values),
                   PAPER_GAIN[family], float(distance_mm), source=source)
