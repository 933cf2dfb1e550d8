"""The paper profile's channel kernels are the paper's recipe as printed (issue 29, item 1): the very
kernels `udc-render psf --method paper` writes at 640 / 520 / 450 nm, and the choice is recorded."""
from __future__ import annotations

import json

import numpy as np
import pytest

from udc_render.cli import build_parser, main
from udc_render.cli.args import capture_setup
from udc_render.pipeline import plan_kernels
from udc_render.scene.geometry import psf_lens
from udc_render.synth_kernels import PAPER_CHANNEL_NM

pytestmark = pytest.mark.usefixtures("render_cache")


@pytest.fixture(scope="module")
def packed(udc, tmp_path_factory):
    """64 × 32 px of 3.1 µm (the packed RGGB plane's pitch), one band, 2 spp, 21-px kernels."""
    path = tmp_path_factory.mktemp("packed") / "mon.toml"
    return path, udc.write_scene(path, udc.monitor_doc(image="pattern:slanted_edge", sensor_px=(64, 32), pitch_um=3.1,
                                                       render={"spp": 2, "margin_um": 31.0},
                                                       bands={"range_nm": [500, 600], "step_nm": 100}))


def _paper_plan(path, scene, *options):
    cfg, displays = capture_setup(build_parser().parse_args(["synth", str(path), "--display", "toled",
                                                             "--profile", "paper", "--no-cache", *options]))
    return cfg, plan_kernels(scene, displays, cfg)


def test_paper_profile_kernels_are_psf_method_paper(packed, tmp_path):
    path, scene = packed
    cfg, planned = _paper_plan(path, scene)
    ks = planned.channel["toled"]
    assert cfg.channel_kernels == "paper" and ks.pixel_um == 3.1 and ks.params["method"] == "paper"
    np.testing.assert_array_equal(ks.wavelengths_nm, [640.0, 520.0, 450.0])
    assert PAPER_CHANNEL_NM == (640.0, 520.0, 450.0)
    lens = psf_lens(scene, planned.object_distance_m)  # f/1.8: D = 3333.3 µm, the paper's 3333 to 1e-4
    np.testing.assert_allclose(ks.ratio_r, [2.41, 2.98, 3.44], rtol=1.1e-4)  # the printed r
    lens_options = [f"--{k.replace('_', '-')}={getattr(lens, k)!r}" for k in
                    ("focal_length_um", "aperture_um", "focus_distance_mm", "object_distance_mm")]
    assert main(["psf", "--display", "toled", "--method", "paper", "--wavelengths-nm", "640,520,450",
                 "--pitch-um", "3.1", "--kernel-px", str(ks.size_px), *lens_options, "--no-cache",
                 "--out", str(tmp_path)]) == 0
    cli = np.load(tmp_path / "psf.npz")
    assert str(cli["method"]) == "paper"
    np.testing.assert_array_equal(ks.kernels, cli["kernels"])  # the same call: bit for bit
    np.testing.assert_allclose(ks.kernels.sum(axis=(1, 2)), 1.0, rtol=1e-5)
    assert np.all(np.isfinite(ks.kernels))


def test_camera_weighted_kernels_stay_an_option(packed):
    path, scene = packed
    cfg, planned = _paper_plan(path, scene, "--channel-kernels", "camera")
    ks = planned.channel["toled"]
    assert cfg.channel_kernels == "camera" and ks.params["illuminant"] == "D65" and ks.params["method"] == "mft"
    assert len(ks.params["sample_wavelengths_nm"]) > 3  # a weighted sum over the visible, not one wavelength
    paper = _paper_plan(path, scene)[1].channel["toled"]
    assert np.max(np.abs(ks.kernels - paper.kernels)) > 0.05 * paper.kernels.max()


@pytest.mark.parametrize("choice", ["paper", "camera"])
def test_the_choice_is_recorded(packed, tmp_path, choice):
    path, _ = packed
    assert main(["synth", str(path), "--display", "toled", "--profile", "paper", "--channel-kernels", choice,
                 "--no-cache", "--quiet", "--out", str(tmp_path)]) == 0
    synth = json.loads((tmp_path / "synth.json").read_text())
    assert synth["channel_kernels"] == choice and synth["profile"]["applied"]["channel_kernels"] == choice
    assert synth["profile"]["options"] == {"channel_kernels": choice}
    capture = json.loads((tmp_path / "toled" / "capture.json").read_text())
    assert capture["channel_kernels"].startswith({"paper": "the paper's recipe", "camera": "camera × D65"}[choice])
