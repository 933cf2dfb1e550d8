"""The restorer conditioned on the panel's description (restore.models_conditioned, 'wiener-unet'): its Wiener
features, its dependence on the description, its counts, and its training online with each crop's description."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from restore.conditioning import bank_descriptions, description_tensors
from restore.counting import count_macs, count_parameters, mac_breakdown
from restore.degrade import Degrader
from restore.models import UNET_CONFIG, build_model
from restore.models_conditioned import NSR_FLOOR, WIENER_UNET_CONFIG, WienerFeatures, WienerUNet
from restore.online import OnlineBatches, clean_images
from restore.train import TrainSettings, load_model, train
from tests.conftest import write_pairs
from tests.restore.test_augment import with_display_records
from tests.restore.test_online import _blur_panel
from tests.restore.test_train import train_interrupted_at_epoch_2
from udc_render.cli import main
from udc_render.dataset.bank import Panel, read_bank, save_panel, write_bank_json
from udc_render.description.make import dataset_rig, describe_display, describe_panel
from udc_render.sensor import SensorConfig, mosaic_of, pack_rggb

K = 129
TINY = {"type": "wiener-unet", "width": 4, "depth": 2, "fine_levels": 1, "fine_extra_width": 4,
        "wiener_features": 1, "code_dim": 8}
TINY_9 = {**TINY, "kernel_px": 9}  # descriptions in a 9-px window: the test bank's 9-px blurs, a cheap T-OLED kernel


@pytest.fixture(autouse=True)
def two_threads():
    old = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(old)


def _kernels(sigmas_px, weight: float = 0.4) -> torch.Tensor:
    """[1, 3, K, K]: (1 − weight) δ + weight · a unit Gaussian of σ per channel (|K(f)| ≥ 1 − 2 · weight > 0)."""
    r = torch.arange(K, dtype=torch.float64) - K // 2
    out = []
    for s in sigmas_px:
        g = torch.exp(-(r[:, None] ** 2 + r[None, :] ** 2) / (2 * s * s))
        k = weight * g / g.sum()
        k[K // 2, K // 2] += 1 - weight
        out.append(k)
    return torch.stack(out)[None].float()


def _description(kernels, gamma=(0.5, 0.4, 0.4, 0.3), read=0.0, shot=0.0, batch: int = 1) -> dict:
    """The description tensors (restore.conditioning.TENSOR_KEYS) of a panel of these kernels and γ."""
    return {"kernels": kernels.expand(batch, -1, -1, -1), "outside": torch.zeros(batch, 3),
            "gamma": torch.tensor([gamma] * batch), "gain": torch.full((batch,), 4.0),
            "lambda_read": torch.full((batch, 4), read), "lambda_shot": torch.full((batch, 4), shot),
            "saturation": torch.full((batch,), 2.0), "black_level_dn": torch.zeros(batch),
            "white_level_dn": torch.full((batch,), 65535.0), "bit_depth": torch.full((batch,), 16.0),
            "distance_mm": torch.zeros(batch)}


def test_wiener_features_of_a_noiseless_capture_recover_the_image():
    """A 64-px packed crop (smaller than the 129-px kernel window) of an image blurred by linear convolution with
    the description's kernels (R: 0, Gr and Gb: 1, B: 2) and scaled by γ, no noise (NSR = NSR_FLOOR = 1e-4 against
    |K|² ≥ 0.04): the deconvolved planes equal the image to 1e-3 beyond 16 px of the edge (measured 1.7e-4), and
    their mean error over the whole crop, edges and mirror included, is under a tenth of the blurred capture's
    (measured 0.0012 against 0.027)."""
    h = 64
    torch.manual_seed(0)
    big = F.avg_pool2d(torch.rand(1, 4, h + 2 * K, h + 2 * K), 3, 1, 1)
    kernels = _kernels((1.5, 3.0, 6.0))
    blurred = F.conv2d(big, kernels[0, [0, 1, 1, 2], None].flip(-1, -2), groups=4)  # a convolution, not correlation
    o = (blurred.shape[-1] - h) // 2
    capture, image = blurred[..., o:o + h, o:o + h], big[..., o + K // 2:o + K // 2 + h, o + K // 2:o + K // 2 + h]
    d = _description(kernels)
    out = WienerFeatures(0)(capture * d["gamma"][:, :, None, None], d)
    assert NSR_FLOOR <= 1e-4 and out.shape == image.shape
    assert (out - image)[..., 16:-16, 16:-16].abs().max() < 1e-3
    assert (out - image).abs().mean() < 0.1 * (capture - image).abs().mean()


def test_the_wiener_features_invert_the_online_degradation_with_the_banks_description(tmp_path):
    """The conventions agree end to end: a noiseless crop degraded by restore.online through a panel whose kernel is
    0.75 δ + 0.25 δ two sensor pixels down and right (one packed pixel: packed_window keeps it exact), γ 0.5, is
    deconvolved with describe_panel's description (restore.conditioning.bank_descriptions) to the clean crop's
    planes: within 5e-4 beyond 8 px of the edge (measured 1.0e-4; the scene beyond the crop is not the mirror, and
    the inverse filter decays by 1/3 a pixel), against the input ÷ γ's mean error of 0.020."""
    k = np.zeros((3, 9, 9), np.float32)
    k[:, 4, 4], k[:, 6, 6] = 0.75, 0.25
    sensor = SensorConfig(form="per_channel", gain=2.0, gamma_rggb=(0.25,) * 4, exposure_s=0.03, noise="none")
    out = tmp_path / "bank"
    write_bank_json(out, {"frame_px": [96, 64]}, [save_panel(out, 0, Panel("diagonal", k, 1.55, (0.5,) * 3, sensor,
                                                                            None, None, None, {"brightness": 1.0}))], 1)
    bank = read_bank(out)
    data = write_pairs(tmp_path / "pairs", splits=(("train", 1),), size_px=(64, 96))
    batches = OnlineBatches(clean_images(data, "train"), bank, Degrader(bank.panels), 64, 1, seed=0, workers=0)
    x, y = batches.sample(dict(batches.draw(0, 0), mode=0))
    planes = WienerFeatures(0)(x[None], description_tensors(bank_descriptions(bank, 9)))[0]
    clean = torch.from_numpy(pack_rggb(mosaic_of(y.numpy())))
    assert (planes - clean)[:, 8:-8, 8:-8].abs().max() < 5e-4
    assert (x / 0.5 - clean).abs().mean() > 0.01


