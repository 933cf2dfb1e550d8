"""UPC's PSF mode (udc_render.design.upc) and the scores (udc_render.design.metrics): closed forms, invariants,
and their saved numbers (design/upc_layout_metric.md: Yang & Sankaranarayanan's mtf_radial.mat, means over
k = 1…146, R / G / B)."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.ndimage import uniform_filter

from psf import layouts
from udc_render.design import metrics, torch_psf as tp, upc
from udc_render.sensor.config import SensorConfig

THEIR_REPEAT_MEANS = (0.144, 0.156, 0.147)
THEIR_REPEAT_MINIMA = (0.0098, 0.0120, 0.0132)
THEIR_TURNED_MINIMA = (0.107, 0.109, 0.113)


def _toled(edge: bool) -> torch.Tensor:
    """The preset T-OLED in a 168 µm cell (21 × 8 µm); edge: its opening framed at the tile's left edge."""
    cell = tp.preset_cell(layouts.toled(pitch_um=168.0), 21)
    return torch.tensor(np.roll(cell, -int(np.argmax(cell.sum(0) > 0)), axis=1) if edge else cell)


def test_grid_sizes_are_theirs():
    # 2 ⌊λ f / (2 δ1 δ2)⌋: 610 nm · 10 mm / (8 µm · 0.5 µm) = 1525 → 1524; 1325 → 1324; 1175 → 1174
    assert upc.grid_sizes() == (1524, 1324, 1174)
    assert upc.tiles_for(1524) == 73


def test_box_decimation_is_matlabs_imfilter():
    """imfilter(p, ones(4)/16): zero padding, rows i−1 … i+2 (scipy's uniform_filter with origin −1)."""
    p = torch.tensor(np.random.default_rng(0).random((20, 20)))
    ref = uniform_filter(p.numpy(), 4, mode="constant", origin=-1)[::4, ::4]
    assert np.abs(upc._box_decimate(p).numpy() - ref).max() < 1e-14


def test_a_d4_symmetric_cell_is_the_same_turned_or_not():
    cell = np.zeros((21, 21))
    cell[6:15, 6:15] = 1.0
    cell = torch.tensor(cell)
    turned = upc.psf(cell, tp.tile_transforms(upc.tiles_for(1524), 0)).numpy()
    plain = upc.psf(cell).numpy()
    assert turned.shape == (3, 294, 294) and np.allclose(plain.sum(axis=(1, 2)), 1.0, atol=1e-12)
    assert np.abs(turned - plain).max() < 1e-12 * plain.max()


def test_the_crops_share_of_a_comb_counts_its_orders():
    """One open 8 µm sample per 168 µm cell: a comb of 21 equal orders per axis M / 21 bins apart (aliased: their
    field is sampled at 8 µm), each an Airy spot of the 4 mm disc. The 1174² crop keeps the orders within ±587 bins:
    (17 / 21)² in R, (19 / 21)² in G, all of B's (M = 1174). Measured −0.70 / −0.12 / 0 %: R's outer order lies
    6 bins inside the crop's edge, and its spot's tail falls outside."""
    cell = torch.zeros(21, 21, dtype=torch.float64)
    cell[10, 10] = 1.0
    kept = upc.kept_fraction(cell).numpy()
    orders = [2 * np.floor(upc.CROP_PX // 2 / (m / 21)) + 1 for m in upc.grid_sizes()]
    assert orders == [17, 19, 21]
    assert np.all(np.abs(kept / (np.array(orders) / 21) ** 2 - 1) < 0.015) and abs(kept[2] - 1) < 1e-12


def test_repeated_toled_reproduces_their_numbers():
    """Measured: ring means .149 / .164 / .153 (3–5 % above theirs), minima .0096 / .0123 / .0133 (≤ 2.5 %)."""
    s = metrics.ring_summary(upc.psf(_toled(False)).numpy(), 147)
    assert np.all(np.abs(np.array(s["mean_of_ring_means"]) / THEIR_REPEAT_MEANS - 1) < 0.10)
    assert np.all(np.abs(np.array(s["mean_of_ring_minima"]) / THEIR_REPEAT_MINIMA - 1) < 0.05)


@pytest.mark.parametrize("edge, lo, hi", [(True, 0.7, 1.3), (False, 0.3, 0.5)])
def test_turned_toled_minima_depend_on_the_framing(edge, lo, hi):
    """Their randomRot90 turns each tile about its centre: an opening framed at the tile's edge moves with the
    turn, a centred one does not. Measured: .098 / .103 / .109 framed at the edge (0.92–0.96 × theirs), .044 /
    .046 / .051 centred (0.41–0.45 ×); the issue's bound for reproducing their baseline is 30 %."""
    turns = tp.tile_transforms(upc.tiles_for(1524), 0)
    s = metrics.ring_summary(upc.psf(_toled(edge), turns).numpy(), 147)
    ratio = np.array(s["mean_of_ring_minima"]) / THEIR_TURNED_MINIMA
    assert np.all((ratio > lo) & (ratio < hi)), ratio


def test_ring_stats_of_a_radial_map():
    i = np.abs(np.arange(21) - 10)
    m = np.rint(np.hypot(i[None, :], i[:, None]))
    means, mins = metrics.ring_stats(m)
    assert np.array_equal(means, np.arange(10)) and np.array_equal(mins, np.arange(10))


def test_mtf_of_a_point_is_one():
    k = np.zeros((15, 15))
    k[7, 7] = 3.0
    assert np.allclose(metrics.mtf(k), 1.0, rtol=0, atol=1e-15)


def test_natural_spectrum_is_inverse_square_with_the_stated_variance():
    s = metrics.natural_spectrum(16, 0.01)
    assert abs(s.mean() - 0.01) < 1e-15 and s[0, 0] == 0.0
    assert abs(s[0, 2] / s[0, 1] - 0.25) < 1e-12 and abs(s[1, 1] / s[0, 1] - 0.5) < 1e-12


def test_wiener_mse_closed_forms():
    s = np.full((8, 8), 0.02)
    assert abs(metrics.wiener_mse(np.ones((8, 8)), s, 0.01) - 0.02 * 0.01 / 0.03) < 1e-15
    assert abs(metrics.wiener_mse(np.zeros((8, 8)), s, 0.01) - 0.02) < 1e-15
    assert abs(metrics.wiener_mse(np.ones((8, 8)), s, 0.01, 0.5) - 0.02 * 0.01 / (0.25 * 0.02 + 0.01)) < 1e-15


def test_restorability_of_a_point_kernel_is_the_closed_form():
    sensor = SensorConfig()
    k = np.zeros((1, 15, 15))
    k[0, 7, 7] = 1.0
    r = metrics.restorability(k, 0.2, sensor, mean_level=0.5, contrast=0.3)
    n = (0.2 * 0.5 * 15506.0 + 4.87 ** 2) / 15506.0 ** 2
    s = metrics.natural_spectrum(15, (0.3 * 0.5) ** 2)
    assert abs(r["noise_variance"][0] - n) < 1e-18
    assert abs(r["wiener_mse"][0] - np.mean(s * n / (0.04 * s + n))) < 1e-15
