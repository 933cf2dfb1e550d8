"""The closed-form light shares of a cell (udc_render.design.far_light) against Si's closed form and the engine."""
from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np
from scipy.special import sici

from psf import Lens, compute_kernels
from psf.micrograph import MicrographLayout
from udc_render.design.far_light import light_shares

ROOT = Path(__file__).resolve().parents[2]


def _axis_share(a: float) -> float:
    """∫_{−a}^{a} sinc²(t) dt = (2 / π) (Si(2πa) − sin²(πa) / (πa))."""
    return 2 / np.pi * (sici(2 * np.pi * a)[0] - np.sin(np.pi * a) ** 2 / (np.pi * a))


def test_one_square_opening_sends_the_sinc_squares_share_into_the_window():
    """One open 8 µm square: its far field is sinc²(ν δ) per axis, so the window |u| ≤ W holds (∫_{−a}^{a} sinc²)²,
    a = W δ / (λ z) (measured 2e-5 off at pad 4: the Riemann sum's edge)."""
    cell = np.zeros((5, 5))
    cell[2, 2] = 1.0
    got = light_shares(cell, 8.0, 0.52, 6000.0, 400.0, 1774.5)
    assert abs(got["window"] - _axis_share(400.0 * 8.0 / (0.52 * 6000.0)) ** 2) < 1e-4
    assert got["window"] < got["acceptance"] < 1.0


def test_the_shares_do_not_change_with_the_tiles_turn():
    """A square window and a disc are unchanged by D4, so each turn of the cell has its shares (module doc)."""
    cell = (iio.imread(ROOT / "docs/figures/design/kicks/k16/cell.png") == 255).astype(float)
    ref = light_shares(cell, 8.0, 0.45, 6000.0, 395.25, 1774.5)
    for turned in (np.rot90(cell), np.rot90(cell, 2), cell[:, ::-1], np.rot90(cell[:, ::-1])):
        got = light_shares(turned, 8.0, 0.45, 6000.0, 395.25, 1774.5)
        assert all(abs(got[k] - ref[k]) < 1e-12 for k in ref)


def test_the_light_past_the_window_is_the_engines_energy_outside():
    """The designed cell k16 tiled with the engine's quarter-turns (psf.compute_kernels, 255 px of 3.1 µm, d = 0):
    the closed form's share past the window within 4 % of the engine's energy_outside (measured 1.3–2.0 %, the
    engine's aperture blur and pixels spilling a little more; the bound was set after seeing them)."""
    cell = (iio.imread(ROOT / "docs/figures/design/kicks/k16/cell.png") == 255).astype(float)
    layout = MicrographLayout("k16", 8.0, random_rotation=True, seed=0, image=cell)
    engine = compute_kernels(layout, Lens(), (450.0, 520.0, 640.0), 3.1, 255, precision="float64").energy_outside
    for lam_nm, outside in zip((450.0, 520.0, 640.0), engine):
        share = light_shares(cell, 8.0, lam_nm / 1000, Lens().image_distance_um, 255 * 3.1 / 2, 1774.5)["window"]
        assert abs((1 - share) / outside - 1) < 0.04, (lam_nm, 1 - share, outside)
