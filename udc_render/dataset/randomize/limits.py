"""What a randomization's ranges must hold for every draw, checked when the file is read, not when a bank meets the
draw that fails.

- A periodic panel's exact power series (psf.banding, the banding at d) over (4 m + 1)² lags, m = ⌊p / λ⌋, is refused
  beyond psf.plan.MAX_SERIES_LAGS. The largest period a range draws is the largest pitch (× the largest length_scale
  for a display file's periodic layout) × the largest disorder_cells where either disorder σ can be > 0 (the
  disordered supercell is the period), checked at shortest_nm(): the shortest wavelength of any camera's table
  (psf.spectral.CAMERAS), at or below the bank's shortest sample (conservative by under 1 % in the period: the
  midpoint rule starts half a step above it).
- A display file's T(λ) × the largest transmission_scale stays ≤ 1, and a micrograph is drawn without disorder
  (panels.file_display refuses such a draw).
"""
from __future__ import annotations

import math
from functools import cache

from psf.micrograph import MicrographLayout
from psf.plan import MAX_SERIES_LAGS, series_lags
from psf.spectral import CAMERAS, load_sensitivities
from udc_render.dataset.randomize.panels import (
    RandomizeError,
    check_file_transmission,
    file_base,
    micrograph_disorder_error,
)

__all__ = ["check_ranges", "shortest_nm"]


@cache
def shortest_nm() -> float:
    """The shortest wavelength of any camera's table (psf.spectral.CAMERAS), read once when first asked (not at
    import: every command that imports the randomization would read the tables)."""
    return min(float(load_sensitivities(c)[0][0]) for c in CAMERAS)


def _disordered(dists: dict, family: str) -> bool:
    return max(dists[f"display.{family}.disorder_position_um"].support) > 0 or \
        max(dists[f"display.{family}.disorder_size_sd"].support) > 0


def _check_period(dists: dict, family: str, where: str, key: str, period_um: float) -> None:
    """One line naming the key when the family's largest period's series passes MAX_SERIES_LAGS at shortest_nm()."""
    cells = int(max(dists[f"display.{family}.disorder_cells"].support)) if _disordered(dists, family) else 1
    period = period_um * cells  # the largest supercell's
    shortest = shortest_nm()
    lags = series_lags((period, period), shortest)
    if lags > MAX_SERIES_LAGS:
        allowed = (math.floor((math.sqrt(MAX_SERIES_LAGS) - 1) / 4) + 1) * shortest * 1e-3
        with_cells = f" × disorder_cells {cells}" if cells > 1 else ""
        raise RandomizeError(f"{where}: {key} = {dists[key].describe()!r}{with_cells}: draws a period of {period:.0f} "
                             f"µm, whose exact power series at {shortest:g} nm needs {lags:.3g} lags; allowed ≤ "
                             f"{MAX_SERIES_LAGS:.3g}: expected periods below {allowed:.0f} µm")


def _check_file(dists: dict, path: str, where: str) -> None:
    display = file_base(path, where)
    if display.is_glass:
        return  # refused at the draw (panels.file_display), with the path
    key = "display.file.transmission_scale"
    check_file_transmission(path, display, max(dists[key].support), repr(dists[key].describe()), where)
    if isinstance(display.layout, MicrographLayout) and _disordered(dists, "file"):
        raise micrograph_disorder_error(path, where)
    if getattr(display.layout, "periodic", True):
        length = "display.file.length_scale"
        period = max(display.layout.period_um) * max(dists[length].support)
        _check_period(dists, "file", where, length, period)


def check_ranges(dists: dict, where: str) -> None:
    """The module doc's checks over the families the file can draw."""
    families = dists["display.family"].support
    for family in ("toled", "poled"):
        if family in families:
            key = f"display.{family}.pitch_um"
            _check_period(dists, family, where, key, max(dists[key].support))
    if "file" in families:
        for path in dists["display.file.path"].support:
            if path:
                _check_file(dists, path, where)
