"""`udc-render study design` (udc_render.studies.design_knobs) on a tiny setting: both parts and the outputs."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from udc_render.design import metrics, torch_psf as tp
from udc_render.design.config import DesignConfig
from udc_render.design.held_out import held_out_draws
from udc_render.design.optimise import Designer
from udc_render.studies import design_knobs as dk
from udc_render.studies.design_knobs_report import write

TINY = {"cell_um": 96.0, "kernel_px": 15, "samples": (64, 128), "steps": (2,), "design_pupil_samples": 64}


@pytest.fixture(scope="module")
def sampling():
    return dk.sampling_rows(TINY)


def test_the_sampling_rows_measure_against_the_finest_setting(sampling):
    rows = sampling
    assert [r["cell"] for r in rows] == ["toled_edge"] * 2 + ["scatter"] * 2
    for ref in (rows[1], rows[3]):  # the finest setting is the reference
        assert ref["error_psnr_db"] == 0 and ref["error_ring_minima_rel"] == 0
    # the samples per cell follow the engine's display grid: 3 and 5 samples across a 96 µm cell
    assert [r["samples_per_cell"] for r in rows[:2]] == [3, 5]
    for coarse, fine in ((rows[0], rows[1]), (rows[2], rows[3])):
        assert coarse["error_psnr_db"] == max(abs(a - b) for a, b in zip(coarse["psnr_db"], fine["psnr_db"])) > 0
        assert coarse["cpu_s"] > 0 and coarse["cpu_gradient_s"] > 0


def test_the_study_cells_are_open_at_20_percent():
    """The T-OLED's area-weighted raster keeps its exact open area; the scatter opens round(0.2 · 441) squares."""
    c = dk.cells(168.0)
    assert c["toled_edge"].shape == (21, 21) and abs(c["toled_edge"].mean() - 0.2) < 1e-12
    assert c["scatter"].sum() == 88 and set(np.unique(c["scatter"])) == {0.0, 1.0}


def test_the_steps_rows_score_the_searched_cell_as_the_numpy_metric_does(tmp_path, sampling):
    """The search's cell after 2 steps, scored by the designer (torch), equals metrics.restorability's mean Wiener
    MSE of the torch PSF's kernels of that cell on the held-out tiling, the light outside the window lost (numpy);
    the swaps keep round(0.2 · 144) = 29 squares, and the search beats its initial scatter on the held-out tiling."""
    first, row = dk.steps_rows(TINY)
    assert first["steps"] == 0 and first["steps_done"] == 0 and abs(first["open_area"] - 29 / 144) < 1e-12
    assert row["steps"] == 2 and abs(row["open_area"] - 29 / 144) < 1e-12 and row["cpu_s"] > first["cpu_s"]
    assert abs(row["psnr_db"] + 10 * np.log10(row["objective"])) < 1e-12 and row["psnr_db"] > first["psnr_db"]
    designer = Designer(DesignConfig(cell_um=96.0, kernel_px=15, pupil_samples=64, steps=2))
    designer.step()
    designer.step()
    cell = designer.cell
    turns = designer.transforms("final")
    k, inside = (v.numpy() for v in tp.kernels_and_window(torch.tensor(cell), designer.grid, turns))
    mse = metrics.restorability(k, cell.mean() * inside)["wiener_mse"]
    assert abs(np.mean(mse) / row["objective"] - 1) < 1e-9
    names = write({"config": {**TINY, "feature_um": 8.0, "open_fraction": 0.2, "seed": 0,
                              "wavelengths_nm": (640.0, 520.0, 450.0), "threads": 1},
                   "sampling": sampling, "steps": [first, row]}, tmp_path)
    assert all((tmp_path / n).stat().st_size > 0 for n in names)
    assert "| 2 | 2 | " in (tmp_path / "study_design.md").read_text()


