"""`study realism` (first part): the observables and their verdicts on analytic cases."""
from __future__ import annotations

import numpy as np
import pytest

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


def test_quick_study_writes_rows_with_the_papers_values(tmp_path, monkeypatch):
    monkeypatch.setenv("UDC_RENDER_CACHE", str(tmp_path / "cache"))
    assert main(["study", "realism", "--quick", "--out", str(tmp_path)]) == 0
    md = (tmp_path / "study_realism.md").read_text()
    assert "mostly lost in the mid-band frequency" in md and "no null observed" in md and "P-OLED finer" in md
    assert (tmp_path / "study_realism.png").stat().st_size > 0
    rows = (tmp_path / "study_realism.csv").read_text().splitlines()
    assert rows[0] == ",".join(realism.COLUMNS) and len(rows) > 10
