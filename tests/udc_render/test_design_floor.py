"""`design --upc-floor` (udc_render.design.floor) and `--init PATH`: the floor's ratio against metrics.ring_summary
(numpy masks), its hinge in closed form, the search's start from a cell PNG, and the refusals."""
from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from udc_render import cli
from udc_render.design import job, metrics, torch_psf as tp, upc
from udc_render.design.cells import RINGS, toled_reference
from udc_render.design.config import DesignConfig
from udc_render.design.floor import FLOOR_WEIGHT, UpcFloor
from udc_render.design.optimise import Designer

FLOORED = dict(objective="crop", contrast=1.0, pupil_samples=64, kernel_px=31, scatters=1, steps=2, candidates=3,
               far_veil=True)


def _binary21(k: int, seed: int) -> np.ndarray:
    flat = np.zeros(441)
    flat[np.random.default_rng(seed).permutation(441)[:k]] = 1.0
    return flat.reshape(21, 21)


def _numpy_minima(cell: np.ndarray, transforms) -> np.ndarray:
    with torch.no_grad():
        k = upc.psf(torch.tensor(cell), transforms).numpy()
    return np.array(metrics.ring_summary(k, RINGS)["mean_of_ring_minima"])


def test_the_floors_ratio_is_upcs_statistic_over_the_toleds_on_the_same_tiling():
    """ratios(cell) = ring_summary's mean ring minima of the cell ÷ the edge-framed T-OLED's (numpy masks, a separate
    implementation), channel by channel, on the floor's tiling; the T-OLED over itself is 1."""
    floor = UpcFloor(1.26, "GB", 21, 168.0, 0.2, seed=0, turned=True)
    cell = _binary21(88, 4)
    turns = floor.transforms("search")
    expected = _numpy_minima(cell, turns)[1:] / _numpy_minima(toled_reference(168.0, 0.2), turns)[1:]
    with torch.no_grad():
        got = floor.ratios(torch.tensor(cell), "search").numpy()
        itself = floor.ratios(torch.tensor(toled_reference(168.0, 0.2)), "final").numpy()
    assert np.allclose(got, expected, rtol=1e-10) and np.allclose(itself, 1, rtol=1e-12)


def test_the_uncropped_floor_takes_out_the_share_upcs_crop_drops():
    """floor_uncropped: ring_summary's minima times the share inside UPC's crop (its sum of |FFT|², a closed form of
    the power in the crop, not the normalised PSF); blue's crop is its whole grid, so there the two floors agree."""
    cell, ref = _binary21(88, 8), toled_reference(168.0, 0.2)
    floor = UpcFloor(1.26, "RGB", 21, 168.0, 0.2, seed=1, turned=True, uncropped=True)
    plain = UpcFloor(1.26, "RGB", 21, 168.0, 0.2, seed=1, turned=True)
    turns = floor.transforms("search")
    with torch.no_grad():
        shares = [upc.kept_fraction(torch.tensor(c), turns).numpy() for c in (cell, ref)]
        got, cropped = (f.ratios(torch.tensor(cell), "search").numpy() for f in (floor, plain))
    expected = _numpy_minima(cell, turns) * shares[0] / (_numpy_minima(ref, turns) * shares[1])
    assert np.allclose(got, expected, rtol=1e-10) and abs(got[2] / cropped[2] - 1) < 1e-12
    assert np.all(shares[0][:2] < 1)


def test_the_floor_multiplies_the_objective_by_its_hinge():
    """searched = J (1 + FLOOR_WEIGHT Σ max(0, log R − log ratio)): J at or above the floor, the closed form below."""
    cell = _binary21(88, 5)
    x = torch.tensor(cell)
    plain = Designer(DesignConfig(**FLOORED))
    with torch.no_grad():
        j = float(plain.objective(x, plain.transforms("search")))
        ratio = float(UpcFloor(1.0, "G", 21, 168.0, 0.2, 0, True).ratios(x, "search")[0])
        for r, factor in ((0.5 * ratio, 1.0), (2.0 * ratio, 1 + FLOOR_WEIGHT * np.log(2.0))):
            floored = Designer(DesignConfig(**FLOORED, upc_floor=r))
            assert abs(float(floored.searched(x, "search")) / (j * factor) - 1) < 1e-9
            assert floored.score(cell)["objective"] == plain.score(cell)["objective"]
            assert "upc_floor_ratios" in floored.score(cell) and "upc_floor_ratios" not in plain.score(cell)