def _aperiodic_rig(tmp_path):
    """A turned asymmetric 60 µm tile before a 400 µm aperture at d = 0.6 mm, P = 3 phases on whole samples."""
    from psf import Lens, MicrographLayout, compute_kernels
    from psf.plan import make_plan
    img = np.zeros((30, 30))
    img[4:26, 6:13] = 1.0
    img[20:26, 13:24] = 1.0
    display = MicrographLayout("tile", 2.0, "amplitude", True, 5, img)
    lens, wl, d_mm = Lens(aperture_um=400.0), np.array([520.0]), 0.6

    def plan(sensor):
        return make_plan(display, lens, wl, 3.1, 31, d_mm, 3, "mft", 128, "float64", True, "band_limited", sensor, [])
    step = plan((100.0, 100.0)).grid.dx_um
    sensor = (3 * 30 * step * lens.image_distance_um / 600.0,) * 2  # phases at 0, ±30 samples
    ks = compute_kernels(display, lens, wl, 3.1, 31, d_mm, 3, pupil_samples=128, precision="float64",
                         sensor_um=sensor)
    return display, ks, plan(sensor)


def test_the_raster_power_is_the_engines_phase_power_and_the_blend_passes_through_it(tmp_path):
    """Part (d)'s exact P(s) (one FFT correlation over the engine's window) at the phases' whole-sample shifts
    equals the engine's phase powers (its shift ramps and gather); the blend's profile passes through the phases;
    psf-4's profile repeats with the tile (p = 21 samples)."""
    from udc_render.design.tiling_power import raster_power
    display, ks, plan = _aperiodic_rig(tmp_path)
    power = raster_power(plan, 520.0)
    ny, nx = power.shape
    at = np.rint(plan.shifts / np.array([plan.grid.dx_um, plan.grid.dy_um])).astype(int)
    assert np.array_equal(np.abs(at).max(axis=(0, 1)), [30, 30])
    sampled = power[at[..., 1] % ny, at[..., 0] % nx]
    np.testing.assert_allclose(sampled / sampled.mean(), ks.field_power[0], rtol=0, atol=1e-10)
    assert ks.transmittance[0] == pytest.approx(sampled.mean() / (np.pi * 200.0 ** 2), rel=1e-10)
    prof = dk.field_profiles(display, ks, plan, power)
    assert prof["exact"].shape == (61, 61)
    on = prof["blend"][at[..., 1] + 30, at[..., 0] + 30] / prof["exact"][at[..., 1] + 30, at[..., 0] + 30]
    assert np.ptp(on) < 1e-12  # equal at the phases up to the profiles' own means
    n = round(display.period_um[0] / plan.grid.dx_um)
    np.testing.assert_allclose(prof["one_tile"][:, n:], prof["one_tile"][:, :-n], rtol=1e-12)
    assert np.ptp(prof["exact"]) > 1e-3  # the tiles differ across the shifts: a test that could fail


def test_the_study_keeps_a_part_made_with_the_same_settings(tmp_path):
    """run_study resumes part by part: a part in OUT's study_design.json is kept when its own settings and the shared
    ones are unchanged, and made again otherwise."""
    import json
    config = {"cell_um": 96.0, "kernel_px": 31, "feature_um": 8.0, "open_fraction": 0.2, "seed": 0,
              "wavelengths_nm": [640.0, 520.0, 450.0], "threads": 1, "banding_distance_mm": 2.0,
              "samples": [64], "steps": [2], "design_pupil_samples": 64, "sample_um": [8.0], "phases": [2]}
    parts = {p: [{"part": p}] for p in ("sampling", "steps", "banding", "field")}
    (tmp_path / "study_design.json").write_text(json.dumps({"config": config, **parts}))
    assert dk._kept_parts(tmp_path, config) == parts
    assert set(dk._kept_parts(tmp_path, {**config, "phases": [2, 4]})) == {"sampling", "steps", "banding"}
    assert dk._kept_parts(tmp_path, {**config, "threads": 2}) == {}
    assert dk._kept_parts(tmp_path / "none", config) == {}


