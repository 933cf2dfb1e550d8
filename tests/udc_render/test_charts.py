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
    assert slope == pytest.approx(math.tan(math.radians(angle)), abs=5e-5)  # clockwise from vertical; 1.5e-5
    assert np.interp(150, rows + 0.5, cross) == pytest.approx(200, abs=0.05)  # through the centre


def test_dead_leaves_cover_the_panel_deterministically():
    a = charts.dead_leaves(320, 180, seed=3)
    assert np.array_equal(a, charts.dead_leaves(320, 180, seed=3))
    assert not np.array_equal(a, charts.dead_leaves(320, 180, seed=4))
    assert 0 <= a.min() and a.max() <= 1
    # uniform grey levels: the panel mean is near 1/2 and many distinct leaves are visible
    assert abs(a.mean() - 0.5) < 0.1 and np.unique(a).size > 100


def test_colour_dead_leaves_paint_the_grey_discs_from_the_palette():
    palette = np.array([[0.1, 0.2, 0.3], [0.9, 0.5, 0.0], [0.0, 0.0, 1.0]])
    grey = charts.dead_leaves(320, 180, seed=3)
    img = charts.dead_leaves_colour(320, 180, 3, palette)
    assert img.shape == (3, 180, 320)
    colours = {tuple(c) for c in img.reshape(3, -1).T}
    assert colours == {tuple(c) for c in palette}  # every pixel a palette colour, each colour used
    for v in np.unique(grey)[:50]:  # one disc (one grey level), one colour
        assert len({tuple(c) for c in img[:, grey == v].T}) == 1
    with pytest.raises(ValueError, match="palette"):
        charts.dead_leaves_colour(32, 18, 0, np.ones((4, 4)))


def test_colour_dead_leaves_take_a_photographs_colours():
    """pattern:dead_leaves_colour:SEED: the panel's colours are pixels of the seed's built-in photograph
    (sRGB-decoded); a uniform draw per disc, so the panel's mean is near the photograph's."""
    from udc_render.content.monitor_image import photo_palette
    img = pattern("dead_leaves_colour:2", 640, 360)
    palette = photo_palette(2)
    assert img.shape == (3, 360, 640) and 0 <= img.min() and img.max() <= 1
    sample = {tuple(c) for c in img[:, ::37, ::41].reshape(3, -1).T}
    assert sample <= {tuple(c) for c in palette}
    assert not np.array_equal(img[0], img[2])  # colour, not grey
    assert np.abs(img.mean(axis=(1, 2)) - palette.mean(axis=0)).max() < 0.1


def test_pattern_names_with_arguments():
    img = pattern("sine_x:8", 64, 32)
    assert img.shape == (3, 32, 64) and np.array_equal(img[0], img[2])
    assert np.array_equal(pattern("siemens", 64, 32)[0], charts.siemens(64, 32, 72))
    for bad in ("sine_x:many", "slanted_edge:60", "siemens:0", "white:3", "spiral"):
        with pytest.raises(DisplayImageError, match=r"^content.image = 'pattern:"):
            pattern(bad, 64, 32)


def _dead_leaves_one_by_one(cols, rows, seed, r_min_px=charts.DEAD_LEAVES_R_MIN_PX):
    """The definition, disc by disc (the implementation before the batched fill): the oracle of the fast one."""
    rng = np.random.default_rng(seed)
    r_max = charts.DEAD_LEAVES_R_MAX_FRACTION * rows
    img, covered, left, batch = np.zeros((rows, cols)), np.zeros((rows, cols), bool), rows * cols, 4096
    while left:
        u = rng.random(batch)
        radii = (r_min_px ** -2 + u * (r_max ** -2 - r_min_px ** -2)) ** -0.5
        cx, cy, value = rng.random(batch) * cols, rng.random(batch) * rows, rng.random(batch)
        for r, x0, y0, v in zip(radii, cx, cy, value):
            r0, r1 = max(int(y0 - r), 0), min(int(y0 + r) + 1, rows)
            c0, c1 = max(int(x0 - r), 0), min(int(x0 + r) + 1, cols)
            yy = np.arange(r0, r1)[:, None] + 0.5 - y0
            xx = np.arange(c0, c1)[None, :] + 0.5 - x0
            new = (xx * xx + yy * yy <= r * r) & ~covered[r0:r1, c0:c1]
            n = int(new.sum())
            if n:
                img[r0:r1, c0:c1][new] = v
                covered[r0:r1, c0:c1] |= new
                left -= n
                if not left:
                    break
    return img


@pytest.mark.parametrize("cols, rows, seed", [(320, 180, 3), (97, 61, 0), (640, 360, 11)])
def test_dead_leaves_batched_equal_the_disc_by_disc_definition(cols, rows, seed):
    """The batched fill (culled discs, then every disc against the last pixels) paints the same bits as the
    definition, disc by disc."""
    assert np.array_equal(charts.dead_leaves(cols, rows, seed), _dead_leaves_one_by_one(cols, rows, seed))
