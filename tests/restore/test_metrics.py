"""The evaluation protocol's image metrics (restore.metrics) and the one PSNR (udc_render.metrics)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torch import nn

from restore.lpips import LPIPS
from restore.metrics import image_metrics, lpips_distance, ssim
from udc_render.metrics import BORDER_PX, border_px, display_referred
from udc_render.io.previews import daylight_balance
from udc_render.metrics import psnr_db

torch.set_num_threads(2)
ONES = np.ones(3)


def test_psnr_of_constant_offsets():
    a = np.full((3, 4, 4), 0.3)
    assert psnr_db(a, a + 0.1) == pytest.approx(20.0, rel=1e-12)  # MSE 0.01
    assert psnr_db(a, a + 0.25) == pytest.approx(20 * math.log10(4), rel=1e-12)  # MSE 1/16
    assert psnr_db(a, a + 0.2, peak=2.0) == pytest.approx(20.0, rel=1e-12)  # 4 / 0.04
    assert psnr_db(a, a) == math.inf


def test_display_referred_balances_clips_encodes_and_crops():
    assert (border_px(64, 200), border_px(65, 65)) == (0, BORDER_PX)
    x = display_referred(np.full((3, 8, 8), 0.5), ONES)
    assert x.dtype == np.float64 and x.shape == (3, 8, 8)
    assert x.ravel() == pytest.approx(np.full(x.size, 1.055 * 0.5 ** (1 / 2.4) - 0.055), rel=1e-12)
    # balance × 0.25 = [1, 0.25, 0.001]: sRGB 1, the power segment, the linear segment (12.92 x)
    y = display_referred(np.full((3, 4, 4), 0.25), np.array([4.0, 1.0, 0.004]))[:, 0, 0]
    assert y == pytest.approx([1.0, 1.055 * 0.25 ** (1 / 2.4) - 0.055, 12.92 * 0.001], rel=1e-12)
    clipped = display_referred(np.broadcast_to(np.array([3.0, -1.0, 1.0])[:, None, None], (3, 2, 2)), ONES)
    assert clipped[:, 0, 0] == pytest.approx([1.0, 0.0, 1.0], abs=1e-15)
    assert display_referred(np.zeros((3, 96, 128)), ONES).shape == (3, 96 - 2 * BORDER_PX, 128 - 2 * BORDER_PX)


def test_ssim_of_constant_images_is_the_luminance_term():
    """σ = 0 in both: SSIM = (2 μa μb + C1) / (μa² + μb² + C1), C1 = (0.01 · 1)²."""
    a, b = np.full((3, 16, 16), 0.5), np.full((3, 16, 16), 0.25)
    assert ssim(a, b) == pytest.approx((2 * 0.5 * 0.25 + 1e-4) / (0.5 ** 2 + 0.25 ** 2 + 1e-4), rel=1e-9)
    assert ssim(a, a) == pytest.approx(1.0, rel=1e-12)


def test_image_metrics_use_the_one_psnr_on_display_referred_images():
    rng = np.random.default_rng(0)
    gt = rng.random((3, 40, 48)).astype(np.float32)
    restored = gt + rng.normal(0, 0.05, gt.shape).astype(np.float32)
    bal = daylight_balance()
    a, b, lp = display_referred(restored, bal), display_referred(gt, bal), LPIPS()
    assert image_metrics(restored, gt, bal, lp) == {"psnr_db": psnr_db(a, b), "ssim": ssim(a, b),
                                                    "lpips": lpips_distance(a, b, lp)}
    assert lpips_distance(a, a, lp) == 0.0


def test_metric_protocol_on_identical_and_shifted_images():
    rng = np.random.default_rng(0)
    gt = rng.random((3, 96, 128)).astype(np.float32) * 0.8
    bal = daylight_balance()
    m = image_metrics(gt, gt, bal, LPIPS())
    assert m["psnr_db"] == math.inf and m["ssim"] == pytest.approx(1.0) and m["lpips"] == pytest.approx(0, abs=1e-6)
    worse = image_metrics(gt * 0.5, gt, bal, LPIPS())
    assert worse["psnr_db"] < 20 and worse["ssim"] < 1 and worse["lpips"] > 0
    # values outside [0, 1] are clipped by the protocol: 10 × white scores like white
    assert image_metrics(np.full_like(gt, 10), np.full_like(gt, 1), bal, LPIPS())["psnr_db"] == math.inf


class _Constant(nn.Module):
    """A 'model' restoring every packed RAW [N, 4, h, w] to the constant `value` [N, 3, 2h, 2w]."""

    def __init__(self, value: float):
        super().__init__()
        self.value = nn.Parameter(torch.tensor(value))

    def forward(self, x):
        n, _, h, w = x.shape
        return self.value.expand(n, 3, 2 * h, 2 * w)


def test_validation_psnr_clips_both_images_to_0_1():
    from restore.train import validation_psnr
    packed = np.zeros((4, 4, 4), np.float32)
    pairs = [(packed, np.full((3, 8, 8), 1.5, np.float32)), (packed, np.full((3, 8, 8), 0.5, np.float32))]
    # 0.75 against the clipped 1: MSE 1/16; against 0.5: MSE 1/16
    cpu = torch.device("cpu")
    assert validation_psnr(_Constant(0.75), pairs, cpu) == pytest.approx(20 * math.log10(4), rel=1e-12)
    assert validation_psnr(_Constant(2.0), pairs[:1], cpu) == math.inf
    assert validation_psnr(_Constant(0.5), [], cpu) is None