def test_the_ceilings_block_error_in_closed_form():
    """Draws alternating variances v1, v2: blocks of 1 err by √(v/m) − 1 against m = (v1 + v2) / 2, RMS times
    √(M / (M − 1)); blocks of 2 hold both and do not err; equal draws never err; a ratio to itself never errs."""
    v1, v2 = 4.0, 9.0
    var = np.array([[v1], [v2], [v1], [v2]])
    m = (v1 + v2) / 2
    expected = np.sqrt(((np.sqrt(v1 / m) - 1) ** 2 + (np.sqrt(v2 / m) - 1) ** 2) / 2 * 4 / 3)
    assert abs(dk._block_error(var, 1) - expected) < 1e-12
    assert dk._block_error(var, 2) < 1e-12 and dk._block_error(np.full((4, 3), 2.0), 1) < 1e-12
    assert dk._block_error(var, 1, var) < 1e-12


def test_the_ceiling_rows_cover_the_draw_counts():
    """Part (e) on the quick setting: one row per draw count, its blocks of the truth's draws, finite errors."""
    rows = dk.ceiling_rows({"cell_um": 96.0, "ceiling_draws": (1, 2), "ceiling_truth": 4})
    assert [(r["draws"], r["blocks"]) for r in rows] == [(1, 4), (2, 2)]
    for r in rows:
        assert r["cpu_s"] > 0 and all(0 <= r[k] < 1 for k in ("error_toled_rel", "error_scatter_rel",
                                                              "error_ratio_rel"))


def test_the_kicks_rows_start_at_the_plain_optimum_and_never_fall():
    """Part (f) on a tiny setting: the 0-kick row is the plain search's converged cell (the same run without kicks),
    the best on the search's tiling never falls as kicks are added, the open area is kept, CPU time grows."""
    cfg = {**TINY, "kicks": (1, 2), "kick_swaps": (2,)}
    rows = dk.kicks_rows(cfg)
    plain = Designer(DesignConfig(cell_um=96.0, kernel_px=15, pupil_samples=64, steps=100_000))
    while not plain.finished:
        plain.step()
    assert [(r["kick_swaps"], r["kicks"]) for r in rows] == [(2, 0), (2, 1), (2, 2)]
    assert abs(rows[0]["search_psnr_db"] + 10 * np.log10(plain.current)) < 1e-12
    assert abs(rows[0]["psnr_db"] - plain.score(plain.cell)["psnr_db"]) < 1e-12
    search = [r["search_psnr_db"] for r in rows]
    assert search == sorted(search) and all(abs(r["open_area"] - 29 / 144) < 1e-12 for r in rows)
    assert rows[0]["cpu_s"] < rows[1]["cpu_s"] <= rows[2]["cpu_s"]


def test_the_tilings_rows_pair_each_search_with_the_single_draws():
    """Part (g) on a tiny setting: the M = 1 row is the plain search's optimum (its held-out mean recomputed here on
    the held-out draws, its gain exactly 0); each row's gain is the mean of its per-draw PSNRs less M = 1's; the
    M = 2 search scores its own cell on the mean of its two draws."""
    cfg = {**TINY, "search_tilings": (1, 2), "held_tilings": 3}
    rows = dk.tilings_rows(cfg)
    plain = Designer(DesignConfig(cell_um=96.0, kernel_px=15, pupil_samples=64))
    while not plain.finished:
        plain.step()
    x = torch.tensor(plain.best_cell)
    j = [float(plain.objective(x, t)) for t in held_out_draws(plain, 3)]
    assert abs(rows[0]["held_psnr_db"] + 10 * np.log10(np.mean(j))) < 1e-12 and rows[0]["gain_db"] == 0.0
    diff = np.subtract(rows[1]["held_draws_psnr_db"], rows[0]["held_draws_psnr_db"])
    assert abs(rows[1]["gain_db"] - diff.mean()) < 1e-12 and rows[1]["search_tilings"] == 2
    assert abs(rows[0]["search_psnr_db"] + 10 * np.log10(plain.best)) < 1e-12


