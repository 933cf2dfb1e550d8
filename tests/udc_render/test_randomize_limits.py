"""randomize.limits: a range some draw of which the engine would refuse is refused when the file is read."""
from __future__ import annotations

import math

import pytest

from psf.errors import PSFError
from psf.plan import MAX_SERIES_LAGS, _check_series
from udc_render.dataset.randomize import RandomizeError, load_distributions
from udc_render.dataset.randomize.limits import shortest_nm

# the longest period the engine's series holds at the shortest wavelength: m = ⌊p / λ⌋ ≤ (√MAX − 1) / 4
SHORTEST_NM = shortest_nm()
M_TOP = math.floor((math.sqrt(MAX_SERIES_LAGS) - 1) / 4)
P_TOP_UM = (M_TOP + 1) * SHORTEST_NM * 1e-3  # periods below it pass, at it they fail


def _load(tmp_path, text: str):
    f = tmp_path / "mine.toml"
    f.write_text(text)
    return load_distributions(f)


def test_the_bound_is_the_engines_own():
    """The period the file check allows is the engine's: psf.plan's check passes just below it and refuses at it
    (at SHORTEST_NM, the shortest wavelength any camera's channels reach: every longer one has fewer lags)."""
    _check_series((P_TOP_UM * (1 - 1e-9), P_TOP_UM * (1 - 1e-9)), SHORTEST_NM)
    with pytest.raises(PSFError):
        _check_series((P_TOP_UM, P_TOP_UM), SHORTEST_NM)
    assert 1000 < P_TOP_UM < 2000  # 2.5e8 lags near 380 nm: 1.5 mm (psf.plan's comment: 1008 µm ran, 2688 µm did not)


def test_a_disordered_supercell_whose_period_the_engine_refuses_is_refused_on_read(tmp_path):
    """The T-OLED's largest pitch × the largest disorder_cells is the period; only where disorder can be drawn."""
    cells = math.ceil(P_TOP_UM / 320.0)  # 320 µm: the default's largest T-OLED pitch
    text = (f'[display]\nfamily = "toled"\n[display.toled]\n'
            f'disorder_cells = {{dist = "choice", values = [2, {cells}]}}\n')
    _load(tmp_path, text)  # no disorder drawn: the supercell is never made
    with pytest.raises(RandomizeError) as e:
        _load(tmp_path, text + "disorder_position_um = 2.0\n")
    line = str(e.value)
    assert len(line.splitlines()) == 1 and "display.toled.pitch_um" in line and f"disorder_cells {cells}" in line
    assert f"expected periods below {P_TOP_UM:.0f} µm" in line and str(tmp_path / "mine.toml") in line
    _load(tmp_path, text.replace(str(cells), str(cells - 1)) + "disorder_position_um = 2.0\n")  # 320 (c − 1) passes


def test_a_pitch_the_engine_refuses_is_refused_on_read_and_the_default_is_held(tmp_path):
    with pytest.raises(RandomizeError) as e:
        _load(tmp_path, f'[display.poled]\npitch_um = {{dist = "uniform", low = 50, high = {P_TOP_UM + 1:.0f}}}\n')
    assert "display.poled.pitch_um" in str(e.value) and "lags" in str(e.value)
    _load(tmp_path, '[display]\nfamily = "toled"\n[display.poled]\npitch_um = 5000\n')  # a family never drawn
    load_distributions("default")


def test_the_guides_bound_is_the_engines():
    """Consistency, not physics: docs/guides/randomize.md states the period bound the check holds."""
    from pathlib import Path
    guide = (Path(__file__).parents[2] / "docs/guides/randomize.md").read_text()
    assert f"periods of {P_TOP_UM:.0f} µm and more" in guide and f"at {SHORTEST_NM:.0f} nm" in guide
