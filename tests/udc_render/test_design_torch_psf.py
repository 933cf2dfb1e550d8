"""The torch PSF of a free-form cell (udc_render.design.torch_psf) against the engine's own kernels (psf).

Tolerance: 1e-8 of the peak in float64, the engine's own oracle bound for its kernels
(tests/psf/test_psf_oracles.py::test_airy_intensity_engine_point_samples); 1e-6 in float32 (its unit-sum bound,
test_kernels_have_unit_sum). Measured: 2e-15 (float64), 2e-7 (float32).
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from psf import Lens, compute_kernels, layouts
from psf.micrograph import MicrographLayout
from psf.pupil import cell_raster
from restore.known import packed_from_sensor
from udc_render.design import torch_psf as tp

LENS = Lens()
WL = (450.0, 640.0)


def _engine(cell, pixel_um, rotate, size_px, pupil, precision="float64", flip=False):
    lay = MicrographLayout("cell", pixel_um, random_rotation=rotate, seed=3, image=cell, flip=flip)
    ks = compute_kernels(lay, LENS, WL, size_px=size_px, pupil_samples=pupil, precision=precision)
    return lay, ks.kernels


def _torch(cell, pixel_um, lay, size_px, pupil, dtype=torch.float64):
    grid = tp.cell_grid(cell.shape[0], pixel_um, LENS, WL, 3.1, size_px, pupil)
    turns = lay.tile_rotations(grid.tiles, grid.tiles) if lay.random_rotation else None
    return tp.kernels(torch.tensor(cell, dtype=dtype), grid, turns).numpy()


def test_raster_matrix_is_the_engines_band_limited_raster():
    cell = np.random.default_rng(0).random((7, 7))
    b = tp.raster_matrix(11, 7)
    ref, _ = cell_raster(MicrographLayout("cell", 9.0, image=cell), 11, 11, "band_limited")
    assert np.abs(b @ cell @ b.T - ref).max() < 1e-12


@pytest.mark.parametrize("rotate, flip", [(False, False), (True, False), (True, True)])
def test_kernels_equal_the_engines_float64(rotate, flip):
    """A grey 168 µm T-OLED cell (21 × 8 µm), plain and with the engine's random quarter-turns; with their mirror
    images too (D4: tile_flip), its slit cut at the cell's centre line (the whole T-OLED is its own mirror image)."""
    cell = tp.preset_cell(layouts.toled(pitch_um=168.0), 21)
    if flip:
        cell[:, 11:] = 0.0
    lay, ref = _engine(cell, 8.0, rotate, 31, 256, flip=flip)
    got = _torch(cell, 8.0, lay, 31, 256)
    assert np.abs(got - ref).max() < 1e-8 * ref.max()


def test_kernels_equal_the_engines_float32():
    cell = np.random.default_rng(1).random((5, 5))
    lay, ref = _engine(cell, 9.0, True, 31, 128, "float32")
    got = _torch(cell, 9.0, lay, 31, 128, torch.float32)
    assert np.abs(got - ref).max() < 1e-6 * ref.max()


@pytest.mark.parametrize("rotate, bound", [(True, 1e-12), (False, 0.01)])
def test_window_fraction_is_the_engines(rotate, bound):
    """1 − energy_outside. Turned tiles: the engine's raster sum κ Σ|m|² A, the same formula (measured 2e-15).
    Plain tiling: the engine takes the exact power series instead; the raster's differs by 0.38 % here
    (0.2–1.3 % over three cells at 256 pupil samples; bound 1 %, set after measuring)."""
    cell = np.random.default_rng(1).random((7, 7))
    lay = MicrographLayout("cell", 9.0, random_rotation=rotate, seed=3, image=cell)
    ks = compute_kernels(lay, LENS, WL, size_px=63, pupil_samples=256, precision="float64")
    grid = tp.cell_grid(7, 9.0, LENS, WL, 3.1, 63, 256)
    _, inside = tp.kernels_and_window(torch.tensor(cell), grid, lay.tile_rotations(grid.tiles, grid.tiles))
    assert np.abs(inside.numpy() / (1 - ks.energy_outside) - 1).max() < bound


def test_gradient_is_the_finite_difference():
    cell = torch.tensor(np.random.default_rng(2).random((5, 5)), dtype=torch.float64, requires_grad=True)
    grid = tp.cell_grid(5, 9.0, LENS, (520.0,), 3.1, 15, 64)
    weight = torch.tensor(np.random.default_rng(3).random((15, 15)), dtype=torch.float64)

    def loss(c):
        return (tp.kernels(c, grid)[0] * weight).sum()
    loss(cell).backward()
    h, e = 1e-3, torch.zeros_like(cell)
    e[2, 1] = h
    fd = (loss(cell.detach() + e) - loss(cell.detach() - e)) / (2 * h)
    assert abs(float(cell.grad[2, 1]) - float(fd)) < 1e-6 * abs(float(fd))  # rounding ε·L/h: 2e-8 rel., measured 1.4e-8


def test_a_mirrored_cell_mirrors_the_kernel():
    cell = np.random.default_rng(4).random((5, 5))
    grid = tp.cell_grid(5, 9.0, LENS, (520.0,), 3.1, 15, 64)
    k = tp.kernels(torch.tensor(cell), grid).numpy()
    m = tp.kernels(torch.tensor(cell[:, ::-1].copy()), grid).numpy()
    assert np.abs(m - k[..., ::-1]).max() < 1e-12 * k.max()


