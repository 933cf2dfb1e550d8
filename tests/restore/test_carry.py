"""Carrying finished models between run folders (restore.studies.carry), as `udc-render results --carry` does."""
import numpy as np
import pytest
import torch

from restore.data import list_pairs, load_pair
from restore.studies.carry import CARRIED, bring_back, keep
from restore.train import TrainError, TrainSettings, load_model, predict, train
from tests.conftest import write_pairs

TINY_UNET = {"type": "unet", "width": 8, "depth": 3}


def test_a_carried_model_comes_back_finished_and_is_not_trained_again(tmp_path):
    data = write_pairs(tmp_path / "pairs", splits=(("train", 4), ("test", 1)), size_px=(32, 32))
    s = TrainSettings(model=TINY_UNET, display="blur", epochs=3, batch=2, crop_px=16, lr=1e-3)
    summary = train(data, tmp_path / "run", s, progress=False)
    full = load_model(tmp_path / "run" / "model.pt", "cpu")[0]
    keep(tmp_path / "run", tmp_path / "carry" / "unet_blur")
    weights = torch.load(tmp_path / "carry" / "unet_blur" / "model.pt", weights_only=False)["state_dict"]
    assert {v.dtype for v in weights.values() if v.is_floating_point()} == {torch.float16}
    assert (tmp_path / "run" / "model.pt").read_bytes() == (tmp_path / "carry" / "unet_blur" / "model.pt").read_bytes()
    assert sorted(p.name for p in (tmp_path / "carry" / "unet_blur").iterdir()) == sorted(CARRIED)

    assert bring_back(tmp_path / "carry" / "unet_blur", tmp_path / "fresh", s)
    assert train(data, tmp_path / "fresh", s, progress=False) == summary  # finished: nothing loaded or trained
    assert not (tmp_path / "fresh" / "checkpoint.pt").exists()
    half, record = load_model(tmp_path / "fresh" / "model.pt", "cpu")
    assert next(half.parameters()).dtype == torch.float32 and record["display"] == "blur"
    packed, _ = load_pair(list_pairs(data, "test", ["blur"])[0])
    a, b = (predict(m, packed, torch.device("cpu")) for m in (full, half))
    assert 0 < np.abs(a - b).max() < 1e-2 * np.abs(a).max()  # float16 weights: rounded, not a different model

    keep(tmp_path / "fresh", tmp_path / "carry" / "unet_blur")  # idempotent: the same bytes
    carried = tmp_path / "carry" / "unet_blur" / "model.pt"
    assert (tmp_path / "fresh" / "model.pt").read_bytes() == carried.read_bytes()
    assert not bring_back(tmp_path / "carry" / "unet_blur", tmp_path / "run", s)  # a begun run keeps its own files


def test_a_run_still_training_is_not_carried_back_as_finished(tmp_path):
    data = write_pairs(tmp_path / "pairs", splits=(("train", 2),), size_px=(16, 16))
    s = TrainSettings(model=TINY_UNET, display="blur", epochs=2, batch=2, crop_px=14)
    assert not bring_back(tmp_path / "nothing", tmp_path / "run", s)
    train(data, tmp_path / "run", s, progress=False)
    (tmp_path / "run" / "checkpoint.pt").unlink()
    longer = TrainSettings(model=TINY_UNET, display="blur", epochs=3, batch=2, crop_px=14)
    (tmp_path / "run" / "train.json").unlink()  # the same folder under a longer schedule: not finished
    summary = train(data, tmp_path / "run", longer, progress=False)
    assert summary["epochs"] == 3 and (tmp_path / "run" / "checkpoint.pt").is_file()


def test_a_carried_run_of_other_settings_is_a_one_line_error_naming_the_carry(tmp_path):
    data = write_pairs(tmp_path / "pairs", splits=(("train", 2),), size_px=(16, 16))
    s = TrainSettings(model=TINY_UNET, display="blur", epochs=1, batch=2, crop_px=14)
    train(data, tmp_path / "run", s, progress=False)
    keep(tmp_path / "run", tmp_path / "carry" / "unet_blur")
    other = TrainSettings(model=TINY_UNET, display="blur", epochs=1, batch=2, crop_px=14, lr=1e-3)
    with pytest.raises(TrainError, match=r"carry/unet_blur/train.json: lr = 0.001 differs .* delete .*carry/unet_blur"):
        bring_back(tmp_path / "carry" / "unet_blur", tmp_path / "fresh", other)
    assert not (tmp_path / "fresh").exists()


def test_extra_records_are_kept_beside_the_model(tmp_path):
    data = write_pairs(tmp_path / "pairs", splits=(("train", 2),), size_px=(16, 16))
    train(data, tmp_path / "run", TrainSettings(model=TINY_UNET, display="blur", epochs=1, batch=2, crop_px=14),
          progress=False)
    (tmp_path / "bank.json").write_text('{"complete": true}')
    keep(tmp_path / "run", tmp_path / "carry" / "unet_random_blur", {"bank.json": tmp_path / "bank.json"})
    carried = tmp_path / "carry" / "unet_random_blur"
    assert sorted(p.name for p in carried.iterdir()) == sorted((*CARRIED, "bank.json"))
    assert (carried / "bank.json").read_text() == '{"complete": true}'
    assert max(carried.iterdir(), key=lambda p: p.stat().st_mtime_ns).name == "model.pt"  # last: a whole copy


def test_a_bf16_budget_with_models_to_train_is_refused_before_any_dataset(tmp_path, monkeypatch):
    """Where bfloat16 is emulated (restore.precision.bf16_native) the cpu budget (autocast bf16) is refused at once
    while a model is still to train; the shipped slot holds every model, so scoring it is not refused."""
    import restore.precision
    from restore.precision import PrecisionError
    from restore.studies.budgets import shipped_folder
    from restore.studies.results import check_precision, models_to_train, run_results
    monkeypatch.setattr(restore.precision, "bf16_native", lambda device: False)
    with pytest.raises(PrecisionError,
                       match=r"--budget cpu: 8 models to train \(unet_toled, unet_poled, .+\) in bfloat16"):
        run_results(tmp_path / "out", "cpu", carry=None, progress=False)
    assert not (tmp_path / "out").exists()
    assert models_to_train(tmp_path / "out", shipped_folder()) == []
    check_precision(tmp_path / "out", "cpu", shipped_folder())  # nothing to train: allowed
    check_precision(tmp_path / "out", "quick", None)  # float32 budget: allowed
