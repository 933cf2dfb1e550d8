"""`udc-render design --symmetry c2` (udc_render.design.symmetry): the point-symmetric cell, its orbits, the search
that keeps it, the dipole it removes, and the refusals."""
from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from udc_render import cli
from udc_render.design.config import DesignConfig
from udc_render.design.optimise import Designer
from udc_render.design.symmetry import kicked_orbits, orbits, symmetric_scatter
from udc_render.design.torch_psf import tile, tile_transforms

# a 5 × 5 cell of 8 µm, 6 open squares: 3 open pairs of the 12 (the centre closed)
SMALL = dict(cell_um=40.0, feature_um=8.0, open_fraction=0.24, pupil_samples=64, kernel_px=31, scatters=2, seed=3,
             tiling="repeated", symmetry="c2", steps=100, candidates=3 * 9)


def _half_turn(k: np.ndarray) -> np.ndarray:
    """The D4 element g R² of each element g (torch_psf.transform_tile's numbering: the mirror kept, 2 more turns)."""
    return (k & 4) | ((k + 2) & 3)


@pytest.mark.parametrize("c", [4, 5, 21])
def test_the_orbits_partition_the_cell_into_half_turn_pairs(c):
    groups = orbits(c, "c2")
    flat = np.concatenate(groups)
    assert np.array_equal(np.sort(flat), np.arange(c * c))
    turned = np.rot90(np.arange(c * c).reshape(c, c), 2).ravel()
    assert all(set(turned[g]) == set(g) for g in groups)
    assert [len(g) for g in groups].count(1) == c % 2 and len(orbits(c, "none")) == c * c


def test_a_point_symmetric_tile_is_its_own_half_turn():
    """A c2 cell tiled with any D4 draw equals the tiling with each element turned by 180° more, to the bit (its
    eight images are four), while a generic cell's differs; and its centroid is the tile's centre: no dipole."""
    cell = symmetric_scatter(21, 88, np.random.default_rng(0))
    draw = tile_transforms(6, 0)
    for c, same in ((cell, True), (np.roll(cell, 1, axis=1), False)):
        a, b = (tile(torch.from_numpy(c), t).numpy() for t in (draw, _half_turn(draw)))
        assert np.array_equal(a, b) == same
    y, x = np.mgrid[-10:11, -10:11]
    assert cell.sum() == 88 and (cell * x).sum() == 0 and (cell * y).sum() == 0


def test_a_kick_moves_pairs_and_keeps_the_symmetry():
    cell = symmetric_scatter(21, 89, np.random.default_rng(1))
    out = kicked_orbits(cell, orbits(21, "c2"), 5, np.random.default_rng(2))
    assert out.sum() == 89 and np.array_equal(out, np.rot90(out, 2)) and np.sum((cell > 0.5) & (out < 0.5)) == 10
    assert out[10, 10] == cell[10, 10] == 1


def test_the_c2_search_stays_symmetric_and_ends_in_a_local_optimum_of_all_pair_swaps():
    """With every pair swap a candidate (3 open × 9 opaque pairs), each step keeps the cell point-symmetric and its
    6 open squares and lowers the objective, and the search stops where no pair swap lowers it (exhaustively)."""
    d = Designer(DesignConfig(**SMALL))
    previous = d.current
    while not d.finished:
        rec = d.step()
        assert d.cell.sum() == 6 and np.array_equal(d.cell, np.rot90(d.cell, 2)) and d.cell[2, 2] == 0
        if rec["swap"]:
            assert rec["objective"] < previous
            previous = rec["objective"]
    assert d.converged
    flat, pairs = d.cell.ravel(), [g for g in orbits(5, "c2") if len(g) == 2]
    for o in (g for g in pairs if flat[g[0]] == 1):
        for z in (g for g in pairs if flat[g[0]] == 0):
            trial = flat.copy()
            trial[o], trial[z] = 0.0, 1.0
            assert d.search_score(trial.reshape(5, 5)) >= d.current * (1 - 1e-5)


def test_a_c2_run_starts_from_a_point_symmetric_scatter():
    cell = Designer(DesignConfig(**{**SMALL, "open_fraction": 0.28})).cell  # 7 open: the centre and 3 pairs
    assert cell.sum() == 7 and cell[2, 2] == 1 and np.array_equal(cell, np.rot90(cell, 2))


def test_design_refuses_a_cell_the_symmetry_cannot_take(tmp_path, capsys):
    png = tmp_path / "cell.png"
    lopsided = np.zeros((21, 21), np.uint8)
    lopsided.ravel()[:88] = 255
    iio.imwrite(png, lopsided)
    for argv, says in ((["--init", "toled"], "--symmetry c2: --init toled is not point-symmetric"),
                       (["--init", str(png)], f"--init {png}: the cell is not point-symmetric"),
                       (["--cell-um", "32", "--open-area", "0.19"],
                        "--symmetry c2: 3 open squares (--open-area 0.19) are odd, and the even 4² cell has no centre"),
                       (["--kicks", "1", "--kick-swaps", "45"],
                        "--kick-swaps 45: the cell has 44 square pairs to swap"),
                       (["--symmetry", "c4"], "--symmetry: invalid choice: 'c4'")):
        assert cli.main(["design", "--symmetry", "c2", *argv, "--out", str(tmp_path / "never")]) == 2
        err = capsys.readouterr().err
        assert says in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "never").exists()
