"""The two metric protocols of udc_render.metrics on hand-computable captures."""
from __future__ import annotations

import math

import numpy as np
import pytest

from udc_render.io.capture import capture_psnr_db, gt_references
from udc_render.metrics import PROTOCOLS, display_referred
from udc_render.sensor import mosaic_of, pack_rggb

ONES = np.ones(3)


def _psnr(packed, gt, rgb, balance):
    """Both protocols' PSNR of a capture (packed RAW, demosaiced rgb) as the summaries compute them."""
    return capture_psnr_db(packed, display_referred(rgb, balance), gt_references(gt, balance))


def test_paper_protocol_scores_the_packed_raw_linearly():
    """GT 0.5 everywhere, a capture reading 0.6: MSE 0.01, PSNR 20 dB exactly, whatever the balance."""
    gt = np.full((3, 96, 128), 0.5)
    packed = np.full((4, 48, 64), 0.6)
    psnr = _psnr(packed, gt, gt, np.array([2.0, 1.0, 0.5]))
    assert psnr["paper"] == pytest.approx(20.0, abs=1e-12)
    assert math.isinf(psnr["srgb"])  # the demosaiced image equals the ground truth


def test_paper_protocol_clips_at_the_white_level_and_keeps_the_mosaic_sites():
    """A ground truth above the white level and a saturated capture agree (both clip to 1); an error on
    the R sites alone is counted on the R plane only: a quarter of the samples at 0.2 → MSE 0.01."""
    gt = np.full((3, 8, 8), 1.5)
    assert math.isinf(_psnr(np.ones((4, 4, 4)), gt, np.ones((3, 8, 8)), ONES)["paper"])
    gt = np.full((3, 8, 8), 0.5)
    packed = pack_rggb(mosaic_of(gt)).copy()
    packed[0] += 0.2
    assert _psnr(packed, gt, gt, ONES)["paper"] == pytest.approx(20.0, abs=1e-12)


def test_srgb_protocol_encodes_after_the_balance():
    """Balanced 0.5 vs 1.0 (after ×2): sRGB 0.7354 vs 1.0 in every pixel (no border on 8 px)."""
    gt = np.full((3, 8, 8), 0.5)
    rgb = np.full((3, 8, 8), 0.25)
    enc = 1.055 * 0.5 ** (1 / 2.4) - 0.055
    expected = 10 * math.log10(1 / (1.0 - enc) ** 2)
    assert _psnr(pack_rggb(mosaic_of(rgb)), gt, rgb, np.full(3, 2.0))["srgb"] == pytest.approx(expected)


def test_every_protocol_is_named():
    assert set(PROTOCOLS) == {"paper", "srgb"} and all(PROTOCOLS.values())


def test_the_quarter_table_is_display_referred_bit_for_bit():
    """The summaries' fast srgb path gives the float path's bits: bilinear_quarters (shifted integer sums) / 4 equals
    demosaic_bilinear (scipy's 3 × 3 convolution) on a whole-number mosaic, and display_referred_quarters (a table per
    channel) equals display_referred of quarters / 4 / range, with values below black and above the range (both
    clipped); real quarters are refused."""
    from udc_render.metrics import display_referred, display_referred_quarters
    from udc_render.sensor import bilinear_quarters, demosaic_bilinear
    rng = np.random.default_rng(4)
    mosaic = rng.integers(0, 1100, (96, 130)).astype(np.int32) - 64  # black level 64, white 1023
    quarters = bilinear_quarters(mosaic)
    assert quarters.dtype == np.int32 and np.array_equal(quarters / 4, demosaic_bilinear(mosaic))
    bal = np.array([2.1, 1.0, 1.6])
    assert np.array_equal(display_referred_quarters(quarters, 959, bal), display_referred(quarters / 4 / 959, bal))
    with pytest.raises(TypeError, match="integer quarters"):
        display_referred_quarters(quarters / 4, 959, bal)
