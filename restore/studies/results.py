"""`udc-render results`: the whole loop in one resumable command, written up as RESULTS.md.

    datasets (udc-render dataset, builtin images, glass + T-OLED + P-OLED; physical and paper profiles)
      ─► train UNet and ResNet per display ─► evaluate input, DeP, ResNet, UNet on the test split
      ─► the same on held-out photographs (restore.studies.heldout)
      ─► face detection (restore.face_study) ─► RESULTS.md (tables, budget, the paper's ordering checked)

Every stage resumes: the dataset and training runs pick up where they stopped; evaluation and the
face study are re-run (minutes to an hour). BUDGETS holds the settings; 'cpu' makes the paper's framing
(2048 × 1024, 150/20/30 items per profile) and trains each model to its validation plateau under an epoch
cap, about a working day of this 2-core machine in all; 'quick' is a smoke run, 'paper' the paper's
schedule (for a GPU). Changing a budget's training values makes the existing run folders refuse to resume.
"""
from __future__ import annotations

import time
from pathlib import Path

from restore.studies.budgets import BUDGETS, DISPLAYS, TRAIN_ORDER, run_dir, ship
from restore.studies.orderings import ordering_checks
from udc_render.dataset.bank import BANK_FILE
from udc_render.io.files import save_text

__all__ = ["BUDGETS", "ordering_checks", "run_results"]  # what `udc-render results` reads


def carried(carry: Path | None, row: str, display: str) -> bool:
    """Whether `carry` holds the finished model of `row` for `display` (restore.studies.carry.keep)."""
    return carry is not None and (carry / f"{row}_{display}" / "model.pt").is_file()


def carried_last(carry: Path | None) -> tuple:
    """TRAIN_ORDER with the rows whose models `carry` holds for every display moved to the end (stable): a fresh
    machine trains what is missing first and remakes the datasets and banks that only check a carried model
    (hours) after it, so a session's training outlives it in the carry folder sooner."""
    return tuple(sorted(TRAIN_ORDER, key=lambda r: all(carried(carry, r[0], d) for d in DISPLAYS)))


def models_to_train(out: Path, carry: Path | None) -> list[str]:
    """The runs (<row>_<display>) whose model.pt is neither in out/train nor in `carry`."""
    return [f"{row}_{d}" for row, _, _ in TRAIN_ORDER for d in DISPLAYS
            if not ((run_dir(out, row, d) / "model.pt").is_file() or carried(carry, row, d))]


def check_precision(out: Path, budget: str, carry: Path | None) -> None:
    """Refuse at once, before any dataset is made, a budget that trains in bfloat16 where bfloat16 is emulated
    (restore.precision.bf16_native) while a model is still to train."""
    from restore.precision import PrecisionError, bf16_native
    from restore.train import pick_device
    if BUDGETS[budget].get("autocast") != "bf16" or bf16_native(pick_device("auto")):
        return
    if todo := models_to_train(out, carry):
        names = ", ".join(todo[:3]) + (", ..." if len(todo) > 3 else "")
        raise PrecisionError(f"--budget {budget}: {len(todo)} models to train ({names}) in bfloat16, which this CPU "
                             "emulates (13-30× slower than float32): run it on a CPU with AVX-512 or a GPU, or "
                             "--carry their finished models")


