"""`udc-render study render`: the quick grid writes its table, CSV and plot, and the numbers behave
as Monte Carlo error must (falling with spp, as 1/sqrt(spp) on the unbiased rgb_matrix path)."""
import csv
import math
from types import SimpleNamespace

import numpy as np
import pytest

from udc_render.studies import render_knobs as sr


def test_budget_spp_spends_the_same_samples_on_every_bands_per_render_line():
    # 30 bands at 400:700:10: 1, 2, 4, 8, 30 bands per render make 30, 15, 8, 4, 1 renders
    assert [sr.n_groups(30, b) for b in (1, 2, 4, 8, 30)] == [30, 15, 8, 4, 1]
    assert [sr.budget_spp(128, g) for g in (30, 15, 8, 4, 1)] == [4, 8, 16, 32, 128]
    assert sr.budget_spp(8, 30) == 1  # never below one sample


def test_reference_noise_is_measured_from_its_halves_and_taken_out():
    rng = np.random.default_rng(0)
    edges = np.linspace(400, 700, 31)
    truth = np.broadcast_to(np.linspace(1.0, 2.0, 30)[:, None, None], (30, 40, 50))
    rms = float(np.sqrt(np.mean(truth ** 2)))

    def image(sigma):  # additive noise of relative RMS sigma over the whole image
        return SimpleNamespace(bands=(truth + sigma * rms * rng.standard_normal(truth.shape)).astype(np.float32),
                               meta={"noise_rel": None})

    ref = sr.Reference(image(0.02), image(0.02), edges)
    assert ref.noise == pytest.approx(0.02 / math.sqrt(2), rel=0.03)  # mean of two halves
    out = ref.compare(image(0.05).bands)
    assert out["rel_error"] == pytest.approx(math.hypot(0.05, 0.02 / math.sqrt(2)), rel=0.03)
    assert out["rel_error_net"] == pytest.approx(0.05, rel=0.03)
    assert out["band_mean_dev"] < 0.008  # zero-mean noise: band sums over 2000 px agree to ~0.2 % each
    biased = ref.compare(1.03 * image(0.05).bands)
    assert biased["band_mean_dev"] == pytest.approx(0.03, abs=0.008)
    assert sr.net(0.01, 0.02) == 0.0


def test_quick_study_writes_csv_table_plot_and_error_falls_with_spp(tmp_path):
    # about 10 s with Dr.Jit's kernel cache warm, 25 s cold, on 2 cores
    rows = sr.run_study(tmp_path, quick=True, progress=False)
    for name in ("study_render.csv", "study_render.md", "study_render.png", "study_render.json"):
        assert (tmp_path / name).stat().st_size > 0
    with open(tmp_path / "study_render.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert {"scene", "path", "variant", "spp", "bands_per_render", "seconds", "rel_error",
            "noise_rel"} <= set(table[0])
    assert len(table) == len(rows)
    assert {r["scene"] for r in table} == {"monitor", "room"}
    assert all(float(r["seconds"]) > 0 and r["variant"] for r in table)
    assert {r["bands_per_render"] for r in table if r["scene"] == "room"} == {str(b) for b in sr.QUICK.room_bpr}

    rgb = sorted((r for r in rows if r["role"] == "sweep" and r["path"] == "rgb_matrix"), key=lambda r: r["spp"])
    assert [r["spp"] for r in rgb] == list(sr.QUICK.rgb_spp)
    errs = [r["rel_error_net"] for r in rgb]
    assert all(a > b for a, b in zip(errs, errs[1:])), errs
    # 16× the samples: 4× less error for pure Monte Carlo noise
    assert 3.0 < errs[0] / errs[-1] < 5.3, errs
    # rgb_matrix is unbiased: the error against an independent reference equals the run's own
    # noise estimate (the spread of its passes)
    for r in rgb:
        assert 0.8 < r["err_over_noise"] < 1.25, r
    assert "Recommended defaults" in (tmp_path / "study_render.md").read_text()
