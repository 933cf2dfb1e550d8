"""Profiles (udc_render.profiles): what each sets, options that override it, and two syntheses of one
scene that differ only where the profile says."""
from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import asdict

import pytest

from udc_render.cli import build_parser, main
from udc_render.cli.args import capture_setup
from udc_render.optics.stray import StrayLight
from udc_render.profiles import DEFAULT_PROFILE, PHYSICAL_DISTANCE_MM, PROFILES, ProfileError, describe, resolve_profile
from udc_render.sensor import DefectConfig, FpnConfig

pytestmark = pytest.mark.usefixtures("render_cache")


@pytest.fixture(scope="module")
def scene(tmp_path_factory, udc):
    """64 × 32 px of 49.6 µm, one 100 nm band, 2 spp, 9-px kernels: the cheapest synthesis."""
    path = tmp_path_factory.mktemp("scene") / "mon.toml"
    udc.write_scene(path, udc.monitor_doc(image="pattern:slanted_edge", sensor_px=(64, 32), pitch_um=49.6,
                                          render={"spp": 2, "margin_um": 150},
                                          bands={"range_nm": [500, 600], "step_nm": 100}))
    return path


def _setup(*argv):
    """(cfg, displays by name) that `udc-render synth` would use for these options."""
    cfg, displays = capture_setup(build_parser().parse_args(["synth", "monitor", *argv]))
    return cfg, {d.name: d for d in displays}


def test_the_profiles_set_what_they_say():
    assert DEFAULT_PROFILE == "physical" and set(PROFILES) == {"paper", "physical"}
    paper, physical = PROFILES["paper"], PROFILES["physical"]
    assert (paper.form, paper.channel_kernels, paper.distance_mm, paper.defects) == ("per_channel", "paper", 0.0, None)
    assert (physical.form, physical.channel_kernels, physical.distance_mm, physical.defects) == (
        "spectral", "camera", PHYSICAL_DISTANCE_MM, DefectConfig())
    assert PHYSICAL_DISTANCE_MM > 0
    cfg, d = _setup("--display", "toled,poled")  # no --profile: the default
    assert cfg.profile["name"] == "physical" and cfg.form == "spectral" and cfg.defects == DefectConfig()
    assert [d[n].distance_mm for n in ("glass", "toled", "poled")] == [0.0, PHYSICAL_DISTANCE_MM, PHYSICAL_DISTANCE_MM]
    cfg, d = _setup("--display", "toled,poled", "--profile", "paper")
    assert cfg.profile["name"] == "paper" and cfg.form == "per_channel" and cfg.defects is None
    assert cfg.channel_kernels == "paper" == cfg.profile["applied"]["channel_kernels"]
    assert all(v.distance_mm == 0.0 for v in d.values())
    assert "form per_channel (channel kernels paper)" in describe(cfg.profile)
    assert (cfg.sensor.noise, cfg.sensor.lambda_source) == ("gaussian", "sensor")  # the paper's noise (l.178)
    assert cfg.profile["applied"]["noise"] == {"noise": "gaussian", "lambda_source": "sensor"}
    assert _setup()[0].sensor.noise == "poisson"  # physical: the sensor config's
    assert (f"profile physical: form spectral, display-to-lens distance {PHYSICAL_DISTANCE_MM:g} mm"
            in describe(_setup()[0].profile))


def test_explicit_options_override_the_profile():
    cfg, d = _setup("--display", "toled,poled", "--distance-mm", "0.5")
    assert cfg.form == "spectral" and cfg.defects == DefectConfig()
    assert d["toled"].distance_mm == d["poled"].distance_mm == 0.5 and d["glass"].distance_mm == 0.0
    assert cfg.profile["options"] == {"distance_mm": 0.5} and cfg.profile["applied"]["distance_mm"] == 0.5
    assert "0.5 mm (option)" in describe(cfg.profile)
    cfg, d = _setup("--profile", "paper", "--form", "spectral", "--distance-mm", "2")
    assert cfg.form == "spectral" and cfg.defects is None and d["toled"].distance_mm == 2.0
    assert cfg.profile["options"] == {"form": "spectral", "distance_mm": 2.0}
    cfg, d = _setup("--profile", "physical", "--form", "per_channel")  # no field-dependent kernels in that form
    assert cfg.form == "per_channel" and cfg.defects == DefectConfig() and d["toled"].distance_mm == 0.0
    assert cfg.profile["applied"]["distance_mm"] == 0.0 and cfg.profile["notes"]
    assert cfg.channel_kernels == "camera"  # the physical profile keeps the camera-weighted kernels
    cfg, _ = _setup("--profile", "paper", "--channel-kernels", "camera")
    assert cfg.form == "per_channel" and cfg.channel_kernels == "camera"
    assert cfg.profile["options"] == {"channel_kernels": "camera"}
    assert "(channel kernels camera (option))" in describe(cfg.profile)
    cfg, _ = _setup("--profile", "paper", "--noise-model", "poisson")
    assert cfg.sensor.noise == "poisson" and cfg.profile["options"] == {"noise": "poisson"}
    assert "noise poisson (option)" in describe(cfg.profile)


