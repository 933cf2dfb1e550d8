"""The sampled power of a tiling (udc_render.design.tiling_power) against the geometric shadow, the exact series of
the repeated tiling, a D4 symmetry and Parseval."""
from __future__ import annotations

import math

import numpy as np
import pytest

from psf.banding import PowerSeries, power_grid
from psf.lens import Lens
from psf.micrograph import MicrographLayout
from udc_render.design.tiling_power import sampled_banding, tiled_cell, tiling_power, window_tiles
from udc_render.errors import UdcError

LENS = Lens(focal_length_um=6000.0, aperture_um=900.0)  # a small disc: fast, still ~8 cells across
SPAN_UM = (120.0, 80.0)  # beyond the cells' 72 µm period on both axes


def _cell(seed: int = 3, size: int = 9) -> np.ndarray:
    """A binary cell of 8 µm squares with no symmetry (seeded)."""
    return (np.random.default_rng(seed).random((size, size)) < 0.3).astype(float)


def _turned(tiles: int) -> np.ndarray:
    return np.random.default_rng(7).integers(0, 8, size=(tiles, tiles))


def test_near_the_lens_the_power_is_the_geometric_shadow_of_the_turned_tiling():
    """d → 0: P(s) = Σ_r A(r) |m(r + s)|² δ², summed directly (no FFT) over the same tiling for a few shifts."""
    cell = _cell()
    power, step = tiling_power(cell, 8.0, LENS, 520.0, 1e-6, SPAN_UM, _turned, sample_um=4.0)
    tiles, k, _ = window_tiles(cell.shape[0], 8.0, LENS, 520.0, 1e-6, SPAN_UM, 4.0)
    mask = tiled_cell(cell, _turned(tiles), k) ** 2
    n = mask.shape[0]
    edges = (np.arange(n + 1) - n / 2) * step
    disc = LENS.aperture_area_fraction(edges, edges)
    cy, cx = power.shape[0] // 2, power.shape[1] // 2
    for jy, jx in ((0, 0), (5, -13), (-15, 30)):
        direct = (disc * np.roll(mask, (-jy, -jx), axis=(0, 1))).sum() * step ** 2
        assert abs(power[cy + jy, cx + jx] / direct - 1) < 1e-9


def test_the_repeated_tiling_follows_the_exact_power_series():
    """At d = 2 mm the sampled P of a repeated cell follows psf.banding.PowerSeries relative to its mean. The
    series drops the evanescent orders' power (0.5–0.8 % of the mean here), so means are compared apart; the
    profile's tolerance 2e-4 of the mean is the knob study's bound at δ = 2 µm (1.1e-4 on the rig's lens)."""
    cell = _cell()
    layout = MicrographLayout("cell", 8.0, image=cell)
    for wl in (450.0, 640.0):
        power, step = tiling_power(cell, 8.0, LENS, wl, 2000.0, SPAN_UM, sample_um=2.0)
        jy, jx = power.shape[0] // 2, power.shape[1] // 2
        xs, ys = np.arange(-jx, jx + 1) * step, np.arange(-jy, jy + 1) * step
        series = power_grid(PowerSeries(layout, LENS, wl * 1e-3, 2000.0).truncated(1e-7), layout.period_um, -xs, -ys)
        assert np.abs(power / power.mean() - series / series.mean()).max() < 2e-4
        # Parseval: the mean over a whole number of periods is the open area over the disc
        p = round(layout.period_um[0] / step)
        whole = power[jy:jy + p, jx:jx + p].mean()
        assert abs(whole / (cell.mean() * math.pi * LENS.aperture_um ** 2 / 4) - 1) < 1e-3


def test_a_d4_symmetric_cell_turned_is_the_cell_repeated():
    cell = np.zeros((9, 9))
    cell[2:7, 2:7] = 1.0
    cell[4, :] = 1.0
    cell[:, 4] = 1.0
    plain, _ = tiling_power(cell, 8.0, LENS, 520.0, 2000.0, SPAN_UM, sample_um=4.0)
    turned, _ = tiling_power(cell, 8.0, LENS, 520.0, 2000.0, SPAN_UM, _turned, sample_um=4.0)
    assert np.abs(turned - plain).max() <= 1e-10 * plain.mean()


def test_an_open_display_prints_no_bands_in_either_tiling():
    b = sampled_banding(np.ones((5, 5)), 8.0, LENS, (520.0,), 2.0, sample_um=4.0)
    for tiling in ("repeated", "turned"):
        assert b[tiling]["peak_to_peak"][0] < 1e-9 and b[tiling]["rms_one_period"][0] < 1e-9


def test_a_turned_asymmetric_cell_bands_beyond_one_period():
    """A random tiling has no period: its power over the whole span varies more than over one period of shifts,
    while the repeated tiling's max − min over the span and over one period agree (its power is periodic; the
    relative figures differ by their means, the span not being a whole number of periods)."""
    b = sampled_banding(_cell(), 8.0, LENS, (520.0,), 2.0, sample_um=4.0)
    rep, turn = b["repeated"], b["turned"]
    span = rep["peak_to_peak"][0] * rep["mean_power_um2"][0]
    period = rep["peak_to_peak_one_period"][0] * rep["mean_power_one_period_um2"][0]
    assert abs(span / period - 1) < 1e-9
    assert turn["peak_to_peak"][0] > 1.2 * turn["peak_to_peak_one_period"][0]


def test_a_distance_beyond_the_raster_is_refused_at_once():
    with pytest.raises(UdcError, match="--distance-mm 5000: the sampled banding needs"):
        tiling_power(_cell(), 8.0, LENS, 520.0, 5e6, SPAN_UM)
