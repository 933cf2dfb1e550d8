"""The evaluation protocol's image metrics (restore.metrics) and the one PSNR (udc_render.metrics)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torch import nn

from restore.lpips import LPIPS
from restore.metrics import image_metrics, level_scores, lpips_distance, paper_metrics, ssim
from udc_render.io.previews import daylight_balance
from udc_render.metrics import BORDER_PX, border_px, display_referred, psnr_db

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


def test_image_metrics_use_the_one_psnr_under_both_protocols():
    rng = np.random.default_rng(0)
    gt = rng.random((3, 40, 48)).astype(np.float32)
    restored = gt + rng.normal(0, 0.05, gt.shape).astype(np.float32)
    bal = daylight_balance()
    a, b, lp = display_referred(restored, bal), display_referred(gt, bal), LPIPS()
    c, d = np.clip(restored.astype(np.float64), 0, 1), np.clip(gt.astype(np.float64), 0, 1)  # paper: linear
    assert image_metrics(restored, gt, bal, lp) == {"psnr_db_srgb": psnr_db(a, b), "ssim_srgb": ssim(a, b),
                                                    "lpips_srgb": lpips_distance(a, b, lp),
                                                    "psnr_db_paper": psnr_db(c, d), "ssim_paper": ssim(c, d),
                                                    **level_scores(restored, gt)}
    assert lpips_distance(a, a, lp) == 0.0


def test_paper_protocol_scores_the_input_on_its_packed_raw():
    """The input row: packed RAW 0.6 against a ground truth of 0.5: 20 dB whatever the demosaic."""
    from udc_render.sensor import pack_rggb
    gt = np.full((3, 96, 128), 0.5)
    packed = np.full((4, 48, 64), 0.6)
    m = image_metrics(np.zeros_like(gt), gt, np.ones(3), LPIPS(), packed=packed)
    assert m["psnr_db_paper"] == pytest.approx(20.0, abs=1e-12)
    assert pack_rggb(np.zeros((96, 128))).shape == packed.shape


def test_metric_protocol_on_identical_and_shifted_images():
    rng = np.random.default_rng(0)
    gt = rng.random((3, 96, 128)).astype(np.float32) * 0.8
    bal = daylight_balance()
    m = image_metrics(gt, gt, bal, LPIPS())
    assert m["psnr_db_srgb"] == m["psnr_db_paper"] == math.inf and m["ssim_srgb"] == pytest.approx(1.0)
    assert m["ssim_paper"] == pytest.approx(1.0) and m["lpips_srgb"] == pytest.approx(0, abs=1e-6)
    worse = image_metrics(gt * 0.5, gt, bal, LPIPS())
    assert worse["psnr_db_srgb"] < 20 and worse["ssim_srgb"] < 1 and worse["lpips_srgb"] > 0
    # values outside [0, 1] are clipped by the protocol: 10 × white scores like white
    same = image_metrics(np.full_like(gt, 10), np.full_like(gt, 1), bal, LPIPS())
    assert same["psnr_db_srgb"] == same["psnr_db_paper"] == math.inf  # both clip at the white level


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


def test_level_matched_psnr_solves_each_channels_gain():
    """An output at half the level in R and twice in B, plus noise: the plain PSNR pays for the level, the
    level-matched one equals the PSNR of the noise alone (scaled by the same gains), for RGB and packed RAW."""
    from restore.metrics import level_matched_psnr_db, paper_metrics
    from udc_render.metrics import psnr_db
    rng = np.random.default_rng(0)
    gt = rng.uniform(0.05, 0.45, (3, 96, 128))
    noise = rng.normal(0, 0.01, gt.shape)
    gains = np.array([0.5, 1.0, 2.0])[:, None, None]
    out = gains * (gt + noise)
    plain, matched = paper_metrics(out, gt)["psnr_db_paper"], level_matched_psnr_db(out, gt)
    crop = (slice(None), slice(16, -16), slice(16, -16))
    # the gains are solved from the noisy output: measured 0.0039 dB from the noise's own PSNR
    assert matched - plain > 20 and matched == pytest.approx(psnr_db((gt + noise)[crop], gt[crop]), abs=0.015)
    from udc_render.sensor import mosaic_of, pack_rggb
    packed = 0.3 * pack_rggb(mosaic_of(gt))
    assert level_matched_psnr_db(None, gt, packed=packed) > 150  # an exact gain: no error left but rounding


def test_an_output_at_k_times_the_truth_has_level_k_and_loses_exactly_that_to_it():
    """Oracle: y = k_c · b (below the clip) has level k_c per channel; its PSNR is 10·log10(1 / mean(((1 − k)·b)²))
    on the protocol's crop, all of it level: matched, only float64 rounding is left. A structural error survives
    the match."""
    from udc_render.sensor import mosaic_of, pack_rggb
    rng = np.random.default_rng(1)
    gt = rng.uniform(0.05, 0.5, (3, 96, 128))
    k = np.array([0.85, 0.54, 1.2])
    m = {**paper_metrics(k[:, None, None] * gt, gt), **level_scores(k[:, None, None] * gt, gt)}
    assert (m["level_r"], m["level_g"], m["level_b"]) == pytest.approx(tuple(k), rel=1e-12)
    crop = gt[:, 16:-16, 16:-16]
    loss = 10 * math.log10(1 / np.mean(((1 - k[:, None, None]) * crop) ** 2))
    assert m["psnr_db_paper"] == pytest.approx(loss, rel=1e-9) and m["psnr_db_paper_matched"] > 250
    noisy = level_scores(0.5 * (gt + rng.normal(0, 0.01, gt.shape)), gt)
    assert 35 < noisy["psnr_db_paper_matched"] < 45 and noisy["level_g"] == pytest.approx(0.5, abs=1e-3)  # 2.4e-4
    packed = level_scores(None, gt, packed=0.3 * pack_rggb(mosaic_of(gt)))  # the input row: its two greens averaged
    assert (packed["level_r"], packed["level_g"], packed["level_b"]) == pytest.approx((0.3, 0.3, 0.3), rel=1e-12)
    dark = level_scores(np.zeros_like(gt), np.zeros_like(gt))  # no light in the truth: level 1 by definition
    assert dark["level_g"] == 1.0
