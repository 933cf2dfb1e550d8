"""`udc-render study layout` (udc_render.studies.layout): its outputs on a small micrograph, its refusals."""
from __future__ import annotations

import json
import re
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from psf import layouts
from udc_render import cli
from udc_render.design.floor import UpcFloor
from udc_render.studies.layout import frame_cell, upc_cell


def test_upc_cell_keeps_the_open_area_and_frames_at_the_edge():
    cell = layouts.toled(pitch_um=317.0).cell_raster(159, 159)[0]
    small = upc_cell(cell)
    assert small.shape == (21, 21) and abs(small.mean() - cell.mean()) < 1e-12
    edge = upc_cell(frame_cell(cell, "edge"))
    assert edge[:, 0].sum() > 0 and edge[:, -1].sum() == 0 and abs(edge.sum() - small.sum()) < 1e-12


def test_study_layout_writes_its_tables_and_figures(tmp_path, capsys):
    tile = np.zeros((21, 21), np.uint8)
    tile[1:20, 0:5] = 255
    iio.imwrite(tmp_path / "slit.png", tile)
    out = tmp_path / "study"
    rc = cli.main(["study", "layout", "--display", str(tmp_path / "slit.png"), "--micrograph-pixel-um", "8",
                   "--quick", "--out", str(out)])
    assert rc == 0
    doc = json.loads((out / "study_layout.json").read_text())
    assert abs(doc["open_fraction"] - 95 / 441) < 1e-12
    rep, turned = doc["upc"]["repeated"], doc["upc"]["turned"]
    # a turned tiling lifts the ring minima of a slit framed at the edge (measured 0.10 against 0.01)
    assert all(t > 5 * r for t, r in zip(turned["mean_of_ring_minima"], rep["mean_of_ring_minima"]))
    assert all(len(c) == 147 for c in rep["ring_minima"])
    assert all(p > 0 for p in doc["restorability"]["turned"]["wiener_psnr_db"])
    assert "| UPC-compatible | turned |" in (out / "study_layout.md").read_text()
    # UPC's crop keeps all of blue's light (their 470 nm grid is the crop) and less of red's
    assert abs(turned["kept"][2] - 1) < 1e-9 and 0 < turned["kept"][0] < turned["kept"][1] <= 1
    assert "1174² crop" in (out / "study_layout.md").read_text()
    # the banding at d = 2 mm: a vertical slit bands along x far more than along y (measured 4.7–5.0e-3
    # against 0.85–0.94e-3)
    band = doc["banding"]
    assert band["distance_mm"] == 2.0 and all(x > 2 * y for x, y in zip(band["amplitude_x"], band["amplitude_y"]))
    assert "## Banding at d = 2 mm" in (out / "study_layout.md").read_text()
    assert (out / "study_layout_mtf.png").stat().st_size > 0 and (out / "study_layout_rings.png").stat().st_size > 0


