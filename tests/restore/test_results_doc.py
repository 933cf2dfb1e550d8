"""The results document's ordering checks are computed from the tables (restore.studies.results)."""
from restore.studies.orderings import PAPER_SYN_GAP_DB, ordering_checks


def _results(psnr: dict) -> dict:
    return {"methods": {name: {"displays": {d: {"psnr_db_paper": v} for d, v in by_display.items()}}
                        for name, by_display in psnr.items()}}


def test_ordering_checks_follow_the_tables():
    table = {"dep": {"toled": 28.5, "poled": 17.0}, "unet": {"toled": 36.7, "poled": 30.5},
             "unet_syn": {"toled": 32.4, "poled": 25.9}, "resnet": {"toled": 36.3, "poled": 27.4},
             "input": {"toled": 20.0, "poled": 12.0}}  # the paper's Table 2 (UNet (Syn): UNet − 4.3 / 4.6)
    checks = {claim: (ok, values) for claim, ok, values in ordering_checks(_results(table))}
    assert all(ok for ok, _ in checks.values()) and len(checks) == 2 * 2 + 5
    ok, values = checks["UNet (Syn) below UNet on toled (PSNR)"]
    assert "gap 4.30 dB" in values and f"paper {PAPER_SYN_GAP_DB['toled']:g} dB" in values

    table["unet"]["poled"] = 19.0  # within 3 dB of DeP, below the UNet (Syn), easier than the T-OLED: all fail
    table["unet"]["toled"] = 18.0
    checks = {claim: ok for claim, ok, _ in ordering_checks(_results(table))}
    assert not checks["UNet above DeP by ≥ 3 dB on poled (PSNR)"]
    assert not checks["UNet (Syn) below UNet on poled (PSNR)"]
    assert not checks["P-OLED harder than T-OLED for unet (PSNR)"]
    assert checks["P-OLED harder than T-OLED for dep (PSNR)"]


def test_face_table_puts_the_papers_recall_beside_ours():
    from restore.studies.faces import faces_markdown
    rows = [{"condition": "clean", "display": "glass", "faces": 45, "found": 28, "recall": 28 / 45},
            *({"condition": c, "display": d, "faces": 45, "found": f, "recall": f / 45}
              for c, d, f in (("degraded", "toled", 1), ("degraded", "poled", 0), ("DeP", "toled", 7),
                              ("DeP", "poled", 0), ("unet", "toled", 20), ("unet", "poled", 9)))]
    lines = faces_markdown({"rows": rows}).splitlines()
    assert lines[0] == "| MTCNN recall | T-OLED | paper | P-OLED | paper |"
    assert lines[2] == "| clean | 62 % (28/45) | 60 % | 62 % (28/45) | 60 % |"  # the same clean view twice
    assert lines[4] == "| DeP | 16 % (7/45) | — | 0 % (0/45) | — |"  # the paper has no DeP row
    assert lines[5] == "| unet | 44 % (20/45) | 56 % | 20 % (9/45) | 39 % |"


def test_face_exposure_text_is_computed_from_the_face_table():
    from restore.studies.results_document import faces_levels_text
    table = {"chart_level": {"toled": 0.163, "poled": 0.055}, "train_level": {"toled": 0.347, "poled": 0.116},
             "level_gain": {"toled": 0.347 / 0.163, "poled": 0.116 / 0.055}}
    text = faces_levels_text(table)[0]
    assert "T-OLED 0.163 against 0.347 (k = 2.13); P-OLED 0.055 against 0.116 (k = 2.11)" in text
    assert faces_levels_text({"rows": []}) == []  # a table made without the training levels: no sentence


def test_evaluation_stamp_follows_the_checkpoint_and_the_data(tmp_path):
    """A row is scored again (restore.studies.scoring.evaluate_rows) exactly when its stamp changes."""
    import json

    from restore.studies.scoring import evaluation_stamp
    data = tmp_path / "data"
    data.mkdir()
    (data / "manifest.jsonl").write_text(json.dumps({"item": 0, "split": "test"}) + "\n")
    ckpt = tmp_path / "model.pt"
    ckpt.write_bytes(b"weights a")
    first = evaluation_stamp(data, str(ckpt))
    assert evaluation_stamp(data, str(ckpt)) == first
    assert len({first, evaluation_stamp(data, "input"), evaluation_stamp(data, "dep")}) == 3
    ckpt.write_bytes(b"weights b")  # retrained
    assert evaluation_stamp(data, str(ckpt)) != first
    ckpt.write_bytes(b"weights a")
    (data / "manifest.jsonl").write_text(json.dumps({"item": 1, "split": "test"}) + "\n")  # other items
    assert evaluation_stamp(data, str(ckpt)) != first