def test_the_output_depends_on_the_kernels_and_is_equivariant_under_the_batchs_order():
    """Two kernels give two outputs (at initialisation, through the Wiener features: measured 0.0085; codes alone
    once their FiLM is not zero, by less at initialisation: the random encoder's codes differ by 6e-4); the same
    capture ×2 with γ ×2 and no noise gives the same output (x / γ and Wiener(x) / γ); permuting a batch of three
    crops and their descriptions permutes the outputs. A 32-px packed crop: the window is mirrored more than once."""
    torch.manual_seed(1)
    model = build_model(TINY).eval()
    x = torch.rand(1, 4, 32, 32)
    sharp, soft = _description(_kernels((1.0, 1.0, 1.0))), _description(_kernels((4.0, 4.0, 4.0), 0.45))
    with torch.no_grad():
        a, b = model(x, sharp), model(x, soft)
        assert a.shape == (1, 3, 64, 64) and (a - b).abs().max() > 1e-3
        doubled = _description(_kernels((1.0, 1.0, 1.0)), gamma=(1.0, 0.8, 0.8, 0.6))
        assert (model(2 * x, doubled) - a).abs().max() < 1e-5  # outputs of order 0.1: float32 rounding
        codes = build_model({**TINY, "wiener": False})
        assert torch.equal(codes(x, sharp), codes(x, soft))  # FiLM starts at zero: the identity
        for film in codes.film_encoder:
            torch.nn.init.normal_(film.linear.weight, std=0.5)
        assert (codes(x, sharp) - codes(x, soft)).abs().max() > 1e-5  # measured 7e-5; the same call: bit-equal
        xs = torch.rand(3, 4, 32, 32)
        ds = [_description(_kernels((s, 2 * s, 3 * s)), read=1e-4 * s, shot=1e-3) for s in (1.0, 1.5, 2.5)]
        batch = {k: torch.cat([d[k] for d in ds]) for k in ds[0]}
        out = model(xs, batch)
        perm = torch.tensor([2, 0, 1])
        assert (model(xs[perm], {k: v[perm] for k, v in batch.items()}) - out[perm]).abs().max() < 1e-5


