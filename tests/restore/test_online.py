"""Training on the online degradation (restore.online, `udc-render train --degrade online --bank DIR`)."""
from __future__ import annotations

import json
import math
import threading
import time
from dataclasses import replace

import numpy as np
import pytest
import torch

from restore.data import DataError, dihedral
from restore.degrade import Degrader, normalised
from restore.online import OnlineBatches, clean_images, region, validation_pairs
from restore.train import TrainSettings, load_model, predict, train
from tests.conftest import write_pairs
from tests.restore.test_train import train_interrupted_at_epoch_2
from udc_render.cli import main
from udc_render.dataset.bank import Panel, read_bank, save_panel, write_bank_json
from udc_render.sensor import SensorConfig, demosaic_bilinear, unpack_rggb
from udc_render.streams import stream

TINY_UNET = {"type": "unet", "width": 8, "depth": 3}
GAMMA, GAIN, READ_NOISE_E = 0.5, 8.0, 400.0  # read noise σ 0.4 of the white level after /γ: a very noisy capture


@pytest.fixture(autouse=True)
def two_threads():
    old = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(old)


def _blur_panel(name: str, sigma_px: float) -> Panel:
    """A panel of a Gaussian blur (9 px), γ = 0.5 at gain 8, Poisson shot noise and a strong read noise."""
    r = np.arange(9) - 4
    k = np.exp(-(r[:, None] ** 2 + r[None, :] ** 2) / (2 * sigma_px ** 2))
    k = np.repeat((k / k.sum())[None], 3, axis=0).astype(np.float32)
    sensor = SensorConfig(form="per_channel", gain=GAIN, gamma_rggb=(GAMMA / GAIN,) * 4, exposure_s=0.03,
                          read_noise_e=READ_NOISE_E)
    return Panel(name, k, 1.55, (GAMMA,) * 3, sensor, None, None, None, {"brightness": 1.0})


@pytest.fixture
def bank(tmp_path):
    """A bank of two blur panels (σ 1 and 2 px), written with the library's own writer."""
    out = tmp_path / "bank"
    records = [save_panel(out, i, _blur_panel(n, s)) for i, (n, s) in enumerate((("soft", 1.0), ("softer", 2.0)))]
    write_bank_json(out, {"test": "two Gaussian blurs"}, records, 2)
    return out


def _settings(bank_dir, **kw) -> TrainSettings:
    b = read_bank(bank_dir)
    names = [p.name for p in b.panels]
    return TrainSettings(**{"model": TINY_UNET, "display": ",".join(names), "batch": 4, "crop_px": 48, "lr": 3e-3,
                            "degrade": {"mode": "online", "bank_fingerprint": b.fingerprint, "panels": names}, **kw})


def _psnr(a, b):
    return 10 * math.log10(1 / np.mean((np.clip(a, 0, 1) - np.clip(b, 0, 1)) ** 2))


@pytest.mark.slow  # ~28 s; the mechanism: test_resumed_online_training_continues_identically
def test_online_training_improves_over_its_input(tmp_path, bank):
    """40 Adam steps of a width-8 UNet on 32-px crops degraded on the fly (no capture on disk): on the validation
    images, degraded once through the panels, it beats the input (bilinear demosaic / γ) by > 3 dB, and its
    training loss falls by half (measured: 18.5 dB against 11.5, loss 0.258 → 0.095; ~12 s on 2 loaded cores)."""
    data = write_pairs(tmp_path / "pairs", splits=(("train", 8), ("val", 2)), size_px=(64, 96))
    s = _settings(bank, epochs=10, crops_per_pair=2, crop_px=32)
    summary = train(data, tmp_path / "run", s, progress=False, bank=bank)
    assert summary["steps"] == 40 and summary["train_pairs"] == 8  # the clean images; 16 crops an epoch
    log = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=False)["log"]
    assert log[-1]["loss"] < 0.5 * log[0]["loss"]
    b = read_bank(bank)
    val = validation_pairs(clean_images(data, "val"), b, Degrader(b.panels), s.seed)
    model, _ = load_model(tmp_path / "run" / "model.pt", "cpu")
    restored = np.mean([_psnr(predict(model, x, torch.device("cpu")), y) for x, y in val])
    identity = np.mean([_psnr(demosaic_bilinear(unpack_rggb(x)) / GAMMA, y) for x, y in val])
    assert restored > identity + 3.0, (restored, identity)
    assert summary["val_psnr_db"] == pytest.approx(restored, abs=0.05)
    lines = [json.loads(ln) for ln in (tmp_path / "run" / "online.jsonl").read_text().splitlines()]
    assert [ln["epoch"] for ln in lines] == list(range(1, 11)) and all(len(ln["crops"]) == 16 for ln in lines)
    crops = np.array([c[:5] for ln in lines for c in ln["crops"]])
    assert set(crops[:, 1]) == {0, 1} and (crops[:, 3] % 2 == 0).all() and (crops[:, 4] % 2 == 0).all()


