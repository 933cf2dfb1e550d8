"""A restorer that needs the panel's description gets it in evaluation from describe_display of the --display file
(restore.conditioning), and is refused in one line without one or with one made for another frame."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from restore.conditioning import TENSOR_KEYS, description_tensors
from restore.models import MODELS
from restore.train import save_torch
from tests.conftest import write_pairs
from tests.restore.test_augment import with_display_records
from udc_render.cli import main
from udc_render.description.make import dataset_rig, describe_display, describe_fit

K = 9


class Described(torch.nn.Module):
    """A stand-in for a conditioned restorer: the packed input ÷ γ of its description, the greens averaged, each
    plane doubled in size; every description it restores with is kept in `seen`."""
    TYPE, NEEDS_DESCRIPTION = "described", True
    seen: list = []

    def __init__(self, description_spec: dict):
        super().__init__()
        self.config = {"type": self.TYPE, "description_spec": description_spec}
        self.description_spec = description_spec
        self.scale = torch.nn.Parameter(torch.ones(1))

    def forward(self, x, description):
        if not x.is_meta:  # not its MACs being counted (restore.counting)
            Described.seen.append({k: v.detach().clone() for k, v in description.items()})
        y = x / description["gamma"][:, :, None, None]
        rgb = torch.stack([y[:, 0], (y[:, 1] + y[:, 2]) / 2, y[:, 3]], dim=1)
        return torch.nn.functional.interpolate(rgb, scale_factor=2) * self.scale


@pytest.fixture
def data(tmp_path, monkeypatch):
    """A test split of two items captured through display file mine.toml (a T-OLED at gain 6), its captures' and
    items' records as `udc-render dataset` writes them, and the stand-in model registered."""
    monkeypatch.setitem(MODELS, Described.TYPE, Described)
    Described.seen.clear()
    (tmp_path / "mine.toml").write_text('[display]\nname = "mine"\ngain = 6\n[display.layout]\ntype = "toled"\n')
    data = write_pairs(tmp_path / "pairs", splits=(("test", 2),), displays=("mine",))
    return with_display_records(data, "mine", str(tmp_path / "mine.toml"), gain=6.0)


def _checkpoint(path, frame_px=(96, 64)) -> str:
    spec = {"camera": "Nikon 5100 (NPL)", "sensor_pitch_um": 1.55, "frame_px": list(frame_px), "bit_depth": 16,
            "black_level_dn": 0, "white_level_dn": 65535, "kernel_px": K}
    model = Described(spec)
    save_torch(path, {"model_config": model.config, "state_dict": model.state_dict(), "display": "mine",
                      "settings": {"display": "mine"}})
    return str(path)


def _evaluate(data, model, out, *display) -> int:
    return main(["evaluate", "--data", str(data), "--model", model, "--out", str(out), "--previews", "0", "--quiet",
                 *(["--display", display[0]] if display else [])])


def test_the_model_is_given_what_describe_display_computes_for_the_file(tmp_path, data):
    """evaluate --display FILE: the description the model restores with is describe_display of that file for the
    dataset's sensor (capture.json), frame and rig (synth.json) in the model's kernel window."""
    model = _checkpoint(tmp_path / "model.pt")
    assert _evaluate(data, model, tmp_path / "out", str(tmp_path / "mine.toml")) == 0
    item = sorted((data / "test" / "shard_0000").iterdir())[0]
    sensor = json.loads((item / "mine" / "capture.json").read_text())["sensor"]
    want = description_tensors([describe_display(tmp_path / "mine.toml", sensor, (96, 64), dataset_rig(item),
                                                 kernel_px=K)])
    assert len(Described.seen) == 2 and all(set(s) == set(TENSOR_KEYS) for s in Described.seen)
    for k in TENSOR_KEYS:
        assert torch.equal(Described.seen[0][k], want[k]), k
    results = json.loads((tmp_path / "out" / "results.json").read_text())["methods"]["described"]
    assert results["descriptions"] == {"mine": f"display file {tmp_path / 'mine.toml'}"}


def test_a_fit_folder_describes_the_panel_with_its_sensor_file(tmp_path, data):
    """--display DIR of `udc-render fit`: display.toml with sensor.toml's noise (describe_fit)."""
    fit = tmp_path / "fit"
    fit.mkdir()
    (fit / "display.toml").write_text((tmp_path / "mine.toml").read_text())
    (fit / "sensor.toml").write_text('noise = "gaussian"\nlambda_source = "fixed"\nlambda_read = 2e-6\n'
                                     'lambda_shot = 3e-4\n')
    assert _evaluate(data, _checkpoint(tmp_path / "model.pt"), tmp_path / "out", str(fit)) == 0
    item = sorted((data / "test" / "shard_0000").iterdir())[0]
    sensor = json.loads((item / "mine" / "capture.json").read_text())["sensor"]
    want = describe_fit(fit, sensor, (96, 64), dataset_rig(item), kernel_px=K)
    np.testing.assert_array_equal(Described.seen[0]["lambda_shot"][0].numpy(), np.float32([3e-4] * 4))
    assert torch.equal(Described.seen[0]["kernels"], description_tensors([want])["kernels"])


def test_without_a_description_or_with_another_frames_one_line(tmp_path, data, capsys):
    model = _checkpoint(tmp_path / "model.pt")
    for display in ([], ["mine"]):  # the checkpoint's own display, or the dataset's name: neither describes it
        assert _evaluate(data, model, tmp_path / "out", *display) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "restores only with the panel's description" in err, err
    other = _checkpoint(tmp_path / "other.pt", frame_px=(2048, 1024))
    assert _evaluate(data, other, tmp_path / "out", str(tmp_path / "mine.toml")) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "frame_px = (96, 64), but described was made for frame_px = [2048, 1024]" \
        in err, err