def test_its_counts_are_the_papers_unet_topology_plus_the_conditioning():
    """With no extra width and neither conditioning's parameters counted, the backbone is restore.models.UNet on
    4 + maps input channels: the same parameters and, on the meta device at 4 × 512 × 1024, the same MACs per part
    (the paper's UNet counts are pinned in test_models). FiLM adds (code_dim + 1) · 2c per level; the Wiener features
    4 · f · 9 filter weights and one prior per map. The extra width raises the MACs of the fine levels only."""
    cfg = {**WIENER_UNET_CONFIG, "fine_extra_width": 0}
    model = build_model(cfg)
    maps = 4 * (1 + cfg["wiener_features"])
    unet = {"type": "unet", "in_channels": 4 + maps, "width": 32, "depth": 5, "sub_encoders": 2,
            "second_encoder_levels": 4}
    parts = ("encoder", "residual_encoder", "up", "decoder", "to_rgb")
    backbone = sum(count_parameters(getattr(model, p)) for p in parts)
    assert backbone == count_parameters(build_model(unet))
    ch = [32 * 2 ** i for i in range(5)]
    film = sum((cfg["code_dim"] + 1) * 2 * c for c in ch + ch[:-1])
    assert count_parameters(model.film_encoder) + count_parameters(model.film_decoder) == film
    assert count_parameters(model.wiener) == 4 * cfg["wiener_features"] * 9 + maps
    assert count_parameters(model) == backbone + film + count_parameters(model.wiener) + count_parameters(model.codes)
    ours, paper = mac_breakdown(cfg), mac_breakdown(unet, (1, 4 + maps, 512, 1024))
    assert all(ours[p] == paper[p] for p in parts)
    wide = mac_breakdown(WIENER_UNET_CONFIG)
    assert wide["encoder"] > ours["encoder"] and count_macs(WIENER_UNET_CONFIG) > count_macs(cfg)
    assert count_macs({**cfg, "fine_levels": 0, "fine_extra_width": 32}) == count_macs(cfg)


def _bank(tmp_path, frame_px=(96, 64)):
    """Two Gaussian-blur panels (restore's online tests'), bank.json naming the frame."""
    out = tmp_path / "bank"
    records = [save_panel(out, i, _blur_panel(n, s)) for i, (n, s) in enumerate((("soft", 1.0), ("softer", 2.0)))]
    write_bank_json(out, {"frame_px": list(frame_px)}, records, 2)
    return out


def _settings(bank_dir, **kw) -> TrainSettings:
    b = read_bank(bank_dir)
    names = [p.name for p in b.panels]
    return TrainSettings(**{"model": TINY_9, "display": ",".join(names), "batch": 2, "crop_px": 32, "lr": 1e-3,
                            "degrade": {"mode": "online", "bank_fingerprint": b.fingerprint, "panels": names}, **kw})


