"""The budgets of `udc-render results` (restore.studies.results), the displays and rows they train, where each
row's run lives, and the shipped weights' slots. Light on purpose: the CLI reads BUDGETS when it builds its parser.
"""
from __future__ import annotations

import json
from pathlib import Path

from udc_render.io.files import save_json

BUDGETS = {
    "quick": {"items": (4, 1, 2), "sensor_px": (256, 128), "epochs": {"unet": 2, "resnet": 1},
              "crop_px": {"unet": 64, "resnet": 32}, "crops_per_pair": 1, "batch": 2, "face_sensor_px": (512, 256),
              "heldout_items": 2, "lr": 1e-4, "plateau_db": 0.1, "val_every": 1,
              "models": {"unet": {"type": "unet", "width": 8},
                         "resnet": {"type": "resnet", "features": 8, "blocks": 2}},
              "random_panels": 2},
    # cpu: epoch caps, not targets; each model stops at the 0.1 dB plateau, which needs ≥ 6 validations in the
    # last two fifths, so ≥ 26 epochs at val_every 2. Validation on the central 768-px square (a ResNet validation
    # of 20 whole frames would take 6 min). The forward in bfloat16 (half the step time on this CPU,
    # bench_train) paid for the ResNet's cap of 80 (50 before: it had not plateaued there). Caps: about a
    # working day of this machine if nothing plateaus.
    "cpu": {"items": (150, 20, 30), "sensor_px": (2048, 1024), "epochs": {"unet": 80, "resnet": 80},
            "crop_px": {"unet": 256, "resnet": 128}, "crops_per_pair": 2, "batch": 4, "face_sensor_px": (2048, 1024),
            "heldout_items": None, "lr": 2e-4, "plateau_db": 0.1, "val_every": 2, "val_crop_px": 768,
            "clip_grad_norm": 0.5, "autocast": "bf16", "models": {"unet": None, "resnet": None},
            "random_panels": 16, "carry": "shipped"},
    "paper": {"items": (400, 40, 60), "sensor_px": (2048, 1024), "epochs": {"unet": 400, "resnet": 400},
              "crop_px": {"unet": 256, "resnet": 256}, "crops_per_pair": 1, "batch": 4, "face_sensor_px": (2048, 1024),
              "lr": 1e-4,
              "models": {"unet": None, "resnet": None}, "random_panels": 32},
}
DISPLAYS = ("toled", "poled")
DISPLAY_NAMES = {"toled": "T-OLED", "poled": "P-OLED"}
PROFILES = ("physical", "paper")  # udc_render.profiles: the captures, and the paper's synthesis (UNet (Syn))


# (row, model kind, the profile whose pairs train it): the paper's rows; UNet (Syn) is trained on the paper's
# own synthesis and tested on the physical captures, as the paper's synthetic-to-real row; UNet (randomized)
# on the physical dataset's clean renders degraded on the fly through randomized panels (restore.studies.
# random_row; 'random_panels' per display). The document's order; TRAIN_ORDER is the training's.
ROWS = (("unet", "unet", "physical"), ("unet_syn", "unet", "paper"), ("unet_random", "unet", "random"),
        ("resnet", "resnet", "physical"))
# The order of training: the rows on the physical captures first, so that the paper dataset (0.5 h), which only
# UNet (Syn) trains on, is made after them. A session that starts from a fresh clone remakes the physical
# dataset (0.7 h) and then trains, and its finished models outlive it (--carry).
TRAIN_ORDER = tuple(sorted(ROWS, key=lambda r: r[2] == "paper"))


def run_dir(out: Path, row: str, display: str) -> Path:
    """The training run folder of one row's model for one display."""
    return out / "train" / f"{row}_{display}"


# The shipped weights: two slots in restore/trained, one holding the models RESULTS.md describes (named by
# shipped.json), the other the carry of a run under way. A run's --write makes its own slot the shipped one
# (ship) and the other stale, to be removed by `git rm`: the weights never move between folders, since every
# commit's diff counts whole binary files and a move counts each model twice (docs/ARCHITECTURE.md).
TRAINED_DIR = Path(__file__).resolve().parents[1] / "trained"
SLOTS = ("cpu", "cpu_next")
SHIPPED_FILE = "shipped.json"  # {"slot": one of SLOTS, "rows": the rows its models cover}


def shipped(trained: Path = TRAINED_DIR) -> dict:
    """restore/trained/shipped.json: the slot whose models RESULTS.md describes, and their rows."""
    return json.loads((trained / SHIPPED_FILE).read_text())


def shipped_folder(trained: Path = TRAINED_DIR) -> Path:
    """The folder of the shipped models (the cpu budget's default --carry)."""
    return trained / shipped(trained)["slot"]


def default_carry(budget: str) -> Path | None:
    """The budget's --carry when none is given: the cpu budget's is the shipped slot; others keep nothing."""
    return shipped_folder() if BUDGETS[budget].get("carry") == "shipped" else None


def ship(carry: Path, rows: list[str], trained: Path = TRAINED_DIR) -> str | None:
    """After a run's document is written: make `carry`, when it is a slot of `trained`, the shipped one with its
    models' rows (shipped.json, atomic). Returns the other slot when it holds files (stale: `git rm -r` it), else
    None; a carry outside the slots ships nothing."""
    carry = Path(carry).resolve()
    if carry.parent != trained.resolve() or carry.name not in SLOTS:
        return None
    save_json(trained / SHIPPED_FILE, {"slot": carry.name, "rows": sorted(rows)})
    other = next(s for s in SLOTS if s != carry.name)
    return other if (trained / other).is_dir() and any((trained / other).iterdir()) else None
