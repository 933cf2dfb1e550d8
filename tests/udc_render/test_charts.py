"""Procedural monitor charts (udc_render.charts) and their `pattern:` names: analytic properties."""
import math

import numpy as np
import pytest

from udc_render.content import charts
from udc_render.content.monitor_image import DisplayImageError, pattern


def test_sine_has_exactly_its_cycles_along_its_axis():
    img = charts.sine(480, 270, 37, "x")
    spec = np.abs(np.fft.rfft(img[0] - img[0].mean()))
    assert int(np.argmax(spec)) == 37 and spec[37] > 1e3 * np.delete(spec, 37).max()  # a pure tone
    assert np.ptp(img, axis=0).max() < 1e-15  # constant down the columns
    col = charts.sine(480, 270, 12, "y")[:, 0]
    assert int(np.argmax(np.abs(np.fft.rfft(col - col.mean())))) == 12
    assert 0 <= img.min() and img.max() <= 1


def test_siemens_star_has_its_spokes_around_a_circle():
    img = charts.siemens(960, 540, 36)
    phi = np.linspace(0, 2 * np.pi, 4096, endpoint=False)
    r = 200.0  # px from the centre, inside the 0.45 × 540 = 243 px star
    x = (480 + r * np.cos(phi)).astype(int)
    y = (270 + r * np.sin(phi)).astype(int)
    ring = img[y, x]
    spec = np.abs(np.fft.rfft(ring - ring.mean()))
    assert int(np.argmax(spec)) == 36  # 36 periods around the circle
    assert img[5, 5] == 0.5 and img[270, 480 + 250] == 0.5  # grey outside the star


def test_slanted_edge_crosses_half_level_on_the_tilted_line():
    angle = 5.0
    img = charts.slanted_edge(400, 300, angle)
    assert img.min() == pytest.approx(0.2) and img.max() == pytest.approx(0.8)
    # per row, the 0.5 crossing by linear interpolation between neighbouring pixel centres
    rows = np.arange(300)
    cross = [np.interp(0.5, img[j], np.arange(400) + 0.5) for j in rows]
    slope = np.polyfit(rows + 0.5, cross, 1)[0]
    assert slope == pytest.approx(math.tan(math.radians(angle)), abs=2e-3)  # clockwise from vertical
    assert np.interp(150, rows + 0.5, cross) == pytest.approx(200, abs=0.05)  # through the centre


def test_dead_leaves_cover_the_panel_deterministically():
    a = charts.dead_leaves(320, 180, seed=3)
    assert np.array_equal(a, charts.dead_leaves(320, 180, seed=3))
    assert not np.array_equal(a, charts.dead_leaves(320, 180, seed=4))
    assert 0 <= a.min() and a.max() <= 1
    # uniform grey levels: the panel mean is near 1/2 and many distinct leaves are visible
    assert abs(a.mean() - 0.5) < 0.1 and np.unique(a).size > 100


def test_pattern_names_with_arguments():
    img = pattern("sine_x:8", 64, 32)
    assert img.shape == (3, 32, 64) and np.array_equal(img[0], img[2])
    assert np.array_equal(pattern("siemens", 64, 32)[0], charts.siemens(64, 32, 72))
    for bad in ("sine_x:many", "slanted_edge:60", "siemens:0", "white:3", "spiral"):
        with pytest.raises(DisplayImageError, match=r"^content.image = 'pattern:"):
            pattern(bad, 64, 32)