def straight_and_resumed(tmp_path, monkeypatch, data, s: TrainSettings, bank) -> str:
    """Train s straight and interrupted after two epochs then resumed: assert the same weights and the same
    online.jsonl; returns that log."""
    train(data, tmp_path / "straight", s, progress=False, bank=bank)
    train_interrupted_at_epoch_2(monkeypatch, data, tmp_path / "resumed", s, bank=bank)
    train(data, tmp_path / "resumed", s, progress=False, bank=bank)
    a = torch.load(tmp_path / "straight" / "model.pt", weights_only=False)["state_dict"]
    b = torch.load(tmp_path / "resumed" / "model.pt", weights_only=False)["state_dict"]
    assert all(torch.equal(a[k], b[k]) for k in a)
    log = (tmp_path / "straight" / "online.jsonl").read_text()
    assert log == (tmp_path / "resumed" / "online.jsonl").read_text()
    return log


def test_resumed_online_training_continues_identically(tmp_path, bank, monkeypatch):
    """Interrupted after two epochs and resumed: the same weights and the same recorded draws as a straight run."""
    data = write_pairs(tmp_path / "pairs", splits=(("train", 3),), size_px=(48, 64))
    straight_and_resumed(tmp_path, monkeypatch, data, _settings(bank, epochs=4, batch=2, crop_px=32, lr=1e-3), bank)


def test_crops_take_mirrored_scene_beyond_the_frame_a_fresh_draw_each_epoch_and_the_same_in_workers(tmp_path, bank):
    img = np.random.default_rng(0).random((3, 10, 12)).astype(np.float32)
    for y0, x0, pad in ((-3, -4, (3, 4)), (-13, -15, (13, 15))):  # one reflection (slices), several (a gather)
        padded = np.pad(img, ((0, 0), (pad[0], pad[0]), (pad[1], pad[1])), "reflect")
        np.testing.assert_array_equal(region(torch.from_numpy(img), y0, x0, *padded.shape[1:]).numpy(), padded)
    np.testing.assert_array_equal(region(torch.from_numpy(img), 2, 3, 5, 6).numpy(), img[:, 2:7, 3:9])
    for mode in range(8):  # the crops are turned on the device as restore.data.dihedral turns arrays
        np.testing.assert_array_equal(dihedral(torch.from_numpy(img), mode).numpy(), dihedral(img, mode))
    data = write_pairs(tmp_path / "pairs", splits=(("train", 2),), size_px=(48, 64))
    b = read_bank(bank)
    batches = OnlineBatches(clean_images(data, "train"), b, Degrader(b.panels), 32, 2, seed=0, workers=0)
    d0, it = batches.epoch(0)
    x, y = next(it)
    assert x.shape == (2, 4, 16, 16) and y.shape == (2, 3, 32, 32) and x.dtype == torch.float32
    assert batches.epoch(0)[0] == d0 and batches.epoch(1)[0] != d0
    d, m = d0[0], batches.degrader.margin_px  # the first crop, cut from the numpy image as the module doc says
    gt = clean_images(data, "train")[d["image"]].pixels
    y0, x0, n = d["y0"], d["x0"], 32 + 2 * m
    scene = np.pad(gt, ((0, 0), (m, m), (m, m)), "reflect")[:, y0:y0 + n, x0:x0 + n]
    clean = torch.from_numpy(np.ascontiguousarray(dihedral(scene, d["mode"])))
    dn = batches.degrader.degrade(clean, d["panel"], gt.shape[1:], (d["y0"], d["x0"]),
                                  torch.Generator().manual_seed(d["noise_seed"]))
    assert torch.equal(x[0], normalised(dn, b.panels[d["panel"]]).float()) and torch.equal(y[0], clean[:, m:-m, m:-m])
    in_workers = OnlineBatches(clean_images(data, "train"), b, Degrader(b.panels), 32, 2, seed=0, workers=1)
    xw, yw = next(in_workers.epoch(0)[1])
    assert torch.equal(x, xw) and torch.equal(y, yw)  # a worker process, crop by crop, degrades the same numbers


