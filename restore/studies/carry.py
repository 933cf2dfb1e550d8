"""Carry a results run's finished models between work folders: the part of `udc-render results` that takes
hours to make and little room to keep.

A session that starts from a fresh clone has no out/ folder. The datasets are remade there with the same bytes
(udc_render.dataset: every file is deterministic, so restore.train.data_fingerprint matches), but the training
runs are hours each. `udc-render results --carry DIR` therefore keeps every finished model in DIR, a folder
that git tracks, and brings it back into a run folder that lacks it; restore.train then finds the run
finished (train.json, model.pt, train_summary.json) and does not train it again:

    DIR/<row>_<display>/   train.json, train_summary.json, loss.csv, loss.png, model.pt

The checkpoint (weights and Adam's moments, 3× the weights) is not kept, so a model still training when a
session ends starts over in the next. model.pt is kept with float16 weights (the paper's UNet: 17.9 MB
instead of 35.7 MB); the run's own model.pt is rounded the same way when it is kept, so what is scored is
what is carried, in this session and later ones. load_model widens the weights back to float32.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import torch

from restore.train import TrainError, TrainSettings, save_torch, settings_differ
from udc_render.io.files import atomic_path

# model.pt last: it marks a whole copy
CARRIED = ("train.json", "train_summary.json", "loss.csv", "loss.png", "model.pt")


def _copy(src: Path, dst: Path) -> None:
    with atomic_path(dst, dst.suffix) as tmp:
        shutil.copyfile(src, tmp)


def bring_back(carried: Path, run: Path, settings: TrainSettings) -> bool:
    """Copy the carried finished run `carried` into `run` when `run` has not begun (no train.json); True if
    copied. A carried run of other settings is a one-line TrainError."""
    if (run / "train.json").is_file() or not (carried / "model.pt").is_file():
        return False
    if diff := settings_differ(carried / "train.json", settings):
        raise TrainError(f"{carried / 'train.json'}: {diff}: delete {carried} to train this model again")
    run.mkdir(parents=True, exist_ok=True)
    for name in CARRIED:
        _copy(carried / name, run / name)
    return True


def half_weights(path: Path) -> None:
    """Store model.pt's floating-point weights as float16 (in place, atomically; idempotent)."""
    state = torch.load(path, map_location="cpu", weights_only=False)
    weights = state["state_dict"]
    if all(not v.is_floating_point() or v.dtype == torch.float16 for v in weights.values()):
        return
    state["state_dict"] = {k: v.half() if v.is_floating_point() else v for k, v in weights.items()}
    save_torch(path, state)


def keep(run: Path, carried: Path, extra: dict[str, Path] | None = None) -> None:
    """Round the finished run's weights to float16 (its own model.pt too) and copy its record into `carried`,
    with `extra` {name: file} beside it (the UNet (randomized) row: its bank's bank.json, which lets a fresh
    machine check the model without making the bank; restore.studies.random_row.carried_bank)."""
    half_weights(run / "model.pt")
    carried.mkdir(parents=True, exist_ok=True)
    files = {**{name: run / name for name in CARRIED[:-1]}, **(extra or {}), CARRIED[-1]: run / CARRIED[-1]}
    for name, src in files.items():  # model.pt last: it marks a whole copy
        if not (carried / name).is_file() or (carried / name).read_bytes() != src.read_bytes():
            _copy(src, carried / name)
