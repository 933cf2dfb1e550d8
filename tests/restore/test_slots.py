"""restore.studies.budgets' slots: a run's --write ships its own slot in place (no weight moves between folders)
and names the other one stale; a carry outside the slots ships nothing."""
import json

from restore.studies.budgets import SHIPPED_FILE, default_carry, ship, shipped, shipped_folder


def _slots(tmp_path, shipped_slot="cpu"):
    trained = tmp_path / "trained"
    for slot in ("cpu", "cpu_next"):
        (trained / slot / "unet_toled").mkdir(parents=True)
        (trained / slot / "unet_toled" / "model.pt").write_bytes(slot.encode())
    (trained / SHIPPED_FILE).write_text(json.dumps({"slot": shipped_slot, "rows": ["unet"]}))
    return trained


def test_a_written_run_ships_its_slot_and_names_the_other_stale(tmp_path):
    trained = _slots(tmp_path)
    assert shipped_folder(trained) == trained / "cpu"
    assert ship(trained / "cpu_next", ["unet_syn", "unet"], trained) == "cpu"
    assert shipped(trained) == {"slot": "cpu_next", "rows": ["unet", "unet_syn"]}
    assert (trained / "cpu_next" / "unet_toled" / "model.pt").read_bytes() == b"cpu_next"  # not moved
    assert (trained / "cpu" / "unet_toled" / "model.pt").is_file()  # git rm's to do, not this function's


def test_an_emptied_other_slot_is_not_stale_and_a_foreign_carry_ships_nothing(tmp_path):
    trained = _slots(tmp_path)
    (trained / "cpu_next" / "unet_toled" / "model.pt").unlink()
    (trained / "cpu_next" / "unet_toled").rmdir()
    (trained / "cpu_next").rmdir()
    assert ship(trained / "cpu", ["unet"], trained) is None and shipped(trained)["slot"] == "cpu"
    (tmp_path / "elsewhere").mkdir()
    assert ship(tmp_path / "elsewhere", ["unet"], trained) is None and shipped(trained)["slot"] == "cpu"
    assert ship(trained / "other", ["unet"], trained) is None


def test_the_cpu_budget_carries_into_the_shipped_slot_and_the_others_nowhere():
    assert default_carry("cpu") == shipped_folder() and shipped_folder().is_dir()
    assert default_carry("quick") is None and default_carry("paper") is None