def test_a_sensor_config_file_keeps_its_noise(tmp_path):
    f = tmp_path / "sensor.toml"
    f.write_text('noise = "none"\n')
    cfg, _ = _setup("--profile", "paper", "--sensor-config", str(f))
    assert cfg.sensor.noise == "none" and cfg.profile["applied"]["noise"]["noise"] == "none"
    assert cfg.profile["options"] == {"sensor_config": "a file"}
    cfg, d = _setup("--profile", "paper", "--distance-mm", "0")
    assert d["toled"].distance_mm == 0.0 and cfg.form == "per_channel"


def test_display_files_keep_their_own_distance(tmp_path):
    f = tmp_path / "mine.toml"
    f.write_text('[display]\nname = "mine"\ndistance_mm = 2.5\n[display.layout]\ntype = "toled"\n')
    _, d = _setup("--display", f"toled,{f}")
    assert d["mine"].distance_mm == 2.5 and d["toled"].distance_mm == PHYSICAL_DISTANCE_MM
    _, d = _setup("--display", f"toled,{f}", "--distance-mm", "0.25")
    assert d["mine"].distance_mm == d["toled"].distance_mm == 0.25


def test_impossible_or_unknown_choices_are_one_line(scene, tmp_path, capsys):
    with pytest.raises(ProfileError, match="per_channel"):
        _setup("--profile", "paper", "--distance-mm", "1")
    with pytest.raises(ProfileError, match="'nope'"):
        resolve_profile("nope", _setup()[0], [])
    for argv, says in ((["--profile", "paper", "--distance-mm", "1"], "--distance-mm 1 with form per_channel"),
                       (["--profile", "nope"], "invalid choice: 'nope'")):
        assert main(["synth", str(scene), *argv, "--out", str(tmp_path / "o"), "--quiet"]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and err.startswith("udc-render: error: ") and says in err, err
    r = subprocess.run([sys.executable, "-m", "udc_render.cli", "dataset", "--builtin", "--count", "1", "--profile",
                        "Physical", "--out", str(tmp_path / "d")], capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert "--profile" in r.stderr and "'Physical'" in r.stderr


def _differing(a: dict, b: dict) -> set[str]:
    return {k for k in a.keys() | b.keys() if a.get(k) != b.get(k)}


def test_profiles_differ_only_where_they_say(scene, tmp_path):
    """One scene synthesised under each profile: synth.json differs in form, channel kernels, defects, fixed-pattern
    noise, the far field the spectral form adds, the ground truth's optics (the spectral form's
    monitor planes) and the profile record alone (the job's sensor record also in the noise); each capture.json's
    display record only in the distance (glass: not at all); the physical captures carry the defect and FPN records,
    the paper's none. The same goes for a dataset's job.json."""
    out = {}
    for name in ("paper", "physical"):
        out[name] = tmp_path / name
        assert main(["synth", str(scene), "--display", "toled", "--profile", name, "--quiet", "--out",
                     str(out[name])]) == 0
    synth = {n: json.loads((o / "synth.json").read_text()) for n, o in out.items()}
    assert _differing(synth["paper"], synth["physical"]) == {"form", "channel_kernels", "defects", "fpn", "profile",
                                                             "stray_light", "gt_noise", "far_field", "gt_optics"}
    assert synth["paper"]["far_field"]["far_share"] == {}  # the far field is the spectral form's (optics.far_field)
    assert synth["physical"]["far_field"]["threshold"] == synth["paper"]["far_field"]["threshold"]
    # both average the paper's 16 ground-truth frames, each with its own noise model (gaussian / poisson)
    assert synth["paper"]["gt_frames"] == synth["physical"]["gt_frames"] == 16
    assert {n: s["gt_noise"]["noise"] for n, s in synth.items()} == {"paper": "gaussian", "physical": "poisson"}
    assert synth["physical"]["stray_light"]["settings"]["haze"] == {"poled": 0.015}  # optics.stray's default
    assert synth["paper"]["stray_light"] == {"settings": StrayLight.off().describe(), "applied": False}
    assert synth["paper"]["channel_kernels"] == "paper" and synth["physical"]["channel_kernels"] is None  # spectral
    assert synth["physical"]["profile"]["name"] == "physical" and synth["paper"]["profile"]["name"] == "paper"
    assert synth["physical"]["defects"] == asdict(DefectConfig()) and synth["paper"]["defects"] is None
    assert synth["physical"]["fpn"] == asdict(FpnConfig()) and synth["paper"]["fpn"] is None
    cap = {n: {v: json.loads((o / v / "capture.json").read_text()) for v in ("glass", "toled")} for n, o in out.items()}
    assert cap["paper"]["glass"]["display"] == cap["physical"]["glass"]["display"]
    assert _differing(cap["paper"]["toled"]["display"], cap["physical"]["toled"]["display"]) == {"distance_mm"}
    assert cap["physical"]["toled"]["display"]["distance_mm"] == PHYSICAL_DISTANCE_MM
    assert cap["paper"]["toled"]["defects"] is None and cap["physical"]["toled"]["defects"]["seed"] == 0
    assert cap["paper"]["toled"]["fpn"] is None and cap["physical"]["toled"]["fpn"]["prnu"] == FpnConfig().prnu
    # the dataset job records the same: only the synthesis knobs and the displays differ
    from udc_render.dataset import DatasetJob, _shared, job_params
    from udc_render.dataset.plan import image_list
    from udc_render.scene import load_scene
    images, source = image_list(None)
    params = {}
    for name in ("paper", "physical"):
        cfg, displays = capture_setup(build_parser().parse_args(["dataset", "--builtin", "--count", "1", "--display",
                                                                 "toled", "--profile", name]))
        job = DatasetJob(load_scene(scene), displays, cfg, out=tmp_path / "ds", split=(1, 0, 0))
        params[name] = job_params(job, _shared(job, tmp_path / "ds"), source, images)
    assert _differing(params["paper"], params["physical"]) == {"synth", "displays"}
    assert _differing(params["paper"]["synth"], params["physical"]["synth"]) == {"form", "channel_kernels", "defects",
                                                                                 "fpn", "profile", "sensor",
                                                                                 "stray_light"}
    assert _differing(params["paper"]["synth"]["sensor"], params["physical"]["synth"]["sensor"]) == {
        "noise", "lambda_source"}
    assert params["paper"]["synth"]["channel_kernels"] == "paper"


def _demo_request(tmp_path, monkeypatch, *args) -> tuple:
    """(cfg, {display: distance_mm}) that `udc-render demo ARGS` hands the synthesis, which is not run."""
    import udc_render.cli.synth as cli_synth
    seen = {}
    monkeypatch.setattr(cli_synth, "synth_and_write",
                        lambda scene, displays, cfg, out, quiet: seen.update(displays=displays, cfg=cfg))
    assert main(["demo", "--out", str(tmp_path), "--quiet", *args]) == 0
    return seen["cfg"], {d.name: d.distance_mm for d in seen["displays"]}


def test_demo_asks_for_the_default_profile(tmp_path, monkeypatch):
    """`udc-render demo` hands the synthesis the default profile: the fast suite's check of its wiring (the
    synthesis itself, 100 s of d > 0 kernels even on a tiny scene: test_demo_uses_the_default_profile, slow)."""
    cfg, distances_mm = _demo_request(tmp_path, monkeypatch)
    assert cfg.profile["name"] == DEFAULT_PROFILE and cfg.defects == DefectConfig()
    assert distances_mm == {"glass": 0.0, "toled": PHYSICAL_DISTANCE_MM, "poled": PHYSICAL_DISTANCE_MM}


@pytest.mark.slow
def test_demo_uses_the_default_profile(scene, tmp_path, monkeypatch):
    """`udc-render demo` (here on the tiny scene in place of the built-in monitor) runs the default profile."""
    import udc_render.scene
    tiny = udc_render.scene.load_scene(scene)
    monkeypatch.setattr(udc_render.scene, "load_scene", lambda name: tiny)
    assert main(["demo", "--out", str(tmp_path), "--quiet"]) == 0
    synth = json.loads((tmp_path / "synth.json").read_text())
    assert synth["profile"]["name"] == DEFAULT_PROFILE and synth["defects"] == asdict(DefectConfig())
    for view in ("toled", "poled"):
        record = json.loads((tmp_path / view / "capture.json").read_text())
        assert record["display"]["distance_mm"] == PHYSICAL_DISTANCE_MM and record["defects"] is not None


def test_demo_takes_the_paper_profile(tmp_path, monkeypatch):
    """`udc-render demo --profile paper` asks the synthesis for the per-channel form at d = 0 without defects
    (the synthesis itself runs in test_demo_uses_the_default_profile, slow, and the synth tests)."""
    cfg, distances_mm = _demo_request(tmp_path, monkeypatch, "--profile", "paper")
    assert cfg.profile["name"] == "paper" and cfg.defects is None
    assert distances_mm == {"glass": 0.0, "toled": 0.0, "poled": 0.0}
