"""psf.micrograph's flip: each randomly turned tile also mirrored at random (D4, quarter_turns(flips=True)). Oracles:
the raster of a mirrored or turned tile is the mirrored or turned raster (so mirroring the raster mirrors the tile);
a tile that D4 leaves unchanged tiles the same with and without mirrors, to the bit; the draws without flips are the
former quarter turns, and a display without flip keeps its description (its cache keys)."""
from __future__ import annotations

import numpy as np
import pytest

from psf.engine import compute_kernels
from psf.layouts import LayoutError
from psf.lens import Lens
from psf.micrograph import MicrographLayout, quarter_turns
from psf.pupil import cell_raster

RIG = dict(wavelengths_nm=(450.0, 640.0), pixel_um=6.2, size_px=17, pupil_samples=1024)


@pytest.mark.parametrize("n, mode", [(7, "band_limited"), (9, "band_limited"), (7, "area"), (8, "area")])
def test_the_raster_of_a_mirrored_or_turned_tile_is_the_mirrored_or_turned_raster(n, mode):
    """On the engine's rasters (band-limited: odd n, psf.pupil.display_grid; an even one is complex at its Nyquist
    order and commutes with neither)."""
    img = np.random.default_rng(n).random((5, 5))
    ref, _ = cell_raster(MicrographLayout("c", 8.0, image=img), n, n, mode)
    for op in (np.fliplr, np.rot90):
        got, _ = cell_raster(MicrographLayout("c", 8.0, image=op(img)), n, n, mode)
        assert np.abs(got - op(ref)).max() < 1e-12


def test_a_tile_that_d4_leaves_unchanged_tiles_alike_with_and_without_flips():
    """A centred cross is unchanged by every D4 element: the mirrored tiling's kernels are the turned one's (to 1e-12
    of the peak: its raster is D4-symmetric to rounding, 4e-16); an L-shaped tile's differ by far more (the mirrors
    are used), and both keep the light past the window within 0.02."""
    cross = np.zeros((9, 9))
    cross[4, 1:8] = cross[1:8, 4] = 1.0
    ell = np.zeros((9, 9))
    ell[1:8, 1] = ell[7, 1:6] = 1.0
    for cell, same in ((cross, True), (ell, False)):
        k = [compute_kernels(MicrographLayout("c", 8.0, "amplitude", True, 3, cell, flip), Lens(), precision="float64",
                             **RIG) for flip in (False, True)]
        a, b = np.asarray(k[0].kernels), np.asarray(k[1].kernels)
        assert (np.abs(a - b).max() < 1e-12 * a.max()) == same and (same or np.abs(a - b).max() > 1e-3 * a.max())
        assert np.allclose(k[0].energy_outside, k[1].energy_outside, atol=0.02)


def test_the_draws_keep_the_quarter_turns_and_add_their_mirrors():
    turns, d4 = quarter_turns(5, 40, 30), quarter_turns(5, 40, 30, flips=True)
    assert set(np.unique(turns)) == {0, 1, 2, 3} and set(np.unique(d4)) == set(range(8))
    assert set(np.unique(quarter_turns(5, 40, 30, square=False, flips=True))) == {0, 2, 4, 6}
    plain = MicrographLayout("m", 1.0, "amplitude", True, 3, np.ones((4, 4)))
    assert "flip" not in plain.describe() and MicrographLayout("m", 1.0, "amplitude", True, 3, np.ones((4, 4)),
                                                               True).describe()["flip"] is True


def test_a_flip_without_turns_is_refused(tmp_path):
    import imageio.v3 as iio
    path = tmp_path / "c.png"
    iio.imwrite(path, np.full((4, 4), 255, np.uint8))
    says = r"flip \(--tile-flip\) mirrors randomly turned tiles; it needs random_rotation \(--tile-rotation\)"
    with pytest.raises(LayoutError, match=says):
        MicrographLayout.load(path, 8.0, flip=True)