def test_a_search_starts_from_a_former_designs_cell(tmp_path):
    """--init PATH starts from the PNG's cell exactly (0 / 255, the run's squares and open area)."""
    cell = _binary21(88, 6)
    iio.imwrite(tmp_path / "cell.png", (cell * 255).astype(np.uint8))
    d = Designer(DesignConfig(**FLOORED, init=str(tmp_path / "cell.png")))
    assert np.array_equal(d.cell, cell)


def test_a_search_starts_from_a_coarser_designs_cell(tmp_path):
    """--init PATH of a coarser design (a 21² cell of 8 µm squares on a 42² cell of 4 µm): each square split into
    2 × 2, the open area kept exactly (88 × 4 = 352 of 1764 squares: --open-area 88 / 441)."""
    cell = _binary21(88, 6)
    iio.imwrite(tmp_path / "cell.png", (cell * 255).astype(np.uint8))
    fine = DesignConfig(**{**FLOORED, "feature_um": 4.0, "open_fraction": 88 / 441}, init=str(tmp_path / "cell.png"))
    start = Designer(fine).cell
    assert start.shape == (42, 42) and np.array_equal(start[::2, ::2], cell) and start.sum() == 352
    assert np.array_equal(start[1::2, 1::2], cell)


@pytest.mark.parametrize("image, says", [
    (np.zeros((20, 21), np.uint8), "expected a square grey PNG of 0 and 255 (a design's cell.png) of 21 px or a side"),
    (np.zeros((20, 20), np.uint8), "of 21 px or a side that divides it, got shape (20, 20)"),
    (np.full((21, 21), 128, np.uint8), "expected a square grey PNG of 0 and 255"),
    ((_binary21(87, 1) * 255).astype(np.uint8), "87 open squares on the 21² cell; the open area needs 88"),
])
def test_a_bad_start_cell_is_refused_in_one_line(tmp_path, capsys, image, says):
    iio.imwrite(tmp_path / "start.png", image)
    assert cli.main(["design", "--init", str(tmp_path / "start.png"), "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err
    assert says in err and f"--init {tmp_path / 'start.png'}" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "never").exists()


@pytest.mark.parametrize("argv, says", [
    (["--init", "poled"], "--init poled: not scatter or toled, and not a readable cell PNG"),
    (["--objective", "rings", "--upc-floor", "1.3"], "--upc-floor: takes --objective wiener or crop in --optics rig"),
    (["--optics", "upc", "--objective", "upc", "--upc-floor", "1.3"], "--upc-floor: takes --objective wiener or crop"),
    (["--upc-floor", "1.3", "--floor-channels", "GX"], "--floor-channels GX: expected some of RGB, each once"),
    (["--upc-floor", "0"], "--upc-floor"),
    (["--floor-uncropped"], "--floor-uncropped: takes --upc-floor"),
])
def test_the_floor_refuses_in_one_line(tmp_path, capsys, argv, says):
    assert cli.main(["design", *argv, "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "never").exists()


def test_upcs_ratio_over_more_tilings_is_each_draws_ratio():
    """design.json's draws: draw k is the tiling of stream keys ('upc', k); the T-OLED over itself is 1 on each."""
    ref, cell = toled_reference(168.0, 0.2), _binary21(88, 7)
    draws = job.ratio_over_draws({"design": cell, "toled_edge": ref}, seed=2, n=2)
    ratios = [_numpy_minima(cell, t) / _numpy_minima(ref, t)
              for t in (tp.tile_transforms(upc.TILES, 2, keys=("upc", k)) for k in range(2))]
    assert np.allclose(draws["mean"], np.mean(ratios, axis=0), rtol=1e-12)
    assert np.allclose(draws["min"], np.min(ratios, axis=0), rtol=1e-12)
    itself = job.ratio_over_draws({"design": ref, "toled_edge": ref}, seed=2, n=2)
    assert np.allclose(itself["mean"], 1, rtol=1e-12) and np.allclose(itself["sd"], 0, atol=1e-12)
