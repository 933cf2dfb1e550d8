"""`udc-render design` (udc_render.design.optimise, .job): the objective against the engine, the swap search, the
resume, the display file every command takes, and the refusals."""
from __future__ import annotations

import json

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from psf import Lens, compute_kernels
from psf.micrograph import MicrographLayout
from restore.known import packed_from_sensor
from udc_render import cli
from udc_render.design import job, metrics, torch_psf as tp, upc
from udc_render.design.cells import RINGS
from udc_render.design.config import DesignConfig
from udc_render.design.optimise import RIG_WAVELENGTHS_NM, Designer
from udc_render.design.starts import scatter
from udc_render.design.symmetry import kicked_orbits, orbits
from udc_render.optics.displays import DisplayError, load_display

TINY = dict(cell_um=200.0, feature_um=40.0, open_fraction=0.24, steps=4, pupil_samples=64, kernel_px=31, scatters=3,
            seed=3)


def _binary(c: int, k: int, seed: int) -> np.ndarray:
    flat = np.zeros(c * c)
    flat[np.random.default_rng(seed).permutation(c * c)[:k]] = 1.0
    return flat.reshape(c, c)


@pytest.mark.parametrize("scene", [{}, {"mean_level": 0.41, "contrast": 0.51}, {"pixel_um": 6.2},
                                   {"pixel_um": 6.2, "packed": True}])
def test_the_wiener_objective_is_the_restorability_of_the_engines_kernels(scene):
    """A binary cell's score (torch) equals metrics.restorability on psf.compute_kernels' kernels (numpy) at the open
    area × the fraction of the light inside the window (kernels_and_window; the plain tiling's differs from the
    engine's power series by under 1 %, test_design_torch_psf), at the default scene and at --mean-level and
    --contrast given, at another sensor pitch (--pixel-um: the engine's pixel_um), and on that pitch's packed
    planes (--packed: restore.known.packed_from_sensor of the engine's kernels, its R, Gr, B; bound 1e-6 there,
    packed_from_sensor's float32)."""
    d = Designer(DesignConfig(**{**TINY, "tiling": "repeated", "cell_um": 40.0, "feature_um": 8.0, **scene}))
    cell = _binary(5, 6, 0)
    parts = d.score(cell)
    engine = compute_kernels(MicrographLayout("cell", 8.0, image=cell), Lens(), RIG_WAVELENGTHS_NM,
                             pixel_um=d.config.pixel_um, size_px=31, pupil_samples=64, precision="float64")
    _, inside = tp.kernels_and_window(torch.tensor(cell), d.grid, None)  # the engine's: test_design_torch_psf
    kept = float(cell.mean()) * inside.numpy()
    kernels = engine.kernels
    if d.config.packed:
        kernels = packed_from_sensor(kernels)[[0, 1, 3]].astype(np.float64)
        kernels /= kernels.sum(axis=(1, 2), keepdims=True)
    ref = np.mean(metrics.restorability(kernels, kept, mean_level=d.config.mean_level,
                                        contrast=d.config.contrast)["wiener_mse"])
    bound = 1e-6 if d.config.packed else 1e-10
    assert abs(parts["objective"] / ref - 1) < bound and abs(parts["open_area"] - 6 / 25) < 1e-15
    assert abs(parts["psnr_db"] + 10 * np.log10(ref)) < 10 * bound


def test_the_far_veil_adds_the_bias_of_the_light_past_the_window():
    """--far-veil adds ((1 − f) / f)² μ² per channel to the wiener objective, f the share inside the window:
    kernels_and_window's exactly, and within 5 % of the bias by the engine's energy_outside (psf.compute_kernels;
    measured 2.7 % at f ≈ 0.24, where the bias magnifies the shares' small difference, test_design_torch_psf, by
    2 / (1 − f))."""
    config = {**TINY, "tiling": "repeated", "cell_um": 40.0, "feature_um": 8.0}
    cell = _binary(5, 6, 0)
    d = Designer(DesignConfig(**config))
    plain = d.score(cell)["objective"]
    veiled = Designer(DesignConfig(**config, far_veil=True)).score(cell)["objective"]
    _, inside = tp.kernels_and_window(torch.tensor(cell), d.grid, None)
    f = inside.numpy()
    assert abs((veiled - plain) / (np.mean(((1 - f) / f) ** 2) * metrics.MEAN_LEVEL ** 2) - 1) < 1e-10
    outside = compute_kernels(MicrographLayout("cell", 8.0, image=cell), Lens(), RIG_WAVELENGTHS_NM, size_px=31,
                              pupil_samples=64, precision="float64").energy_outside
    engine = np.mean((np.asarray(outside) / (1 - np.asarray(outside))) ** 2) * metrics.MEAN_LEVEL ** 2
    assert abs((veiled - plain) / engine - 1) < 0.05
    dim = {**config, "mean_level": 0.41}  # the veil is the scene's mean: --mean-level's
    gap = (Designer(DesignConfig(**dim, far_veil=True)).score(cell)["objective"]
           - Designer(DesignConfig(**dim)).score(cell)["objective"])
    assert abs(gap / (np.mean(((1 - f) / f) ** 2) * 0.41 ** 2) - 1) < 1e-10