def test_crops_and_their_order_come_from_named_streams(tmp_path, bank):
    """The epoch's order is the permutation of stream (seed, 'online order', e) and crop k draws from stream (seed,
    'online crop', e, k), crop 0 included (default_rng([seed, e, 0]) was default_rng([seed, e]), the order's)."""
    data = write_pairs(tmp_path / "pairs", splits=(("train", 3),), size_px=(48, 64))
    b = read_bank(bank)
    batches = OnlineBatches(clean_images(data, "train"), b, Degrader(b.panels), 32, 2, seed=5, workers=0)
    draws, _ = batches.epoch(4)
    assert draws == [batches.draw(4, int(k)) for k in stream(5, "online order", 4).permutation(3)]
    rng, first = stream(5, "online crop", 4, 0), batches.draw(4, 0)
    assert [first[k] for k in ("image", "panel", "mode")] == [int(rng.integers(n)) for n in (3, 2, 8)]


def test_online_command_and_its_one_line_refusals(tmp_path, bank, capsys):
    data = write_pairs(tmp_path / "pairs", splits=(("train", 2),), size_px=(48, 64))
    cfg = tmp_path / "tiny.toml"
    cfg.write_text('type = "unet"\nwidth = 4\ndepth = 2\n')
    base = ["train", "--data", str(data), "--model", "unet", "--config", str(cfg), "--out", str(tmp_path / "run"),
            "--epochs", "1", "--crop-px", "32", "--quiet"]
    assert main(base + ["--degrade", "online", "--bank", str(bank), "--display", "soft"]) == 0
    assert "trained unet on 2 clean images degraded online through soft, 1 epochs" in capsys.readouterr().out
    for argv, words in ((["--degrade", "online"], "--degrade online needs --bank"),
                        (["--bank", str(bank), "--display", "blur"], "--bank goes with --degrade online"),
                        ([], "--display is required with --degrade dataset"),
                        (["--degrade", "online", "--bank", str(bank), "--display", "nope"], "'nope' is not a panel"),
                        (["--degrade", "online", "--bank", str(tmp_path)], "no bank.json"),
                        (["--degrade", "online", "--bank", str(bank), "--crop-px", "80"], "--crop-px = 80: larger")):
        assert main(base[:-1] + ["--out", str(tmp_path / "r2"), *argv]) == 2, argv
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and words in err, err


def test_a_model_trained_online_is_scored_on_its_panels_displays(tmp_path, bank, capsys):
    """evaluate without --display scores a model trained online on the dataset's displays named as the bank's
    panels it drew from (here a dataset whose display is 'soft')."""
    data = write_pairs(tmp_path / "pairs", splits=(("train", 2), ("test", 1)), size_px=(48, 64), displays=("soft",))
    s = _settings(bank, epochs=1, batch=2, crop_px=32)
    s = replace(s, display="soft", degrade={**s.degrade, "panels": ["soft"]})
    train(data, tmp_path / "run", s, progress=False, bank=bank)
    assert main(["evaluate", "--data", str(data), "--model", str(tmp_path / "run" / "model.pt"), "--out",
                 str(tmp_path / "eval")]) == 0
    assert "soft" in capsys.readouterr().out


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_on_a_gpu_the_batches_made_ahead_in_a_thread_are_the_same(tmp_path, bank):
    """--degrade-workers 1 on a GPU (its default): the batches made in a thread on their own stream equal those made
    in the process (the same generators' draws); two threads are refused in one line."""
    data = write_pairs(tmp_path / "pairs", splits=(("train", 3),), size_px=(48, 64))
    b = read_bank(bank)

    def epoch(device, workers):
        ob = OnlineBatches(clean_images(data, "train"), b, Degrader(b.panels, device), 32, 2, seed=0, crops_per_image=3,
                           workers=workers)
        return [(x.cpu(), y.cpu()) for x, y in ob.epoch(1)[1]]
    inline, ahead = epoch("cuda", 0), epoch("cuda", None)  # the default on a GPU: the thread
    assert len(inline) == len(ahead) == 5 and inline[0][0].abs().max() > 0
    assert all(torch.equal(a[0], c[0]) and torch.equal(a[1], c[1]) for a, c in zip(inline, ahead))
    ob = OnlineBatches(clean_images(data, "train"), b, Degrader(b.panels, "cuda"), 32, 2, seed=0, crops_per_image=3)
    assert ob.workers == 1
    it = ob.epoch(0)[1]  # a loop that stops after 3 of 5 batches, the thread waiting to queue its end: closed at once
    for _ in range(3):
        next(it)
    time.sleep(1.0)
    closer = threading.Thread(target=it.close)
    closer.start()
    closer.join(timeout=10)
    assert not closer.is_alive()
    with pytest.raises(DataError, match="--degrade-workers 2: on cuda"):
        OnlineBatches(clean_images(data, "train"), b, Degrader(b.panels, "cuda"), 32, 2, seed=0, workers=2)
