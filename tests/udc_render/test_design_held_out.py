"""The design's objective on many held-out tilings, paired with the exact T-OLED the simulator takes
(udc_render.design.held_out), the search over several tilings (--search-tilings) and `study held-out`
(udc_render.studies.design_held_out)."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from psf import Lens, compute_kernels, layouts
from psf.micrograph import MicrographLayout
from psf.spectral import channel_weights
from psf.turned import TurnedLayout, edge_framed
from udc_render import cli
from udc_render.design import held_out, metrics, torch_psf as tp
from udc_render.design.cells import SIMULATOR_TILE_SEED, layout_cell
from udc_render.design.config import DesignConfig
from udc_render.design.optimise import CHANNEL_ILLUMINANT, RIG_WAVELENGTHS_NM, Designer
from udc_render.design.starts import scatter
from udc_render.sensor.config import SensorConfig
from udc_render.studies.design_held_out import at_pitch

TINY = dict(cell_um=40.0, feature_um=8.0, open_fraction=0.24, steps=2, pupil_samples=64, kernel_px=31, scatters=2,
            seed=3)


def test_a_grey_cell_scored_at_its_own_transmission_is_the_engines_restorability():
    """The preset T-OLED's area-weighted raster (the held-out reference's kind of cell: grey edges), tiled plainly and
    scored at its transmission Σ|a|² / c², equals metrics.restorability of psf.compute_kernels' kernels of the same
    amplitude micrograph at that transmission × the share inside the window (kernels_and_window's, as the binary
    cell's test in test_design_optimise), to its 1e-10."""
    cell, pixel_um = layout_cell(layouts.toled(pitch_um=40.0, open_fraction=0.24), pixel_um=8.0)
    d = Designer(DesignConfig(**{**TINY, "feature_um": pixel_um, "tiling": "repeated"}))
    t = float(np.mean(cell ** 2))
    assert abs(float(np.mean(cell)) - 0.24) < 1e-12 and t < 0.24  # area-weighted: grey edges pass less power
    score = float(d.objective(torch.tensor(cell), None, t))
    engine = compute_kernels(MicrographLayout("cell", pixel_um, image=cell), Lens(), RIG_WAVELENGTHS_NM, size_px=31,
                             pupil_samples=64, precision="float64")
    _, inside = tp.kernels_and_window(torch.tensor(cell), d.grid, None)  # the engine's within 1 %
    ref = np.mean(metrics.restorability(engine.kernels, t * inside.numpy())["wiener_mse"])
    assert abs(score / ref - 1) < 1e-10


def test_the_simulators_tiling_and_the_exact_toled_score_as_the_engines_kernels():
    """The 'engine' group's draw and the exact T-OLED (held_out.preset_toled: a binary raster with its edges on the
    grid, scored with the LTPS limit lifted), turned: the objective equals metrics.restorability of
    psf.compute_kernels' kernels of the preset itself, from its Fourier series (psf.turned), framed and turned by
    the engine for SIMULATOR_TILE_SEED, to 1e-10 (the grey cell's test above)."""
    config = DesignConfig(**TINY)
    cell, scoring = held_out.preset_toled(config)
    d, design = Designer(scoring), Designer(config)
    t = float(np.mean(cell ** 2))
    assert np.all((cell == 0) | (cell == 1)) and abs(t - 0.24) < 1e-12 and d.tiles == design.tiles
    assert scoring.feature_um == pytest.approx(1 / 3) and cell.shape == (120, 120)
    draw = held_out.engine_draw(design)
    score = float(d.objective(torch.tensor(cell), draw, t))
    toled = layouts.toled(pitch_um=40.0, open_fraction=0.24)
    engine = compute_kernels(TurnedLayout(edge_framed(toled), SIMULATOR_TILE_SEED), Lens(), RIG_WAVELENGTHS_NM,
                             size_px=31, pupil_samples=64, precision="float64")
    _, inside = tp.kernels_and_window(torch.tensor(cell), d.grid, draw)
    ref = np.mean(metrics.restorability(engine.kernels, t * inside.numpy())["wiener_mse"])
    assert abs(score / ref - 1) < 1e-10


def test_the_exact_toled_is_the_preset_layout_trained_tiles(tmp_path):
    """`study layout-trained`'s toled168_20.toml@edge@turned is the preset framed at the edge and turned with the
    simulator's tile seed (no raster); preset_toled's cell is that preset exactly; a study with simulator=True
    pairs every cell with it on one more group of one draw."""
    from restore.studies.layout_trained import entry_display
    lay = entry_display("docs/figures/design/toled168_20.toml@edge@turned", tmp_path).layout
    assert isinstance(lay, TurnedLayout) and lay.random_rotation and lay.seed == SIMULATOR_TILE_SEED
    cell, scoring = held_out.preset_toled(DesignConfig(feature_um=8.0))
    c = cell.shape[0]
    assert c == 2520 and np.array_equal(cell, np.round(lay.base.cell_raster(c, c)[0]))
    d = Designer(DesignConfig(**TINY))
    doc = held_out.held_out_comparison(d, {"s": scatter(d.config, "scatter", 1)}, 2, simulator=True)
    assert len(doc["engine"]["psnr_db"]["s"]) == 1 and set(doc["d4"]["vs"]["s"]) == {"toled_preset", "toled_squares"}
    assert doc["toled_preset_transmission"] == pytest.approx(0.24, abs=1e-12)


def test_held_out_draws_are_the_same_for_every_cell_and_apart_from_the_searchs():
    """One cell under two names scores alike on every draw (paired difference exactly 0, led on no draw); the draws
    are neither the search's nor the final one; the quarter-turns draw only rotations."""
    d = Designer(DesignConfig(**TINY))
    cell = scatter(d.config, "scatter", 0)
    doc = held_out.held_out_comparison(d, {"a": cell, "b": cell.copy()}, 3)
    for group in ("d4", "quarter_turns"):
        assert doc[group]["psnr_db"]["a"] == doc[group]["psnr_db"]["b"]
        assert len(doc[group]["psnr_db"]["a"]) == 3
    draws = held_out.held_out_draws(d, 3)
    assert not any(np.array_equal(t, d.transforms(w)) for t in draws for w in ("search", "final"))
    assert max(int(t.max()) for t in held_out.held_out_draws(d, 3, flips=False)) <= 3
    assert max(int(t.max()) for t in draws) >= 4


def test_the_paired_difference_is_the_mean_of_the_draws_differences():
    """vs[name][ref]: the mean, the standard error (sample sd / √n) and the count of positive differences of the
    per-draw PSNRs, recomputed here from doc['psnr_db']."""
    d = Designer(DesignConfig(**TINY))
    doc = held_out.held_out_comparison(d, {"s": scatter(d.config, "scatter", 1)}, 4)["d4"]
    for ref in ("toled_preset", "toled_squares"):
        diff = np.subtract(doc["psnr_db"]["s"], doc["psnr_db"][ref])
        v = doc["vs"]["s"][ref]
        assert v["mean"] == pytest.approx(diff.mean(), abs=1e-12)
        assert v["se"] == pytest.approx(diff.std(ddof=1) / 2, abs=1e-12) and v["leads"] == int((diff > 0).sum())


def test_the_search_over_m_tilings_lowers_their_mean():
    """--search-tilings 2: the searched objective is the mean of J on the search's draw and its first further draw
    (two objective calls here); 1 is the former single draw."""
    one = Designer(DesignConfig(**TINY))
    two = Designer(DesignConfig(**TINY, search_tilings=2))
    x = torch.tensor(scatter(one.config, "scatter", 2))
    j = [float(one.objective(x, one.transforms("search", m))) for m in (0, 1)]
    assert float(two.searched(x, "search")) == pytest.approx(np.mean(j), rel=1e-12)
    assert float(one.searched(x, "search")) == pytest.approx(j[0], rel=1e-12) and j[0] != j[1]


@pytest.mark.slow  # 20-80 s on a core: out of CI's 20 min
def test_design_json_holds_the_held_out_comparison(tmp_path):
    """A turned wiener run writes design.json's held_out (n draws, both groups, the design against both T-OLEDs)
    and a study of two folders ranks them on the first's objective; --held-out-tilings 0 writes none."""
    argv = ["design", "--cell-um", "40", "--feature-um", "8", "--open-area", "0.24", "--steps", "2", "--scatters", "2",
            "--pupil-samples", "64", "--kernel-px", "31", "--seed", "3", "--quiet"]
    assert cli.main([*argv, "--held-out-tilings", "2", "--out", str(tmp_path / "a")]) == 0
    assert cli.main([*argv, "--held-out-tilings", "0", "--init", "toled", "--out", str(tmp_path / "b")]) == 0
    doc = json.loads((tmp_path / "a" / "design.json").read_text())["held_out"]
    assert doc["n"] == 2 and set(doc["d4"]["vs"]["design"]) == {"toled_preset", "toled_squares"}
    assert json.loads((tmp_path / "b" / "design.json").read_text())["held_out"] is None
    folders = f"{tmp_path / 'a'},{tmp_path / 'b'}"
    assert cli.main(["study", "held-out", "--designs", folders, "--quick", "--out", str(tmp_path / "s")]) == 0
    study = json.loads((tmp_path / "s" / "study_held_out.json").read_text())
    assert [r["design"] for r in study["rows"]] == [str(tmp_path / "a"), str(tmp_path / "b")]
    assert study["rows"][0]["draws"] != study["rows"][1]["draws"] and (tmp_path / "s" / "study_held_out.png").is_file()
    assert "engine_toled_preset" in study["rows"][0] and "d4_toled_simulator" not in study["rows"][0]
    for light in [r for r in study["rows"]] + [study["toleds"]["toled_preset_light"]]:  # far_light's shares, R, G, B
        assert all(0 < b < w < 1 for w, b in zip(light["past_window"], light["beyond_acceptance"], strict=True))
    assert cli.main(["study", "channel-step", "--designs", folders, "--quick", "--out", str(tmp_path / "c")]) == 0
    rows = json.loads((tmp_path / "c" / "study_channel_step.json").read_text())["rows"]
    lam = channel_weights(SensorConfig().camera, CHANNEL_ILLUMINANT, 40.0)[0]
    assert [r["channel_step_nm"] for r in rows] == [0.0, 80.0, 40.0] and rows[-1]["error_db"] == 0.0
    assert rows[0]["wavelengths"] == 3 and rows[-1]["wavelengths"] == len(lam)
    engine = {r["design"]: r["engine_toled_preset"] for r in study["rows"]}  # at the designs' own step, 40
    assert json.loads((tmp_path / "a" / "design.json").read_text())["config"]["channel_step_nm"] == 40.0
    assert rows[2]["margins_db"] == pytest.approx(engine, abs=1e-9) != rows[0]["margins_db"]
    assert cli.main(["study", "held-out", "--designs", folders, "--quick", "--pixel-um", "9.3", "--out",
                     str(tmp_path / "p")]) == 0
    coarse = json.loads((tmp_path / "p" / "study_held_out.json").read_text())["toleds"]["objective"]
    assert (coarse["pixel_um"], coarse["kernel_px"]) == (9.3, 11) and study["toleds"]["objective"]["pixel_um"] == 3.1


@pytest.mark.parametrize("pixel_um, kernel_px", [(3.1, 255), (6.2, 129), (12.4, 65), (1.55, 511), (4.0, 199)])
def test_at_pitch_keeps_the_kernels_window_in_um(pixel_um, kernel_px):
    """255 px of 3.1 µm (790.5 µm) at 6.2 µm: 129 px (799.8 µm, the layout-trained banks'), at 12.4 µm: 65 px, at
    1.55 µm 511 px (792.05 µm: 510 px would cover it, but a kernel is odd), at 4 µm 199 px (796 µm; 197.6 needed)."""
    config = at_pitch(DesignConfig(**{**TINY, "kernel_px": 255}), pixel_um)
    assert (config.pixel_um, config.kernel_px) == (pixel_um, kernel_px) and config.kernel_px % 2 == 1
    assert at_pitch(config, None) is config
    packed = at_pitch(DesignConfig(**{**TINY, "kernel_px": 255}), pixel_um, packed=True)
    assert packed.packed and packed.objective_px == 2 * (kernel_px // 4) + 1 and not config.packed


@pytest.mark.parametrize("what, says", [
    ("nofolder", "no design.json there; expected a `udc-render design` output folder"),
    ("other_cell", "differs from the first design's"),
    ("display", "--designs: `study held-out`, `study channel-step` and `study design-bands` take it, and only they"),
    ("pixel", "--pixel-um 6.2: only `study held-out` takes the objective's pitch"),
    ("packed", "--packed: only `study held-out` scores the objective on packed planes"),
])
def test_study_held_out_refuses_in_one_line(tmp_path, capsys, what, says):
    a = tmp_path / "a"
    a.mkdir()
    (a / "design.json").write_text(json.dumps({"config": {**TINY, "tiling": "turned"}}))
    import imageio.v3 as iio
    iio.imwrite(a / "cell.png", (scatter(DesignConfig(**TINY), "scatter", 0) * 255).astype(np.uint8))
    b = tmp_path / "b"
    b.mkdir()
    (b / "design.json").write_text(json.dumps({"config": {**TINY, "cell_um": 48.0}}))
    iio.imwrite(b / "cell.png", (scatter(DesignConfig(**{**TINY, "cell_um": 48.0}), "scatter", 0) * 255
                                 ).astype(np.uint8))
    argv = {"nofolder": ["held-out", "--designs", str(tmp_path / "none")],
            "other_cell": ["held-out", "--designs", f"{a},{b}"],
            "display": ["layout", "--designs", str(a)],
            "pixel": ["channel-step", "--designs", str(a), "--pixel-um", "6.2"],
            "packed": ["design-bands", "--designs", str(a), "--packed"]}[what]
    assert cli.main(["study", *argv, "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "never").exists()


def test_the_reference_cell_puts_every_edge_on_the_grid_or_takes_the_finest_raster():
    """cells.reference_cell: the T-OLED at 168 µm and 20 % on 2520² squares of 1/15 µm (its slit's edges at 196/3 and
    42/5 µm), binary, its open area exact; at 21.3 % its edges need squares of 1/25 µm (4200², past EXACT_MAX_PX): the
    finest raster, 4032², area-weighted, its mean amplitude the open area and only the edges grey."""
    from udc_render.design.cells import EXACT_MAX_PX, reference_cell
    cell, pixel = reference_cell(layouts.toled(pitch_um=168.0, open_fraction=0.2))
    assert cell.shape == (2520, 2520) and pixel == pytest.approx(1 / 15)
    assert cell.mean() == pytest.approx(0.2, abs=1e-12) and np.all((cell == 0) | (cell == 1))
    fine, pixel = reference_cell(layouts.toled(pitch_um=168.0, open_fraction=0.213))
    grey = (fine > 1e-9) & (fine < 1 - 1e-9)
    assert fine.shape == (4032, 4032) and 4032 <= EXACT_MAX_PX and pixel == pytest.approx(168 / 4032)
    assert fine.mean() == pytest.approx(0.213, rel=1e-9) and 0 < grey.sum() < 4 * 4032
