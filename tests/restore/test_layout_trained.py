"""`udc-render study layout-trained` (restore.studies.layout_trained): its layouts at equal footing, the paired
differences, the one-line refusals, and the quick study end to end (slow)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from psf.turned import TurnedLayout
from restore.online import clean_images
from restore.studies.layout_trained import NAME, ROW_KEYS, entry_display, paired, run_study, score_set, study_budget
from restore.studies.robustness import study_scene, write_clean_images
from udc_render.cli import main
from udc_render.errors import UdcError
from udc_render.scene.geometry import sensor_kernel_px

FIGURES = Path(__file__).resolve().parents[2] / "docs" / "figures" / "design"


def test_a_preset_cell_framed_and_turned_keeps_its_open_area_and_gets_the_gain_one_over_it(tmp_path):
    """@edge@turned: the preset itself (psf.turned: no raster), its slit moved to the tile's edge and turned per tile;
    its open area is the preset's 20 % exactly, the gain 1 / 0.2, and no EXR is written."""
    d = entry_display(f"{FIGURES / 'toled168_20.toml'}@edge@turned", tmp_path)
    assert isinstance(d.layout, TurnedLayout) and d.layout.random_rotation and d.name == "toled168_20_edge_turned"
    assert d.layout.period_um == (168.0, 168.0) and not d.layout.periodic
    assert d.layout.power_transmittance == pytest.approx(0.20, rel=1e-12)
    assert d.gain == pytest.approx(5.0, rel=1e-12)
    slit = d.layout.base.openings[0]
    assert slit.cx_um - slit.width_um / 2 == pytest.approx(0.0, abs=1e-12) and not list(tmp_path.glob("*.exr"))
    plain = entry_display(str(FIGURES / "poled_20.toml"), tmp_path)
    assert plain.layout.describe()["kind"] == "periodic" and plain.gain == pytest.approx(1 / 0.2)


def test_a_micrograph_cell_is_taken_pixel_for_pixel(tmp_path):
    d = entry_display(f"{FIGURES / 'design_crop' / 'design.toml'}@turned", tmp_path)
    source = entry_display(str(FIGURES / "design_crop" / "design.toml"), tmp_path)
    assert np.array_equal(d.layout.image, source.layout.image) and d.layout.random_rotation
    assert d.gain == pytest.approx(source.gain)


@pytest.mark.parametrize("spec, match", [("toled@sideways", "unknown or repeated modifier @sideways"),
                                         ("toled@turned@turned", "unknown or repeated modifier @turned"),
                                         ("glass", "glass has no pixel layout")])
def test_a_bad_entry_is_refused_in_one_line(tmp_path, spec, match):
    with pytest.raises(UdcError, match=match):
        entry_display(spec, tmp_path)


def test_the_cli_refuses_a_bad_entry_before_any_work(tmp_path, capsys):
    assert main(["study", "layout-trained", "--display", "toled,poled@flipped", "--out", str(tmp_path / "o")]) != 0
    err = capsys.readouterr().err
    assert "poled@flipped" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o" / "banks").exists()


@pytest.mark.parametrize("option, says", [("--train-epochs", "--train-epochs 0: expected a count ≥ 1"),
                                          ("--pitch-um", "--pitch-um must be > 0, got 0")])
def test_the_cli_refuses_a_zero_count_or_pitch_before_any_work(tmp_path, capsys, option, says):
    assert main(["study", "layout-trained", "--display", "toled", option, "0", "--out", str(tmp_path / "o")]) != 0
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("count", ["1", "257"])
def test_the_cli_refuses_a_score_set_out_of_range_before_any_work(tmp_path, capsys, count):
    assert main(["study", "layout-trained", "--display", "toled", "--score-images", count, "--out",
                 str(tmp_path / "o")]) != 0
    err = capsys.readouterr().err
    assert f"--score-images {count}: expected a count in 2 … 256" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_a_larger_score_set_begins_with_the_training_sets_validation_images(tmp_path):
    """--score-images n: the budget's items, then more of the same generator, so the first validation images (and
    their noise draws, drawn per image) are the ones the default scores; n equal to the budget's is its own set."""
    b = study_budget(quick=True)
    train_set = write_clean_images(tmp_path / "clean", b)
    assert score_set(tmp_path, b, None) == score_set(tmp_path, b, b.val_images) == train_set
    larger = score_set(tmp_path, b, b.val_images + 2)
    first, more = clean_images(train_set, "val"), clean_images(larger, "val")
    assert len(more) == b.val_images + 2 and len(clean_images(larger, "train")) == b.train_images
    for a, c in zip(first, more):
        assert np.array_equal(a.pixels, c.pixels)
    assert not np.array_equal(more[-1].pixels, more[0].pixels)


def test_a_finer_pitch_keeps_the_frame_and_the_kernels_reach():
    """--pitch-um 3.1: the full budget's 512 × 256 px at half its pitch, its kernels twice the pixels (the same
    reach in µm: 129 px of 6.2 µm, 257 of 3.1), the rest of the recipe unchanged."""
    full, fine = study_budget(), study_budget(pitch_um=3.1)
    assert (full.pitch_um, fine.pitch_um) == (6.2, 3.1) and fine.sensor_px == full.sensor_px
    assert fine == study_budget(pitch_um=3.1) and {**vars(fine), "pitch_um": 6.2} == vars(full)
    assert (sensor_kernel_px(study_scene(full)), sensor_kernel_px(study_scene(fine))) == (129, 257)
    assert study_budget(epochs=240).epochs == 240 and study_budget(quick=True).pitch_um == 12.4


def test_paired_differences():
    p = paired([21.0, 23.0, 22.5], [20.0, 22.0, 23.0])
    d = np.array([1.0, 1.0, -0.5])
    assert p["mean_db"] == pytest.approx(d.mean()) and p["wins"] == 2 and p["n"] == 3
    assert p["se_db"] == pytest.approx(d.std(ddof=1) / math.sqrt(3))
    assert math.isnan(paired([1.0], [0.0])["se_db"])


@pytest.mark.slow
def test_the_quick_study_compares_two_layouts_and_resumes(tmp_path):
    """Two layouts (the repeated T-OLED in a 168 µm cell, and it turned): a bank, a UNet and scores each; the
    reference's paired differences are zero; a second run recomputes nothing and gives the same document."""
    specs = [str(FIGURES / "toled168_20.toml"), f"{FIGURES / 'toled168_20.toml'}@edge@turned"]
    doc = run_study(tmp_path, specs, quick=True, progress=False)
    assert [r["layout"] for r in doc["rows"]] == ["toled168_20", "toled168_20_edge_turned"]
    assert doc["paired"]["toled168_20"]["unet"]["mean_db"] == 0.0
    for r in doc["rows"]:
        assert all(math.isfinite(r[f"psnr_{k}_db"]) for k in ROW_KEYS)
    again = run_study(tmp_path, specs, quick=True, progress=False)
    assert again["rows"] == doc["rows"]
    assert json.loads((tmp_path / f"{NAME}.json").read_text())["specs"] == specs
    assert (tmp_path / f"{NAME}_restored.png").is_file()
