"""`udc-render study robustness` (restore.studies.robustness): the report on hand-made rows, and the quick study."""
from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from restore.studies.robustness_report import COLUMNS, SETS, summary_rows, write_report
from udc_render.errors import UdcError

BUDGET = {"name": "quick", "model": {"type": "unet", "width": 8}, "steps": 40, "epochs": 10, "train_images": 8,
          "crops_per_image": 2, "batch": 4, "crop_px": 32, "lr": 3e-3, "clip_grad_norm": None, "val_images": 4,
          "sensor_px": [128, 64], "pitch_um": 24.8, "bands_nm": "400:700:100", "field_phases": 2, "train_panels": 4,
          "heldout_panels": 2, "seeds": {"train": 0, "score": 2026}}


def _row(s, panel, inp, fixed, rnd, level_db=1.0, dep=15.0):
    """A score row; its level-matched PSNR is each PSNR + level_db."""
    return {"set": s, "panel": panel, "family": "poled", "distance_mm": 2.0, "images": 4, "psnr_input_db": inp,
            "psnr_dep_db": dep, "psnr_dep_noiseless_db": dep + 3, "psnr_fixed_db": fixed, "psnr_randomized_db": rnd,
            "psnr_input_level_db": inp + level_db, "psnr_dep_level_db": dep + level_db,
            "psnr_dep_noiseless_level_db": dep + 3 + level_db, "psnr_fixed_level_db": fixed + level_db,
            "psnr_randomized_level_db": rnd + level_db, "seconds": 1.5}


def _result(rows):
    return {"rows": rows, "budget": BUDGET, "times": {"clean images": 0.5, "bank default": 2.0},
            "train": {"fixed": {"seconds": 10.0, "steps": 40, "val_psnr_db": 20.0},
                      "randomized": {"seconds": 12.0, "steps": 40, "val_psnr_db": 19.0}}}


def test_the_drops_are_against_each_models_own_default_panel_score():
    """A set's PSNR is its panels' mean; each model's drop is its set PSNR less its own default-panel PSNR."""
    rows = [_row("default", "poled", 12.0, 24.0, 22.0), _row("heldout", "random_000", 10.0, 18.0, 21.0),
            _row("heldout", "random_001", 14.0, 20.0, 23.0), _row("far", "poled", 11.0, 19.5, 21.5)]
    s = {r["set"]: r for r in summary_rows(rows)}
    assert list(s) == ["default", "heldout", "far"]  # SETS' order, only the sets present
    held, far = s["heldout"], s["far"]
    assert held["panels"] == 2 and held["psnr_fixed_db"] == 19.0 and held["psnr_input_db"] == 12.0
    assert held["drop_fixed_db"] == pytest.approx(-5.0) and held["drop_randomized_db"] == pytest.approx(0.0)
    assert far["drop_fixed_db"] == pytest.approx(-4.5) and far["randomized_minus_fixed_db"] == pytest.approx(2.0)
    assert s["default"]["drop_fixed_db"] == 0.0
    assert s["heldout"]["psnr_fixed_level_db"] == 20.0 and s["far"]["drop_fixed_level_db"] == pytest.approx(-4.5)
    assert summary_rows(rows[1:])[0]["drop_fixed_db"] is None  # no default row: no drop


def test_the_report_writes_its_table_figure_and_budget(tmp_path):
    rows = [_row(s, f"p_{s}", 10.0 + i, 20.0 - i, 19.0) for i, s in enumerate(SETS)]
    write_report(tmp_path, _result(rows))
    with open(tmp_path / "study_robustness.csv") as f:
        table = list(csv.DictReader(f))
    assert [r["set"] for r in table] == list(SETS) and list(table[0]) == COLUMNS
    assert float(table[6]["drop_fixed_db"]) == pytest.approx(-6.0) and float(table[6]["drop_randomized_db"]) == 0.0
    md = (tmp_path / "study_robustness.md").read_text()
    assert "40 Adam steps" in md and "crops of 32 px" in md and "total 35 s" in md  # 0.5 + 2 + 10 + 12 + 7 × 1.5
    assert "| T-OLED at d = 8 mm | 1 | 16.00 | 15.00 | 18.00 | 14.00 | -6.00 | 19.00 | 0.00 | +5.00 |" in md
    # level-matched
    assert "| T-OLED at d = 8 mm | 1 | 17.00 | 16.00 | 19.00 | 15.00 | -6.00 | 20.00 | 0.00 | +5.00 |" in md
    assert (tmp_path / "study_robustness.png").stat().st_size > 1000


def test_a_non_finite_score_is_refused_in_one_line(tmp_path):
    rows = [_row("default", "poled", 12.0, math.nan, 22.0)]
    with pytest.raises(UdcError, match=r"non-finite PSNR for \('default', 'poled', 'fixed'\)"):
        write_report(tmp_path, _result(rows))


