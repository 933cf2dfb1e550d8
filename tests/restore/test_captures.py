"""Every crop's own capture in the online degradation (restore.captures, `udc-render train --capture-draws`)."""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from restore.captures import CROP_KEYS, captured_panel, crop_capture, crop_values, load_capture_draws
from restore.data import dihedral
from restore.degrade import Degrader, normalised
from restore.online import OnlineBatches, clean_images
from tests.conftest import write_pairs
from tests.restore.test_online import _blur_panel, _settings, straight_and_resumed
from udc_render.cli import main
from udc_render.dataset.bank import read_bank, save_panel, write_bank_json
from udc_render.sensor import DefectConfig, FpnConfig, defect_map, fpn_maps, pack_rggb
from udc_render.streams import stream

OWN_GAIN_SCALE, OWN_EXPOSURE_SCALE = 2.0, 0.5  # the panel's own capture draw, divided out by captured_panel


def _panel(name: str, sigma_px: float, seed: int):
    """A blur panel with defect pixels and FPN, its sensor that of a capture drawn at gain × 2 and exposure × 0.5."""
    p = _blur_panel(name, sigma_px)
    return replace(p, defects=DefectConfig(1e-3, 1e-2, 3e4, seed), fpn=FpnConfig(0.01, 1.0, 0.3, 0.5, 5.0, seed + 1),
                   record={"brightness": 0.5, "capture_draw": {"gain_scale": OWN_GAIN_SCALE,
                                                               "exposure_scale": OWN_EXPOSURE_SCALE}})


@pytest.fixture
def bank(tmp_path):
    out = tmp_path / "bank"
    records = [save_panel(out, i, _panel(n, s, 10 * i)) for i, (n, s) in enumerate((("soft", 1.0), ("softer", 2.0)))]
    write_bank_json(out, {"test": "two Gaussian blurs with FPN and defects"}, records, 2)
    return out


def test_a_crops_capture_is_drawn_within_the_ranges_and_replaces_its_panels_sensor_and_maps():
    draws = load_capture_draws("default")
    caps = [crop_capture(draws, 0, e, k) for e in range(3) for k in range(40)]
    for key in CROP_KEYS:
        dist, values = draws.dists[key], [c.values[key] for c in caps]
        if dist.kind == "fixed":
            assert set(values) == set(dist.support), key
        else:
            assert dist.low <= min(values) and max(values) <= dist.high, key
    assert len({c.brightness for c in caps}) == len(caps) and len({c.read_noise_e for c in caps}) == len(caps)
    assert crop_capture(draws, 0, 1, 7) == caps[47] and crop_capture(draws, 1, 1, 7) != caps[47]
    panel = _panel("soft", 1.0, 3)
    for cap in caps[:5]:
        own = captured_panel(panel, cap)
        assert own.sensor.gain == pytest.approx(panel.sensor.gain / OWN_GAIN_SCALE * cap.gain_scale, rel=1e-15)
        assert own.sensor.exposure_s == pytest.approx(panel.sensor.exposure_s / OWN_EXPOSURE_SCALE
                                                      * cap.exposure_scale, rel=1e-15)
        assert own.sensor.read_noise_e == cap.read_noise_e and own.sensor.gamma_rggb == panel.sensor.gamma_rggb
        assert own.fpn == cap.fpn and own.defects == cap.defects and own.maps == "crop"  # maps of its own
        assert own.kernels is panel.kernels
    assert captured_panel(replace(panel, fpn=None), caps[0]).fpn is None  # FPN off stays off
    assert captured_panel(replace(panel, defects=None), caps[0]).defects is None  # and defects


