"""`study realism`: the observables and their verdicts on analytic cases, and the presets against the
paper's facts (pitch order, the T-OLED's x contrast kept at low frequencies and lost mid-band, no
P-OLED null below Nyquist)."""
from __future__ import annotations

import numpy as np
import pytest

from psf import layouts
from udc_render.cli import main
from udc_render.studies import realism


def _obs(mx, my):
    f = np.linspace(0, 0.5, mx.size)
    return {"f": f, "mtf_x": np.asarray(mx, float), "mtf_y": np.asarray(my, float)}


def test_x_loss_band_and_relative_mtf_on_hand_made_curves():
    ones = np.ones(11)
    dip = ones.copy()
    dip[4:7] = 0.2  # f = 0.20 … 0.30 cycles/px lost along x
    assert realism.x_loss_band(_obs(dip, ones)) == pytest.approx((0.2, 0.3), abs=1e-12)
    assert realism.x_loss_band(_obs(ones, ones)) is None
    glass = _obs(ones, ones)
    assert realism.min_relative_mtf(_obs(ones * 0.5, dip), glass) == 0.2
    assert realism.band_ratio(_obs(dip, ones), realism.MID_THIRD) == pytest.approx(0.2)  # f = 0.2, 0.25, 0.3


def test_mid_band_verdict_on_hand_made_curves():
    f = np.linspace(0, 0.5, 101)
    kept_low = np.where(f < 0.05, 1.0, 0.25)  # the lowest decade keeps its contrast
    flat = np.full_like(f, 0.25)
    rows = realism.x_contrast_rows({}, {"f": f, "mtf_x": kept_low, "mtf_y": np.ones_like(f)})
    assert rows[-1]["verdict"] == "mid-band"
    rows = realism.x_contrast_rows({}, {"f": f, "mtf_x": flat, "mtf_y": np.ones_like(f)})
    assert rows[-1]["verdict"].startswith("**lost")


def test_presets_pitch_order():
    """The paper, l.116: the P-OLED has the finer pitch."""
    assert layouts.poled().pitch_x_um < layouts.toled().pitch_x_um


def test_toled_preset_keeps_low_frequencies_and_loses_the_mid_band():
    obs = realism.observe(realism.Config("toled"), 255)
    low, mid = realism.band_ratio(obs, realism.LOW_DECADE), realism.band_ratio(obs, realism.MID_THIRD)
    assert low >= realism.LOW_OVER_MID * mid and mid < 0.5
    old = realism.observe(realism.Config("toled", (("pitch_um", 60.0),)), 255)  # the old preset fails
    assert (realism.band_ratio(old, realism.LOW_DECADE)
            < realism.LOW_OVER_MID * realism.band_ratio(old, realism.MID_THIRD))


def test_poled_preset_has_no_mtf_null_below_nyquist():
    glass = realism.observe(realism.Config("glass"), 511)
    obs = realism.observe(realism.Config("poled"), 511)
    assert realism.min_relative_mtf(obs, glass) > realism.NULL_LEVEL


@pytest.mark.slow
def test_quick_study_writes_rows_with_the_papers_values(tmp_path):
    """The whole quick study (PSF and capture rows; ~1.5 min with a warm kernel cache, ~5 min cold)."""
    assert main(["study", "realism", "--quick", "--out", str(tmp_path)]) == 0
    md = (tmp_path / "study_realism.md").read_text()
    assert "mostly lost in the mid-band frequency" in md and "no null observed" in md and "P-OLED finer" in md
    assert "γ Gb (white-square regression" in md and "DeP PSNR order" in md and "bands at d = 1 mm" in md
    assert (tmp_path / "study_realism.png").stat().st_size > 0 and (tmp_path / "study_realism_capture.png").is_file()
    rows = (tmp_path / "study_realism.csv").read_text().splitlines()
    assert rows[0] == ",".join(realism.COLUMNS) and len(rows) > 10
