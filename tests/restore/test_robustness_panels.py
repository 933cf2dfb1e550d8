"""restore.studies.robustness_panels: the randomized UNet on the first N panels of the robustness study's bank."""
from __future__ import annotations

import csv
import json
import math

import pytest

from restore.studies.robustness import BUDGETS
from restore.studies.robustness_panels import (
    COLUMNS,
    PANEL_SETS,
    STEM,
    Run,
    first_panels,
    run_name,
    run_panels,
    summary,
)
from udc_render.dataset.bank import Bank
from udc_render.errors import UdcError


def _study_row(s, panel, rnd, fixed=10.0, dep=12.0):
    return {"set": s, "panel": panel, "psnr_randomized_db": rnd, "psnr_randomized_level_db": rnd + 1,
            "psnr_fixed_db": fixed, "psnr_dep_db": dep}


def test_the_summary_puts_the_studys_own_model_at_its_panel_count():
    """N rows in ascending order, each set the mean over its panels; N = train_panels from the study's rows; a
    capture-per-crop run at N = train_panels after it, from its own rows."""
    b = BUDGETS["full"]
    rows = [{"panels": 4, "set": "heldout", "panel": "random_000", "psnr_db": 20.0, "psnr_level_db": 21.0},
            {"panels": 4, "set": "heldout", "panel": "random_001", "psnr_db": 22.0, "psnr_level_db": 23.0},
            {"panels": 4, "set": "toled", "panel": "toled", "psnr_db": 18.0, "psnr_level_db": 19.0},
            {"panels": b.train_panels, "captures": True, "set": "heldout", "panel": "random_000", "psnr_db": 27.0,
             "psnr_level_db": 28.0},
            {"panels": b.train_panels, "seed": 5, "set": "heldout", "panel": "random_000", "psnr_db": 23.0,
             "psnr_level_db": 24.0}]
    study = [_study_row("heldout", "random_000", 24.0), _study_row("heldout", "random_001", 26.0),
             _study_row("toled", "toled", 21.0)]
    table = summary(rows, study, b, {Run(4): {"steps": 100, "seconds": 5.0},
                                     Run(b.train_panels, True): {"steps": 100, "seconds": 7.0},
                                     Run(b.train_panels, seed=5): {"steps": 100, "seconds": 8.0}},
                    {"steps": 100, "seconds": 6.0})
    assert [(r["panels"], r["captures"], r["seed"]) for r in table] == [
        (4, "the panel's", 0), (b.train_panels, "the panel's", 0), (b.train_panels, "the panel's", 5),
        (b.train_panels, "its own", 0)]
    assert table[3]["psnr_heldout_db"] == 27.0 and table[3]["train_s"] == 7.0 and "psnr_toled_db" not in table[3]
    assert table[2]["psnr_heldout_level_db"] == 24.0 and table[2]["train_s"] == 8.0
    assert [run_name(r) for r in (Run(4), Run(16, True), Run(16, seed=5))] == [
        "randomized_n4", "randomized_captures", "randomized_seed5"]
    assert table[0]["psnr_heldout_db"] == 21.0 and table[0]["psnr_heldout_level_db"] == 22.0
    assert table[1]["psnr_heldout_db"] == 25.0 and table[1]["psnr_toled_level_db"] == 22.0
    assert "psnr_default_db" not in table[0]  # a set without rows has no mean


def test_a_panel_count_outside_the_bank_is_refused_in_one_line(tmp_path):
    bank = Bank(tmp_path, {}, ["p0", "p1", "p2"])
    assert first_panels(bank, 2).panels == ["p0", "p1"]
    with pytest.raises(UdcError, match=r"--counts: 4 panels: expected 1 to 3"):
        first_panels(bank, 4)
    with pytest.raises(UdcError, match=r"--counts: 0 panels: expected 1 to 4"):  # refused before any computation
        run_panels(tmp_path / "study", [0], quick=True, progress=False)
    with pytest.raises(UdcError, match=r"--seeds: 0: the study's own training seed"):
        run_panels(tmp_path / "study", [2], quick=True, progress=False, seeds=(0,))
    assert not (tmp_path / "study").exists()