def test_a_crop_degraded_with_its_capture_equals_its_panel_given_that_sensor(tmp_path, bank):
    """Oracle: the first crop of a batch made with capture draws equals the crop cut by hand, scaled by the
    capture's brightness and degraded by a Degrader whose one panel carries that capture's sensor and FPN."""
    data = write_pairs(tmp_path / "pairs", splits=(("train", 2),), size_px=(48, 64))
    b = read_bank(bank)
    draws = load_capture_draws("default")
    batches = OnlineBatches(clean_images(data, "train"), b, Degrader(b.panels), 32, 2, seed=0, workers=0,
                            captures=draws)
    d0, it = batches.epoch(0)
    x, y = next(it)
    d, m = d0[0], batches.degrader.margin_px
    cap = d["capture"]
    assert cap == crop_capture(draws, 0, 0, int(stream(0, "online order", 0).permutation(batches.crops)[0]))
    gt = clean_images(data, "train")[d["image"]].pixels
    n = 32 + 2 * m
    scene = np.pad(gt, ((0, 0), (m, m), (m, m)), "reflect")[:, d["y0"]:d["y0"] + n, d["x0"]:d["x0"] + n]
    clean = torch.from_numpy(np.ascontiguousarray(dihedral(scene, d["mode"]))) * cap.brightness
    own = captured_panel(b.panels[d["panel"]], cap)
    dn = Degrader([own]).degrade(clean, 0, gt.shape[1:], (d["y0"], d["x0"]),
                                 torch.Generator().manual_seed(d["noise_seed"]))
    assert torch.equal(x[0], normalised(dn, own).float()) and torch.equal(y[0], clean[:, m:-m, m:-m])
    plain = OnlineBatches(clean_images(data, "train"), b, Degrader(b.panels), 32, 2, seed=0, workers=0)
    assert not torch.equal(next(plain.epoch(0)[1])[0], x)  # the panel's own capture is another
    in_workers = OnlineBatches(clean_images(data, "train"), b, Degrader(b.panels), 32, 2, seed=0, workers=1,
                               captures=draws)
    xw, yw = next(in_workers.epoch(0)[1])
    assert torch.equal(x, xw) and torch.equal(y, yw)


def test_two_crops_of_one_panel_get_maps_of_their_own_recorded_and_drawn_again(tmp_path, bank):
    """With capture draws each crop has its own defect map and FPN maps: those of a crop-sized sensor with its
    capture's settings and seeds (sensor.defects.defect_map, sensor.fpn.fpn_maps), two crops of one panel
    different ones, and the seeds recorded in online.jsonl's entry (crop_values) draw them again."""
    data = write_pairs(tmp_path / "pairs", splits=(("train", 4),), size_px=(48, 64))
    b = read_bank(bank)
    batches = OnlineBatches(clean_images(data, "train"), b, Degrader(b.panels), 32, 2, seed=0, workers=0,
                            captures=load_capture_draws("default"))
    draws = batches.epoch(0)[0]
    d1, d2 = [d for d in draws if d["panel"] == draws[0]["panel"]][:2]
    maps = batches.degrader.maps
    kinds, gains = [], []
    for d in (d1, d2):
        own = captured_panel(b.panels[d["panel"]], d["capture"])
        crop = [((48, 64), (d["y0"], d["x0"]))]
        kinds.append(maps.defect_classes(crop, (32, 32), [own.defects], [True])[0].numpy())
        gains.append(maps.fpn(crop, (32, 32), [own.fpn], [True])[0][0].numpy())
        seeds = crop_values(d["capture"])[-2:]
        assert seeds == [own.defects.seed, own.fpn.seed]
        np.testing.assert_array_equal(kinds[-1], pack_rggb(defect_map(32, 32, replace(own.defects, seed=seeds[0]))))
        np.testing.assert_allclose(gains[-1], pack_rggb(fpn_maps(32, 32, replace(own.fpn, seed=seeds[1])).gain),
                                   rtol=1e-6)
    assert d1["capture"].defects.seed != d2["capture"].defects.seed and d1["capture"].fpn.seed != d2["capture"].fpn.seed
    assert not np.array_equal(gains[0], gains[1])