def test_the_rings_objective_is_upcs_statistic_in_their_sampling():
    """--optics upc --objective rings scores −mean log of metrics.ring_summary's mean ring minima (numpy masks) of
    upc.psf on the held-out tiling, over the channels asked; in the rig's optics, of the engine-exact kernels."""
    cell = _binary(21, 88, 1)
    full = Designer(DesignConfig(objective="rings", optics="upc", scatters=1))
    blue = Designer(DesignConfig(objective="rings", optics="upc", channels="B", scatters=1))
    with torch.no_grad():
        k = upc.psf(torch.tensor(cell), full.transforms("final")).numpy()
    minima = np.array(metrics.ring_summary(k, RINGS)["mean_of_ring_minima"])
    assert abs(full.score(cell)["objective"] / -np.mean(np.log(minima)) - 1) < 1e-12
    assert abs(blue.score(cell)["objective"] / -np.log(minima[2]) - 1) < 1e-12 and blue.score(cell)["psnr_db"] is None
    rig = Designer(DesignConfig(**{**TINY, "objective": "rings", "channels": "GB"}))
    small = _binary(5, 6, 2)
    with torch.no_grad():
        kernels = tp.kernels(torch.tensor(small), rig.grid, rig.transforms("final")).numpy()
    ring_minima = metrics.ring_summary(kernels[1:])["mean_of_ring_minima"]
    assert abs(rig.score(small)["objective"] / -np.mean(np.log(ring_minima)) - 1) < 1e-12


@pytest.mark.parametrize("dropped, changed", [
    (("optics", "channels"), {"channels": "B"}),
    (("upc_floor", "floor_channels", "floor_uncropped"), {"upc_floor": 1.3}),
    (("banding_ceiling",), {"banding_ceiling": 0.95}),
    (("kicks", "kick_swaps"), {"kick_swaps": 2}),
    (("pixel_um",), {"pixel_um": 6.2}),
    (("packed",), {"packed": True}),
])
def test_a_checkpoint_from_before_a_later_option_resumes(dropped, changed):
    """A state saved without a later option's settings (their defaults then) loads into the default run only."""
    state = Designer(DesignConfig(**TINY)).state()
    old = {**state, "config": {k: v for k, v in state["config"].items() if k not in dropped}}
    Designer(DesignConfig(**TINY)).load(old)
    with pytest.raises(tp.DesignError, match=rf"other settings \({next(iter(changed))}\)"):
        Designer(DesignConfig(**{**TINY, **changed})).load(old)


def _assert_no_swap_lowers(d: Designer) -> None:
    """Every swap of an open and an opaque square of d's cell scores no lower than its current objective."""
    flat = d.cell.ravel()
    for i in np.flatnonzero(flat):
        for j in np.flatnonzero(flat == 0):
            trial = flat.copy()
            trial[i], trial[j] = 0.0, 1.0
            assert d.search_score(trial.reshape(d.cell.shape)) >= d.current * (1 - 1e-5)


@pytest.mark.parametrize("tiling", ["repeated", pytest.param("turned", marks=pytest.mark.slow)])  # turned: 9 s, CI time
def test_the_search_ends_in_a_local_optimum_of_all_swaps(tiling):
    """With every swap a candidate (3 open × 6 opaque squares of a 3 × 3 cell), the search lowers its objective at
    each step, keeps the 3 open squares, and stops where no swap lowers it (checked exhaustively)."""
    d = Designer(DesignConfig(**{**TINY, "cell_um": 120.0, "open_fraction": 0.34, "tiling": tiling, "steps": 100,
                                 "candidates": 3 * 6}))
    previous = d.current
    while not d.finished:
        rec = d.step()
        assert d.cell.sum() == 3 and set(np.unique(d.cell)) == {0.0, 1.0}
        if rec["swap"]:
            flat = d.cell.ravel()
            assert rec["objective"] < previous and flat[rec["swap"][1]] == 1 and flat[rec["swap"][0]] == 0
            previous = rec["objective"]
    assert d.converged and 0 < d.step_done < 100 and d.current == d.search_score(d.cell)
    _assert_no_swap_lowers(d)