@pytest.mark.slow
def test_the_quick_study_scores_every_set_and_resumes(tmp_path):
    """The quick study (~3-4 min on 2 loaded cores): seven sets, both models' scores finite and every panel scored
    on the same images; a re-run with a score row removed re-scores only that row, to the same values."""
    from restore.studies.robustness import BUDGETS, SCORES_FILE, run_study
    out, cache = tmp_path / "study", str(tmp_path / "kernels")
    result = run_study(out, quick=True, cache_dir=cache, progress=False)
    b = BUDGETS["quick"]
    with open(out / "study_robustness.csv") as f:
        table = list(csv.DictReader(f))
    assert [r["set"] for r in table] == list(SETS) and list(table[0]) == COLUMNS
    assert [int(r["panels"]) for r in table] == [1, b.heldout_panels, 1, 1, 1, 1, 1]
    assert all(math.isfinite(float(r[c])) for r in table for c in COLUMNS[3:])
    assert all(r["images"] == b.val_images and len(r["per_image_db"]["randomized"]) == b.val_images
               and len(r["per_image_db"]["dep"]) == len(r["per_image_db"]["dep_noiseless"]) == b.val_images
               for r in result["rows"])
    assert result["train"]["fixed"]["steps"] == result["train"]["randomized"]["steps"] == b.steps
    trained = json.loads((out / "train" / "randomized" / "train.json").read_text())
    assert trained["degrade"]["panels"] == [f"random_{i:03d}" for i in range(b.train_panels)]
    far = {r["set"]: (r["panel"], r["distance_mm"]) for r in result["rows"] if r["set"] in ("far", "toled_far")}
    assert far == {"far": ("poled", 8.0), "toled_far": ("toled", 8.0)}
    lines = (out / SCORES_FILE).read_text().splitlines()
    (out / SCORES_FILE).write_text("\n".join(lines[:-1]) + "\n")
    again = run_study(out, quick=True, cache_dir=cache, progress=False)
    last = json.loads(lines[-1])
    redone = again["rows"][-1]
    assert (redone["set"], redone["panel"]) == (last["set"], last["panel"])
    assert np.allclose(redone["per_image_db"]["fixed"], last["per_image_db"]["fixed"], atol=1e-6)
    assert again["rows"][:-1] == result["rows"][:-1]


@pytest.fixture
def fake_scoring(monkeypatch, tmp_path):
    """restore.studies.robustness.score with one panel per set, models that are their files' bytes and a
    score_panel that scores each model by its length; returns (the study module, out, banks, the calls)."""
    from types import SimpleNamespace

    import restore.studies.robustness as R
    from restore.studies.robustness_report import MODELS, ROWS
    calls = []

    def score_panel(models, bank, index, images):
        calls.append(bank.panels[index].name)
        scores = {k: [float(len(models[k])) if k in MODELS else 10.0] for k in ROWS if k not in MODELS or k in models}
        return {**scores, **{f"{k}_level": v for k, v in scores.items()}}
    monkeypatch.setattr(R, "load_model", lambda path, device: (path.read_bytes(), {}))
    monkeypatch.setattr(R, "clean_images", lambda data, split: [])
    monkeypatch.setattr(R, "images_fingerprint", lambda data: "the validation images")
    monkeypatch.setattr(R, "score_panel", score_panel)
    out = tmp_path / "study"
    for key in MODELS:
        (out / "train" / key).mkdir(parents=True)
        (out / "train" / key / "model.pt").write_bytes(b"weights")
    record = {"display": {"distance_mm": 2.0, "name": "poled"}}
    banks = {s: SimpleNamespace(fingerprint=f"bank {s}", panels=[SimpleNamespace(name=f"{s} panel", record=record)])
             for s in SETS}
    return R, out, banks, calls


def test_a_retrained_model_or_another_bank_recomputes_its_scores(fake_scoring, capsys):
    R, out, banks, calls = fake_scoring
    first = R.score(out, banks, out / "clean", progress=False)
    assert len(calls) == len(SETS) and {r["psnr_fixed_db"] for r in first} == {7.0}
    assert R.score(out, banks, out / "clean", progress=False) == first and len(calls) == len(SETS)
    (out / "train" / "fixed" / "model.pt").write_bytes(b"retrained weights")
    again = R.score(out, banks, out / "clean", progress=False)
    assert len(calls) == 2 * len(SETS) and {r["psnr_fixed_db"] for r in again} == {17.0}
    assert f"study robustness: {len(SETS)} logged rows in" in capsys.readouterr().out
    banks["heldout"].fingerprint = "another bank"
    R.score(out, banks, out / "clean", progress=False)
    assert calls[2 * len(SETS):] == ["heldout panel"]


