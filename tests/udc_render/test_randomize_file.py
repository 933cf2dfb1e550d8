"""The randomization's family 'file': a user's display file or micrograph, drawn around (randomize.panels)."""
from __future__ import annotations

import numpy as np
import pytest

from psf.micrograph import MicrographLayout
from udc_render.dataset.randomize import RandomizeError, draw_panels, load_distributions
from udc_render.io.images import write_png
from udc_render.optics.displays import load_display

PANEL_TOML = """[display]
name = "my_poled"
gain = 20
distance_mm = 0

[display.layout]
type = "poled"
pitch_um = 70
open_fraction = 0.25
small_to_large = 0.8

[display.transmission]
type = "flat"
value = 0.04
"""


def _tile(path, side_px: int = 16):
    """A micrograph tile: an open square in the middle of an opaque cell, 8-bit."""
    img = np.zeros((side_px, side_px), np.uint8)
    img[side_px // 4:3 * side_px // 4, side_px // 4:3 * side_px // 4] = 255
    path.parent.mkdir(exist_ok=True)
    write_png(path, img)


def _ranges(tmp_path, text: str):
    (tmp_path / "panels").mkdir(exist_ok=True)
    (tmp_path / "panels" / "my_poled.toml").write_text(PANEL_TOML)
    f = tmp_path / "mine.toml"
    f.write_text(text)
    return f


def test_a_file_panel_is_the_file_with_its_lengths_and_t_scaled_at_the_drawn_distance(tmp_path):
    f = _ranges(tmp_path, """[display]
family = "file"
distance_mm = {dist = "uniform", low = 1.0, high = 2.0}

[display.file]
path = "panels/my_poled.toml"
length_scale = {dist = "uniform", low = 0.9, high = 1.1}
transmission_scale = {dist = "log_uniform", low = 0.5, high = 2.0}
haze = 0.01
""")
    dists = load_distributions(f)
    assert dists["display.file.path"].values == (str((tmp_path / "panels" / "my_poled.toml").resolve()),)
    base = load_display(str(tmp_path / "panels" / "my_poled.toml"))
    for p in draw_panels(dists, 6, seed=3):
        s, ts = p.values["display.file.length_scale"], p.values["display.file.transmission_scale"]
        lay = p.display.layout
        assert p.family == "file" and 0.9 <= s <= 1.1 and p.haze == 0.01
        assert lay.pitch_x_um == pytest.approx(70 * s, rel=1e-12)
        assert [o.rx_um for o in lay.openings] == pytest.approx([o.rx_um * s for o in base.layout.openings], rel=1e-12)
        assert lay.open_fraction == pytest.approx(base.layout.open_fraction, rel=1e-12)  # a scale keeps the shape
        assert p.display.transmission(550.0) == pytest.approx(0.04 * ts, rel=1e-12)
        assert p.display.gain == 20 and 1.0 <= p.display.distance_mm <= 2.0
    a, b = draw_panels(dists, 2, seed=3), draw_panels(dists, 2, seed=3)
    assert [x.values for x in a] == [x.values for x in b]


def test_a_micrograph_panel_scales_its_pixel_and_a_choice_mixes_files_with_presets(tmp_path):
    _tile(tmp_path / "panels" / "tile.png")
    f = _ranges(tmp_path, """[display]
family = {dist = "choice", values = ["poled", "file"]}

[display.file]
path = {dist = "choice", values = ["panels/tile.png", "panels/my_poled.toml"]}
length_scale = 2.0
""")
    panels = draw_panels(load_distributions(f), 24, seed=0)
    tiles = [p for p in panels if isinstance(p.display.layout, MicrographLayout)]
    assert {p.family for p in panels} == {"poled", "file"} and tiles
    assert all(p.display.layout.pixel_um == 2.0 and p.display.layout.period_um == (32.0, 32.0) for p in tiles)
    assert any(p.family == "file" and not isinstance(p.display.layout, MicrographLayout) for p in panels)
    poled_only = _ranges(tmp_path, '[display]\nfamily = "poled"\n')
    alone = draw_panels(load_distributions(poled_only), 24, seed=0)
    for p in panels:  # every key has its own stream: a P-OLED drawn beside files is the P-OLED drawn alone
        if p.family == "poled":
            assert p.values == alone[p.index].values


def test_the_default_draws_are_unchanged_by_the_file_family():
    """The default's panels draw no display.file key (golden: the first panel of seed 0 as before the family)."""
    p = draw_panels(load_distributions("default"), 1, seed=0)[0]
    assert not any(k.startswith("display.file.") for k in p.values)


@pytest.mark.parametrize("text, words", [
    ('[display]\nfamily = "file"\n', "the family 'file' needs display.file.path"),
    ('[display]\nfamily = "file"\n[display.file]\npath = "panels/none.toml"\n', "no such file"),
    ('[display.file]\npath = {dist = "uniform", low = 0, high = 1}\n', "a fixed value or dist = 'choice'"),
    ('[display.file]\nlength_scale = 0\n', "display.file.length_scale = 0"),
])
def test_a_bad_file_family_is_refused_in_one_line(tmp_path, text, words):
    f = _ranges(tmp_path, text)
    with pytest.raises(RandomizeError) as e:
        load_distributions(f)
    assert words in str(e.value) and len(str(e.value).splitlines()) == 1 and str(f) in str(e.value)


@pytest.mark.parametrize("text, words", [
    ('[display.file]\npath = "panels/bright.toml"\ntransmission_scale = 4.0\n', "at 2: expected T ≤ 1 (at most 2)"),
    ('[display.file]\npath = "panels/tile.png"\ndisorder_size_sd = 0.1\n', "is a micrograph"),
    ('[display.file]\npath = "panels/bad.toml"\n', "display.file.path = "),
])
def test_a_file_panel_that_cannot_be_drawn_is_refused_in_one_line(tmp_path, text, words):
    _tile(tmp_path / "panels" / "tile.png")
    (tmp_path / "panels" / "bad.toml").write_text("[display]\ngain = -1\n")
    (tmp_path / "panels" / "bright.toml").write_text(PANEL_TOML.replace("value = 0.04", "value = 0.5"))
    f = _ranges(tmp_path, '[display]\nfamily = "file"\n' + text)
    with pytest.raises(RandomizeError) as e:
        draw_panels(load_distributions(f), 1, seed=0)
    assert words in str(e.value) and len(str(e.value).splitlines()) == 1