def train_models(out: Path, b: dict, progress: bool, times: dict, carry: Path | None = None) -> dict:
    """Every row's model per display, trained or resumed in out/train/<row>_<display> in TRAIN_ORDER (with
    `carry`: carried_last), each profile's dataset made or resumed when the first row that trains on it is
    reached: {(row, display): model.pt}. With `carry`, each finished model is kept in carry/<row>_<display> and
    brought back from there into a run folder that lacks it (restore.studies.carry)."""
    from restore.models import RESNET_CONFIG, UNET_CONFIG
    from restore.studies.carry import bring_back, keep
    from restore.studies.datasets import make_dataset
    from restore.studies.random_row import (
        BANK_SECONDS_FILE,
        BankRecord,
        bank_plan,
        carried_bank,
        online_settings,
        random_bank,
        restore_bank_seconds,
    )
    from restore.train import TrainSettings, data_fingerprint, train
    defaults = {"unet": UNET_CONFIG, "resnet": RESNET_CONFIG}
    models, datasets = {}, {}
    for row, kind, profile in carried_last(carry):
        cfg = dict(b["models"][kind] or defaults[kind])
        source = "physical" if profile == "random" else profile  # random: the physical clean renders
        if source not in datasets:
            datasets[source] = make_dataset(out, b, source, progress)
        data = datasets[source]
        for d in DISPLAYS:
            t = time.perf_counter()
            run = run_dir(out, row, d)
            settings = TrainSettings(model=cfg, display=d, epochs=b["epochs"][kind], batch=b["batch"],
                                     crop_px=b["crop_px"][kind], crops_per_pair=b["crops_per_pair"], lr=b["lr"],
                                     data_fingerprint=data_fingerprint(data), plateau_db=b.get("plateau_db"),
                                     val_crop_px=b.get("val_crop_px"), clip_grad_norm=b.get("clip_grad_norm"),
                                     autocast=b.get("autocast"))
            bank = None
            if profile == "random":  # a carried model is checked against its bank's record; else make the bank
                plan = bank_plan(out, b, d)
                record = carried_bank(carry / run.name, plan) if carry else None
                if record:
                    restore_bank_seconds(carry / run.name, out)
                else:
                    bank = random_bank(out, plan, progress)
                    record = BankRecord.of(bank)
                settings = online_settings(settings, record)
            if carry:
                bring_back(carry / run.name, run, settings)
            train(data, run, settings, val_every=b.get("val_every", 10), progress=progress,
                  bank=None if bank is None else bank.folder)
            if carry:
                keep(run, carry / run.name, {} if bank is None else
                     {f: bank.folder / f for f in (BANK_FILE, BANK_SECONDS_FILE)})
            models[(row, d)] = run / "model.pt"
            times[f"train_{row}_{d}_s"] = time.perf_counter() - t
    return models


def run_results(out: Path, budget: str = "cpu", write: Path | None = None, progress: bool = True,
                carry: Path | None = None) -> dict:
    """Run every stage into `out` and write `out`/RESULTS.md with its figures in `out`/figures; with
    `write`, the document there too, its figures in docs/figures/results beside it; with `carry`, the
    finished models kept there and brought back from there (train_models); with both, a `carry` that is a slot of
    restore/trained becomes the shipped one (budgets.ship; 'stale_slot' in the result names the other)."""
    from restore.studies.datasets import dataset_folders
    from restore.studies.faces import face_experiment
    from restore.studies.heldout import make_held_out_dataset
    from restore.studies.results_document import copy_figures, plot_training_curves, results_document
    from restore.studies.scoring import error_band_rows, evaluate_rows, training_levels
    b, out = BUDGETS[budget], Path(out)
    check_precision(out, budget, carry)
    t0, times = time.perf_counter(), {}
    models = train_models(out, b, progress, times, carry)
    datasets = dataset_folders(out)  # both made by train_models: every profile trains a row
    data = datasets["physical"]  # every row is tested on the physical captures
    t = time.perf_counter()
    results = evaluate_rows(data, models, out / "eval", progress)
    times["evaluate_s"] = time.perf_counter() - t
    t = time.perf_counter()
    heldout = make_held_out_dataset(out, b["sensor_px"], b.get("heldout_items"), progress)
    heldout_results = evaluate_rows(heldout, models, out / "eval_heldout", progress)
    times["heldout_s"] = time.perf_counter() - t
    t = time.perf_counter()
    bands = error_band_rows(data, models, out / "error_bands")
    times["error_bands_s"] = time.perf_counter() - t
    t = time.perf_counter()
    faces = face_experiment(out / "faces", {d: [models[(kind, d)] for kind in ("unet", "resnet")] for d in DISPLAYS},
                            b["face_sensor_px"], progress=progress, train_level=training_levels(data))
    times["faces_s"] = time.perf_counter() - t
    times["total_s"] = time.perf_counter() - t0
    targets = [(out / "RESULTS.md", out / "figures")]  # (document, its figures' folder)
    if write:
        targets.append((Path(write), Path(write).parent / "docs" / "figures" / "results"))
    plot_training_curves(out, out / "train" / "training_curves.png")  # drawn once, copied per document
    for doc, fig_dir in targets:
        figures = copy_figures(out, fig_dir)
        save_text(doc, results_document(results, heldout_results, bands, faces, b, budget, datasets, out, times,
                                        figures, doc.parent, carry))
    stale = ship(carry, sorted({row for row, _ in models})) if write and carry else None
    return {"results": results, "heldout": heldout_results, "error_bands": bands, "faces": faces, "times": times,
            "stale_slot": stale}



