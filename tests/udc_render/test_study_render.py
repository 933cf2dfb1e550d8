"""`udc-render study render`: the quick grid writes its table, CSV and plot, and the numbers behave
as Monte Carlo error must (falling with spp, as 1/sqrt(spp) on the unbiased rgb_matrix path with the
independent sampler, faster with ldsampler); every sampler's pass noise estimate is honest against the
exact (analytic) monitor reference; the report names the fastest sampler."""
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

    # An RMS over 60 000 values errs by 1 / √(2 · 60 000) = 0.29 % (1σ): asserted 1.5 % (5σ; measured ≤ 0.62 %)
    ref = sr.Reference(image(0.02), image(0.02), edges)
    assert ref.noise == pytest.approx(0.02 / math.sqrt(2), rel=0.015)  # mean of two halves
    out = ref.compare(image(0.05).bands)
    assert out["rel_error"] == pytest.approx(math.hypot(0.05, 0.02 / math.sqrt(2)), rel=0.015)
    assert out["rel_error_net"] == pytest.approx(0.05, rel=0.015)
    assert out["band_mean_dev"] < 0.008  # zero-mean noise: band sums over 2000 px agree to ~0.2 % each
    biased = ref.compare(1.03 * image(0.05).bands)
    assert biased["band_mean_dev"] == pytest.approx(0.03, abs=0.008)
    assert sr.net(0.01, 0.02) == 0.0
    # an exact reference (the analytic render): no noise to take out
    exact = sr.Reference(SimpleNamespace(bands=truth.astype(np.float32), meta={"render_path": "analytic"}), None, edges)
    assert exact.noise == exact.noise_xyz == 0.0 and exact.path == "analytic"
    out = exact.compare(image(0.05).bands)
    assert out["rel_error_net"] == out["rel_error"] == pytest.approx(0.05, rel=0.015)


def test_time_to_a_target_interpolates_the_measured_runs_and_extrapolates_the_local_slope():
    from udc_render.studies.render_analysis import fit_series, time_to
    # error = spp^-0.75 exactly, time = 1 + spp / 10
    rs = [{"spp": n, "seconds": 1 + n / 10, "rel_error_net": n ** -0.75} for n in (4, 16, 64)]
    fit = fit_series(rs)
    assert fit["slope"] == pytest.approx(-0.75) and fit["slope_tail"] == pytest.approx(-0.75)
    t = time_to(rs, 8 ** -0.75, "rel_error_net", fit)  # between 4 and 16: log-log interpolation
    assert t["how"] == "interpolated" and t["spp"] == pytest.approx(8)
    assert 1.4 < t["seconds"] < 2.6
    assert time_to(rs, 0.5, "rel_error_net", fit)["how"] == "≤ first run"
    t = time_to(rs, 256 ** -0.75, "rel_error_net", fit)  # beyond the last run: the tail's slope
    assert t["how"].startswith("extrapolated") and t["spp"] == pytest.approx(256, rel=1e-6)
    assert t["seconds"] == pytest.approx(1 + 25.6, rel=1e-6)


@pytest.mark.slow  # ~18 s; its pieces: the three tests above
def test_quick_study_writes_csv_table_plot_and_error_falls_with_spp(tmp_path):
    # about 15 s with Dr.Jit's kernel cache warm, 30 s cold, on 2 cores
    rows = sr.run_study(tmp_path, quick=True, progress=False)
    for name in ("study_render.csv", "study_render.md", "study_render.png", "study_render.json"):
        assert (tmp_path / name).stat().st_size > 0
    with open(tmp_path / "study_render.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert {"scene", "path", "sampler", "variant", "spp", "spp_requested", "bands_per_render", "seconds",
            "rel_error", "noise_rel", "err_over_noise"} <= set(table[0])
    assert len(table) == len(rows)
    assert {r["scene"] for r in table} == {"monitor", "room"}
    assert all(float(r["seconds"]) > 0 and r["variant"] for r in table)
    assert {r["bands_per_render"] for r in table if r["scene"] == "room"} == {str(b) for b in sr.QUICK.room_bpr}
    sweep = [r for r in rows if r["role"] == "sweep"]

    # the monitor's reference is the analytic render: exact, noise 0, error 0 by construction; a high-spp
    # Mitsuba render differs from it by its own noise only
    ref = next(r for r in rows if r["role"] == "reference" and r["scene"] == "monitor")
    assert ref["path"] == "analytic" and ref["noise_rel"] == 0.0 and ref["rel_error"] == 0.0 and ref["seconds"] > 0
    assert all(r["ref_noise_rel"] == 0.0 and r["ref_path"] == "analytic" for r in sweep if r["scene"] == "monitor")
    chk = next(r for r in rows if r["role"] == "exact_check")
    assert 0.8 < chk["err_over_noise"] < 1.25 and chk["band_mean_dev"] < 1e-3, chk

    # every sampler has its series, on the monitor (rgb_matrix) and in the room (the scene's bands per render)
    for scene, path in (("monitor", "rgb_matrix"), ("room", "spectral")):
        for smp in sr.QUICK.samplers:
            assert len([r for r in sweep if r["scene"] == scene and r["path"] == path and r["sampler"] == smp]) >= 3

    rgb = sorted((r for r in sweep if r["path"] == "rgb_matrix" and r["sampler"] == "independent"),
                 key=lambda r: r["spp"])
    assert [r["spp"] for r in rgb] == list(sr.QUICK.rgb_spp)
    errs = [r["rel_error_net"] for r in rgb]
    assert all(a > b for a, b in zip(errs, errs[1:])), errs
    # 16× the samples: 4× less error for independent Monte Carlo noise
    assert 3.0 < errs[0] / errs[-1] < 5.3, errs
    # ldsampler (8, 32, 128 requested = rendered: 2 passes of a power of 4) converges faster: 16× the samples,
    # at least 8× less error (measured ~14×: the slope is about -0.95)
    ld = sorted((r for r in sweep if r["path"] == "rgb_matrix" and r["sampler"] == "ldsampler"), key=lambda r: r["spp"])
    assert [r["spp"] for r in ld] == [r["spp_requested"] for r in ld] == list(sr.QUICK.rgb_sampler_spp)
    assert ld[0]["rel_error_net"] / ld[-1]["rel_error_net"] > 8, ld

    # the pass noise estimate is honest for every sampler: the true error over it within 1.25× of 1 against
    # the exact monitor reference (0.94-1.03 measured), within 1.5× in the room (its reference's noise is
    # taken out in quadrature; 0.97-1.00 measured)
    for r in sweep:
        if r["noise_rel"] and r["path"] == "rgb_matrix":
            assert 0.8 < r["err_over_noise"] < 1.25, r
        elif r["noise_rel"] and r["scene"] == "room":
            assert 1 / 1.5 < r["err_over_noise"] < 1.5, r

    an = __import__("json").loads((tmp_path / "study_render.json").read_text())["analysis"]
    rec = an["recommend"]["sampler"]["recommended"]
    assert rec in sr.QUICK.samplers
    assert an["samplers"]["monitor"]["best"]["0.01"]["sampler"] in sr.QUICK.samplers
    md = (tmp_path / "study_render.md").read_text()
    assert "Recommended defaults" in md and f"Sampler of the Monte Carlo paths: {rec}" in md
