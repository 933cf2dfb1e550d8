"""End-to-end restoration checks on rendered captures (slow: `pytest -m slow`)."""
import json

import numpy as np
import pytest

pytestmark = pytest.mark.slow


def test_face_study_recalls_the_clean_chart_and_loses_faces_behind_the_displays(tmp_path):
    """The chart's boxes mapped through the rig's geometry must match MTCNN's detections on the
    clean capture of the easy chart (measured at 1024 × 512: 45/45, mean IoU 0.85; at 512 × 256: 42/45)."""
    from restore.studies.faces import face_experiment
    t = face_experiment(tmp_path / "faces", sensor_px=(512, 256), progress=False,
                        chart={"face_px": (60, 160), "contrast": (1.0, 1.0)})
    rows = {(r["condition"], r["display"]): r for r in t["rows"]}
    clean = rows[("clean", "glass")]
    assert clean["recall"] >= 0.8 and clean["mean_iou_of_matches"] > 0.75
    assert rows[("degraded", "poled")]["recall"] < clean["recall"]
    assert rows[("degraded", "toled")]["recall"] < clean["recall"]
    assert (tmp_path / "faces" / "detections.png").is_file() and (tmp_path / "faces" / "faces.md").is_file()


def test_results_quick_budget_runs_every_stage(tmp_path):
    from restore.studies.results import run_results
    r = run_results(tmp_path / "res", "quick", progress=False, carry=tmp_path / "carry")
    methods = r["results"]["methods"]
    assert set(methods) == {"input", "dep", "dep_exact", "unet", "resnet", "unet_syn", "unet_random"}
    for d in ("toled", "poled"):
        # DeP improves on the degraded input on rendered T-OLED and P-OLED pairs
        assert methods["dep"]["displays"][d]["psnr_db_paper"] > methods["input"]["displays"][d]["psnr_db_paper"]
        assert np.isfinite(methods["unet"]["displays"][d]["psnr_db_paper"])
        assert np.isfinite(methods["unet_random"]["displays"][d]["psnr_db_paper"])  # trained online, scored on d
        assert (tmp_path / "res" / "banks" / f"random_{d}" / "bank.json").is_file()
    doc = (tmp_path / "res" / "RESULTS.md").read_text()
    assert doc.startswith("# Restoration results")
    assert "## Training (quick budget)" in doc and "![training curves](figures/training_curves.png)" in doc
    assert (tmp_path / "res" / "figures" / "training_curves.png").is_file()
    assert "| test | " in doc  # the content table per split
    # two training lines, a row in each protocol's table, one in the level table, one held out, one per display in
    # the error bands
    assert doc.count("| unet_syn |") == 8 and doc.count("| unet_random |") == 8
    assert "## Where the error lies (spatial frequency)" in doc
    assert "## Level and structure (test split, paper protocol)" in doc and "| input | " in doc.split("## Level")[1]
    assert (tmp_path / "res" / "figures" / "error_bands_poled.png").is_file()
    assert set(r["heldout"]["methods"]) == set(methods) and "## Held-out photographs (a content check)" in doc
    assert r["heldout"]["methods"]["input"]["displays"]["toled"]["images"] == 2
    faces = {(row["condition"], row["display"]) for row in r["faces"]["rows"]}
    assert {("unet", "poled"), ("resnet", "toled"), ("unet ×k", "toled"), ("resnet ×k", "poled")} <= faces
    assert all(k > 0 for k in r["faces"]["level_gain"].values()) and "A `×k` row restores" in doc
    row_seconds = {ev: json.loads((tmp_path / "res" / ev / "row_seconds.json").read_text())
                   for ev in ("eval", "eval_heldout")}
    assert all(set(s) == set(methods) and min(s.values()) > 0 for s in row_seconds.values())
    assert "## Machine time" in doc and "| scoring, test split |" in doc
    # the paper dataset is made after every row on the physical captures (budgets.TRAIN_ORDER)
    paper_first = min(p.stat().st_mtime_ns for p in (tmp_path / "res" / "dataset_paper").rglob("*") if p.is_file())
    assert all((tmp_path / "res" / "train" / f"{row}_{d}" / "loss.csv").stat().st_mtime_ns < paper_first
               for row in ("unet", "unet_random", "resnet") for d in ("toled", "poled"))

    # a second run resumes every stage: nothing is rendered, trained or scored again (timing.jsonl, the loss
    # logs and the per-image scores untouched), and the manifests and models are the same bytes
    res = tmp_path / "res"
    scores = {p: p.stat().st_mtime_ns for p in res.rglob("metrics_*.csv")}
    untouched = {p: p.stat().st_mtime_ns for p in res.rglob("*") if p.name in ("timing.jsonl", "loss.csv")}
    same = {p: p.read_bytes() for p in res.rglob("*") if p.name in ("model.pt", "manifest.jsonl")}
    again = run_results(res, "quick", progress=False, carry=tmp_path / "carry")
    assert len(untouched) == 3 + 4 * 2 and all(p.stat().st_mtime_ns == t for p, t in untouched.items())
    assert len(same) == 3 + 4 * 2 and all(p.read_bytes() == b for p, b in same.items())
    assert len(scores) == 2 * 7 * 2 and all(p.stat().st_mtime_ns == t for p, t in scores.items())
    assert all(json.loads((res / ev / "row_seconds.json").read_text()) == v for ev, v in row_seconds.items())
    for d in ("toled", "poled"):  # the same weights on the same pairs
        assert (again["results"]["methods"]["unet"]["displays"][d]["psnr_db_paper"] ==
                methods["unet"]["displays"][d]["psnr_db_paper"])

    # a fresh machine (a new out, the carry only): the rows come back from the carry without training, and the
    # UNet (randomized) row is checked against its carried bank.json without making the bank; its time is kept
    fresh = run_results(tmp_path / "fresh", "quick", progress=False, carry=tmp_path / "carry")
    assert not (tmp_path / "fresh" / "banks" / "random_toled").exists()
    assert not any((tmp_path / "fresh" / "train").rglob("checkpoint.pt"))
    for d in ("toled", "poled"):
        assert (tmp_path / "fresh" / "train" / f"unet_random_{d}" / "loss.csv").read_bytes() == \
            (res / "train" / f"unet_random_{d}" / "loss.csv").read_bytes()
        assert fresh["results"]["methods"]["unet_random"]["displays"][d]["psnr_db_paper"] == \
            methods["unet_random"]["displays"][d]["psnr_db_paper"]
    assert json.loads((tmp_path / "fresh" / "banks" / "seconds.json").read_text()) == \
        json.loads((res / "banks" / "seconds.json").read_text())