def test_a_kick_moves_the_given_swaps_and_keeps_the_open_area():
    cell = _binary(21, 88, 4)
    for swaps in (1, 4, 88):
        out = kicked_orbits(cell, orbits(21, "none"), swaps, np.random.default_rng(swaps))
        assert out.sum() == 88 and np.sum((cell > 0.5) & (out < 0.5)) == swaps and cell.sum() == 88


def test_kicks_end_at_the_best_local_optimum_and_never_above_the_plain_search():
    """With every swap a candidate (a 3 × 3 cell, 3 open): the plain search's optimum is the kicked run's first one
    (same start, same steps); each kick starts kick_swaps swaps from the best cell so far; the design is the best of
    the optima and a local optimum of all swaps (checked exhaustively); its objective ≤ the plain search's."""
    base = {**TINY, "cell_um": 120.0, "open_fraction": 0.34, "tiling": "repeated", "steps": 100, "candidates": 18}
    plain = Designer(DesignConfig(**base))
    while not plain.finished:
        plain.step()
    d = Designer(DesignConfig(**base, kicks=3, kick_swaps=1))
    optima, best = [], d.cell
    while not d.finished:
        before = d.best_cell
        rec = d.step()
        if rec["swap"] is None:
            optima.append(rec["best"])
            if "kick" in rec:
                assert np.sum((before > 0.5) & (d.cell < 0.5)) == 1 and d.cell.sum() == 3
        best = d.best_cell
    assert d.kicks_done == 3 and d.converged and len(optima) == 4 and optima[0] == plain.current
    assert d.current == d.best == min(r["objective"] for r in d.losses) <= plain.current
    assert np.array_equal(d.cell, best)
    _assert_no_swap_lowers(d)


def _cut_and_resumed(config: DesignConfig, out, monkeypatch, at_step: int, checkpoint_steps: int) -> dict:
    """A design run interrupted before step at_step (checkpoints every checkpoint_steps), then resumed to its end."""
    monkeypatch.setattr(job, "CHECKPOINT_STEPS", checkpoint_steps)
    real_step = Designer.step

    def interrupt(self):
        if self.step_done == at_step:
            raise KeyboardInterrupt
        return real_step(self)
    monkeypatch.setattr(Designer, "step", interrupt)
    with pytest.raises(KeyboardInterrupt):
        job.run_design(config, out, quiet=True, compare=False)
    monkeypatch.setattr(Designer, "step", real_step)
    return job.run_design(config, out, quiet=True, compare=False)


def test_an_interrupted_kicked_run_resumes_to_the_same_result(tmp_path, monkeypatch):
    config = DesignConfig(**{**TINY, "steps": 12, "kicks": 2, "kick_swaps": 2, "candidates": 6})
    whole = job.run_design(config, tmp_path / "whole", quiet=True, compare=False)
    kicks = [i for i, r in enumerate(whole["losses"]) if "kick" in r]
    assert kicks and whole["kicks_done"] >= 1
    again = _cut_and_resumed(config, tmp_path / "cut", monkeypatch, kicks[0] + 1, 1)
    assert again["losses"] == whole["losses"] and again["final"] == whole["final"]
    assert whole["search_objective"] == min(r["best"] for r in whole["losses"])


def test_a_finished_run_resumed_with_more_kicks_is_the_longer_run(tmp_path):
    """Raising --kicks (or --steps) on a finished run's folder goes on from its last optimum: the record and the
    design equal a run with the larger budget from the start; lowering the budget is refused."""
    short, long = ({**TINY, "steps": 40, "kicks": k, "kick_swaps": 2, "candidates": 6} for k in (1, 3))
    job.run_design(DesignConfig(**short), tmp_path / "grown", quiet=True, compare=False)
    grown = job.run_design(DesignConfig(**long), tmp_path / "grown", quiet=True, compare=False)
    whole = job.run_design(DesignConfig(**long), tmp_path / "whole", quiet=True, compare=False)
    assert grown["kicks_done"] == whole["kicks_done"] == 3 and grown["converged"]
    assert grown["losses"] == whole["losses"] and grown["final"] == whole["final"]
    with pytest.raises(tp.DesignError, match=r"other settings \(kicks\)"):
        job.run_design(DesignConfig(**short), tmp_path / "whole", quiet=True, compare=False)
    capped = job.run_design(DesignConfig(**{**TINY, "steps": 2}), tmp_path / "steps", quiet=True, compare=False)
    more = job.run_design(DesignConfig(**TINY), tmp_path / "steps", quiet=True, compare=False)
    four = job.run_design(DesignConfig(**TINY), tmp_path / "four", quiet=True, compare=False)
    assert capped["steps_done"] == 2 and more["losses"] == four["losses"] and more["final"] == four["final"]