def test_an_arranged_pattern_of_one_element_is_the_repeated_tiling():
    """Part (h)'s scores against the repeated tiling's own code path: a pattern of K × K identical identity tiles is
    the cell repeated plainly, so its objective equals Designer(tiling 'repeated')'s at every K, and the bands of the
    ceiling's own T-OLED over the repeated T-OLED (itself) are 1 at every K (its registrations over K periods are
    its own)."""
    from udc_render.studies import design_arrangement as da
    cfg = {**TINY, "held_tilings": 2}
    cell = da._designer(cfg, "arranged", 1).ceiling.reference.numpy()  # cells.toled_reference
    repeated = Designer(DesignConfig(cell_um=96.0, kernel_px=15, pupil_samples=64, tiling="repeated"))
    j = float(repeated.objective(torch.tensor(cell, dtype=torch.float64), None))
    for k in (1, 2, 3):
        row = da._pattern_row(da._designer(cfg, "arranged", k), cell, np.zeros((k, k), int))
        assert abs(row["psnr_db"] + 10 * np.log10(j)) < 1e-9, k
        np.testing.assert_allclose(row["bands"], 1.0, rtol=1e-9)


def test_a_d4_symmetric_cell_arranged_is_the_same_display_for_every_pattern():
    """A cell that every D4 element leaves unchanged (a centred square) tiles alike whatever the pattern: every K and
    every random pattern scores the same PSNR and bands (an invariant of the pattern's handling and registration),
    and part (h)'s rows carry it (their gap to the turned cell, the same display, is 0)."""
    from udc_render.studies import design_arrangement as da
    cell = np.zeros((12, 12))
    cell[4:8, 4:8] = 1.0
    cfg = {**TINY, "held_tilings": 2, "arrangement": (1, 2, 3), "arrangement_draws": 2}
    rows = da.arrangement_rows(cfg, {"square": cell}, 0)
    assert [r["tiles"] for r in rows] == [None, 1, 2, 3]
    for r in rows[1:]:
        assert abs(r["gap_db"]) < 1e-9 and np.ptp(r["psnr_draws_db"]) < 1e-9
        np.testing.assert_allclose(r["bands_draws"], [rows[1]["bands_over_repeated"]] * 2, rtol=1e-6)
        assert r["sweep_cpu_s"] == 7 * r["tiles"] ** 2 * (r["cpu_s"] + r["cpu_bands_s"])


def test_the_guides_arranged_k_table_is_the_committed_study():
    """Consistency, not physics: the design guide's part (h) rows are the committed study's figures."""
    import json
    from pathlib import Path
    root = Path(__file__).parents[2]
    rows = json.loads((root / "docs/figures/design/study_knobs/study_design.json").read_text())["arrangement"]
    by = {(r["cell"], r["tiles"]): r for r in rows}
    guide = (root / "docs/guides/design.md").read_text()
    for k in sorted({r["tiles"] for r in rows if r["tiles"]}):
        t, s = by[("toled_edge", k)], by[("scatter", k)]
        best = t["best_psnr_db"] - by[("toled_edge", None)]["psnr_db"]
        row = (f"| {t['gap_db']:+.3f}, {best:+.3f} | {t['bands_over_repeated'][1]:.3f} | {s['gap_db']:+.3f} | "
               f"{s['bands_over_repeated'][1]:.3f} | {t['sweep_cpu_s']:.0f} / {s['sweep_cpu_s']:.0f} |")
        assert f"| {k} ({k * 168} µm)" in guide and row.replace("-", "−") in guide, row
    turned = [by[(c, None)]["bands_over_repeated"][1] for c in ("toled_edge", "scatter")]
    assert f"| turned | reference | {turned[0]:.3f} | reference | {turned[1]:.3f} | |" in guide
