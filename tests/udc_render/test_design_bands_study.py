"""`udc-render study design-bands` (udc_render.studies.design_bands): the designs' bands on many held-out D4 draws,
paired with the turned T-OLED at each design's open area."""
from __future__ import annotations

import json
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from udc_render import cli
from udc_render.design import job
from udc_render.design.config import DesignConfig
from udc_render.design.starts import scatter
from udc_render.studies import design_bands

DESIGNS = Path(__file__).resolve().parents[2] / "docs/figures/design"
TINY = dict(cell_um=40.0, feature_um=8.0, open_fraction=0.24, steps=2, pupil_samples=64, kernel_px=31, scatters=2,
            seed=3)


@pytest.mark.slow  # 20-80 s on a core: out of CI's 20 min
def test_the_first_draws_are_design_jsons_committed_banding():
    """spec_f95 on draws 0 and 1: the ratios its design.json holds (the search's run, 2026-11), the se their sd
    over √2, the draws below 1 counted from them."""
    folder = DESIGNS / "channel_step/spec_f95"
    config, cell = design_bands.check([folder])[str(folder)]
    row = design_bands._row("spec_f95", config, cell, draws=2, checks=0, cache={})
    saved = json.loads((folder / "design.json").read_text())["banding"]
    assert np.allclose(row["ratio"], saved["ratio"][:2], rtol=1e-12, atol=0)
    ratio = np.asarray(saved["ratio"][:2])
    assert np.allclose(row["se"], ratio.std(0, ddof=1) / np.sqrt(2), rtol=1e-9)
    assert row["below"] == (ratio < 1).sum(0).tolist() and row["raster_change"] is None


def _design(folder: Path, **config) -> Path:
    folder.mkdir()
    cfg = {**TINY, **config}
    (folder / "design.json").write_text(json.dumps({"config": cfg}))
    iio.imwrite(folder / "cell.png", (scatter(DesignConfig(**cfg), "scatter", 0) * 255).astype(np.uint8))
    return folder


def test_the_toled_is_scored_once_per_open_area_and_raster(tmp_path, monkeypatch):
    """Three designs at two open areas: the T-OLED's bands are computed once per open area, raster (2 µm and the
    check's 1 µm) and tiling (the design's, and repeated on one draw), and every ratio is the design's over the
    T-OLED's at its own open area, draw by draw; over the repeated T-OLED, each draw over its one figure."""
    calls = []

    def fake_sd(cell, pixel_um, tiling, seeds, sample_um=2.0):
        calls.append((cell.shape, sample_um, tiling))
        return [[float(cell.mean()) * (1 + s) * c for c in (1.0, 2.0, 3.0)] for s in seeds]

    monkeypatch.setattr(job, "banding_sd", fake_sd)
    folders = [_design(tmp_path / "a"), _design(tmp_path / "b"), _design(tmp_path / "c", open_fraction=0.32)]
    doc = design_bands.run_study(tmp_path / "out", folders, quick=True)
    toleds = [c for c in calls if c[0] != (5, 5)]
    assert len(toleds) == 6 and len(calls) == 6 + 2 * 3
    assert sorted(c[2] for c in toleds) == ["repeated"] * 2 + ["turned"] * 4
    for r, folder in zip(doc["rows"], folders):
        config, cell = design_bands.check([folder])[str(folder)]
        toled, _ = job.toled_banding_cell(config.cell_um, config.open_fraction)
        assert np.allclose(r["ratio"], cell.mean() / toled.mean())
        assert np.allclose(r["over_repeated"]["mean"], 1.5 * cell.mean() / toled.mean())  # draws 0, 1: × 1, × 2
        assert r["raster_change"] == pytest.approx([0.0, 0.0, 0.0], abs=1e-9)  # area-weighted: the same open area
    for name in ("json", "csv", "md", "png"):
        assert (tmp_path / "out" / f"study_design_bands.{name}").is_file()


def test_study_design_bands_refuses_a_folder_in_one_line(tmp_path, capsys):
    assert cli.main(["study", "design-bands", "--designs", str(tmp_path / "none"),
                     "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err
    assert "no design.json there" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "never").exists()


def test_a_design_whose_start_is_gone_is_read():
    """design.json's search-only settings are not read back: k8_then_swaps3 started from a cell PNG under /tmp that
    no longer exists, and its folder still reads (its 88 open squares of 21 × 21)."""
    config, cell = design_bands.check([DESIGNS / "kicks/k8_then_swaps3"])[str(DESIGNS / "kicks/k8_then_swaps3")]
    assert cell.shape == (21, 21) and int(cell.sum()) == 88 and config.init == "scatter"


@pytest.mark.slow  # 20-80 s on a core: out of CI's 20 min
def test_an_arranged_design_of_one_element_bands_as_its_cell_repeated(tmp_path):
    """An arranged design whose 2 × 2 pattern is one element throughout is its cell repeated: over the repeated
    T-OLED it reads banding_sd's registered figure of the cell repeated (a period of four cells against one: rel
    1e-9, rounding of windows of other sizes), that figure lies within its single registrations' range, each
    registration is one offset of the super-cell's period on the 2 µm raster, and the study writes its map."""
    folder = _design(tmp_path / "one", tiling="arranged", arrangement=2)
    saved = json.loads((folder / "design.json").read_text())
    (folder / "design.json").write_text(json.dumps({**saved, "arrangement": [[3, 3], [3, 3]]}))
    doc = design_bands.run_study(tmp_path / "out", [folder], quick=True)
    row = doc["rows"][0]
    config, cell = design_bands.check([folder])[str(folder)]
    assert row["tiling"] == "arranged" and cell.shape == (10, 10)
    toled, toled_um = job.toled_banding_cell(config.cell_um, config.open_fraction)
    expected = np.divide(job.banding_sd(cell[:5, :5], 8.0, "repeated", [0])[0],
                         job.banding_sd(toled, toled_um, "repeated", [0])[0])
    assert np.allclose(row["over_repeated"]["mean"], expected, rtol=1e-9, atol=0)
    reg = row["registrations"]
    assert reg["offsets"] == (2 * 40 // 2) ** 2
    assert all(lo <= m <= hi for lo, m, hi in zip(reg["min"], row["over_repeated"]["mean"], reg["max"]))
    assert len(row["raster_change"]) == 3 and np.isfinite(row["raster_change"]).all()  # quick: one check
    assert (tmp_path / "out" / "study_design_bands_registrations_one.png").is_file()
    assert "arranged" in (tmp_path / "out" / "study_design_bands.md").read_text()