@pytest.mark.parametrize("argv, says", [
    (["--display", "glass"], "glass has no pixel layout"),
    (["--display", "missing.png"], "no such file"),
    (["--distance-mm", "0"], "--distance-mm"),
    (["--train-seed", "1"], "only `study layout-trained` trains"),
    (["--train-epochs", "240"], "only `study layout-trained` trains"),
    (["--pitch-um", "3.1"], "--pitch-um 3.1: only `study layout-trained` takes a sensor pitch"),
])
def test_study_layout_refuses_in_one_line(tmp_path, capsys, argv, says):
    out = tmp_path / "never"
    assert cli.main(["study", "layout", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1 and not out.exists()


def test_a_non_square_micrograph_is_refused(tmp_path, capsys):
    iio.imwrite(tmp_path / "wide.png", np.full((10, 20), 255, np.uint8))
    assert cli.main(["study", "layout", "--display", str(tmp_path / "wide.png"), "--quick",
                     "--out", str(tmp_path / "o")]) == 2
    assert "square tile" in capsys.readouterr().err and not (tmp_path / "o").exists()


def _rgb(values, fmt: str, strip: bool = False) -> str:
    return " / ".join(format(v, fmt).lstrip("0") if strip else format(v, fmt) for v in values)


@pytest.mark.parametrize("first, folder, tiling", [
    ("designed (19.95 %), turned", "study_design", "turned"),
    ("designed (19.95 %), repeated", "study_design", "repeated"),
    ("T-OLED 20 %, turned, slit at the edge", "study_toled168_20_edge", "turned"),
    ("T-OLED 20 %, repeated", "study_toled168_20_edge", "repeated"),
    ("P-OLED 20 %, turned", "study_poled_20", "turned"),
    ("P-OLED 20 %, repeated", "study_poled_20", "repeated"),
])
def test_the_design_guide_prints_the_committed_runs_numbers(first, folder, tiling):
    """docs/guides/design.md's comparison table is the committed JSONs' (the banding: the repeated tiling's)."""
    root = Path(__file__).resolve().parents[2]
    text = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8")
    rows = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| ")}
    doc = json.loads((root / "docs" / "figures" / "design" / folder / "study_layout.json").read_text())
    r = doc["restorability"][tiling]
    numbers = [_rgb(doc["upc"][tiling]["mean_of_ring_minima"], ".3f", True),
               _rgb(doc["exact"][tiling]["mean_of_ring_minima"], ".3f", True),
               _rgb(r["wiener_psnr_db"], ".1f"), _rgb(r["window"]["wiener_psnr_db"], ".1f")]
    banding = _rgb([v * 1e3 for v in doc["banding"]["strongest"]], ".2f")
    numbers.append(banding if tiling == "repeated" else "no period")
    assert all(n in rows[first] for n in numbers), (rows[first], numbers)
    assert abs(doc["open_fraction"] - 0.2) < 1 / 441


def test_the_design_guide_prints_the_committed_designs_margin_over_the_scatters():
    """docs/guides/design.md's designed-against-scatters paragraph is the committed design.json's."""
    root = Path(__file__).resolve().parents[2]
    text = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    doc = json.loads((root / "docs" / "figures" / "design" / "design" / "design.json").read_text())
    base, upc = doc["scatters"], doc["upc"]["turned"]
    assert base["n"] == 20 and doc["converged"] and doc["steps_done"] == 56
    for phrase in (f"design scores {doc['final']['psnr_db']:.2f} dB",
                   f"score {base['mean']:.2f} ± {base['std']:.2f} dB",
                   f"best of them {base['best']:.2f} dB", f"design is {base['margin']:.2f} dB, "
                   f"{base['margin'] / base['std']:.0f} sd", _rgb(upc["design"], ".3f", True),
                   _rgb(upc["ratio"], ".2f") + " ×"):
        assert phrase in text, phrase
    assert base["margin"] > 5 * base["std"]  # the design beats the best scatter well outside the scatters' spread


@pytest.mark.parametrize("folder, row, swaps", [
    ("design_upc_B", "UPC's crop: searched for blue's ring minima, from a scatter", 23),
    ("design_upc_B_toled", "UPC's crop: searched for blue's ring minima, from the T-OLED", 51),
])
def test_the_design_guide_prints_the_committed_blue_searches(folder, row, swaps):
    """docs/guides/design.md's blue searches (`--optics upc --objective rings --channels B`) are the committed
    design.json's: the table's shares, ring means and minima, the ratio to the T-OLED of the same run, the swaps."""
    root = Path(__file__).resolve().parents[2]
    text = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8")
    rows = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| ")}
    doc = json.loads((root / "docs" / "figures" / "design" / folder / "design.json").read_text())
    cfg, upc = doc["config"], doc["upc"]["turned"]
    assert (cfg["optics"], cfg["objective"], cfg["channels"]) == ("upc", "rings", "B") and doc["converged"]
    assert doc["steps_done"] == swaps and abs(np.exp(-doc["final"]["objective"]) / upc["design"][2] - 1) < 0.01
    kept = " / ".join(f"{v:.3f}".lstrip("0") for v in upc["kept"]["design"][:2]) + " / 1"
    for number in (kept, _rgb(upc["ring_means"]["design"], ".3f", True), _rgb(upc["design"], ".3f", True)):
        assert number in rows[row], (rows[row], number)
    flat = " ".join(text.split())
    held_out = f"{np.exp(-doc['final']['objective']):.3f}".lstrip("0")
    assert f"**{upc['ratio'][2]:.2f} ×**" in flat and f"({held_out} after {swaps} swaps" in flat


@pytest.mark.parametrize("folder, row", [
    ("study_toled168_20_edge", "UPC's crop: T-OLED 20 %, slit at the edge"),
    ("study_design", "UPC's crop: designed for `wiener`"),
    ("crop_studies/design", "UPC's crop: designed for `crop`"),
])
def test_the_design_guide_prints_the_committed_shares_kept_by_upcs_crop(folder, row):
    """docs/guides/design.md's table of UPC's crop: the committed `study layout` JSONs' turned rows."""
    root = Path(__file__).resolve().parents[2]
    text = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8")
    rows = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| ")}
    t = json.loads((root / "docs" / "figures" / "design" / folder / "study_layout.json").read_text())["upc"]["turned"]
    assert abs(t["kept"][2] - 1) < 1e-9
    kept = " / ".join(f"{v:.3f}".lstrip("0") for v in t["kept"][:2]) + " / 1"
    for number in (kept, _rgb(t["mean_of_ring_means"], ".3f", True), _rgb(t["mean_of_ring_minima"], ".3f", True)):
        assert number in rows[row], (rows[row], number)


def test_the_design_guide_prints_the_committed_upc_loss_run():
    """docs/guides/design.md's run of UPC's loss in their optics is the committed design.json's."""
    root = Path(__file__).resolve().parents[2]
    text = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    doc = json.loads((root / "docs" / "figures" / "design" / "design_upc_loss" / "design.json").read_text())
    upc = doc["upc"]["turned"]
    assert (doc["config"]["optics"], doc["config"]["objective"]) == ("upc", "upc") and doc["converged"]
    assert f"converged after {doc['steps_done']} swaps at **{_rgb(upc['ratio'], '.2f')} ×**" in text
    assert f"keeping {' / '.join(f'{v:.3f}'.lstrip('0') for v in upc['kept']['design'][:2])} / 1" in text


@pytest.mark.parametrize("seed, folder", [(0, "layout_trained_e240"), (1, "layout_trained_e240_seed1"),
                                          (2, "layout_trained_e240_seed2")])
def test_the_design_guide_prints_the_committed_240_epoch_margins(seed, folder):
    """docs/guides/design.md's UNet margins at 240 epochs are the committed runs' (design − turned T-OLED, paired)."""
    root = Path(__file__).resolve().parents[2]
    text = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    doc = json.loads((root / "docs" / "figures" / "design" / folder / "study_layout_trained.json").read_text())
    assert doc["seeds"]["train"] == seed and doc["budget"]["epochs"] == 240
    p = doc["paired"]["design_turned"]["unet"]
    margin = f"{p['mean_db']:+.2f} ± {p['se_db']:.2f} dB (seed {seed}, {p['wins']} of {p['n']})"
    assert margin.replace("-", "−") in text, margin


def test_the_design_guide_prints_the_committed_veil_design():
    """docs/guides/design.md's design with --far-veil: its run, its UPC ratios, and its paired margins through the
    simulator are the committed JSONs'."""
    root = Path(__file__).resolve().parents[2]
    text = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    figures = root / "docs" / "figures" / "design"
    design = json.loads((figures / "design_veil" / "design.json").read_text())
    assert design["config"]["far_veil"] and design["converged"]
    assert f"converged after {design['steps_done']} swaps and {design['evaluations']} exact scores" in text
    assert f"{_rgb(design['upc']['turned']['ratio'], '.2f')} × the T-OLED in UPC's mode" in text
    study = json.loads((figures / "layout_trained_veil" / "study_layout_trained.json").read_text())
    row = next(r for r in study["rows"] if r["layout"] == "design_turned")
    paired = study["paired"]["design_turned"]
    for key in ("dep", "dep_far", "unet"):
        p = paired[key]
        assert f"{p['mean_db']:+.2f} ± {p['se_db']:.2f} dB ({p['wins']} of {p['n']})" in text, key
    assert f"| {row['psnr_input_db']:.2f} | **{row['psnr_dep_db']:.2f}** | {row['psnr_dep_nofar_db']:.2f} |" in text


def test_the_design_guide_prints_the_veil_designs_unet_seeds():
    """The veil design's UNet margins per training seed (80 epochs) and their mean are the committed runs'."""
    root = Path(__file__).resolve().parents[2]
    text = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    margins = []
    for seed, folder in enumerate(sorted((root / "docs" / "figures" / "design").glob("layout_trained_veil*"))):
        doc = json.loads((folder / "study_layout_trained.json").read_text())
        assert doc["seeds"]["train"] == seed and doc["budget"]["epochs"] == 80
        p = doc["paired"]["design_turned"]["unet"]
        assert f"{p['mean_db']:+.2f} ± {p['se_db']:.2f} dB ({p['wins']} of {p['n']})" in text
        margins.append(p["mean_db"])
    se = np.std(margins, ddof=1) / np.sqrt(len(margins))
    assert f"{np.mean(margins):+.2f} ± {se:.2f} dB over the {['two', 'three', 'four'][len(margins) - 2]} seeds" in text


def test_the_design_guide_prints_the_veil_designs_240_epochs():
    """The veil design's UNet at 240 epochs (seed 0): margin, scores and the gap to DeP are the committed run's;
    the turned T-OLED scores as in the `crop` design's 240-epoch run."""
    root = Path(__file__).resolve().parents[2]
    text = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    figures = root / "docs" / "figures" / "design"
    doc = json.loads((figures / "layout_trained_e240_veil" / "study_layout_trained.json").read_text())
    crop = json.loads((figures / "layout_trained_e240" / "study_layout_trained.json").read_text())
    assert doc["seeds"]["train"] == 0 and doc["budget"]["epochs"] == 240
    rows = {r["layout"]: r for r in doc["rows"]}
    ref = rows["toled168_20_edge_turned"]
    p = doc["paired"]["design_turned"]["unet"]
    assert (f"{rows['design_turned']['psnr_unet_db']:.2f} dB against the turned T-OLED's {ref['psnr_unet_db']:.2f} dB, "
            f"**+{p['mean_db']:.2f} ± {p['se_db']:.2f} dB ({p['wins']} of {p['n']})**") in text
    other = {r["layout"]: r for r in crop["rows"]}["toled168_20_edge_turned"]["psnr_unet_db"]
    assert f"{other:.2f}" == f"{ref['psnr_unet_db']:.2f}"
    assert f"still {ref['psnr_dep_db'] - ref['psnr_unet_db']:.2f} dB below DeP" in text


def test_the_design_guide_prints_the_floored_designs():
    """docs/guides/design.md's `--upc-floor` runs: the table's objective, UPC ratios, draws, shares and the ratio
    normalised before the crop are the committed design.json's; the simulator's margins and the banding ratio are
    the committed studies'."""
    root = Path(__file__).resolve().parents[2]
    text = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    lines = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").splitlines()
    figures = root / "docs" / "figures" / "design"
    for folder in sorted((figures / "floor").iterdir()):
        doc = json.loads((folder / "design.json").read_text())
        t = doc["upc"]["turned"]
        uncropped = np.multiply(t["ratio"], np.divide(t["kept"]["design"], t["kept"]["toled_edge"]))
        assert np.allclose(uncropped, t["ratio_uncropped"], rtol=1e-12)
        floor = UpcFloor(doc["config"]["upc_floor"], doc["config"]["floor_channels"], 21, 168.0, 0.2,
                         doc["config"]["seed"], True, doc["config"]["floor_uncropped"])
        cell = np.asarray(iio.imread(folder / "cell.png")) / 255.0
        with torch.no_grad():
            held = float(floor.ratios(torch.tensor(cell), "search")[0]) / doc["config"]["upc_floor"] - 1
        if doc["config"]["floor_uncropped"]:
            assert held < -0.01  # the uncropped floor was not reached
            assert f"green {uncropped[1]:.2f} × normalised before the crop ({t['ratio'][1]:.2f} × as UPC" in text
            continue
        assert held > -6e-4, (folder.name, held)  # at the floor or above, none more than 0.06 % below
        d = t["draws"]
        row = (f"| `{folder.name}` | {doc['initial']['squares_moved']} / {doc['steps_done']} | "
               f"{doc['final']['psnr_db']:.2f} | {_rgb(t['ratio'], '.2f')} | {d['mean'][1]:.3f} ± {d['sd'][1]:.3f} "
               f"(min {d['min'][1]:.3f}) | {t['kept']['design'][0]:.3f} / {t['kept']['design'][1]:.3f} | "
               f"{uncropped[1]:.2f} |")
        printed = next(line for line in lines if line.startswith(f"| `{folder.name}` |"))
        assert all(f" {c.strip('| ')} |" in printed for c in row.split(" | ")[1:]), (folder.name, row)
    starts = {name: json.loads((figures / "floor" / name / "design.json").read_text())["initial"]["psnr_db"]
              for name in ("crop130", "toled130")}
    assert (f"The `crop` design scores {starts['crop130']:.2f} dB in this objective, the turned T-OLED "
            f"{starts['toled130']:.2f} dB") in text
    study = json.loads((figures / "layout_trained_floor" / "study_layout_trained.json").read_text())
    for key in ("dep", "dep_far", "unet"):
        p = study["paired"]["design_turned"][key]
        assert f"{p['mean_db']:+.2f} ± {p['se_db']:.2f} dB ({p['wins']} of {p['n']})".replace("-", "−") in text, key
    margins = []
    for seed, folder in enumerate(sorted(figures.glob("layout_trained_floor*"))):
        doc = json.loads((folder / "study_layout_trained.json").read_text())
        assert doc["seeds"]["train"] == seed and doc["budget"]["epochs"] == 80
        p = doc["paired"]["design_turned"]["unet"]
        margin = f"{p['mean_db']:+.2f} ± {p['se_db']:.2f} dB (seed {seed}, {p['wins']} of {p['n']}"
        assert margin.replace("-", "−") in text, margin
        margins.append(p["mean_db"])
    se = np.std(margins, ddof=1) / np.sqrt(len(margins))
    assert f"{np.mean(margins):+.2f} ± {se:.2f} dB over the three seeds" in text
    floor = json.loads((figures / "study_floor_veil130" / "study_layout.json").read_text())["banding"]["sampled"]
    toled = json.loads((figures / "study_toled168_20_edge" / "study_layout.json").read_text())["banding"]["sampled"]
    ratio = np.divide(floor["turned"]["rms"], toled["turned"]["rms"])
    assert f"{ratio.min():.3f}–{ratio.max():.3f} × the turned T-OLED's" in text


def _turned_sd(md: Path) -> list[float]:
    """The turned tiling's sampled sd per wavelength from a `study layout` report's "Both tilings" table."""
    part = md.read_text(encoding="utf-8").split("Both tilings")[1]
    return [float(m.group(1)) for m in re.finditer(r"^\| \d+ \| [^|]+\| [0-9.e+-]+, ([0-9.e+-]+) \|", part, re.M)]


def test_the_design_guide_prints_the_banding_over_five_draws():
    """The banding table over D4 draws 0–4: each draw's report (tile seed and framing as named), the sd ratios to
    the turned T-OLED's on the same draw, their mean ± se and the count below 1."""
    root = Path(__file__).resolve().parents[2]
    lines = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").splitlines()
    figures = root / "docs" / "figures" / "design"
    draw0 = {"toled": "study_toled168_20_edge", "veil": "study_design_veil", "veil130": "study_floor_veil130"}

    def reports(name: str) -> list[Path]:
        first = figures / draw0[name] if name in draw0 else figures / "banding_draws" / f"{name}_s0"
        return [first / "study_layout.md"] + [figures / "banding_draws" / f"{name}_s{k}" / "study_layout.md"
                                               for k in (1, 2, 3, 4)]

    for k, md in enumerate(reports("toled")):
        assert f"turned tilings: seed {k} " in md.read_text() and "cell framing: edge" in md.read_text()
    toled = np.array([_turned_sd(md) for md in reports("toled")])
    for name, label in (("crop", "`crop` design"), ("veil", "veil design"), ("veil130", "`veil130`")):
        q = (np.array([_turned_sd(md) for md in reports(name)]) / toled).mean(axis=1)
        row = (f"| {label} | {' / '.join(f'{v:.2f}' for v in q)} | {q.mean():.2f} ± {q.std(ddof=1) / np.sqrt(5):.2f} "
               f"| {(q < 1).sum()} of 5 |")
        assert row in lines, row


def test_the_design_guide_prints_the_dipole_study_and_the_ceiling_runs():
    """The dipole section: the study's rows, fit and extremes are the committed JSON's; the designs' centroid offsets
    are their cell.png's, the predictions the fit's; the ceiling runs' table is their design.json's (the bands on
    draws 0–4: per draw the mean over R, G, B of the ratio to the T-OLED), the veil design's and `veil130`'s the
    committed `study layout` reports'."""
    from udc_render.studies.layout_dipole import centroid_um
    root = Path(__file__).resolve().parents[2]
    raw = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8")
    text, lines = " ".join(raw.split()), raw.splitlines()
    figures = root / "docs" / "figures" / "design"
    study = json.loads((figures / "dipole" / "study_layout_dipole.json").read_text())
    rows = {r["roll"]: r for r in study["rows"]}
    labels = {0: "0 (at the tile's edge)", 8: "8 (centred)"}
    for k in (0, 2, 4, 6, 8):
        r = rows[k]
        row = (f"| {labels.get(k, k)} | {r['centroid_um']:.1f} | {1e3 * r['bands_turned'][1]:.2f} | "
               f"{1e3 * r['bands_repeated'][1]:.2f} | {r['upc_ratio'][1]:.3f} | {r['veil_psnr_db']:.2f} | "
               f"{r['veil_psnr_repeated_db']:.2f} |")
        assert row in lines, row
    fit = study["fit"]
    assert (f"to within {100 * fit['max_rel_misfit_sd']:.1f} % of sd (sd_0 = {1e3 * fit['sd0']:.2f} × 10⁻³, "
            f"κ = {1e9 * fit['kappa_per_um2']:.2f} × 10⁻⁹ per µm²)") in text
    for r in study["rows"]:  # "at 16 µm and below ... less than the repeated one (at 24 µm and above, more)"
        if r["centroid_um"] < 17 or r["centroid_um"] > 24:
            assert (r["bands_turned"][1] < r["bands_repeated"][1]) == (r["centroid_um"] < 17), r["roll"]
    repeated = [1e3 * r["bands_repeated"][1] for r in study["rows"]]
    assert f"({min(repeated):.2f}–{max(repeated):.2f} × 10⁻³)" in text
    centred, edge = rows[8], rows[0]
    assert (f"Centred, it bands {1e3 * centred['bands_turned'][1]:.2f} × 10⁻³ against the repeated "
            f"{1e3 * centred['bands_repeated'][1]:.2f} × 10⁻³") in text
    assert (f"({centred['veil_psnr_db']:.2f} against {edge['veil_psnr_db']:.2f} dB) and two thirds of UPC's ratio "
            f"({centred['upc_ratio'][1]:.2f} ×)") in text
    toled = np.array([_turned_sd(figures / f) for f in ["study_toled168_20_edge/study_layout.md"] + [
        f"banding_draws/toled_s{k}/study_layout.md" for k in (1, 2, 3, 4)]])

    def measured(first: str, name: str) -> np.ndarray:
        mds = [figures / first / "study_layout.md"] + [figures / "banding_draws" / f"{name}_s{k}" / "study_layout.md"
                                                        for k in (1, 2, 3, 4)]
        return (np.array([_turned_sd(md) for md in mds]) / toled).mean(axis=1)

    ceilings = {"veil_b90": 0.9, "veil130_b90": 0.9, "veil_b55": 0.55}
    ceiling = {name: json.loads((figures / "ceiling" / name / "design.json").read_text()) for name in ceilings}
    per_draw = {"crop": measured("banding_draws/crop_s0", "crop"), "veil": measured("study_design_veil", "veil"),
                "veil130": measured("study_floor_veil130", "veil130"),
                **{n: np.mean(d["banding"]["ratio"], axis=1) for n, d in ceiling.items()}}
    cells = {"crop": "design_crop", "veil": "design_veil", "veil130": "floor/veil130", "veil_b90": "ceiling/veil_b90",
             "veil130_b90": "ceiling/veil130_b90", "veil_b55": "ceiling/veil_b55"}
    mu = {n: centroid_um(np.asarray(iio.imread(figures / c / "cell.png")) / 255.0) for n, c in cells.items()}
    law = {n: np.sqrt((fit["a"] + fit["kappa_per_um2"] * m ** 2) / (fit["a"] + fit["kappa_per_um2"] * edge[
        "centroid_um"] ** 2)) for n, m in mu.items()}
    assert (f"{mu['crop']:.1f} µm (the `crop` design), {mu['veil']:.1f} µm (the veil design), {mu['veil130']:.1f} µm "
            f"(`veil130`), {mu['veil_b90']:.1f} µm (`veil_b90`, below), {mu['veil130_b90']:.1f} µm (`veil130_b90`, "
            f"below) and {mu['veil_b55']:.1f} µm (`veil_b55`, below)") in text
    assert f"predicts bands of {' / '.join(f'{law[n]:.2f}' for n in cells)} × the edge-framed T-OLED" in text
    assert f"they are {' / '.join(f'{per_draw[n].mean():.2f}' for n in cells)} ×" in text
    for name, d in ceiling.items():
        dr, q = d["upc"]["turned"]["draws"], per_draw[name]
        assert d["banding"]["seeds"] == [0, 1, 2, 3, 4] and d["config"]["banding_ceiling"] == ceilings[name]
        row = (f"| {d['initial']['squares_moved']} | {d['final']['psnr_db']:.2f} | {dr['mean'][1]:.3f} ± "
               f"{dr['sd'][1]:.3f} (min {dr['min'][1]:.3f}) | {' / '.join(f'{v:.2f}' for v in q)} | {q.mean():.2f} | "
               f"{(q < 1).sum()} of 5 |")
        printed = next(line for line in lines if line.startswith(f"| `{name}` |"))
        assert printed.endswith(row), (printed, row)
        assert " / ".join(f"{v:.2f}" for v in d["final"]["banding_ratios"]) in text
    for name in ("veil", "veil130"):
        q = per_draw[name]
        assert f"| {' / '.join(f'{v:.2f}' for v in q)} | {q.mean():.2f} | {(q < 1).sum()} of 5 |" in raw
    b55 = ceiling["veil_b55"]
    repeated_sd = float(re.search(r"^\| 520 \| [0-9.e+-]+, ([0-9.e+-]+) \|", (figures / "study_toled168_20_edge" /
                                  "study_layout.md").read_text().split("Both tilings")[1], re.M).group(1))
    sd = np.array(b55["banding"]["sd"]["design"])[:, 1]
    share = repeated_sd / toled[:, 1]
    objective = b55["final"]["psnr_db"]
    assert (f"The repeated T-OLED's bands ({1e3 * repeated_sd:.2f} × 10⁻³ in green) are {share.min():.2f}–"
            f"{share.max():.2f} × the turned T-OLED's over draws 0–4") in text
    assert (f"moved {b55['initial']['squares_moved']} squares, its centroid from {mu['veil']:.1f} to "
            f"{mu['veil_b55']:.1f} µm") in text
    assert (f"bands {1e3 * np.sqrt(np.mean(sd ** 2)):.2f} × 10⁻³ in green (root mean square; {1e3 * sd.min():.2f}–"
            f"{1e3 * sd.max():.2f} per draw), level with the repeated T-OLED (below it on {(sd < repeated_sd).sum()} "
            "of 5 draws)") in text
    assert (f"Its objective is {objective:.2f} dB: {edge['veil_psnr_db'] - objective:.2f} dB below the turned T-OLED, "
            f"{objective - rows[4]['veil_psnr_db']:.2f} dB above the T-OLED with its slit at the same centroid "
            f"({rows[4]['veil_psnr_db']:.2f} dB, the table above), and {objective - edge['veil_psnr_repeated_db']:.1f} "
            f"dB above the repeated T-OLED ({edge['veil_psnr_repeated_db']:.2f} dB") in text
    assert f"{rows[4]['centroid_um']:.1f}" == f"{mu['veil_b55']:.1f}"  # "the same centroid": as printed, 0.1 µm
    assert f"UPC's green falls to {b55['upc']['turned']['draws']['mean'][1]:.2f} ×" in text
    trained = json.loads((figures / "layout_trained_ceiling" / "study_layout_trained.json").read_text())
    assert trained["seeds"]["train"] == 0 and trained["budget"]["epochs"] == 80
    margins = [f"{p['mean_db']:+.2f} ± {p['se_db']:.2f} dB".replace("-", "−") for p in
               (trained["paired"]["design_turned"][k] for k in ("dep", "dep_far", "unet"))]
    wins = [trained["paired"]["design_turned"][k]["wins"] for k in ("dep", "dep_far", "unet")]
    assert (f"plain DeP {margins[0]} ({wins[0]} of 8), DeP given the far field {margins[1]} ({wins[1]} of 8), the UNet "
            f"{margins[2]} ({wins[2]} of 8)") in text
    assert (f"plain DeP {margins[0]} (0 of 8), DeP given the far field {margins[1]}, the UNet {margins[2]} "
            "(one seed)") in text
    assert f"which bands {1 / share.max():.1f}–{1 / share.min():.1f} × as much" in text
    b55_trained = json.loads((figures / "layout_trained_b55" / "study_layout_trained.json").read_text())
    per = {r["layout"]: r["per_image_db"] for r in b55_trained["rows"]}
    for key in ("dep", "dep_far", "unet"):
        diff = np.subtract(per["design_turned"][key], per["toled168_20_edge"][key])
        p = b55_trained["paired"]["design_turned"][key]
        assert (diff > 0).all() and p["wins"] == 0
        assert f"{diff.mean():+.2f} ± {diff.std(ddof=1) / np.sqrt(len(diff)):.2f} dB" in text, key
        assert f"{p['mean_db']:+.2f} ± {p['se_db']:.2f} dB".replace("-", "−") in text, key
    both = ceiling["veil130_b90"]["final"]["psnr_db"]
    assert (f"both at {both:.2f} dB (`veil130_b90`), {edge['veil_psnr_db'] - both:.2f} dB below the turned T-OLED's "
            f"{edge['veil_psnr_db']:.2f} dB") in text


def test_the_design_guide_prints_the_ceilings_draws():
    """Part (e) of the committed `study design`: the guide's table and the defaults' row are its JSON's."""
    root = Path(__file__).resolve().parents[2]
    lines = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").splitlines()
    defaults = " ".join((root / "docs" / "concepts" / "defaults.md").read_text(encoding="utf-8").split())
    study = root / "docs" / "figures" / "design" / "study_knobs" / "study_design.json"
    rows = json.loads(study.read_text())["ceiling"]

    def pct(v: float) -> str:
        return f"{float(f'{100 * v:.2g}'):g} %"
    for r in rows:
        row = (f"| {r['draws']}{', the default' if r['draws'] == 8 else ''} | {pct(r['error_toled_rel'])} | "
               f"{pct(r['error_scatter_rel'])} | {pct(r['error_ratio_rel'])} | {r['cpu_s']:.2f} |")
        assert row in lines, row
    ratio = " / ".join(pct(r["error_ratio_rel"])[:-2] for r in rows)
    assert f"the ratio's error {ratio} % at 1 / 2 / 4 / 8 / 16 draws" in defaults


def test_the_design_guide_prints_the_kicks():
    """Part (f) of the committed `study design`: the guide's table is its JSON's gains over the 0-kick row, and the
    defaults' row its largest held-out gain."""
    root = Path(__file__).resolve().parents[2]
    lines = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").splitlines()
    defaults = " ".join((root / "docs" / "concepts" / "defaults.md").read_text(encoding="utf-8").split())
    rows = json.loads((root / "docs" / "figures" / "design" / "study_knobs" / "study_design.json").read_text())["kicks"]
    gains = []
    for swaps in (2, 4, 8):
        these = [r for r in rows if r["kick_swaps"] == swaps]
        base = these[0]
        assert [r["kicks"] for r in these] == [0, 1, 2, 4, 8, 16]
        held = " / ".join(f"{r['psnr_db'] - base['psnr_db']:+.3f}" for r in these[1:])
        search = " / ".join(f"{r['search_psnr_db'] - base['search_psnr_db']:+.3f}" for r in these[1:])
        row = (f"| {swaps}{', the default' if swaps == 4 else ''} | {held} | {search} | {these[-1]['cpu_s']:.0f} "
               f"({base['cpu_s']:.0f}) |")
        assert row in lines, row
        gains += [r["psnr_db"] - base["psnr_db"] for r in these]
    assert f"16 kicks gain at most {max(gains):.3f} dB" in " ".join(lines)
    assert f"at most {max(gains):.3f} dB held out" in defaults


def test_the_design_guide_prints_the_kicked_designs():
    """The guide's kicks table and its claims are the committed design.json's: each row's squares, scores,
    objective, UPC's draws and bands; the kicked runs keep veil130_b90's settings but the kicks, and never end below
    it; k16 is above the turned T-OLED's objective (the dipole study's edge row)."""
    root = Path(__file__).resolve().parents[2]
    figures = root / "docs" / "figures" / "design"
    text = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8")
    lines, flat = text.splitlines(), " ".join(text.split())
    base = json.loads((figures / "ceiling" / "veil130_b90" / "design.json").read_text())
    edge = json.loads((figures / "dipole" / "study_layout_dipole.json").read_text())["rows"][0]
    runs = {"`veil130_b90` (no kicks)": base}
    for name in ("k8_swaps8", "k8", "k16", "k8_then_swaps3"):
        d = json.loads((figures / "kicks" / name / "design.json").read_text())
        assert {k: v for k, v in d["config"].items() if k not in ("kicks", "kick_swaps", "init", "steps")} == {
            k: v for k, v in base["config"].items() if k not in ("init", "steps")}
        assert d["kicks_done"] == d["config"]["kicks"] and d["converged"]
        assert d["final"]["psnr_db"] > base["final"]["psnr_db"]
        runs[f"`{name}`{' (from `k8`)' if name == 'k8_then_swaps3' else ''}"] = d
    for name, d in runs.items():
        dr, q = d["upc"]["turned"]["draws"], np.mean(d["banding"]["ratio"], axis=1)
        kicks = f"{d['config']['kicks']} × {d['config']['kick_swaps']}" if d["config"].get("kicks") else "—"
        row = (f"| {name} | {kicks} | {d['initial']['squares_moved']} | {d['evaluations']} | "
               f"{d['final']['psnr_db']:.2f} | {dr['mean'][1]:.3f} ± {dr['sd'][1]:.3f} (min {dr['min'][1]:.3f}) | "
               f"{' / '.join(f'{v:.2f}' for v in q)} | {q.mean():.2f} | {(q < 1).sum()} of 5 |")
        assert row in lines, row
    k16 = runs["`k16`"]
    assert k16["final"]["psnr_db"] > edge["veil_psnr_db"]
    assert (f"from {base['final']['psnr_db']:.2f} to {k16['final']['psnr_db']:.2f} dB held out, "
            f"{k16['final']['psnr_db'] - edge['veil_psnr_db']:.2f} dB above the turned T-OLED's "
            f"{edge['veil_psnr_db']:.2f} dB") in flat
    assert f"{k16['evaluations'] / base['evaluations']:.0f} × the exact scores of the first optimum" in flat
    defaults = " ".join((root / "docs" / "concepts" / "defaults.md").read_text(encoding="utf-8").split())
    gain = k16["final"]["psnr_db"] - base["final"]["psnr_db"]
    assert (f"16 kicks of 4 swaps gained {gain:.2f} dB held out ({base['final']['psnr_db']:.2f} to "
            f"{k16['final']['psnr_db']:.2f} dB, past the turned T-OLED's {edge['veil_psnr_db']:.2f}") in defaults
    eight = runs["`k8`"]["final"]["psnr_db"] - runs["`k8_swaps8`"]["final"]["psnr_db"]
    assert f"8 kicks of 4 swaps ended {eight:.2f} dB above 8 kicks of 8 (held out)" in defaults
    cells = [np.asarray(iio.imread(figures / "kicks" / n / "cell.png")) for n in ("k16", "k8_then_swaps3")]
    assert f"another cell, {np.sum(cells[0] != cells[1]) // 2} squares apart" in flat


def test_the_design_guide_prints_the_kicked_design_through_the_simulator():
    """The guide's table of k16 and veil130_b90 against the turned T-OLED through `study layout-trained` is the
    committed JSON's (seed 0, 80 epochs, the same display files), and its stated changes are their differences."""
    root = Path(__file__).resolve().parents[2]
    figures = root / "docs" / "figures" / "design"
    text = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8")
    lines, flat = text.splitlines(), " ".join(text.split())
    runs = {name: json.loads((figures / folder / "study_layout_trained.json").read_text())
            for name, folder in (("base", "layout_trained_ceiling"), ("k16", "layout_trained_kicks"))}
    for d in runs.values():
        assert d["seeds"]["train"] == 0 and d["budget"]["epochs"] == 80
    paired = {n: d["paired"]["design_turned"] for n, d in runs.items()}

    def cell(p: dict) -> str:
        return f"{p['mean_db']:+.2f} ± {p['se_db']:.2f} dB ({p['wins']} of 8)".replace("-", "−")
    for key, label in (("dep", "plain DeP"), ("dep_far", "DeP given the far field"), ("unet", "UNet")):
        row = f"| {label} | {cell(paired['base'][key])} | {cell(paired['k16'][key])} |"
        assert row in lines, row
    change = {k: paired["k16"][k]["mean_db"] - paired["base"][k]["mean_db"] for k in ("dep", "dep_far", "unet")}
    assert f"plain DeP by {change['dep']:+.2f} dB" in flat
    assert f"lost {-change['dep_far']:.2f} dB each" in flat and f"{-change['unet']:.2f}" == f"{-change['dep_far']:.2f}"
    seed1 = json.loads((figures / "layout_trained_kicks_seed1" / "study_layout_trained.json").read_text())
    assert seed1["seeds"]["train"] == 1 and seed1["budget"]["epochs"] == 80
    unet = [paired["k16"]["unet"], seed1["paired"]["design_turned"]["unet"]]
    assert f"UNet at {cell(unet[1])}" in flat
    assert f"(mean {np.mean([u['mean_db'] for u in unet]):+.2f} dB)".replace("-", "−") in flat
    assert (f"the UNet is level ({unet[0]['mean_db']:+.2f} and {unet[1]['mean_db']:+.2f} dB, two seeds)".replace(
        "-", "−") in flat)


HELD_OUT_DEP = {"design_veil": "layout_trained_veil", "ceiling/veil128_b100": "layout_trained_f128",
                "floor/veil130": "layout_trained_floor",
                "kicks/k16": "layout_trained_kicks", "ceiling/veil130_b90": "layout_trained_ceiling",
                "ceiling/veil_b55": "layout_trained_b55", "design_crop": "layout_trained_e240"}


def _held_out_doc(root: Path) -> dict:
    return json.loads((root / "docs" / "figures" / "design" / "held_out" / "study_held_out.json").read_text())


def test_the_design_guide_prints_the_held_out_designs():
    """The guide's held-out table is the committed `study held-out` JSON (16 draws, the veil objective) beside each
    design's plain-DeP margin over the turned T-OLED from its committed `study layout-trained` (seed 0; the spec the
    design's design_turned.toml); the designs through the simulator rank alike by both, with the same signs but
    veil128_b100's (one wavelength per channel: test_the_design_guide_prints_the_channel_step)."""
    root = Path(__file__).resolve().parents[2]
    figures = root / "docs" / "figures" / "design"
    doc = _held_out_doc(root)
    assert doc["tilings"] == 16 and doc["toleds"]["objective"]["far_veil"] and doc["toleds"]["objective"][
        "objective"] == "crop"
    lines = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").splitlines()
    both = []
    for r in doc["rows"]:
        name = r["design"].removeprefix("docs/figures/design/")
        dep = "—"
        if name in HELD_OUT_DEP:
            t = json.loads((figures / HELD_OUT_DEP[name] / "study_layout_trained.json").read_text())
            spec = [s for s in t["specs"] if s.endswith("design_turned.toml")]
            assert t["seeds"]["train"] == 0 and len(spec) == 1
            assert t["specs"][0].endswith("toled168_20.toml@edge@turned")
            p = t["paired"]["design_turned"]["dep"]
            dep = f"{p['mean_db']:+.2f} ± {p['se_db']:.2f}".replace("-", "−")
            both.append((name, r["d4_toled_preset"], p["mean_db"]))

        def pm(key: str) -> str:
            return f"{r[key]:+.3f} ± {r[key + '_se']:.3f} ({r[key + '_leads']})".replace("-", "−")
        u = json.loads((figures / name / "design.json").read_text())["upc"]["turned"]
        g = f"{u['draws']['mean'][1]:.3f}" if "draws" in u else f"{u['ratio'][1]:.3f} (one tiling)"
        row = (f"| `{name.split('/')[-1]}` | {g} | {r['psnr_db']:.3f} | {pm('d4_toled_preset')} | "
               f"{pm('d4_toled_squares')} | {dep} |")
        assert row in lines, row
    assert len(both) == 7
    objective, dep = (np.array([b[k] for b in both]) for k in (1, 2))
    assert list(np.argsort(objective)) == list(np.argsort(dep))
    assert [b[0] for b in both if np.sign(b[1]) != np.sign(b[2])] == ["ceiling/veil128_b100"]


def test_the_design_guide_prints_the_search_tilings():
    """Part (g) of the committed `study design`: the guide's table is its JSON's rows (M = 1, 2, 4, 8 on 16 held-out
    draws), and the claims are their gains, excess and CPU ratios."""
    root = Path(__file__).resolve().parents[2]
    text = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8")
    lines, flat = text.splitlines(), " ".join(text.split())
    rows = json.loads((root / "docs" / "figures" / "design" / "study_knobs" / "study_design.json").read_text())[
        "tilings"]
    assert [r["search_tilings"] for r in rows] == [1, 2, 4, 8] and len(rows[0]["held_draws_psnr_db"]) == 16
    for r in rows:
        row = (f"| {r['search_tilings']}{', the default' if r['search_tilings'] == 1 else ''} | {r['steps_done']} | "
               f"{r['held_psnr_db']:.3f} | {r['gain_db']:+.3f} ± {r['gain_se_db']:.3f} | "
               f"{r['search_psnr_db'] - r['held_psnr_db']:+.3f} | {r['cpu_s']:.0f} |").replace("-", "−")
        assert row in lines, row
    gains = " / ".join(f"{r['gain_db']:+.3f}" for r in rows[1:])
    cpu = " / ".join(f"{r['cpu_s'] / rows[0]['cpu_s']:.1f}" for r in rows[1:])
    excess = rows[0]["search_psnr_db"] - rows[0]["held_psnr_db"]
    assert f"fits its one draw by only {excess:.3f} dB, and M = 2 / 4 / 8 gain {gains} dB held out at {cpu} ×" in flat
    defaults = " ".join((root / "docs" / "concepts" / "defaults.md").read_text(encoding="utf-8").split())
    assert f"M = 2 / 4 / 8 gain {gains} dB held out at {cpu} × the CPU time" in defaults


def test_the_design_guide_states_the_held_out_claims():
    """The held-out section's sentences are the committed JSON's: the T-OLEDs' means and their gap, the veil design's
    and veil130's margins, the largest move on the quarter-turns (veil and crop designs; the wiener design apart)."""
    root = Path(__file__).resolve().parents[2]
    flat = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    doc = _held_out_doc(root)
    t, rows = doc["toleds"], {r["design"].split("/")[-1]: r for r in doc["rows"]}
    assert (f"scores {t['d4_toled_preset'] - t['d4_toled_squares']:.3f} dB above the one on the squares "
            f"({t['d4_toled_preset']:.3f} against {t['d4_toled_squares']:.3f} dB") in flat
    veil, v130 = rows["design_veil"], rows["veil130"]
    assert f"by {veil['d4_toled_preset']:.3f} ± {veil['d4_toled_preset_se']:.3f} dB in the objective" in flat
    assert (f"level in the objective ({v130['d4_toled_preset']:+.3f} ± {v130['d4_toled_preset_se']:.3f} dB)"
            .replace("-", "−")) in flat
    assert (f"seemed to lead ({rows['k16']['d4_toled_squares']:+.3f} and {v130['d4_toled_squares']:+.3f} dB)") in flat
    names = ("design_veil", "floor/veil127", "floor/veil130", "floor/veil134")
    m = [rows[n.split("/")[-1]]["d4_toled_preset"] for n in names]
    u = [json.loads((root / "docs" / "figures" / "design" / n / "design.json").read_text())["upc"]["turned"]
         for n in names]
    g = [u[0]["ratio"][1]] + [x["draws"]["mean"][1] for x in u[1:]]
    assert m == sorted(m, reverse=True) and g == sorted(g)
    assert (f"falls from {m[0]:+.3f} dB at UPC's G {g[0]:.3f} (one tiling) to {m[1]:+.3f} ({g[1]:.3f}), {m[2]:+.3f} "
            f"({g[2]:.3f}) and {m[3]:+.3f} dB ({g[3]:.3f} over 8 draws)").replace("-", "−") in flat
    b90 = json.loads((root / "docs" / "figures" / "design" / "ceiling" / "veil_b90" / "design.json").read_text())
    assert (f"(`veil_b90`: {rows['veil_b90']['d4_toled_preset']:+.3f} dB at G "
            f"{b90['upc']['turned']['draws']['mean'][1]:.3f})").replace("-", "−") in flat
    moves = {n: abs(r["quarter_turns_toled_preset"] - r["d4_toled_preset"]) for n, r in rows.items()}
    wiener = moves.pop("design")
    se = [r["d4_toled_preset_se"] for r in rows.values()]
    defaults = " ".join((root / "docs" / "concepts" / "defaults.md").read_text(encoding="utf-8").split())
    assert f"the difference's se is {min(se):.3f}–{max(se):.3f} dB at 16" in defaults
    assert f"move by at most {max(moves.values()):.3f} dB ({wiener:.3f} dB for the `wiener` design" in flat


def test_the_design_guide_prints_veil128_b100():
    """The guide's numbers for `veil128_b100` are its committed design.json's: the held-out margin over the
    simulator's T-OLED, UPC's G over 8 draws, the bands over draws 0–4 and on the ceiling's draws; its settings are
    the command the guide prints."""
    root = Path(__file__).resolve().parents[2]
    flat = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    d = json.loads((root / "docs" / "figures" / "design" / "ceiling" / "veil128_b100" / "design.json").read_text())
    c = d["config"]
    assert (c["upc_floor"], c["banding_ceiling"], c["kicks"], c["kick_swaps"], c["candidates"], c["far_veil"]) == (
        1.28, 1.0, 8, 4, 100, True) and c["init"].endswith("design_veil/cell.png") and d["kicks_done"] == 8
    h, u = d["held_out"]["d4"]["vs"]["design"]["toled_preset"], d["upc"]["turned"]["draws"]
    q = np.mean(d["banding"]["ratio"], axis=1)
    assert f"{d['steps_done']} steps and {d['evaluations']} exact scores" in flat
    below = []
    for name in ("veil127", "veil130", "veil134"):
        f = json.loads((root / "docs" / "figures" / "design" / "floor" / name / "design.json").read_text())
        below.append(f["config"]["upc_floor"] - f["upc"]["turned"]["draws"]["mean"][1])
    assert f"sits {min(below):.3f}–{max(below):.3f} below it" in flat
    assert (f"puts it {h['mean']:+.3f} ± {h['se']:.3f} dB over the simulator's T-OLED on 16 draws (led on "
            f"{h['leads']} of 16), with UPC's G {u['mean'][1]:.3f} ± {u['sd'][1]:.3f} over 8 draws (min "
            f"{u['min'][1]:.3f}) and bands {q.mean():.2f} × the turned T-OLED over draws 0–4 (below it on "
            f"{(q < 1).sum()} of 5; on the held-out tiling's 8 draws of the ceiling's 8 µm raster, "
            f"{np.mean(d['final']['banding_ratios']):.2f} ×") in flat


def test_the_design_guide_prints_veil128_b100_through_the_simulator():
    """The guide's veil128_b100 margins through `study layout-trained` are the committed JSON's (seed 0, 80 epochs,
    its design_turned.toml against the turned T-OLED)."""
    root = Path(__file__).resolve().parents[2]
    flat = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    t = json.loads((root / "docs" / "figures" / "design" / "layout_trained_f128" / "study_layout_trained.json")
                   .read_text())
    assert t["seeds"]["train"] == 0 and t["budget"]["epochs"] == 80
    assert t["specs"] == ["docs/figures/design/toled168_20.toml@edge@turned",
                          "docs/figures/design/ceiling/veil128_b100/design_turned.toml"]
    p = t["paired"]["design_turned"]

    def cell(q: dict) -> str:
        return f"{q['mean_db']:+.2f} ± {q['se_db']:.2f} dB ({q['wins']} of 8)".replace("-", "−")
    assert (f"plain DeP {cell(p['dep'])}, level; DeP given the far field {cell(p['dep_far'])}; the UNet "
            f"{cell(p['unet'])}.") in flat
    assert abs(p["dep"]["mean_db"]) < 2 * p["dep"]["se_db"] and p["dep_far"]["wins"] == 8
    folder = root / "docs" / "figures" / "design" / "layout_trained_f128_seed1"
    seed1 = json.loads((folder / "study_layout_trained.json").read_text())
    assert seed1["seeds"]["train"] == 1 and seed1["budget"]["epochs"] == 80 and seed1["specs"] == t["specs"]
    unet = [p["unet"], seed1["paired"]["design_turned"]["unet"]]
    mean = np.mean([u["mean_db"] for u in unet])
    assert (f"the UNet is at {cell(unet[1])}: level over the two seeds (mean {mean:+.2f} dB"
            .replace("(mean -", "(mean −")) in flat
    assert (f"by the UNet ({unet[0]['mean_db']:+.2f} and {unet[1]['mean_db']:+.2f} dB, two seeds)"
            .replace("-", "−")) in flat


def test_the_design_guide_prints_the_channel_step():
    """The channel-step section is the committed `study channel-step` (its rows; 40 nm the default's error and CPU
    ratio), the held-out study's simulator raster and tiling, and each design's plain DeP from its committed
    `study layout-trained`: the camera's channels give every design DeP's sign, one wavelength per channel does not,
    and the mean distance to DeP of the designs within 0.1 dB falls as printed."""
    root = Path(__file__).resolve().parents[2]
    figures = root / "docs" / "figures" / "design"
    text = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8")
    lines, flat = text.splitlines(), " ".join(text.split())
    rows = json.loads((figures / "channel_step" / "study_channel_step.json").read_text())["rows"]
    assert [r["channel_step_nm"] for r in rows] == [0.0, 80.0, 40.0, 20.0, 10.0, 5.0] and rows[-1]["error_db"] == 0
    for r in rows[:-1]:
        assert f"| {r['wavelengths']} | {r['cpu_s']:.2f} | {r['error_db']:.4f} |" in text
    one, forty = rows[0], rows[2]
    assert (f"40 nm (8 wavelengths) is within {forty['error_db']:.3f} dB of 5 nm at "
            f"{forty['cpu_s'] / one['cpu_s']:.1f} × one wavelength's CPU time, and one wavelength per channel errs by "
            f"{one['error_db']:.2f} dB") in flat
    h = json.loads((figures / "held_out" / "study_held_out.json").read_text())
    t = h["toleds"]
    assert f"{t['d4_toled_simulator']:.3f} against {t['d4_toled_preset']:.3f} dB" in flat
    assert f"{t['d4_toled_simulator'] - t['d4_toled_preset']:.3f} dB apart" in flat
    moved = max(abs(r["engine_toled_simulator"] - r["d4_toled_simulator"]) for r in h["rows"]
                if not r["design"].endswith("/design"))
    assert f"within {moved:.3f} dB of their held-out means" in flat
    mono = {Path(k).name: v for k, v in one["margins_db"].items()}
    spec = {Path(k).name: v for k, v in forty["margins_db"].items()}
    loss = [mono[n] - spec[n] for n in mono]
    assert f"each loses {min(loss):.2f}–{max(loss):.2f} dB against the T-OLED" in flat
    near, signs = [], {"mono": 0, "spec": 0}
    for name, folder in CHANNEL_DEP.items():
        p = json.loads((figures / folder / "study_layout_trained.json").read_text())["paired"]["design_turned"]["dep"]
        row = f"| `{name}` | {mono[name]:+.3f} | {spec[name]:+.3f} | {p['mean_db']:+.2f} ± {p['se_db']:.2f} |"
        assert row.replace("-", "−") in lines, row
        signs["mono"] += np.sign(mono[name]) == np.sign(p["mean_db"])
        signs["spec"] += np.sign(spec[name]) == np.sign(p["mean_db"])
        if abs(p["mean_db"]) < 0.1:
            near.append((abs(mono[name] - p["mean_db"]), abs(spec[name] - p["mean_db"])))
    assert signs == {"mono": 5, "spec": 7} and len(near) == 4
    a, b = np.mean(near, axis=0)
    assert f"mean distance to DeP falls from {a:.3f} dB to {b:.3f} dB" in flat
    defaults = " ".join((root / "docs" / "concepts" / "defaults.md").read_text(encoding="utf-8").split())
    assert (f"within {forty['error_db']:.3f} dB of 5 nm at {forty['cpu_s'] / one['cpu_s']:.1f} × the CPU time; one "
            f"wavelength per channel errs by {one['error_db']:.2f} dB") in defaults


CHANNEL_DEP = {"design_veil": "layout_trained_veil", "veil128_b100": "layout_trained_f128",
               "veil130": "layout_trained_floor", "k16": "layout_trained_kicks",
               "veil130_b90": "layout_trained_ceiling", "veil_b55": "layout_trained_b55",
               "design_crop": "layout_trained_e240"}


def test_the_design_guide_prints_the_camera_channel_searches():
    """The five searches at --channel-step 40 (docs/figures/design/channel_step/): the guide's rows are their
    design.json's (start, floor, ceiling, kicks, squares moved, the held-out margin over the simulator's T-OLED,
    UPC's G over 8 draws, the bands over draws 0–4); the two at UPC's floor trail that T-OLED, the others lead."""
    root = Path(__file__).resolve().parents[2]
    folder = root / "docs" / "figures" / "design" / "channel_step"
    lines = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").splitlines()
    starts = {"design_veil": "veil design", "veil128_b100": "`veil128_b100`", "spec_veil_b100": "`spec_veil_b100`"}
    margins = {}
    for name in ("spec_veil", "spec_veil_b100", "spec_veil128", "spec_f128", "spec_veil_b95"):
        d = json.loads((folder / name / "design.json").read_text())
        c, h, u = d["config"], d["held_out"]["d4"]["vs"]["design"]["toled_preset"], d["upc"]["turned"]["draws"]
        assert c["channel_step_nm"] == 40.0 and c["far_veil"] and c["objective"] == "crop"
        floor = "none" if c["upc_floor"] is None else f"{c['upc_floor']:g}"
        ceiling = "none" if c["banding_ceiling"] is None else str(c["banding_ceiling"])
        bands = "—" if d["banding"] is None else f"{np.mean(d['banding']['ratio']):.2f}"
        row = (f"| `{name}` | {starts[c['init'].split('/')[-2]]} | {floor}, {ceiling} | {d['kicks_done']} | "
               f"{d['initial']['squares_moved']} | {h['mean']:+.3f} ± {h['se']:.3f} ({h['leads']}) | "
               f"{u['mean'][1]:.3f} (min {u['min'][1]:.3f}) | {bands} |").replace("-", "−")
        assert row in lines, row
        margins[name] = h["mean"]
    assert margins["spec_veil"] > margins["spec_veil_b100"] > margins["spec_veil_b95"] > 0 > max(
        margins["spec_veil128"], margins["spec_f128"])


def test_the_design_guide_prints_spec_veil_b100_through_the_simulator():
    """`layout_trained_spec_b100/` is spec_veil_b100's design_turned.toml against the turned T-OLED at training seed 0,
    and the guide's margins (plain DeP, DeP given the far field, the UNet) are its paired rows; seed 1's folder has
    the same specs and DeP, and the guide prints its UNet and the two seeds' mean."""
    root = Path(__file__).resolve().parents[2]
    flat = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    t = json.loads((root / "docs" / "figures" / "design" / "layout_trained_spec_b100" / "study_layout_trained.json"
                    ).read_text())
    assert t["seeds"]["train"] == 0 and t["specs"][0].endswith("toled168_20.toml@edge@turned")
    assert t["specs"][1].endswith("channel_step/spec_veil_b100/design_turned.toml")
    p = t["paired"]["design_turned"]

    def pm(k: str) -> str:
        return f"{p[k]['mean_db']:+.2f} ± {p[k]['se_db']:.2f} dB ({p[k]['wins']} of 8)".replace("-", "−")
    assert f"plain DeP {pm('dep')}, DeP given the far field {pm('dep_far')}, the UNet {pm('unet')}" in flat
    s1 = json.loads((root / "docs" / "figures" / "design" / "layout_trained_spec_b100_seed1" /
                     "study_layout_trained.json").read_text())
    assert s1["seeds"]["train"] == 1 and s1["specs"] == t["specs"]
    q = s1["paired"]["design_turned"]
    assert q["dep"] == p["dep"]  # the same captures and DeP: only the UNet's training differs
    unet = f"{q['unet']['mean_db']:+.2f} ± {q['unet']['se_db']:.2f} dB ({q['unet']['wins']} of 8)".replace("-", "−")
    mean = f"{(q['unet']['mean_db'] + p['unet']['mean_db']) / 2:+.2f}".replace("-", "−")
    assert f"the UNet is at {unet}: level over the two seeds (mean {mean} dB)" in flat



EXACT_REPAIRED = {"design_crop": ("layout_trained", "design_crop"),
                  "veil_b55": ("layout_trained_b55", "ceiling/veil_b55"),
                  "veil130_b90": ("layout_trained_ceiling", "ceiling/veil130_b90"),
                  "veil130": ("layout_trained_floor", "floor/veil130"),
                  "veil128_b100": ("layout_trained_f128", "ceiling/veil128_b100"),
                  "k16": ("layout_trained_kicks", "kicks/k16"),
                  "spec_veil_b100": ("layout_trained_spec_b100", "channel_step/spec_veil_b100")}


def _paired(a, b) -> tuple[str, str]:
    """("mean ± se", "wins of n") of the per-image differences a − b, as the guide prints them."""
    d = np.subtract(a, b)
    return f"{d.mean():+.2f} ± {d.std(ddof=1) / np.sqrt(len(d)):.2f}", f"{(d > 0).sum()} of {len(d)}"


def _pm(a, b) -> str:
    return "{} ({})".format(*_paired(a, b))


def _per_image(folder: str) -> dict:
    """{layout: its per-image PSNRs} of a committed `study layout-trained` folder under docs/figures/design."""
    doc = json.loads((Path(__file__).resolve().parents[2] / "docs" / "figures" / "design" / folder
                      / "study_layout_trained.json").read_text())
    return {r["layout"]: r["per_image_db"] for r in doc["rows"]}


def _against_exact(r0: dict, r1: dict) -> tuple[list, list]:
    """(plain DeP, DeP given the far field, the UNet seed 0, seed 1) as _paired of a design's rows in a seed-0 and a
    seed-1 run against the exact T-OLED's rows of layout_trained_exact(_seed1), and its seed-0 margins over the
    repeated T-OLED and the P-OLED of layout_trained/ (DeP, UNet; DeP, UNet); DeP has no training seed."""
    ref0, ref1 = (_per_image(run)["toled168_20_edge_turned"] for run in ("layout_trained_exact",
                                                                          "layout_trained_exact_seed1"))
    assert r0["dep"] == r1["dep"]
    pairs = [_paired(r0["dep"], ref0["dep"]), _paired(r0["dep_far"], ref0["dep_far"]),
             _paired(r0["unet"], ref0["unet"]), _paired(r1["unet"], ref1["unet"])]
    presets = _per_image("layout_trained")
    return pairs, [np.mean(np.subtract(r0[k], presets[p][k])) for p in ("toled168_20", "poled_20")
                   for k in ("dep", "unet")]


def test_the_design_guide_prints_the_exact_toled():
    """The section on the exact T-OLED: `held_out_exact/`'s rows and T-OLEDs, and `layout_trained_exact/`'s T-OLED
    row paired with the committed seed-0 runs' design rows (their captures and seed-0 training are the same: k16's
    row is layout_trained_kicks' to the bit, and those runs' raster T-OLED rows are one), UPC's G and the bands from
    each design.json; the claims on veil128_b100 and spec_veil_b95 hold."""
    root = Path(__file__).resolve().parents[2]
    figures = root / "docs" / "figures" / "design"
    text = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8")
    lines, flat = text.splitlines(), " ".join(text.split())
    h = json.loads((figures / "held_out_exact" / "study_held_out.json").read_text())
    for r in h["rows"]:
        folder = r["design"].split("design/")[-1]
        u = json.loads((figures / folder / "design.json").read_text())["upc"]["turned"]
        g = f"{u['draws']['mean'][1]:.3f}" if "draws" in u else "—"
        row = (f"| `{Path(folder).name}` | {g} | {r['d4_toled_preset']:+.3f} ± {r['d4_toled_preset_se']:.3f} "
               f"({r['d4_toled_preset_leads']}) | {r['engine_toled_preset']:+.3f} |").replace("-", "−")
        assert row in lines, row
    t = h["toleds"]
    assert f"Against the exact T-OLED ({t['d4_toled_preset']:.3f} dB over the D4 draws)" in flat
    assert f"({t['d4_toled_squares']:.3f} dB, the search's start) now scores above the preset" in flat
    assert f"the exact T-OLED scores **{t['engine_toled_preset']:.3f} dB**" in flat
    rows = _per_image("layout_trained_exact")
    ref = rows["toled168_20_edge_turned"]
    k16 = _per_image("layout_trained_kicks")["design_turned"]
    assert all(k16[k] == rows["k16_turned"][k] for k in ("dep", "dep_far", "unet"))
    raster = None
    for name, (run, folder) in EXACT_REPAIRED.items():
        d = _per_image(run)
        r, old = d["design_turned"], d["toled168_20_edge_turned"]
        raster = raster or old
        assert all(old[k] == raster[k] for k in ("dep", "dep_far", "unet"))
        dj = json.loads((figures / folder / "design.json").read_text())
        u = dj["upc"]["turned"]
        g = f"{u['draws']['mean'][1]:.3f}" if "draws" in u else "—"
        b = f"{np.mean(dj['banding']['ratio']):.2f}" if dj.get("banding") else "—"
        before = np.mean(np.subtract(r["dep"], old["dep"]))
        row = (f"| `{name}` | {g} | {b} | {_pm(r['dep'], ref['dep'])} ({before:+.2f}) "
               f"| {_pm(r['dep_far'], ref['dep_far'])} | {_pm(r['unet'], ref['unet'])} "
               f"({np.mean(np.subtract(r['unet'], old['unet'])):+.2f}) |").replace("-", "−")
        assert row in lines, row
    for name in ("spec_veil_b95", "spec_veil128"):
        r, dj = rows[f"{name}_turned"], json.loads((figures / "channel_step" / name / "design.json").read_text())
        row = (f"| `{name}` | {dj['upc']['turned']['draws']['mean'][1]:.3f} | {np.mean(dj['banding']['ratio']):.2f} | "
               f"{_pm(r['dep'], ref['dep'])} | {_pm(r['dep_far'], ref['dep_far'])} | {_pm(r['unet'], ref['unet'])} |")
        assert row.replace("-", "−") in lines, row
    shift = {k: np.mean(np.subtract(raster[k], ref[k])) for k in ("dep", "dep_far", "unet")}
    assert (f"the exact one loses {shift['dep']:.2f} dB by plain DeP, {shift['dep_far']:.2f} dB by DeP given the far "
            f"field and {shift['unet']:.2f} dB by the UNet") in flat
    presets = _per_image("layout_trained")
    f128 = _per_image("layout_trained_f128")["design_turned"]
    for name, r in (("veil128_b100", f128), ("spec_veil_b95", rows["spec_veil_b95_turned"])):
        m = [np.mean(np.subtract(r[k], presets[p][k])) for p in ("toled168_20", "poled_20") for k in ("dep", "unet")]
        assert f"`{name}` {m[0]:+.2f} / {m[1]:+.2f} dB over the repeated T-OLED and {m[2]:+.2f} / {m[3]:+.2f}" in flat \
            or f"`{name}` {m[0]:+.2f} / {m[1]:+.2f} and {m[2]:+.2f} / {m[3]:+.2f} dB" in flat, (name, m)
        assert all(np.all(np.subtract(r[k], presets[p][k]) > 0) for p in ("toled168_20", "poled_20")
                   for k in ("dep", "unet"))
    b95 = rows["spec_veil_b95_turned"]
    for k in ("dep", "dep_far", "unet"):
        assert np.all(np.subtract(f128[k], ref[k]) > 0) and np.all(np.subtract(b95[k], ref[k]) > 0)


def test_the_design_guide_prints_the_exact_toled_with_seed_1():
    """`layout_trained_exact_seed1/`: the exact T-OLED trained with seed 1, paired with its own rows and with the
    committed seed-1 runs' design rows (their raster T-OLED rows are one); spec_veil_b95 leads on every image."""
    root = Path(__file__).resolve().parents[2]
    flat = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    rows = _per_image("layout_trained_exact_seed1")
    ref = rows["toled168_20_edge_turned"]
    got, raster = {}, None
    for name in ("spec_veil_b95", "spec_veil128"):
        got[name] = rows[f"{name}_turned"]["unet"]
    seed1 = (("veil128_b100", "f128"), ("veil130", "floor"), ("k16", "kicks"), ("spec_veil_b100", "spec_b100"))
    for name, run in seed1:
        d = _per_image(f"layout_trained_{run}_seed1")
        raster = raster or d["toled168_20_edge_turned"]["unet"]
        assert d["toled168_20_edge_turned"]["unet"] == raster
        got[name] = d["design_turned"]["unet"]
    for name, unet in got.items():
        assert f"`{name}` {_pm(unet, ref['unet'])}".replace("-", "−") in flat, name
    assert np.all(np.subtract(got["spec_veil_b95"], ref["unet"]) > 0)


def test_the_design_guide_prints_spec_f95():
    """spec_f95's paragraph: its design.json (a search against the exact T-OLED: held-out margin, UPC's G, bands)."""
    root = Path(__file__).resolve().parents[2]
    d = json.loads((root / "docs" / "figures" / "design" / "channel_step" / "spec_f95" / "design.json").read_text())
    flat = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    c, h, u = d["config"], d["held_out"]["d4"]["vs"]["design"]["toled_preset"], d["upc"]["turned"]["draws"]
    assert (c["upc_floor"], c["banding_ceiling"], c["channel_step_nm"], d["kicks_done"]) == (1.28, 0.95, 40.0, 4)
    assert f"{d['kicks_done']} kicks moved {d['initial']['squares_moved']} squares" in flat
    assert (f"leads the exact T-OLED by {h['mean']:+.3f} ± {h['se']:.3f} dB ({h['leads']} of 16 held-out draws"
            in flat)
    assert f"at UPC's G {u['mean'][1]:.3f} (min {u['min'][1]:.3f}) over 8 tilings" in flat
    assert f"bands {np.mean(d['banding']['ratio']):.3f} × the turned T-OLED over draws 0–4" in flat


def test_the_design_guide_prints_spec_f95_through_the_simulator():
    """spec_f95's rows in both exact runs (seeds 0 and 1) and against the presets of `layout_trained/`."""
    root = Path(__file__).resolve().parents[2]
    flat = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    runs = [_per_image(name) for name in ("layout_trained_exact", "layout_trained_exact_seed1")]
    ((dm, dw), (fm, fw), (u0, w0), (u1, w1)), m = _against_exact(*(run["spec_f95_turned"] for run in runs))
    text = (f"level by plain DeP ({dm} dB, {dw}), leads given the far field ({fm}, {fw}) and by the UNet with both "
            f"seeds ({u0}, {w0}; {u1}, {w1})")
    assert text.replace("-", "−") in flat, text
    assert f"repeated T-OLED by {m[0]:+.2f} / {m[1]:+.2f} dB and the P-OLED by {m[2]:+.2f} / {m[3]:+.2f} dB" in flat


def _agreement() -> tuple[list[str], dict]:
    """The guide's agreement table: per design with a row through the simulator against the exact turned T-OLED,
    its plain DeP margin there (re-paired as test_the_design_guide_prints_the_exact_toled does) and the objective's
    margin on the simulator's own tiling in the default scene (held_out_exact, held_out_exact_f95: the same objective)
    and in the study's (scene/held_out);
    and the mean absolute differences over the designs within 0.1 dB of the T-OLED and over all."""
    figures = Path(__file__).resolve().parents[2] / "docs" / "figures" / "design"
    exact = _per_image("layout_trained_exact")
    ref = exact["toled168_20_edge_turned"]["dep"]
    sim = {"k16": exact["k16_turned"]["dep"]}
    sim.update({n: exact[f"{n}_turned"]["dep"] for n in ("spec_veil_b95", "spec_veil128", "spec_f95")})
    sim.update({n: _per_image(run)["design_turned"]["dep"] for n, (run, _) in EXACT_REPAIRED.items() if n != "k16"})
    engine = {"default": {}, "scene": {}}
    for key, folder in (("default", "held_out_exact"), ("default", "held_out_exact_f95"), ("scene", "scene/held_out")):
        rows = json.loads((figures / folder / "study_held_out.json").read_text())["rows"]
        engine[key].update({Path(r["design"]).name: r["engine_toled_preset"] for r in rows})
    lines, errors = [], {"default": [], "scene": []}
    for name, dep in sorted(sim.items(), key=lambda kv: -np.mean(np.subtract(kv[1], ref))):
        s = float(np.mean(np.subtract(dep, ref)))
        lines.append(f"| `{name}` | {_pm(dep, ref)} | {engine['default'][name]:+.3f} | {engine['scene'][name]:+.3f} |"
                     .replace("-", "−"))
        for key in errors:
            errors[key].append((abs(engine[key][name] - s), s > -0.1))
    mae = {f"{key}_{part}": float(np.mean([e for e, near in v if near or part == "all"]))
           for key, v in errors.items() for part in ("near", "all")}
    return lines, mae


def test_the_design_guide_prints_the_objectives_agreement_with_the_simulator():
    """The scene section's table and mean absolute differences (_agreement) from the committed JSON."""
    root = Path(__file__).resolve().parents[2]
    text = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8")
    lines, flat = text.splitlines(), " ".join(text.split())
    rows, mae = _agreement()
    for row in rows:
        assert row in lines, row
    assert (f"within {mae['scene_near']:.3f} dB on average in the study's scene against {mae['default_near']:.3f} dB "
            f"in the default one") in flat
    assert f"over all ten, {mae['scene_all']:.3f} against {mae['default_all']:.3f} dB" in flat


def test_the_design_guide_prints_the_light_shares_and_the_study_scene_margins():
    """scene/held_out's table: each layout's light past the window and beyond the acceptance (design.far_light) and
    its held-out margin over the exact T-OLED in the study's scene; the T-OLED sends the least light past the window
    of the designs at UPC's ratio (G ≥ 1.26), and for every layout 0.75–0.78 of that light (green) stays inside the
    acceptance."""
    root = Path(__file__).resolve().parents[2]
    figures = root / "docs" / "figures" / "design"
    lines = (root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").splitlines()
    doc = json.loads((figures / "scene" / "held_out" / "study_held_out.json").read_text())

    def shares(light: dict) -> str:
        return " | ".join(" / ".join(f"{100 * v:.2f}" for v in light[k]) for k in ("past_window", "beyond_acceptance"))
    toled = doc["toleds"]["toled_preset_light"]
    assert f"| the exact T-OLED | {shares(toled)} | — |" in lines
    for r in doc["rows"]:
        row = (f"| `{Path(r['design']).name}` | {shares(r)} | {r['d4_toled_preset']:+.3f} ± "
               f"{r['d4_toled_preset_se']:.3f} ({r['d4_toled_preset_leads']}) |").replace("-", "−")
        assert row in lines, row
        kept = (r["past_window"][1] - r["beyond_acceptance"][1]) / r["past_window"][1]
        assert 0.75 < kept < 0.78, (r["design"], kept)
        g = json.loads((figures / r["design"].split("design/")[-1] / "design.json").read_text())["upc"]["turned"]
        if "draws" in g and g["draws"]["mean"][1] >= 1.26:
            assert all(w > t for w, t in zip(r["past_window"], toled["past_window"]))


def test_the_design_guide_prints_the_study_scene_searches():
    """The three searches in the study's scene: their design.json (options, squares moved, held-out margin over the
    exact T-OLED, UPC's G, bands) as the guide prints them; the 4 µm design is spec_f95's cell split 2 × 2 with 12
    squares changed."""
    root = Path(__file__).resolve().parents[2]
    figures = root / "docs" / "figures" / "design"
    flat = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    docs = {n: json.loads((figures / "scene" / n / "design.json").read_text()) for n in ("f95", "b95_floor", "f95_4um")}
    for d in docs.values():
        c = d["config"]
        assert (c["contrast"], c["mean_level"], c["upc_floor"], c["banding_ceiling"], c["channel_step_nm"]) == \
            (0.51, 0.41, 1.28, 0.95, 40.0)
    h = {n: d["held_out"]["d4"]["vs"]["design"]["toled_preset"] for n, d in docs.items()}
    u = {n: d["upc"]["turned"]["draws"] for n, d in docs.items()}
    bands = {n: float(np.mean(d["banding"]["ratio"])) for n, d in docs.items()}
    assert docs["f95"]["initial"]["squares_moved"] == 0
    f95 = h["f95"]
    assert f"leads the exact T-OLED by {f95['mean']:+.3f} ± {f95['se']:.3f} dB ({f95['leads']} of 16" in flat
    b = docs["b95_floor"]
    assert (f"lifts G from 1.204 to {u['b95_floor']['mean'][1]:.3f} (mean over 8 tilings; min "
            f"{u['b95_floor']['min'][1]:.3f}), {b['initial']['squares_moved']} squares moved, bands "
            f"{bands['b95_floor']:.3f} ×") in flat
    assert (f"from +0.129 to {h['b95_floor']['mean']:+.3f} ± {h['b95_floor']['se']:.3f} dB "
            f"({h['b95_floor']['leads']} of 16)").replace("-", "−") in flat
    f = h["f95_4um"]
    assert f"**{f['mean']:+.3f} ± {f['se']:.3f} dB ({f['leads']} of 16)**" in flat
    assert (f"UPC's G {u['f95_4um']['mean'][1]:.3f} (min {u['f95_4um']['min'][1]:.3f}; B "
            f"{u['f95_4um']['mean'][2]:.3f})") in flat and f"**{bands['f95_4um']:.3f} ×**" in flat
    for name, start in (("b95_4um", "channel_step/spec_veil_b95"), ("v128_4um", "ceiling/veil128_b100")):
        d = json.loads((figures / "scene" / name / "design.json").read_text())
        v, g = d["held_out"]["d4"]["vs"]["design"]["toled_preset"], d["upc"]["turned"]["draws"]["mean"][1]
        assert d["config"]["init"] == f"docs/figures/design/{start}/cell.png" and d["config"]["feature_um"] == 4.0
        assert (f"{v['mean']:+.3f} ± {v['se']:.3f} dB ({v['leads']} of 16; G {g:.3f}, bands "
                f"{np.mean(d['banding']['ratio']):.3f} ×)").replace("-", "−") in flat
    light = json.loads((figures / "scene" / "held_out_4um" / "study_held_out.json").read_text())["rows"][0]
    assert light["design"].endswith("scene/f95_4um")
    assert f"Its light past the window is {' / '.join(f'{100 * v:.2f}' for v in light['past_window'])} %" in flat
    fine = iio.imread(figures / "scene" / "f95_4um" / "cell.png") == 255
    coarse = np.kron(iio.imread(figures / "channel_step" / "spec_f95" / "cell.png") == 255, np.ones((2, 2), bool))
    assert fine.sum() == coarse.sum() == 352 and (fine != coarse).sum() == 12


def test_the_design_guide_prints_f95_4um_through_the_simulator():
    """f95_4um's rows (scene/layout_trained, seeds 0 and 1) paired with the exact T-OLED's rows of the exact runs, and
    with spec_f95's and the presets'; DeP has no training seed."""
    root = Path(__file__).resolve().parents[2]
    flat = " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())
    r0, r1 = (_per_image(f"scene/{run}")["f95_4um_turned"] for run in ("layout_trained", "layout_trained_seed1"))
    ((dm, dw), (fm, fw), (u0, w0), (u1, w1)), m = _against_exact(r0, r1)
    text = (f"plain DeP **{dm} dB ({dw})**, DeP given the far field {fm} ({fw}), the UNet {u0} ({w0}, seed 0) and "
            f"{u1} ({w1}, seed 1)")
    assert text.replace("-", "−") in flat, text
    assert f"repeated T-OLED {m[0]:+.2f} / {m[1]:+.2f} dB and over the P-OLED {m[2]:+.2f} / {m[3]:+.2f} dB" in flat
    f95 = _per_image("layout_trained_exact")["spec_f95_turned"]["dep"]
    assert f"(plain DeP {np.mean(np.subtract(r0['dep'], f95)):+.2f} over `spec_f95`'s row;" in flat
    ref0 = _per_image("layout_trained_exact")["toled168_20_edge_turned"]
    assert f"against plain DeP's {np.mean(np.subtract(r0['dep'], ref0['dep'])):+.3f})" in flat