def test_an_interrupted_run_resumes_to_the_same_result(tmp_path, monkeypatch):
    config = DesignConfig(**TINY)
    whole = job.run_design(config, tmp_path / "whole", quiet=True, compare=False)
    assert whole["steps_done"] == 4 and not whole["converged"]  # the interrupt below falls inside the run
    again = _cut_and_resumed(config, tmp_path / "cut", monkeypatch, 3, 2)
    assert again["losses"] == whole["losses"] and again["final"] == whole["final"]
    with pytest.raises(Exception, match="other settings"):
        job.run_design(DesignConfig(**{**TINY, "seed": 1}), tmp_path / "cut", quiet=True, compare=False)


def test_a_slow_step_is_checkpointed_by_time(tmp_path, monkeypatch):
    """With steps slower than CHECKPOINT_S (here 0 s) every step is written, whatever CHECKPOINT_STEPS: a run cut
    before its 4th step keeps its 3 steps (design_state.pt) and resumes to the uninterrupted run's result."""
    config = DesignConfig(**TINY)
    whole = job.run_design(config, tmp_path / "whole", quiet=True, compare=False)
    monkeypatch.setattr(job, "CHECKPOINT_S", 0.0)
    real_step = Designer.step

    def interrupt(self):
        if self.step_done == 3:
            raise KeyboardInterrupt
        return real_step(self)
    monkeypatch.setattr(job, "CHECKPOINT_STEPS", 1000)
    monkeypatch.setattr(Designer, "step", interrupt)
    with pytest.raises(KeyboardInterrupt):
        job.run_design(config, tmp_path / "cut", quiet=True, compare=False)
    assert torch.load(tmp_path / "cut" / "design_state.pt", weights_only=False)["step"] == 3
    monkeypatch.setattr(Designer, "step", real_step)
    again = job.run_design(config, tmp_path / "cut", quiet=True, compare=False)
    assert again["losses"] == whole["losses"] and again["final"] == whole["final"]


def test_the_baseline_scatters_are_scored_as_the_design_is(tmp_path):
    """design.json's scatters: N cells of the same open squares, each scored as the design (held-out tiling); UPC's
    comparison: the T-OLED's slit at the edge of a turned tiling has far higher ring minima than repeated."""
    doc = job.run_design(DesignConfig(**TINY), tmp_path, quiet=True)
    d = Designer(DesignConfig(**TINY))
    base = doc["scatters"]
    assert base["n"] == 3 and base["values"][2] == d.score(scatter(d.config, "scatter", 2))["psnr_db"]
    assert doc["final"]["psnr_db"] == d.score(np.asarray(iio.imread(tmp_path / "cell.png")) / 255.0)["psnr_db"]
    assert doc["initial"]["squares_moved"] <= doc["steps_done"]
    upc = doc["upc"]
    assert all(t > 3 * r for t, r in zip(upc["turned"]["toled_edge"], upc["repeated"]["toled_edge"]))
    assert upc["turned"]["ratio"] == list(np.divide(upc["turned"]["design"], upc["turned"]["toled_edge"]))
    for name in ("design", "toled_edge"):  # a ring's minimum is at most its mean; B's crop is its whole grid
        assert np.all(np.array(upc["turned"]["ring_means"][name]) >= upc["turned"][name])
        assert abs(upc["turned"]["kept"][name][2] - 1) < 1e-9 and 0 < upc["turned"]["kept"][name][0] < 1
    ratio_kept = np.divide(upc["turned"]["kept"]["design"], upc["turned"]["kept"]["toled_edge"])
    assert np.allclose(upc["turned"]["ratio_uncropped"], np.multiply(upc["turned"]["ratio"], ratio_kept))
    draws = upc["turned"]["draws"]
    assert draws["n"] == job.UPC_DRAWS and np.all(np.array(draws["min"]) <= draws["mean"])