def test_machine_time_is_summed_from_what_each_stage_recorded(tmp_path):
    """The budget table adds the datasets' item seconds, the models' summaries and the rows' scoring seconds
    (each summed over resumed parts; a model's active time where it has a loss log), plus this invocation's
    redone stages: a golden total."""
    import json

    from restore.studies.results_document import budget_section
    out = tmp_path / "res"
    datasets = {p: out / f"dataset_{p}" for p in ("physical", "paper")}
    for i, folder in enumerate(datasets.values()):
        folder.mkdir(parents=True)
        (folder / "timing.jsonl").write_text("".join(json.dumps({"item": k, "seconds": 900.0 * (i + 1)}) + "\n"
                                                     for k in range(4)))  # 1 h and 2 h
    for name, seconds in (("unet_toled", 1800.0), ("resnet_poled", 5400.0)):
        (out / "train" / name).mkdir(parents=True)
        (out / "train" / name / "train_summary.json").write_text(json.dumps({"seconds": seconds}))
    (out / "train" / "unet_toled" / "loss.csv").write_text(  # 3 epochs of 720 s, the last one paused for 3 h
        "epoch,step,lr,loss,val_psnr_db,seconds\n1,1,0,0,,720\n2,2,0,0,,1440\n3,3,0,0,,12960\n")
    (out / "eval").mkdir()
    (out / "eval" / "row_seconds.json").write_text(json.dumps({"input": 360.0, "dep": 3240.0}))  # 1 h
    lines = budget_section(out, datasets, {"error_bands_s": 720.0, "faces_s": 1080.0})  # 0.2 h and 0.3 h
    text = "\n".join(lines)
    assert "| dataset, physical profile | 1.00 |" in text and "| dataset, paper profile | 2.00 |" in text
    assert "| training, 2 models | 2.20 |" in text  # 0.7 h active (720 + 720 + 1.5 × 720 s) and 1.5 h
    assert "| scoring, test split | 1.00 |" in text
    assert "| held-out photographs: dataset | 0.00 |" in text  # not made: nothing counted
    assert "| **total** | **6.70** |" in text and "this run took 0.84 of it" in text


def test_training_table_reports_each_models_trend_at_the_end(tmp_path):
    """A model stopped by its epoch cap while still rising shows the plateau as not reached and its rise per
    fifth of the steps: here 0.05 dB per validation of 150 steps, at step 2400 a fifth is 480 steps: +0.16 dB."""
    import json

    from restore.studies.budgets import BUDGETS, run_dir
    from restore.studies.results_document import training_table
    from restore.train import LOG_COLUMNS
    from udc_render.io.files import csv_text
    run = run_dir(tmp_path, "unet", "toled")
    run.mkdir(parents=True)
    log = [{"epoch": 2 * (i + 1), "step": 150 * (i + 1), "lr": 2e-4, "loss": 0.05, "val_psnr_db": 24.0 + 0.05 * i,
            "seconds": 100.0 * (i + 1)} for i in range(16)]
    (run / "loss.csv").write_text(csv_text(log, LOG_COLUMNS))
    (run / "train_summary.json").write_text(json.dumps({"epochs": 32, "epochs_planned": 32, "steps": 2400,
                                                        "plateaued": False, "val_psnr_db": 24.75, "seconds": 3600}))
    lines = training_table(tmp_path, BUDGETS["cpu"])
    assert lines[2] == "| unet | toled | 32 (32) | 2400 | 1.00 | 0.44 | **not reached** | 24.75 | +0.16 |"  # 16 × 100 s


def test_active_time_leaves_out_a_pause_and_keeps_the_validated_epochs():
    """9 epochs of 30 s and 11 validated ones of 36 s, one of them stretched by a 2 h pause: the paused epoch
    counts 1.5 × the median (36 s), the rest as they ran; golden sums."""
    from restore.studies.stage_times import active_seconds
    epochs = [30.0, 36.0] * 9 + [36.0, 36.0]
    epochs[7] += 7200.0
    log = [{"seconds": float(sum(epochs[:k + 1]))} for k in range(len(epochs))]
    assert log[-1]["seconds"] == 7866.0
    assert active_seconds(log) == 666.0 - 36.0 + 54.0
    assert active_seconds(log[:0]) == 0.0
    assert active_seconds([{"seconds": 30.0}] * 1) == 30.0


def test_the_level_table_splits_level_from_structure_and_marks_rows_scored_before_it():
    from restore.evaluate import level_table
    scored = {"psnr_db_paper": 21.43, "psnr_db_paper_matched": 25.20, "level_r": 0.6, "level_g": 0.546, "level_b": 0.5}
    results = {"methods": {"unet_random": {"displays": {"poled": scored}},
                           "unet": {"displays": {"poled": {"psnr_db_paper": 26.35}}}}}
    lines = level_table(results).splitlines()
    assert lines[0] == "| Method | P-OLED PSNR | P-OLED matched | P-OLED level costs | P-OLED level R/G/B |"
    assert lines[2] == "| unet | — | — | — | — |"  # the paper's order: UNet, then UNet (randomized)
    assert lines[3] == "| unet_random | 21.43 | 25.20 | 3.77 | 0.60/0.55/0.50 |"