@pytest.mark.slow
def test_the_quick_study_trains_and_scores_a_smaller_panel_count(tmp_path):
    """The quick robustness study, then N = 2 of its 4 panels, N = 4 with a capture per crop and N = 4 with
    training seed 1: the same steps, every set scored and finite; N = 4 with the panel's captures and seed 0 is
    the study's own randomized model."""
    b = BUDGETS["quick"]
    table = run_panels(tmp_path / "study", [2], quick=True, progress=False, captures=True, seeds=(1,))
    assert [(r["panels"], r["captures"], r["seed"]) for r in table] == [
        (2, "the panel's", 0), (b.train_panels, "the panel's", 0), (b.train_panels, "the panel's", 1),
        (b.train_panels, "its own", 0)]
    assert all(r["steps"] == b.steps for r in table)
    with open(tmp_path / "study" / f"{STEM}.csv") as f:
        written = list(csv.DictReader(f))
    assert list(written[0]) == COLUMNS and len(written) == 4
    assert all(math.isfinite(float(r[f"psnr_{s}{t}_db"])) for r in written for s in PANEL_SETS for t in ("", "_level"))
    assert (tmp_path / "study" / f"{STEM}.png").stat().st_size > 1000


@pytest.fixture
def fake_runs(monkeypatch, tmp_path):
    """score_runs with one panel per set, models that are their files' bytes, each scored by its length;
    returns (the module, out, the banks, the predictions made)."""
    from types import SimpleNamespace

    import restore.studies.robustness_panels as P
    predictions = []

    def predict(model, x, device):
        predictions.append(model)
        return model
    banks = {s: SimpleNamespace(fingerprint=f"bank {s}", panels=[SimpleNamespace(name=f"{s} panel")])
             for s in PANEL_SETS}
    monkeypatch.setattr(P, "read_bank", lambda folder: banks[folder.name])
    monkeypatch.setattr(P, "clean_images", lambda data, split: [])
    monkeypatch.setattr(P, "images_fingerprint", lambda data: "the validation images")
    monkeypatch.setattr(P, "load_model", lambda path, device: (path.read_bytes(), {}))
    monkeypatch.setattr(P, "panel_pairs", lambda bank, panel, images: [(None, None)])
    monkeypatch.setattr(P, "predict", predict)
    monkeypatch.setattr(P, "paper_metrics", lambda y, gt: {"psnr_db_paper": float(len(y))})
    monkeypatch.setattr(P, "level_matched_psnr_db", lambda y, gt: float(len(y)))
    out = tmp_path / "study"
    (out / "train" / run_name(Run(2))).mkdir(parents=True)
    (out / "train" / run_name(Run(2)) / "model.pt").write_bytes(b"weights")
    return P, out, banks, predictions


def test_a_retrained_run_is_scored_again_and_another_runs_rows_are_kept(fake_runs, capsys):
    P, out, banks, predictions = fake_runs
    other = {"panels": 3, "set": "heldout", "panel": "heldout panel", "psnr_db": 1.0}  # logged by another call
    (out / P.ROWS_FILE).write_text(json.dumps(other) + "\n")
    rows = P.score_runs(out, [Run(2)], out / "clean", progress=False)
    assert len(predictions) == len(PANEL_SETS) and rows[0] == other
    assert {r["psnr_db"] for r in rows[1:]} == {7.0}
    assert P.score_runs(out, [Run(2)], out / "clean", progress=False) == rows and len(predictions) == len(PANEL_SETS)
    (out / "train" / run_name(Run(2)) / "model.pt").write_bytes(b"retrained weights")
    again = P.score_runs(out, [Run(2)], out / "clean", progress=False)
    assert len(predictions) == 2 * len(PANEL_SETS) and again[0] == other
    assert {r["psnr_db"] for r in again[1:]} == {17.0}
    assert f"robustness panels: {len(PANEL_SETS)} logged rows in" in capsys.readouterr().out
    banks["toled"].fingerprint = "another bank"
    P.score_runs(out, [Run(2)], out / "clean", progress=False)
    assert len(predictions) == 2 * len(PANEL_SETS) + 1
