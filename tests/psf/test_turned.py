"""psf.turned: a preset's cell turned per tile, from its exact Fourier series. Oracles: a cell whose 1 µm raster is
exact (edges on the grid) gives the micrograph route's kernels; unturned, the preset's own; the turns are the
micrograph's for the seed; the edge framing puts the slit at x = 0. The 1 µm raster of intensities that the
simulator took before keeps light inside the window that the preset sends past it (golden values, the docstring's)."""
from __future__ import annotations

import numpy as np
import pytest

from psf import layouts
from psf.engine import compute_kernels
from psf.layouts import LayoutError, PeriodicLayout, Rect
from psf.lens import Lens
from psf.micrograph import MicrographLayout
from psf.turned import TurnedLayout, edge_framed

RIG = dict(wavelengths_nm=(450.0, 640.0), pixel_um=6.2, size_px=65)


def _raster_micrograph(layout: PeriodicLayout, pixel_um: float, turned: bool) -> MicrographLayout:
    c = round(layout.pitch_x_um / pixel_um)
    return MicrographLayout("cell", layout.pitch_x_um / c, "amplitude", turned, 0, layout.cell_raster(c, c)[0])


def test_a_cell_exact_on_its_raster_turns_as_the_micrograph_does():
    """A rectangle with its edges on the 1 µm grid is its raster exactly: turned at d = 2 mm, the kernels and the
    light outside the window equal the micrograph route's (float32 kernels: 1e-5 of the peak)."""
    box = PeriodicLayout("box", 168.0, 168.0, (Rect(20.0, 84.0, 36.0, 150.0),))
    for d_mm in (0.0, 2.0):
        a = compute_kernels(TurnedLayout(box, 0), Lens(), distance_mm=d_mm, **RIG)
        b = compute_kernels(_raster_micrograph(box, 1.0, True), Lens(), distance_mm=d_mm, **RIG)
        assert np.abs(np.asarray(a.kernels) - np.asarray(b.kernels)).max() < 1e-5 * np.asarray(b.kernels).max()
        assert np.allclose(a.energy_outside, b.energy_outside, rtol=1e-4)


def test_unturned_it_is_the_preset():
    toled = layouts.toled(pitch_um=168.0, open_fraction=0.2)
    a = compute_kernels(TurnedLayout(toled, 0, random_rotation=False), Lens(), **RIG)
    b = compute_kernels(toled, Lens(), **RIG)
    assert np.array_equal(np.asarray(a.kernels), np.asarray(b.kernels))
    assert TurnedLayout(toled, 3).tile_rotations(5, 4).tolist() == \
        MicrographLayout("m", 1.0, "amplitude", True, 3, np.ones((4, 4))).tile_rotations(5, 4).tolist()


def test_the_edge_framing_starts_the_slit_at_zero():
    toled = layouts.toled(pitch_um=168.0, open_fraction=0.2)
    framed = edge_framed(toled)
    slit = framed.openings[0]
    assert slit.cx_um - slit.width_um / 2 == pytest.approx(0.0, abs=1e-12)
    assert framed.open_fraction == pytest.approx(toled.open_fraction, rel=1e-12)
    amp = framed.cell_raster(168, 168)[0]
    assert amp[:, 0].max() > 0.99 and amp[:, -1].max() == 0.0


def test_the_intensity_raster_kept_light_inside_the_window():
    """The T-OLED (168 µm, 20 %) at the layout-trained rig (129 px of 6.2 µm): the preset's share outside the window
    against the √I raster on 1 µm squares (the module doc's numbers, to 1e-4)."""
    toled = layouts.toled(pitch_um=168.0, open_fraction=0.2)
    rig = dict(wavelengths_nm=(450.0, 520.0, 640.0), pixel_um=6.2, size_px=129)
    exact = compute_kernels(toled, Lens(), **rig).energy_outside
    intensity = toled.cell_raster(168, 168)[1]  # the raster `study layout-trained` took before psf.turned
    raster = compute_kernels(MicrographLayout("c", 1.0, "intensity", False, 0, np.sqrt(intensity)), Lens(),
                             **rig).energy_outside
    assert np.allclose(exact, (0.0225, 0.0247, 0.0295), atol=1e-4)
    assert np.allclose(raster, (0.0155, 0.0176, 0.0223), atol=1e-4)


def test_a_rectangular_cell_is_refused():
    with pytest.raises(LayoutError, match="square cell"):
        TurnedLayout(PeriodicLayout("r", 100.0, 50.0, (Rect(50.0, 25.0, 10.0, 10.0),)))
