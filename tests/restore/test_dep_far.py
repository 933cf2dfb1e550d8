"""DeP given the panel's far field (restore.dep_far): the fixed point against its closed-form bound.

Oracle: a frame x and w = x + F(x) made by optics.far_field.far_light (numpy, the synthesis's far light, with the
degrader's mirrored margin), not by the degrader the module calls; the contraction ‖x_n − x‖∞ ≤ s^(n+1) ‖x‖∞ with
s the far kernels' largest share.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from restore.degrade import Degrader
from restore.dep_far import subtract_far
from restore.tensors import region
from tests.restore.test_degrade_wide import PITCH_UM, _far, _frame, _panel
from udc_render.optics.far_field import FarField, far_light


def _with_far(x: np.ndarray, panel) -> np.ndarray:
    """x + F(x) by the numpy synthesis's far_light on the frame with the degrader's mirrored margin."""
    f, (H, W) = panel.far, x.shape[1:]
    m = Degrader([panel], "cpu", torch.float64).margin_px
    ext = region(torch.from_numpy(x), -m, -m, H + 2 * m, W + 2 * m).numpy()
    ff = FarField(f.kernels, f.coarse_px, PITCH_UM, *(np.zeros(3),) * 3, np.ones(3, bool), 1e9, 0.0, 0.0)
    return x + far_light(ext, ff, m, np.eye(3))


@pytest.mark.parametrize("iterations", [1, 2, 4])
def test_the_fixed_point_takes_the_far_field_out_within_its_contraction_bound(iterations):
    panel = _panel(far=_far())
    x = _frame()
    w = _with_far(x, panel)
    s = float(panel.far.kernels.sum(axis=(-2, -1)).max())  # 8 %
    assert np.abs(w - x).max() > 0.1 * s * np.abs(x).max()  # the far field is there to take out (0.24 s)
    err = np.abs(subtract_far(w, panel, iterations).astype(np.float64) - x).max()
    assert err <= s ** (iterations + 1) * np.abs(x).max() + 1e-6  # + float32 rounding of the output


def test_a_panel_without_a_far_field_is_left_as_it_is():
    x = _frame().astype(np.float32)
    np.testing.assert_array_equal(subtract_far(x, _panel()), x)