def test_tile_transforms_are_seeded_and_cover_d4():
    a, b = tp.tile_transforms(40, 7), tp.tile_transforms(40, 7)
    assert np.array_equal(a, b) and set(np.unique(a)) == set(range(8))
    assert set(np.unique(tp.tile_transforms(40, 7, flips=False))) == set(range(4))
    assert not tp.tile_transforms(5, None).any() and not np.array_equal(a, tp.tile_transforms(40, 8))


def test_preset_cell_keeps_the_open_area():
    lay = layouts.toled(pitch_um=168.0)
    assert abs(tp.preset_cell(lay, 21).mean() - lay.open_fraction) < 1e-12


def test_bad_cell_is_one_line():
    grid = tp.cell_grid(5, 9.0, LENS, (520.0,), 3.1, 15, 64)
    with pytest.raises(tp.DesignError, match="expected shape"):
        tp.kernels(torch.zeros((4, 4), dtype=torch.float64), grid)


@pytest.mark.slow
def test_kernels_equal_the_engines_at_its_defaults():
    """The engine's own sampling for 255-px kernels (pupil samples chosen by the engine), quarter-turned."""
    cell = tp.preset_cell(layouts.toled(pitch_um=168.0), 21)
    lay = MicrographLayout("cell", 8.0, random_rotation=True, seed=3, image=cell)
    ref = compute_kernels(lay, LENS, WL, precision="float64").kernels
    grid = tp.cell_grid(21, 8.0, LENS, WL)
    got = tp.kernels(torch.tensor(cell), grid, lay.tile_rotations(grid.tiles, grid.tiles)).numpy()
    assert np.abs(got - ref).max() < 1e-8 * ref.max()


def test_a_coarser_pitch_is_the_finer_kernels_summed_in_blocks():
    """Pixel integration is additive: a 9.3 µm pixel centred on the axis is exactly three 3.1 µm pixels per side, so
    the kernel at 9.3 µm (n px) is the 3 × 3 block sums of the kernel at 3.1 µm (3n px: the same window), and the
    light inside the window is the same (design --pixel-um; bound 1e-12 of the peak, float64 rounding)."""
    cell = torch.tensor(np.random.default_rng(4).random((7, 7)))
    fine = tp.cell_grid(7, 8.0, LENS, WL, 3.1, 63, 128)
    coarse = tp.cell_grid(7, 8.0, LENS, WL, 9.3, 21, 128)
    k_fine, in_fine = tp.kernels_and_window(cell, fine)
    k_coarse, in_coarse = tp.kernels_and_window(cell, coarse)
    blocks = k_fine.numpy().reshape(len(WL), 21, 3, 21, 3).sum(axis=(2, 4))
    assert np.abs(blocks - k_coarse.numpy()).max() < 1e-12 * k_coarse.numpy().max()
    assert np.allclose(in_fine.numpy(), in_coarse.numpy(), rtol=1e-12, atol=0)


@pytest.mark.parametrize("size_px", [31, 33])
def test_the_packed_kernel_is_the_one_dep_deconvolves_with(size_px):
    """design --packed: torch_psf.packed equals restore.known.packed_from_sensor (the restorer's numpy form; its R, Gr
    and B planes, unit sum) for a kernel centre of either parity, bound 1e-6 (packed_from_sensor's float32); a
    sensor-pitch delta at the centre is a packed delta and one shifted by 2 px is shifted by 1 packed px."""
    k = np.random.default_rng(5).random((3, size_px, size_px))
    ref = packed_from_sensor(k)[[0, 1, 3]].astype(np.float64)
    ref /= ref.sum(axis=(1, 2), keepdims=True)
    got = tp.packed(torch.tensor(k)).numpy()
    assert got.shape == ref.shape == (3, 2 * (size_px // 4) + 1, 2 * (size_px // 4) + 1)
    assert np.abs(got - ref).max() < 1e-6 * ref.max()
    c, m = size_px // 2, size_px // 4
    delta = torch.zeros(size_px, size_px, dtype=torch.float64)
    delta[c, c + 2] = 1.0
    shifted = tp.packed(delta).numpy()
    assert shifted[m, m + 1] == 1.0 and shifted.sum() == 1.0


def test_an_arranged_micrograph_is_the_designs_arranged_tiling():
    """The engine's tile_arrangement (a fixed K × K pattern of D4 elements, from the window's first tile) against the
    torch PSF of the design's arranged tiling (torch_psf.arranged): the same display, to the engine's bound."""
    cell = tp.preset_cell(layouts.toled(pitch_um=168.0), 21)
    cell[:, 11:] = 0.0  # not its own mirror image: every D4 element is a distinct tile
    pattern = ((1, 6, 3), (4, 0, 7), (2, 5, 1))
    lay = MicrographLayout("cell", 8.0, image=cell, arrangement=pattern)
    ref = compute_kernels(lay, LENS, WL, size_px=31, pupil_samples=256, precision="float64").kernels
    grid = tp.cell_grid(21, 8.0, LENS, WL, 3.1, 31, 256)
    got = tp.kernels(torch.tensor(cell), grid, tp.arranged(np.array(pattern), grid.tiles)).numpy()
    assert not lay.periodic and np.abs(got - ref).max() < 1e-8 * ref.max()
