"""restore.studies.random_row: the UNet (randomized) row's draws keep the display's family and the documented
ranges, and its training settings point at the bank."""
import hashlib
import json
from types import SimpleNamespace

import pytest

from restore.studies.budgets import BUDGETS, shipped_folder
from restore.studies.random_row import (
    BANK_SECONDS_FILE,
    RANDOM_ROW,
    SECONDS_FILE,
    BankRecord,
    bank_hours,
    bank_plan,
    carried_bank,
    family_distributions,
    online_settings,
    restore_bank_seconds,
)
from restore.train import TrainSettings
from udc_render.dataset.bank import FORMAT_1
from udc_render.dataset.randomize import default_distributions, draw_panels
from udc_render.scene import scenes_dir


@pytest.mark.parametrize("family", ["toled", "poled"])
def test_the_family_is_fixed_and_the_other_ranges_kept(family):
    dists = family_distributions(family)
    panels = draw_panels(dists, 24, 0)
    assert {p.family for p in panels} == {family}
    assert len({round(p.values["display.distance_mm"], 6) for p in panels}) == 24  # d still drawn
    assert all(0.5 <= p.values["display.distance_mm"] <= 5.0 for p in panels)
    default = default_distributions().dists
    assert {k: v for k, v in dists.dists.items() if k != "display.family"} == \
        {k: v for k, v in default.items() if k != "display.family"}


def test_online_settings_name_the_banks_panels():
    bank = SimpleNamespace(panels=[SimpleNamespace(name="random_000"), SimpleNamespace(name="random_001")],
                           fingerprint="abc123")
    s = online_settings(TrainSettings(model={"type": "unet", "width": 8}, display="poled", epochs=3),
                        BankRecord.of(bank))
    assert s.display == "random_000,random_001" and s.epochs == 3
    assert s.degrade == {"mode": "online", "bank_fingerprint": "abc123", "panels": ["random_000", "random_001"]}


def _carried_run(folder, settings, complete=True):
    """A carried run folder with a model and its bank's bank.json made with `settings`."""
    folder.mkdir(parents=True)
    (folder / "model.pt").write_bytes(b"weights")
    doc = {**settings, "format": "udc-render kernel bank 1", "count": 2, "complete": complete,
           "panels": [{"name": "random_000"}, {"name": "random_001"}][:2 if complete else 1]}
    (folder / "bank.json").write_text(json.dumps(doc))
    return folder


def test_a_carried_bank_of_todays_plan_is_taken_without_its_kernels(tmp_path):
    b = BUDGETS["quick"]
    plan = bank_plan(tmp_path / "out", b, "poled")
    assert plan.folder == tmp_path / "out" / "banks" / "random_poled" and len(plan.specs) == b["random_panels"]
    run = _carried_run(tmp_path / "carry" / "unet_random_poled", plan.settings)
    record = carried_bank(run, plan)
    assert record == BankRecord(hashlib.sha256((run / "bank.json").read_bytes()).hexdigest()[:16],
                                ("random_000", "random_001"))
    assert not plan.folder.exists()  # nothing made
    assert carried_bank(run, bank_plan(tmp_path / "out", b, "toled")) is None  # another family's plan: make the bank


def test_a_carried_bank_made_in_another_checkout_is_taken(tmp_path):
    b = BUDGETS["quick"]
    plan = bank_plan(tmp_path / "out", b, "poled")
    assert plan.settings["scene"] == str(scenes_dir() / "monitor.toml")
    elsewhere = _carried_run(tmp_path / "elsewhere", {**plan.settings, "scene": "/another/clone/scenes/monitor.toml"})
    assert carried_bank(elsewhere, plan) is not None  # the built-in scene, recorded by another clone's path
    for scene in ("/another/clone/scenes/office.toml", "/another/clone/mine/monitor.toml", "monitor.toml"):
        run = _carried_run(tmp_path / scene.replace("/", "_"), {**plan.settings, "scene": scene})
        assert carried_bank(run, plan) is None, scene  # another scene, or a user's file of the same name


def test_a_carried_bank_that_is_not_todays_is_not_taken(tmp_path):
    b = BUDGETS["quick"]
    plan = bank_plan(tmp_path / "out", b, "poled")
    settings = plan.settings
    other = _carried_run(tmp_path / "other", {**settings, "kernel_px": settings["kernel_px"] + 2})
    partial = _carried_run(tmp_path / "partial", settings, complete=False)
    no_model = _carried_run(tmp_path / "no_model", settings)
    (no_model / "model.pt").unlink()
    assert all(carried_bank(r, plan) is None for r in (other, partial, no_model))
    assert carried_bank(tmp_path / "missing", plan) is None


def test_a_carried_banks_time_is_counted_once(tmp_path):
    out = tmp_path / "out"
    run = tmp_path / "carry" / "unet_random_poled"
    run.mkdir(parents=True)
    (run / BANK_SECONDS_FILE).write_text(json.dumps({"random_poled": 1800.0}))
    restore_bank_seconds(run, out)
    restore_bank_seconds(run, out)  # a second invocation of the run
    restore_bank_seconds(tmp_path / "nothing", out)
    assert json.loads((out / "banks" / SECONDS_FILE).read_text()) == {"random_poled": 1800.0}
    assert bank_hours(out) == 0.5


@pytest.mark.parametrize("family", ["toled", "poled"])
def test_the_shipped_slots_carried_bank_still_names_todays_plan(tmp_path, family):
    """The shipped UNet (randomized) models were trained through format-1 banks (no far field, no haze: bank.
    FORMAT_1_EFFECTS); their carried bank.json, kept byte for byte, still names the cpu budget's plan, so the
    slot scores without making the banks (udc_render.dataset.bank_make.differing_settings)."""
    run = shipped_folder() / f"{RANDOM_ROW}_{family}"
    if not (run / "bank.json").is_file():
        pytest.skip(f"the shipped slot has no {RANDOM_ROW}_{family} bank.json")
    assert json.loads((run / "bank.json").read_text())["format"] == FORMAT_1
    record = carried_bank(run, bank_plan(tmp_path / "out", BUDGETS["cpu"], family))
    assert record is not None
    assert record.fingerprint == hashlib.sha256((run / "bank.json").read_bytes()).hexdigest()[:16]