def test_trained_online_with_each_crops_description_resumed_and_evaluated_with_display(tmp_path, monkeypatch):
    """`train` through a two-panel bank: every batch's description is description_tensors of describe_panel of each
    crop's panel (as online.jsonl records it) on the bank's frame; the checkpoint records that DescriptionSpec; a run
    interrupted after two epochs and resumed ends with the straight run's weights; `evaluate --display FILE` restores
    the test split with what describe_display computes for the file (the dataset's sensor, frame and rig) in the
    model's window. (~13 s with a cold kernel cache, ~5 s after test_conditioning, which computes the same T-OLED
    kernels.)"""
    bank = _bank(tmp_path)
    data = write_pairs(tmp_path / "pairs", splits=(("train", 2), ("val", 1), ("test", 1)), displays=("mine",))
    (tmp_path / "mine.toml").write_text('[display]\nname = "mine"\n[display.layout]\ntype = "toled"\n')
    data = with_display_records(data, "mine", str(tmp_path / "mine.toml"))
    s = _settings(bank, epochs=3)
    seen, forward = [], WienerUNet.forward

    def spy(self, x, description):
        seen.append({k: v.clone() for k, v in description.items()})
        return forward(self, x, description)
    with monkeypatch.context() as m:
        m.setattr(WienerUNet, "forward", spy)
        train(data, tmp_path / "straight", s, progress=False, bank=bank, degrade_workers=0)
    b = read_bank(bank)
    panels = [describe_panel(p, (96, 64), kernel_px=9) for p in b.panels]
    lines = [json.loads(ln) for ln in (tmp_path / "straight" / "online.jsonl").read_text().splitlines()]
    crops = [c[1] for ln in lines for c in ln["crops"]]
    train_seen = [d for d in seen if d["kernels"].shape[0] == 2]  # batches of 2; validation: one image at a time
    assert len(crops) == 6 and len(train_seen) == 3 and len(set(crops)) == 2
    for i, d in enumerate(train_seen):
        want = description_tensors([panels[p] for p in crops[2 * i:2 * i + 2]])
        assert all(torch.equal(d[k], want[k]) for k in want)
    record = torch.load(tmp_path / "straight" / "model.pt", weights_only=False)
    spec = record["model_config"]["description_spec"]
    assert spec == {**json.loads(json.dumps(panels[0].spec().__dict__))} and spec["frame_px"] == [96, 64]
    train_interrupted_at_epoch_2(monkeypatch, data, tmp_path / "resumed", s, bank=bank, degrade_workers=0)
    train(data, tmp_path / "resumed", s, progress=False, bank=bank, degrade_workers=0)
    a = record["state_dict"]
    r = torch.load(tmp_path / "resumed" / "model.pt", weights_only=False)["state_dict"]
    assert all(torch.equal(a[k], r[k]) for k in a)
    model, _ = load_model(tmp_path / "straight" / "model.pt", "cpu")
    assert model.description_spec == spec
    seen.clear()
    with monkeypatch.context() as m:
        m.setattr(WienerUNet, "forward", spy)
        assert main(["evaluate", "--data", str(data), "--model", str(tmp_path / "straight" / "model.pt"), "--out",
                     str(tmp_path / "eval"), "--display", str(tmp_path / "mine.toml"), "--previews", "0",
                     "--quiet"]) == 0
    item = sorted((data / "test" / "shard_0000").iterdir())[0]
    sensor = json.loads((item / "mine" / "capture.json").read_text())["sensor"]
    want = description_tensors([describe_display(tmp_path / "mine.toml", sensor, (96, 64), dataset_rig(item),
                                                 kernel_px=9)])
    restored = [d for d in seen if not d["kernels"].is_meta]  # not the MACs' count (restore.counting)
    assert len(restored) == 1 and all(torch.equal(restored[0][k], want[k]) for k in want)
    results = json.loads((tmp_path / "eval" / "results.json").read_text())["methods"]["wiener-unet"]
    assert results["descriptions"] == {"mine": f"display file {tmp_path / 'mine.toml'}"}


def test_refused_in_one_line_on_a_datasets_captures_or_a_bank_without_its_frame(tmp_path, capsys):
    data = write_pairs(tmp_path / "pairs", splits=(("train", 2),), size_px=(48, 64))
    cfg = tmp_path / "tiny.toml"
    cfg.write_text("".join(f"{k} = {json.dumps(v)}\n" for k, v in TINY_9.items()))
    base = ["train", "--data", str(data), "--model", "wiener-unet", "--config", str(cfg), "--epochs", "1",
            "--crop-px", "32", "--quiet"]
    bank = tmp_path / "frameless"
    write_bank_json(bank, {}, [save_panel(bank, 0, _blur_panel("soft", 1.0))], 1)
    for argv, words in ((["--display", "blur"], "--model wiener-unet: it restores with the panel's description, "
                                                "which training gives only with the online degradation"),
                        (["--degrade", "online", "--bank", str(bank)], "its bank.json names no frame_px")):
        assert main(base + ["--out", str(tmp_path / "run"), *argv]) == 2, argv
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and words in err, err
    assert not (tmp_path / "run" / "train.json").exists()


def test_the_train_guides_counts_are_the_models():
    """docs/guides/train.md's table of wiener-unet's parameters and MACs at 1 × 4 × 512 × 1024 is the code's."""
    text = (Path(__file__).parents[2] / "docs" / "guides" / "train.md").read_text()
    rows = {"the defaults": WIENER_UNET_CONFIG}
    rows.update({f"`fine_extra_width = {e}`": {**WIENER_UNET_CONFIG, "fine_extra_width": e} for e in (16, 0)})
    rows["the paper's UNet, for comparison"] = UNET_CONFIG
    for label, cfg in rows.items():
        with torch.device("meta"):
            params = count_parameters(build_model(cfg))
        row = f"| {label} | {params:,} | {count_macs(cfg) / 1e9:.1f} G |"
        assert row in text, row