def test_score_rows_without_a_fingerprint_are_recomputed(fake_scoring, capsys):
    R, out, banks, calls = fake_scoring
    rows = R.score(out, banks, out / "clean", progress=False)
    old = [{k: v for k, v in r.items() if k != "fingerprint"} for r in rows]  # a log from before the fingerprints
    (out / R.SCORES_FILE).write_text("".join(json.dumps(r) + "\n" for r in old))
    again = R.score(out, banks, out / "clean", progress=False)
    assert len(calls) == 2 * len(SETS)
    assert [{**r, "seconds": 0} for r in again] == [{**r, "seconds": 0} for r in rows]
    assert f"study robustness: {len(SETS)} logged rows in" in capsys.readouterr().out


def test_another_budgets_clean_images_are_refused_in_one_line(tmp_path):
    """A study folder resumed with another budget: its clean images (kept once made) are not this budget's."""
    from dataclasses import replace

    from restore.studies.robustness import BUDGETS, write_clean_images
    quick = BUDGETS["quick"]
    folder = write_clean_images(tmp_path / "clean", quick)
    manifest = (folder / "manifest.jsonl").read_bytes()
    assert write_clean_images(folder, quick) == folder and (folder / "manifest.jsonl").read_bytes() == manifest
    for other, says in ((BUDGETS["full"], "(12 of 128×64 px; the full budget makes 56 of 512×256 px)"),
                        (replace(quick, sensor_px=(64, 32)), "(12 of 128×64 px; the quick budget makes 12 of 64×32")):
        with pytest.raises(UdcError, match="another budget's clean images") as e:
            write_clean_images(folder, other)
        assert says in str(e.value) and "\n" not in str(e.value)


def test_the_conditioned_model_is_scored_with_each_panels_own_description(tmp_path, monkeypatch):
    """score_panel beside the two UNets, on untrained tiny weights (mechanics only): the conditioned model restores
    every image of a panel with describe_panel of that panel on the bank's frame, in its kernel window; a model
    made for another frame is refused in one line; the report adds its columns."""
    import torch

    from restore.conditioning import described_spec, description_tensors
    from restore.models import build_model
    from restore.models_conditioned import WienerUNet
    from restore.online import CleanImage
    from restore.studies.robustness import score_panel
    from restore.studies.robustness_report import CONDITIONED_COLUMNS
    from tests.restore.test_models_conditioned import TINY_9, _bank
    from udc_render.dataset.bank import read_bank
    from udc_render.description import DescriptionError
    from udc_render.description.make import describe_panel
    bank = read_bank(_bank(tmp_path, frame_px=(64, 32)))
    rng = np.random.default_rng(0)
    images = [CleanImage(f"im{i}", rng.uniform(0.1, 0.8, (3, 32, 64)).astype(np.float32)) for i in range(2)]
    torch.manual_seed(0)
    models = {"fixed": build_model({"type": "unet", "width": 4, "depth": 2}).eval(),
              "randomized": build_model({"type": "unet", "width": 4, "depth": 2}).eval(),
              "conditioned": build_model(TINY_9).eval()}
    seen, forward = [], WienerUNet.forward

    def spy(self, x, description):
        seen.append({k: v.clone() for k, v in description.items()})
        return forward(self, x, description)
    monkeypatch.setattr(WienerUNet, "forward", spy)
    scores = score_panel(models, bank, 1, images)
    want = description_tensors([describe_panel(bank.panels[1], (64, 32), kernel_px=9)])
    assert len(seen) == 2 and all(torch.equal(d[k], want[k]) for d in seen for k in want)
    assert {"conditioned", "conditioned_level", "fixed", "randomized"} <= set(scores)
    assert all(len(v) == 2 and all(map(math.isfinite, v)) for v in scores.values())
    models["conditioned"].set_description_spec(described_spec([describe_panel(bank.panels[0], (96, 64), 9)]))
    with pytest.raises(DescriptionError) as e:
        score_panel(models, bank, 0, images)
    assert "\n" not in str(e.value) and "frame" in str(e.value)
    rows = [dict(_row(s, f"p_{s}", 10.0, 20.0, 19.0), psnr_conditioned_db=21.0 + i, psnr_conditioned_level_db=22.0 + i)
            for i, s in enumerate(SETS)]
    write_report(tmp_path / "report", _result(rows))
    with open(tmp_path / "report" / "study_robustness.csv") as f:
        table = list(csv.DictReader(f))
    assert list(table[0]) == COLUMNS + CONDITIONED_COLUMNS
    assert float(table[6]["drop_conditioned_db"]) == 6.0 and float(table[6]["conditioned_minus_randomized_db"]) == 8.0
    assert "conditioned − randomized" in (tmp_path / "report" / "study_robustness.md").read_text()


def test_conditioned_is_refused_in_one_line_for_another_study(tmp_path, capsys):
    from udc_render.cli import main
    assert main(["study", "psf", "--conditioned", "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--conditioned: only `study robustness`" in err and not (tmp_path / "s").exists()
