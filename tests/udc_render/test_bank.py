"""Kernel banks (udc_render.dataset.bank, `udc-render bank`): written, read back, resumed, refused in one line."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from psf.cache import ENGINE_VERSION
from restore.degrade import Degrader, WideSource
from restore.degrade_wide import WideLight
from restore.tensors import region
from udc_render.cli import main
from udc_render.dataset.bank import (
    BANK_FILE,
    BANK_FORMAT,
    FORMAT_1,
    FORMAT_1_EFFECTS,
    Panel,
    PanelFar,
    PanelHaze,
    read_bank,
    read_panel,
    save_panel,
    write_bank_json,
)
from udc_render.dataset.bank_make import differing_settings, monitor_white_bands
from udc_render.dataset.randomize import draw_capture, draw_panels, load_distributions
from udc_render.optics.apply import far_field_images
from udc_render.optics.displays import PAPER_GAIN, PAPER_GAMMA, preset
from udc_render.pipeline import SynthConfig, plan_kernels, sensor_for_scene
from udc_render.profiles import resolve_profile
from udc_render.scene import load_scene
from udc_render.scene.geometry import psf_lens
from udc_render.scene.overrides import with_overrides
from udc_render.sensor import SensorConfig, band_electron_weights
from udc_render.synth_kernels import paper_channel_kernels

TINY = ["--sensor-px", "64,32", "--pitch-um", "24.8", "--bands-nm", "400:700:100", "--quiet"]


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return str(tmp_path_factory.mktemp("bank_kernels"))


def _bank(out, cache, *argv) -> int:
    return main(["bank", "--out", str(out), "--cache-dir", cache, *TINY, *argv])


def _one_line(capsys, argv, *words):
    assert main(argv) == 2, argv
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err and all(w in err for w in words), err


def test_a_paper_bank_is_the_per_channel_synthesis_and_resumes(tmp_path, cache, capsys):
    """--profile paper: each panel's kernels are the very kernels of synth --form per_channel (the paper's recipe at
    the sensor pitch, 33 px for the tiny sensor's 396 µm margin), the paper's γ and gain, its Gaussian noise, no
    defects or FPN; read back with every file checked. A re-run makes nothing; a deleted panel file is made again
    with the same bytes; glass is a panel only when named."""
    out = tmp_path / "bank"
    assert _bank(out, cache, "--display", "glass,toled", "--profile", "paper") == 0
    bank = read_bank(out)
    assert [p.name for p in bank.panels] == ["glass", "toled"] and bank.margin_px == 16
    scene = with_overrides(load_scene("monitor"), bands_nm="400:700:100", sensor_px=(64, 32), pitch_um=24.8)
    for p in bank.panels:
        ref = paper_channel_kernels(preset(p.name).layout, psf_lens(scene), 24.8, 33, cache_dir=cache)
        np.testing.assert_array_equal(p.kernels, ref.kernels)
        assert p.gamma_rgb == PAPER_GAMMA[p.name] and p.sensor.gain == PAPER_GAIN[p.name]
        assert p.sensor.gamma_rggb[3] == pytest.approx(PAPER_GAMMA[p.name][2] / PAPER_GAIN[p.name])
        assert (p.sensor.noise, p.sensor.lambda_source, p.defects, p.fpn, p.field) == ("gaussian", "sensor", None, None,
                                                                                     None)
        assert p.record["brightness"] == 1.0 and (p.far, p.haze) == (None, None)  # the paper's form has neither
        assert "per-channel form" in p.record["effects"]["not_applied"]["far field"]
    capsys.readouterr()
    assert _bank(out, cache, "--display", "glass,toled", "--profile", "paper") == 0
    assert "0 made now" in capsys.readouterr().out
    toled = out / bank.panels[1].record["file"]
    before = toled.read_bytes()
    toled.unlink()
    assert _bank(out, cache, "--display", "glass,toled", "--profile", "paper") == 0
    assert "1 made now" in capsys.readouterr().out and toled.read_bytes() == before
    assert _bank(tmp_path / "b2", cache, "--display", "toled", "--profile", "paper") == 0
    assert [p.name for p in read_bank(tmp_path / "b2").panels] == ["toled"]


def test_a_physical_bank_has_field_bases_that_degrade(tmp_path, cache):
    """--profile physical: the T-OLED at d = 2 mm gets rank-4 field bases (the camera's channel kernels at the scene's
    band step, 2 × 2 phases here), Poisson noise, defect pixels, FPN and a far field, no haze (the profile's T-OLED
    has none), as its record's effects say; the Degrader takes it with the crop's frame."""
    out = tmp_path / "bank"
    assert _bank(out, cache, "--display", "toled", "--field-phases", "2") == 0
    (p,) = read_bank(out).panels
    assert p.far is not None and p.haze is None and p.record["far_field"]["share_rgb"] == p.far.share_rgb
    effects = p.record["effects"]
    assert any(e.startswith("far field") for e in effects["applied"]) and "haze is 0" in effects["not_applied"]["haze"]
    f = p.field
    assert f.distance_mm == 2.0 and f.rank == 4 and len(f.live) == 4 and f.series is not None
    assert f.bases.shape == (3, 4, 33, 33)
    sums = np.einsum("cqr,cr->cq", f.coeffs, f.bases.astype(np.float64).sum(axis=(-2, -1)))
    assert np.allclose(sums, 1.0, atol=1e-5)  # each phase kernel's basis form keeps its unit sum (phase_basis)
    assert p.sensor.noise == "poisson" and p.defects is not None and p.fpn is not None
    assert p.record["kernel_params"]["distance_mm"] == 2.0
    frame = torch.rand(3, 32, 64)
    dn = Degrader([p]).degrade(region(frame, -16, -16, 64, 96), 0, (32, 64), (0, 0), torch.Generator().manual_seed(0),
                               source=WideSource("frame", frame))
    assert dn.shape == (4, 16, 32) and dn.max() > 0


def test_the_far_field_is_the_spectral_synthesiss(tmp_path, cache):
    """The bank's far field through the torch path equals the spectral synthesis's (pipeline.plan_kernels' far field
    through optics.apply.far_field_images with the camera's band weights) for a scene of the monitor's white
    spectrum, relative to each channel's core light Σ_k w_ck g_k white_k (float64, 1e-13: the same light); the
    shares bank.md states (measured: T-OLED 0.94–1.16 %, P-OLED 5.77–7.64 %, B to R)."""
    out = tmp_path / "bank"
    assert _bank(out, cache, "--display", "toled,poled", "--field-phases", "2") == 0
    scene = with_overrides(load_scene("monitor"), bands_nm="400:700:100", sensor_px=(64, 32), pitch_um=24.8)
    cfg, displays = resolve_profile("physical", SynthConfig(field_phases=2, kernel_cache=cache), [preset("toled"),
                                                                                                    preset("poled")])
    kernels = plan_kernels(scene, displays, cfg)
    edges = np.asarray(scene.bands.edges_nm, float)
    w, white = band_electron_weights(edges, sensor_for_scene(cfg.sensor, scene)), monitor_white_bands(scene)
    frame = torch.from_numpy(np.random.default_rng(0).random((32, 64))).expand(3, -1, -1)  # the white's spectrum
    s = region(frame, -16, -16, 64, 96)[0].numpy()  # with the margin a crop takes (mirrored)
    for p, d in zip(read_bank(out).panels, displays):
        ks, t = kernels.band[d.name], d.transmission.band_means(edges)
        far = far_field_images(white[:, None, None] * s, kernels.far[d.name], 16, t * ks.transmittance, w)
        core = w @ (white * t * ks.transmittance * (1 - ks.energy_outside))
        ours = WideLight([p], 16, torch.device("cpu"), torch.float64).crops([0], [((32, 64), (0, 0))],
                                                                           [WideSource("s", frame)], (32, 64))[0][0]
        np.testing.assert_allclose(ours.numpy(), far / core[:, None, None], rtol=1e-13)  # measured 1.0e-15
    shares = [p.far.share_rgb for p in read_bank(out).panels]
    assert all(0.009 < v < 0.012 for v in shares[0]) and all(0.057 < v < 0.077 for v in shares[1]), shares


@pytest.mark.slow
def test_a_randomized_bank_records_its_draws(tmp_path, cache):
    """--randomize default --panels 2: panel i is draw_panels' i (display, d, lens) with capture draw i's sensor
    (gain × gain_scale, read noise, defects and FPN with their seeds), exposure scale and brightness (~20 s)."""
    out = tmp_path / "bank"
    assert _bank(out, cache, "--randomize", "default", "--panels", "2", "--field-phases", "2") == 0
    bank = read_bank(out)
    dists = load_distributions("default")
    draws = draw_panels(dists, 2, 0)
    for i, p in enumerate(bank.panels):
        cap = draw_capture(dists, 2, 0, i)
        assert p.name == f"random_{i:03d}" and p.field.distance_mm == pytest.approx(draws[i].display.distance_mm)
        assert p.sensor.read_noise_e == cap.read_noise_e and p.defects == cap.defects and p.fpn == cap.fpn
        assert p.record["brightness"] == cap.brightness and p.record["panel_draw"]["index"] == i
    doc = json.loads((out / BANK_FILE).read_text())
    assert doc["randomize_seed"] == 0 and doc["panels"][0]["display"]["source"].startswith("randomize")


def test_bad_bank_options_are_refused_in_one_line(tmp_path, cache, capsys):
    out = str(tmp_path / "b")
    hazy = tmp_path / "hazy.toml"  # a haze the paper's per-channel form cannot apply: refused before any kernel
    hazy.write_text('[display]\nfamily = "poled"\ndistance_mm = 0.0\n[display.poled]\nhaze = 0.02\n')
    for argv, words in (
            (["--display", "toled", "--randomize", "default"], ("--display with --randomize",)),
            (["--panels", "3"], ("--panels and --randomize-seed go with --randomize",)),
            (["--kernel-px", "32"], ("--kernel-px must be an odd integer",)),
            (["--display", "toled", "--channel-kernels", "paper"], ("--channel-kernels paper", "d = 2 mm")),
            (["--randomize", "default", "--distance-mm", "1"], ("--distance-mm with --randomize",)),
            (["--randomize", str(hazy), "--panels", "1", "--profile", "paper"], ("a haze of 0.02", "physical"))):
        _one_line(capsys, ["bank", "--out", out, "--cache-dir", cache, *TINY, *argv], *words)
    assert _bank(tmp_path / "b1", cache, "--display", "glass", "--profile", "paper") == 0
    _one_line(capsys, ["bank", "--out", str(tmp_path / "b1"), "--cache-dir", cache, *TINY, "--display", "glass",
                       "--profile", "paper", "--kernel-px", "21"], "holds a different bank", "kernel_px")
    doc = json.loads((tmp_path / "b1" / BANK_FILE).read_text())
    assert doc["psf_engine"] == ENGINE_VERSION  # kernels of another engine version: refused, not resumed
    (tmp_path / "b1" / BANK_FILE).write_text(json.dumps({**doc, "psf_engine": "psf-4"}))
    _one_line(capsys, ["bank", "--out", str(tmp_path / "b1"), "--cache-dir", cache, *TINY, "--display", "glass",
                       "--profile", "paper"], "holds a different bank", "psf_engine")
    (tmp_path / "b1" / "panel_000_glass.npz").write_bytes(b"not it")
    with pytest.raises(Exception, match="differs from its sha256"):
        read_bank(tmp_path / "b1")
    with pytest.raises(Exception, match="no bank.json"):
        read_bank(tmp_path)


@pytest.mark.slow
def test_a_hazy_randomized_bank_degrades_otherwise_than_a_clear_one(tmp_path, cache):
    """--randomize with the P-OLED's haze fixed at 0.02 and at 0 (every other draw the same: each key has its own
    stream): the hazy panel records and applies its haze, the clear one records why it has none; a bright square on
    black degraded through both with the same noise loses light in the square and gains it 6 px and more away
    (the veil). ~30 s; the fast sibling: tests/restore/test_degrade_wide.py, test_the_haze_moves_its_share_into_a_veil.
    """
    banks = []
    for haze in (0.02, 0.0):
        ranges = tmp_path / f"haze_{haze}.toml"
        ranges.write_text(f'[display]\nfamily = "poled"\ndistance_mm = 1.0\n[display.poled]\nhaze = {haze}\n')
        assert _bank(tmp_path / f"b{haze}", cache, "--randomize", str(ranges), "--panels", "1", "--field-phases",
                     "2") == 0
        banks.append(read_bank(tmp_path / f"b{haze}").panels[0])
    hazy, clear = banks
    assert hazy.haze.share == 0.02 and clear.haze is None and hazy.record["panel_draw"]["haze"] == 0.02
    assert "haze is 0" in clear.record["effects"]["not_applied"]["haze"]
    assert any(e.startswith("haze: 0.02") for e in hazy.record["effects"]["applied"])
    np.testing.assert_array_equal(hazy.kernels, clear.kernels)
    frame = torch.zeros(3, 32, 64)
    frame[:, 8:16, 24:40] = 1.0
    dn = [Degrader([p], "cpu", torch.float64).degrade(
        region(frame, -16, -16, 64, 96).double(), 0, (32, 64), (0, 0), torch.Generator().manual_seed(0),
        source=WideSource("f", frame)) for p in (hazy, clear)]
    moved = (dn[0] - dn[1]).numpy()
    away = np.ones((16, 32), bool)
    away[1:11, 9:23] = False  # sites 6 px and more from the square
    assert moved[:, 4:8, 12:20].sum() < 0 and moved[:, away].mean() > 0


def test_a_format_1_bank_is_read_without_far_field_or_haze_and_never_resumed(tmp_path, cache, capsys):
    """A bank.json of format 1 (made before panels carried the far field and the haze, as the shipped models'
    carried banks) is read with neither, whatever its panel files hold, its effects saying so; its settings name the
    bank today's settings make but for the effects it cannot have (what carried_bank compares), and `udc-render
    bank` refuses to resume it in one line."""
    out = tmp_path / "b1"
    panel = Panel("p", np.full((3, 3, 3), 1 / 9, np.float32), 24.8, (0.3,) * 3, SensorConfig(), None, None, None, {},
                  far=PanelFar(np.full((3, 5, 5), 0.002), 15), haze=PanelHaze(0.015, 2.5))
    record = save_panel(out, 0, panel)
    assert read_panel(out, record).far is not None  # format 2 reads what the file holds
    write_bank_json(out, {"test": "format 1"}, [{k: v for k, v in record.items() if k not in ("far_field", "haze")}], 1)
    (out / BANK_FILE).write_text((out / BANK_FILE).read_text().replace(BANK_FORMAT, FORMAT_1))
    (p,) = read_bank(out).panels
    assert (p.far, p.haze) == (None, None) and p.record["effects"]["not_applied"] == FORMAT_1_EFFECTS
    paper = tmp_path / "paper"
    argv = ["bank", "--out", str(paper), "--cache-dir", cache, *TINY, "--display", "glass", "--profile", "paper"]
    assert main(argv) == 0
    doc = json.loads((paper / BANK_FILE).read_text())
    old = {**{k: v for k, v in doc.items() if k != "effects"}, "format": FORMAT_1}
    assert differing_settings(old, doc) == [] and differing_settings({**old, "format": BANK_FORMAT}, doc) == ["effects"]
    (paper / BANK_FILE).write_text(json.dumps(old))
    _one_line(capsys, argv, "holds a different bank", "format")


def test_a_bank_from_before_the_engine_was_recorded_resumes_only_without_aperiodic_displays():
    """bank.json records psf_engine from psf-5 on; psf-5 changed only aperiodic displays' kernels (their field phases
    across the sensor), so a doc without the key names today's bank unless one of its displays is turned per tile."""
    settings = {"kernel_px": 9, "psf_engine": ENGINE_VERSION,
                "displays": [{"name": "t", "layout": {"kind": "micrograph", "random_rotation": False}}]}
    old = {k: v for k, v in settings.items() if k != "psf_engine"}
    assert differing_settings(old, settings) == []
    turned = {**settings, "displays": [{"name": "t", "layout": {"kind": "micrograph", "random_rotation": True}}]}
    assert differing_settings({k: v for k, v in turned.items() if k != "psf_engine"}, turned) == ["psf_engine"]
    assert differing_settings({**old, "psf_engine": "psf-4"}, settings) == ["psf_engine"]
