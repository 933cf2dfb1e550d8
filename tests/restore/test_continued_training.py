"""restore.studies.continued_training: a finished run continued past its stop (tiny models, CPU seconds)."""
import pytest
import torch

from restore.studies.continued_training import continue_run
from restore.train import TrainError, TrainSettings, data_fingerprint, train
from tests.conftest import write_pairs

TINY_RESNET = {"type": "resnet", "features": 8, "blocks": 2}


@pytest.fixture
def finished_run(tmp_path):
    data = write_pairs(tmp_path / "pairs", splits=(("train", 4), ("val", 1)), size_px=(32, 32))
    s = TrainSettings(model=TINY_RESNET, display="blur", epochs=2, batch=2, crop_px=16, lr=1e-3,
                      data_fingerprint=data_fingerprint(data), plateau_db=0.1)
    train(data, tmp_path / "run", s, val_every=1, progress=False)
    return data, tmp_path / "run"


def _log(folder):
    return torch.load(folder / "checkpoint.pt", weights_only=False)["log"]


def test_continues_the_log_at_the_runs_final_rate_and_leaves_the_run_alone(finished_run, tmp_path):
    data, run = finished_run
    before = (run / "checkpoint.pt").read_bytes()
    rows = continue_run(run, data, tmp_path / "cont", epochs=4, val_every=1, progress=False)
    log = _log(tmp_path / "cont")
    assert [r["epoch"] for r in log] == [1, 2, 3, 4]
    assert log[:2] == _log(run)                              # the run's history, unchanged
    assert [r["lr"] for r in log[2:]] == [5e-4, 5e-4]        # cap 4: halved from epoch 2 on, the run's last rate
    assert [r["epoch"] for r in rows] == [3, 4] and all(r["val_psnr_db"] for r in rows)
    assert (run / "checkpoint.pt").read_bytes() == before
    again = continue_run(run, data, tmp_path / "cont", epochs=4, val_every=1, progress=False)  # resumes: nothing to do
    assert again == rows and _log(tmp_path / "cont") == log
    moved = run.rename(tmp_path / "moved")  # the run folder moved: the continuation still resumes
    assert continue_run(moved, data, tmp_path / "cont", epochs=4, val_every=1, progress=False) == rows


def test_a_folder_continuing_another_run_is_refused(finished_run, tmp_path):
    data, run = finished_run
    continue_run(run, data, tmp_path / "cont", epochs=3, progress=False)
    other = TrainSettings(model=TINY_RESNET, display="blur", epochs=2, batch=2, crop_px=16, lr=5e-4,
                          data_fingerprint=data_fingerprint(data))
    train(data, tmp_path / "other_run", other, progress=False)
    with pytest.raises(TrainError, match="continues another run"):
        continue_run(tmp_path / "other_run", data, tmp_path / "cont", epochs=3, progress=False)


def test_bad_continuations_are_refused_before_training(finished_run, tmp_path):
    data, run = finished_run
    with pytest.raises(TrainError, match=r"--epochs = 2: expected more than the run's 2 epochs"):
        continue_run(run, data, tmp_path / "cont", epochs=2, progress=False)
    with pytest.raises(TrainError, match="must not be the run folder"):
        continue_run(run, data, run, epochs=4, progress=False)
    other = write_pairs(tmp_path / "other", splits=(("train", 5), ("val", 1)), size_px=(32, 32))
    with pytest.raises(TrainError, match="not the dataset the run trained on"):
        continue_run(run, other, tmp_path / "cont2", epochs=4, progress=False)
    with pytest.raises(TrainError, match="expected a training run folder"):
        continue_run(tmp_path / "nothing", data, tmp_path / "cont3", epochs=4, progress=False)
    assert not (tmp_path / "cont").exists() and not (tmp_path / "cont2").exists()
