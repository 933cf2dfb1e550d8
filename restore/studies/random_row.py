"""The UNet (randomized) row of `udc-render results`: the paper's UNet, trained on the fly (restore.online) on
the clean renders of the physical dataset's train split, each crop degraded through a panel drawn from a bank
of the display's family, and tested on the physical captures like every other row.

The bank (out/banks/random_<display>, udc_render.dataset.bank_make): b['random_panels'] panels drawn from the
documented ranges (randomize `default`) with the family fixed to the display's, seed RANDOMIZE_SEED, at the
datasets' rig (the monitor scene at the budget's frame, the physical profile's synthesis settings, the kernel
size `udc-render bank` takes). Validation: the val split's clean renders, image j through panel j mod N.
What it tests: a restorer trained across the unknowns of its panel, on the one panel the captures show
(the default P-OLED or T-OLED: a point inside the ranges), and through the per-channel form it trains on
against the spectral captures it is scored on.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path, PurePosixPath
from typing import NamedTuple

from restore.studies.stage_times import StageTimes
from restore.train import TrainSettings
from udc_render.dataset.bank import BANK_FILE, Bank, bank_json_fingerprint, read_bank
from udc_render.dataset.bank_make import bank_settings, differing_settings, make_bank, random_specs
from udc_render.dataset.randomize import default_distributions, parse
from udc_render.io.files import save_json
from udc_render.pipeline import SynthConfig
from udc_render.profiles import describe, resolve_profile
from udc_render.scene import load_scene, scenes_dir
from udc_render.scene.geometry import sensor_kernel_px
from udc_render.scene.overrides import with_overrides

RANDOM_ROW = "unet_random"
RANDOMIZE_SEED = 0
SECONDS_FILE = "seconds.json"  # out/banks/seconds.json: {bank: seconds spent making it, summed over invocations}
BANK_SECONDS_FILE = "bank_seconds.json"  # in a bank's folder and beside its carried model: {bank: its seconds}


def family_distributions(display: str):
    """randomize `default` with display.family fixed to `display` ('toled' or 'poled')."""
    return parse({"display": {"family": display}}, f"results: the {display} family", default_distributions())


class BankPlan(NamedTuple):
    """The row's bank for one display before any kernel is made: made once (bank_plan) and read both by
    carried_bank (is a carried bank today's?) and by random_bank (make or finish it)."""
    folder: Path
    specs: list
    settings: dict  # bank.json's settings (udc_render.dataset.bank_make.bank_settings)
    kernel_px: int


def bank_plan(out: Path, b: dict, display: str) -> BankPlan:
    """The row's bank for `display` in out/banks/random_<display>. Cheap: draws and settings only."""
    scene = with_overrides(load_scene("monitor"), sensor_px=b["sensor_px"])  # the datasets' (restore.studies.datasets)
    cfg, _ = resolve_profile("physical", SynthConfig(), [])
    size = sensor_kernel_px(scene)
    specs = random_specs(family_distributions(display), b["random_panels"], RANDOMIZE_SEED, scene, cfg)
    extra = {"profile": describe(cfg.profile), "study": "results", "row": RANDOM_ROW, "family": display}
    return BankPlan(out / "banks" / f"random_{display}", specs, bank_settings(scene, cfg, size, specs, extra), size)


def random_bank(out: Path, plan: BankPlan, progress: bool) -> Bank:
    """The row's bank of `plan` (module doc), made or finished in plan.folder; its time counted in
    out/banks/seconds.json."""
    t0 = time.perf_counter()
    times = StageTimes(out / "banks" / SECONDS_FILE)
    if make_bank(plan.folder, plan.specs, plan.settings, plan.kernel_px, progress=progress)["made"]:
        times.add(plan.folder.name, time.perf_counter() - t0)
    seconds = {plan.folder.name: times.seconds.get(plan.folder.name, 0.0)}
    save_json(plan.folder / BANK_SECONDS_FILE, seconds)  # what a carry keeps
    return read_bank(plan.folder)


def restore_bank_seconds(carried_run: Path, out: Path) -> None:
    """Count a carried bank's making time in out/banks/seconds.json (once) when the bank is not made here, so
    that the document's machine time still holds it."""
    path = Path(carried_run) / BANK_SECONDS_FILE
    times = StageTimes(out / "banks" / SECONDS_FILE)
    for bank, seconds in (json.loads(path.read_text()) if path.is_file() else {}).items():
        if bank not in times.seconds:
            times.add(bank, seconds)


@dataclass(frozen=True)
class BankRecord:
    """What a training run records of its bank (restore.train's degrade settings): bank.json's fingerprint and
    the panels' names, in order."""
    fingerprint: str
    panels: tuple[str, ...]

    @classmethod
    def of(cls, bank: Bank) -> BankRecord:
        return cls(bank.fingerprint, tuple(p.name for p in bank.panels))


def carried_bank(carried_run: Path, plan: BankPlan) -> BankRecord | None:
    """The record of the bank a carried finished run trained through, from its copy of bank.json
    (restore.studies.carry.keep), when that bank is complete and its settings are `plan`'s (the test
    make_bank itself applies before resuming a folder): a fresh machine then checks the carried
    model without making the bank's kernels (a third of an hour per display). None otherwise: make the bank."""
    path = Path(carried_run) / BANK_FILE
    if not (Path(carried_run) / "model.pt").is_file() or not path.is_file():
        return None
    doc = json.loads(path.read_text())
    if doc.get("complete") is not True or differing_settings(scene_here(doc, plan.settings), plan.settings):
        return None
    return BankRecord(bank_json_fingerprint(path), tuple(r["name"] for r in doc["panels"]))


def scene_here(doc: dict, settings: dict) -> dict:
    """bank.json's `doc` with its scene read as this checkout's when both name the same built-in scene file
    (scenes/NAME.toml) of two checkouts: bank.json records the scene by its absolute path, and a carried bank made
    in /work/main is today's in a clone elsewhere. What the kernels depend on (frame, pixel pitch, lens, bands,
    synthesis, displays) is compared key by key all the same."""
    theirs, ours = PurePosixPath(str(doc.get("scene", ""))), Path(str(settings.get("scene", "")))
    if ours.parent == scenes_dir() and (theirs.parent.name, theirs.name) == (ours.parent.name, ours.name):
        return {**doc, "scene": settings["scene"]}
    return doc


def bank_hours(out: Path) -> float:
    """The hours spent making the row's banks (out/banks/seconds.json; 0 before any)."""
    return sum(StageTimes(out / "banks" / SECONDS_FILE).seconds.values()) / 3600


def online_settings(settings: TrainSettings, bank: BankRecord) -> TrainSettings:
    """`settings` (the UNet row's recipe) trained on the fly through the panels of `bank`."""
    names = list(bank.panels)
    return replace(settings, display=",".join(names),
                   degrade={"mode": "online", "bank_fingerprint": bank.fingerprint, "panels": names})