def test_a_run_with_capture_draws_records_them_resumes_identically_and_refuses_other_ones(tmp_path, bank,
                                                                                          monkeypatch, capsys):
    data = write_pairs(tmp_path / "pairs", splits=(("train", 3),), size_px=(48, 64))
    s = _settings(bank, epochs=4, batch=2, crop_px=32, lr=1e-3)
    s = replace(s, degrade={**s.degrade, "captures": load_capture_draws("default").describe()})
    log = straight_and_resumed(tmp_path, monkeypatch, data, s, bank)
    crops = [c for line in log.splitlines() for c in json.loads(line)["crops"]]
    assert len(crops) == 4 * 3 and all(len(c) == 6 + len(CROP_KEYS) + 2 for c in crops)
    brightness = 6 + CROP_KEYS.index("exposure.brightness")
    assert len({c[brightness] for c in crops}) == len({c[-2] for c in crops}) == len(crops)  # its own, per crop

    cfg = tmp_path / "tiny.toml"
    cfg.write_text('type = "unet"\nwidth = 4\ndepth = 2\n')
    ranges = tmp_path / "dim.toml"
    ranges.write_text('[exposure]\nbrightness = {dist = "uniform", low = 0.1, high = 0.2}\n')
    base = ["train", "--data", str(data), "--model", "unet", "--config", str(cfg), "--epochs", "1", "--crop-px",
            "32", "--quiet", "--degrade", "online", "--bank", str(bank)]
    assert main(base + ["--out", str(tmp_path / "cli"), "--capture-draws", str(ranges)]) == 0
    recorded = json.loads((tmp_path / "cli" / "train.json").read_text())["degrade"]["captures"]
    assert recorded == load_capture_draws(str(ranges)).describe()
    ranges.write_text('[exposure]\nbrightness = {dist = "uniform", low = 0.3, high = 0.4}\n')  # edited since
    bad = tmp_path / "bad.toml"
    bad.write_text('[exposure]\nbrightness = {dist = "uniform", low = 0.5, high = -1}\n')
    capsys.readouterr()
    for argv, words in ((["--out", str(tmp_path / "cli"), "--epochs", "2", "--capture-draws", str(ranges)],
                         "differs from this folder's run"),
                        (["--out", str(tmp_path / "c2"), "--capture-draws", str(bad)], "brightness"),
                        (["--out", str(tmp_path / "c3"), "--capture-draws", "nope"], "--randomize = 'nope'")):
        assert main(base + argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and words in err, err
    from restore.data import DataError
    from restore.online import run_captures
    with pytest.raises(DataError, match="not the run's"):  # settings made before the file was edited
        run_captures({"captures": recorded})
    dataset_run = ["train", "--data", str(data), "--model", "unet", "--display", "soft", "--out",
                   str(tmp_path / "c4"), "--capture-draws", "default"]
    assert main(dataset_run) == 2 and "goes with --degrade online" in capsys.readouterr().err


def test_capture_draws_from_the_bank_are_those_it_was_drawn_from(tmp_path, bank, capsys):
    """--capture-draws bank reads the distributions a randomized bank recorded (bank.json "randomize"): the same
    crops' captures as the file they came from; a bank not drawn is refused in one line."""
    from udc_render.dataset.randomize import load_distributions
    ranges = tmp_path / "dim.toml"
    ranges.write_text('[exposure]\nbrightness = {dist = "uniform", low = 0.1, high = 0.2}\n')
    drawn = tmp_path / "drawn_bank"
    records = [save_panel(drawn, 0, _panel("soft", 1.0, 0))]
    write_bank_json(drawn, {"randomize": load_distributions(ranges).describe()}, records, 1)
    from_bank = load_capture_draws("bank", read_bank(drawn))
    from_file = load_capture_draws(str(ranges))
    assert [crop_capture(from_bank, 0, 0, k) for k in range(5)] == [crop_capture(from_file, 0, 0, k) for k in range(5)]
    assert from_bank.describe()["sha256"] == from_file.describe()["sha256"] and from_bank.spec == "bank"
    data = write_pairs(tmp_path / "pairs", splits=(("train", 2),), size_px=(48, 64))
    base = ["train", "--data", str(data), "--model", "unet", "--epochs", "1", "--crop-px", "32", "--quiet",
            "--degrade", "online", "--capture-draws", "bank"]
    capsys.readouterr()
    assert main(base + ["--bank", str(bank), "--out", str(tmp_path / "r1")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--capture-draws bank: the bank" in err and "was not drawn" in err, err
