"""`udc-render dataset --randomize` (issue 31) on a tiny scene: the same bytes with 2 workers and after a
resume, every draw recorded in capture.json, synth.json, item.json and job.json and equal to the draw
API's, within its range, and bad input answered with one line and exit status 2."""
import json
import shutil

import numpy as np
import pytest

from tests.udc_render.test_dataset import tree
from udc_render.cli import main
from udc_render.dataset import randomize as R
from udc_render.io.exr import read_exr

pytestmark = pytest.mark.usefixtures("render_cache")

RUN = ["--split", "2,1,1", "--shard-size", "1", "--field-phases", "2", "--panels", "2", "--randomize-seed", "5"]
FOLDERS = ["train/shard_0000/item_000000", "train/shard_0001/item_000001", "val/shard_0000/item_000002",
           "test/shard_0000/item_000003"]


@pytest.fixture(scope="module")
def scene(tiny_dataset_scene):
    return tiny_dataset_scene


def args(scene, out, *extra):
    return ["dataset", "--builtin", "--scene", str(scene), "--randomize", "default", *RUN, "--out", str(out),
            "--quiet", *extra]


@pytest.fixture(scope="module")
def reference(scene, tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "data"
    assert main(args(scene, out)) == 0
    return out


def one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("udc-render: error: ") and "Traceback" not in err
    return lines[0]


def test_two_workers_and_a_resume_give_the_same_bytes(scene, reference, tmp_path):
    two = tmp_path / "two"
    assert main(args(scene, two, "--workers", "2")) == 0
    assert tree(two) == tree(reference)
    resumed = tmp_path / "resumed"
    shutil.copytree(reference, resumed)
    for f in FOLDERS[1:3]:
        shutil.rmtree(resumed / f)
    (resumed / "val/shard_0000/.tmp-item_000002-abcd").mkdir()  # left by a killed run
    assert main(args(scene, resumed)) == 0
    assert tree(resumed) == tree(reference)


def test_every_draw_is_recorded_and_within_its_range(scene, reference):
    from udc_render.scene import load_scene
    from udc_render.scene.geometry import monitor_distance_m
    z_m = monitor_distance_m(load_scene(scene))
    dists = R.load_distributions("default")
    job = json.loads((reference / "job.json").read_text())
    panels = R.draw_panels(dists, 2, 5)
    assert job["randomize"]["panel_draws"] == [R.as_record(p) for p in panels]
    assert job["randomize"]["seed"] == 5 and job["randomize"]["parameters"] == dists.describe()["parameters"]
    assert [d["name"] for d in job["displays"]] == ["glass"]
    manifest = [json.loads(line) for line in (reference / "manifest.jsonl").read_text().splitlines()]
    assert [m["folder"] for m in manifest] == FOLDERS
    for m in manifest:
        item = reference / m["folder"]
        cap = R.draw_capture(dists, 2, 5, m["item"])
        assert m["panel"] == cap.panel == json.loads((item / "item.json").read_text())["panel"]
        assert m["displays"] == ["glass", "random"] and "random/raw.dng" in m["files"]
        synth = json.loads((item / "synth.json").read_text())
        for name in ("glass", "random"):
            c = json.loads((item / name / "capture.json").read_text())
            rec = c["randomized"]
            assert rec == synth["randomized"]
            assert rec["capture"] == R.as_record(cap) and rec["panel"] == R.as_record(panels[cap.panel])
            for key, v in {**rec["capture"]["values"], **rec["panel"]["values"]}.items():
                lo, hi = (dists[key].support if dists[key].kind in ("uniform", "log_uniform")
                          else (min(dists[key].support), max(dists[key].support)))
                assert lo <= v <= hi if not isinstance(v, str) else v in dists[key].support, (key, v)
            # the drawn sensor is the one used
            assert c["read_noise_e"] == pytest.approx(cap.read_noise_e)
            assert c["defects"]["hot_fraction"] == cap.defects.hot_fraction and c["fpn"]["prnu"] == cap.fpn.prnu
            assert c["sensor"]["exposure_s"] == pytest.approx(rec["exposure_s"], rel=1e-12)
            assert rec["exposure_s"] == pytest.approx(rec["base_exposure_s"] * cap.exposure_scale, rel=1e-12)
        c = json.loads((item / "random" / "capture.json").read_text())
        panel = panels[cap.panel]
        assert c["display"] == {**panel.display.describe(), "gain": panel.display.gain * cap.gain_scale}
        # the lens focused off the monitor's plane by the drawn focus error (m⁻¹)
        assert 1e3 / synth["lens"]["focus_distance_mm"] - 1 / z_m == pytest.approx(panel.lens.focus_error_per_m,
                                                                                     abs=1e-9)
        assert panel.lens.focus_error_per_m != 0


def test_brightness_scales_the_scene_not_the_exposure(scene, reference, tmp_path):
    """Brightness 0.5 against 1, every other draw the same (one stream per key): the noise-free ground truth
    halves, the exposure stays."""
    means, exposures = [], []
    for b in (1.0, 0.5):
        toml = tmp_path / f"b{b}.toml"
        toml.write_text(f"[exposure]\nbrightness = {b}\n")
        out = tmp_path / f"b{b}"
        assert main(["dataset", "--builtin", "--scene", str(scene), "--randomize", str(toml), "--panels", "1",
                     "--count", "1", "--field-phases", "2", "--gt-frames", "ideal", "--out", str(out),
                     "--quiet"]) == 0
        gt = read_exr(out / "train/shard_0000/item_000000/gt.exr")
        means.append(float(np.mean([gt[c] for c in "RGB"])))
        exposures.append(json.loads((out / "train/shard_0000/item_000000/synth.json").read_text())["exposure_s"])
    assert exposures[0] == exposures[1]
    assert means[1] / means[0] == pytest.approx(0.5, rel=1e-4)


@pytest.mark.parametrize("extra, says", [
    (["--randomize", "BAD"], "display.distance_mm = -1.0: expected a number in [0, 100] mm"),
    (["--randomize", "missing.toml"], "cannot read"),
    (["--randomize", "ranges.json"], "expected default or a .toml file"),
    (["--panels", "3"], "--panels is for a randomized dataset"),
    (["--randomize", "default", "--panels", "0"], "--panels must be > 0"),
    (["--randomize", "default", "--display", "toled"], "--display toled with --randomize"),
    (["--randomize", "default", "--distance-mm", "2"], "--distance-mm 2.0 with --randomize"),
    (["--randomize", "default", "--profile", "paper"], "need the spectral form"),
])
def test_bad_input_is_one_line(extra, says, tmp_path, monkeypatch, capsys):
    (tmp_path / "BAD").write_text("")
    bad = tmp_path / "bad.toml"
    bad.write_text("[display]\ndistance_mm = -1.0\n")
    extra = [str(bad) if e == "BAD" else e for e in extra]
    monkeypatch.chdir(tmp_path)
    assert main(["dataset", "--builtin", "--count", "1", *extra, "--out", str(tmp_path / "out"), "--quiet"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert says in line, line
    assert not (tmp_path / "out" / "job.json").exists()


def test_another_randomization_on_the_same_folder_is_refused(scene, reference, capsys):
    before = tree(reference)
    assert main(args(scene, reference, "--randomize-seed", "6")) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "holds a different job" in line and "randomize" in line
    assert tree(reference) == before