@pytest.mark.parametrize("symmetry", ["none", "c2"])
def test_the_designed_display_files_are_displays(tmp_path, symmetry):
    """design.toml repeats the cell, design_turned.toml turns it (and, for a point-symmetric cell, whose quarter
    turns give two distinct tiles, mirrors it too: the search's D4)."""
    doc = job.run_design(DesignConfig(**{**TINY, "steps": 2, "symmetry": symmetry}), tmp_path, quiet=True,
                         compare=False)
    plain, turned = load_display(str(tmp_path / "design.toml")), load_display(str(tmp_path / "design_turned.toml"))
    assert plain.layout.image.shape == (5, 5) and plain.layout.pixel_um == 40.0 and not plain.layout.random_rotation
    assert turned.layout.random_rotation and turned.layout.flip == (symmetry == "c2")
    assert abs(plain.layout.open_fraction - doc["open_squares"] / 25) < 1e-15
    assert abs(plain.gain - round(25 / doc["open_squares"], 3)) < 1e-12
    assert json.loads((tmp_path / "design.json").read_text())["cell_px"] == 5
    assert (tmp_path / "design_loss.png").stat().st_size > 0
    bad = tmp_path / "bad.toml"
    bad.write_text((tmp_path / "design_turned.toml").read_text().replace("tile_rotation = true",
                                                                          'tile_rotation = "yes"'))
    with pytest.raises(DisplayError, match="tile_rotation"):
        load_display(str(bad))


@pytest.mark.parametrize("argv, says", [
    (["--open-area", "1.2"], "--open-area 1.2: expected a fraction in (0, 1)"),
    (["--feature-um", "1"], "--feature-um 1.0: below the 1.5 µm"),
    (["--cell-um", "170"], "--cell-um 170.0: the minimum feature size 8.0 µm cannot tile it"),
    (["--open-area", "0.001"], "less than one 8.0 µm square"),
    (["--objective", "crop", "--crop-px", "1"], "--crop-px 1: expected an integer ≥ 2"),
    (["--contrast", "0"], "--contrast"),
    (["--mean-level", "0"], "--mean-level must be > 0, got 0"),
    (["--mean-level", "1.5"], "--mean-level 1.5: expected a fraction of the full well in (0, 1]"),
    (["--init", "poled"], "--init"),
    (["--optics", "upc"], "--optics upc takes --objective upc or rings, got wiener"),
    (["--optics", "upc", "--objective", "rings", "--cell-um", "160"],
     "--optics upc: UPC's sampling takes their 168 µm cell of 8 µm features, got --cell-um 160"),
    (["--channels", "BX"], "--channels BX: expected some of RGB, each once"),
    (["--channels", "GG"], "--channels GG"),
    (["--objective", "upc", "--far-veil"], "--far-veil: takes --objective wiener or crop"),
    (["--kicks", "-1"], "--kicks must be ≥ 0, got -1"),
    (["--kick-swaps", "0"], "--kick-swaps must be > 0, got 0"),
    (["--kicks", "1", "--kick-swaps", "89"], "--kick-swaps 89: the cell has 88 squares to swap; expected 1 … 88"),
    (["--search-tilings", "0"], "--search-tilings must be > 0, got 0"),
    (["--search-tilings", "2", "--tiling", "repeated"], "--search-tilings 2: takes --tiling turned"),
    (["--held-out-tilings", "-1"], "--held-out-tilings must be ≥ 0, got -1"),
    (["--channel-step", "0.5"], "--channel-step 0.5: expected 0 (the rig's 640 / 520 / 450 nm) or a step ≥ 1 nm"),
    (["--channel-step", "-2"], "--channel-step must be ≥ 0, got -2"),
    (["--optics", "upc", "--objective", "rings", "--channel-step", "40"], "--channel-step 40.0: expected 0"),
    (["--pixel-um", "0"], "--pixel-um must be > 0, got 0"),
    (["--optics", "upc", "--objective", "rings", "--channel-step", "0", "--pixel-um", "12.4"],
     "--pixel-um 12.4: takes --optics rig"),
    (["--optics", "upc", "--objective", "rings", "--channel-step", "0", "--packed"],
     "--packed: takes --optics rig with --objective wiener or crop"),
    (["--objective", "rings", "--packed"], "--packed: takes --optics rig with --objective wiener or crop"),
])
def test_design_refuses_in_one_line(tmp_path, capsys, argv, says):
    assert cli.main(["design", *argv, "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "never").exists()
