"""`udc-render dataset` on a 3D scene (a tiny Mitsuba XML Cornell box): item i is a view of the scene from
a jittered camera pose, item 0 the XML sensor's own; the focus distance (hence the kernels) is the same
for every item; a re-run makes nothing, a partial or killed run resumes to the same bytes; the source
options are refused in one line where they do not fit."""
import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from psf.cache import load
from tests.udc_render.cornell_box import ORIGIN, TARGET, cbox_xml
from tests.udc_render.test_dataset import assert_same_files, manifest, one_error_line, tree
from udc_render.cli import main
from udc_render.dataset import DEFAULT_ORIGIN_JITTER_M, DEFAULT_TARGET_JITTER_M, Views

pytestmark = pytest.mark.usefixtures("render_cache")

CBOX = cbox_xml()

# 48 x 32 px of 6.2 µm behind a 1 mm lens, 3 bands, 2 spp, a 31 µm margin (11 px kernels): about a
# second per item
TOML = """[lens]
focal_length_mm = 1.0
f_number = 2.0
[sensor]
width_px = 48
height_px = 32
pitch_um = 6.2
[bands]
range_nm = [400, 700]
step_nm = 100
[render]
spp = 2
margin_um = 31
[content]
type = "mitsuba_xml"
file = "cbox.xml"
"""
FOCUS_M = float(np.linalg.norm(np.subtract(TARGET, ORIGIN)))
FOLDERS = ["train/shard_0000/item_000000", "train/shard_0001/item_000001"]


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cbox")
    (folder / "cbox.xml").write_text(CBOX)
    (folder / "cbox.toml").write_text(TOML)
    return folder / "cbox.toml"


def args(scene, out, *extra):
    return ["dataset", "--scene", str(scene), "--display", "toled", "--count", "2", "--shard-size", "1",
            "--field-phases", "2", "--out", str(out), "--quiet", *extra]


@pytest.fixture(scope="module")
def reference(scene, tmp_path_factory, render_cache):
    """An uninterrupted in-process run (2 items, one per shard), and the kernel files it left in the cache."""
    out = tmp_path_factory.mktemp("ref") / "data"
    before = set(render_cache.glob("*.npz"))
    assert main(args(scene, out)) == 0
    return out, set(render_cache.glob("*.npz")) - before


@pytest.mark.fallback
def test_items_are_views_from_jittered_poses_with_one_focus(reference):
    out, kernel_files = reference
    m = manifest(out)
    assert [e["folder"] for e in m] == FOLDERS and [e["item"] for e in m] == [0, 1]
    assert all("image" not in e for e in m) and len({e["render_seed"] for e in m}) == 2
    poses = [e["pose"] for e in m]
    # item 0: the XML sensor's own pose
    np.testing.assert_allclose(poses[0]["origin_m"], ORIGIN, atol=1e-6)
    np.testing.assert_allclose(poses[0]["target_m"], TARGET, atol=1e-6)
    # item 1: moved within the default jitter box, the up vector kept
    d_origin = np.subtract(poses[1]["origin_m"], poses[0]["origin_m"])
    d_target = np.subtract(poses[1]["target_m"], poses[0]["target_m"])
    assert np.linalg.norm(d_origin) > 1e-3 and np.all(np.abs(d_origin) <= DEFAULT_ORIGIN_JITTER_M)
    assert np.linalg.norm(d_target) > 1e-3 and np.all(np.abs(d_target) <= DEFAULT_TARGET_JITTER_M)
    assert poses[1]["up"] == poses[0]["up"]
    job = json.loads((out / "job.json").read_text())
    assert "images" not in job and job["views"]["base"] == poses[0]
    assert job["views"]["origin_jitter_m"] == list(DEFAULT_ORIGIN_JITTER_M)
    assert job["scene"]["lens"]["focus_distance_m"] == pytest.approx(FOCUS_M)
    for e, pose in zip(m, poses):
        folder = out / e["folder"]
        assert {"gt.exr", "item.json", "synth.json", "glass/raw.dng", "toled/raw.dng"} <= set(e["files"])
        assert json.loads((folder / "item.json").read_text()) == {k: v for k, v in e.items() if k != "files"}
        synth = json.loads((folder / "synth.json").read_text())
        camera = synth["render"]["camera"]
        np.testing.assert_allclose(camera["origin_m"], pose["origin_m"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(camera["target_m"], pose["target_m"], rtol=0, atol=1e-12)
        # the focus (hence the lens-to-sensor distance and the kernels) is the base pose's for every item
        assert camera["focus_distance_m"] == pytest.approx(FOCUS_M)
        assert synth["depth_layers"]["depths_m"] == [camera["focus_distance_m"]]
    # two kernel sets per display (glass, toled): the core kernels and the far field's orders (psf.far,
    # optics.far_field), for both items: the items share the in-focus kernels (the cache's other entries are what
    # is made of them: far fields, field bases, power maps, spectra; psf.cache.cached_arrays)
    assert sum(load(p.stem, p.parent) is not None for p in kernel_files) == 4
    gt = [(out / f / "gt.exr").read_bytes() for f in FOLDERS]
    assert gt[0] != gt[1]


def test_rerun_makes_nothing_and_changes_nothing(scene, reference, tmp_path, capsys):
    out = tmp_path / "data"
    shutil.copytree(reference[0], out)
    before = tree(out)
    assert main(args(scene, out)) == 0
    assert "0 made now" in capsys.readouterr().out
    assert tree(out) == before


def test_partial_run_resumes_to_the_same_bytes(scene, reference, tmp_path, capsys):
    """Item 1 missing and a stale temporary folder of it: the re-run removes the one, makes the other."""
    out = tmp_path / "data"
    shutil.copytree(reference[0], out)
    shutil.rmtree(out / FOLDERS[1])
    stale = out / "train/shard_0001/.tmp-item_000001-abcd"
    stale.mkdir(parents=True)
    (stale / "gt.exr").write_bytes(b"half")
    (out / "manifest.jsonl").write_text("")
    assert main(args(scene, out)) == 0
    said = capsys.readouterr().out
    assert "1 made now" in said and "1 stale temporary folders removed" in said
    assert_same_files(out, reference[0])


def test_killed_run_resumes_to_the_same_bytes(scene, reference, tmp_path, capsys):
    out = tmp_path / "data"
    exe = Path(sys.executable).parent / "udc-render"
    proc = subprocess.Popen([str(exe), *args(scene, out)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    try:  # kill as soon as the first item is being written (or has just been renamed into place)
        while not list(out.glob("*/shard_*/*")) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.002)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    complete = list(out.glob("*/shard_*/item_*"))
    assert len(complete) < 2
    capsys.readouterr()
    assert main(args(scene, out)) == 0
    assert f"{2 - len(complete)} made now" in capsys.readouterr().out
    assert not list(out.glob("*/shard_*/.tmp-*"))
    assert_same_files(out, reference[0])


def test_two_workers_give_the_same_bytes(scene, reference, tmp_path):
    out = tmp_path / "data"
    assert main(args(scene, out, "--workers", "2")) == 0
    assert_same_files(out, reference[0])


@pytest.mark.slow
def test_dask_cluster_gives_the_same_bytes(scene, reference, tmp_path):
    distributed = pytest.importorskip("distributed")
    out = tmp_path / "data"
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None) as c:
        assert main(args(scene, out, "--scheduler", c.scheduler_address)) == 0
    assert_same_files(out, reference[0])


NEAR = {"focal_length_mm = 1.0": "focal_length_mm = 4.0\nfocus_distance_m = 1.0", "f_number = 2.0": "f_number = 1.0"}


def near_focus_runs(scene, tmp_path, monkeypatch, runs) -> dict:
    """Focused at 1 m (a 4 mm f/1 lens) the box lies off focus: each item's depth layer has kernels of its own
    distance, planned by the synthesis in whichever process makes the item. runs: (name, extra options or
    None for a 1-worker Dask cluster, kernel cache folder); returns the output folders by name."""
    toml = scene.parent / "cbox_near.toml"
    text = TOML
    for a, b in NEAR.items():
        text = text.replace(a, b)
    toml.write_text(text)
    outs = {}
    for name, extra, cache in runs:
        monkeypatch.setenv("UDC_RENDER_CACHE", str(tmp_path / cache))
        outs[name] = out = tmp_path / name
        argv = args(toml, out, "--defocus-tolerance-px", "0.1")
        if extra is not None:
            assert main(argv + extra) == 0
            continue
        distributed = pytest.importorskip("distributed")  # its workers have 1 BLAS thread: the kernels get ours
        with distributed.LocalCluster(n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None) as c:
            assert main(argv + ["--scheduler", c.scheduler_address]) == 0
    return outs


@pytest.mark.slow
def test_off_focus_layers_give_the_same_bytes_on_any_worker_count(scene, tmp_path, monkeypatch):
    """A 1-worker and a 2-worker run, each on an empty kernel cache, and a re-run on a warm cache give the
    same bytes (the off-focus kernels computed in the workers with the parent's BLAS threads)."""
    outs = near_focus_runs(scene, tmp_path, monkeypatch, [("one", [], "c1"), ("two", ["--workers", "2"], "c2"),
                                                          ("warm", [], "c1")])
    for e in manifest(outs["one"]):
        layers = json.loads((outs["one"] / e["folder"] / "synth.json").read_text())["depth_layers"]
        assert min(layers["depths_m"]) > 2.5  # the box, not the 1 m focus
    assert len(list((tmp_path / "c1").glob("*.npz"))) > 2  # in focus (planned first) and the layers'
    assert_same_files(outs["two"], outs["one"])
    assert_same_files(outs["warm"], outs["one"])


@pytest.mark.slow
def test_off_focus_layers_on_a_dask_cluster_give_the_same_bytes(scene, tmp_path, monkeypatch):
    outs = near_focus_runs(scene, tmp_path, monkeypatch, [("one", [], "c1"), ("dask", None, "c3")])
    assert_same_files(outs["dask"], outs["one"])


def test_other_jitters_on_the_same_folder_are_refused(scene, reference, capsys):
    out = reference[0]
    before = tree(out)
    for extra in (["--pose-jitter-m", "0.1,0.1,0.1"], ["--target-jitter-m", "0,0,0"]):
        assert main(args(scene, out, *extra)) == 2
        line = one_error_line(capsys.readouterr().err)
        assert "holds a different job" in line and "views" in line
    assert tree(out) == before


def test_views_are_deterministic_within_the_box():
    v = Views((0.0, 1.1, 3.4), (0.0, 0.2, -2.0), (0.0, 1.0, 0.0), (0.15, 0.1, 0.15), (0.3, 0.2, 0.0))
    assert v.pose(0, 0) == ((0.0, 1.1, 3.4), (0.0, 0.2, -2.0), (0.0, 1.0, 0.0))
    poses = [v.pose(7, i) for i in range(1, 50)]
    assert poses == [v.pose(7, i) for i in range(1, 50)]  # the same draw every time
    assert len({p[0] for p in poses}) == 49 and poses != [v.pose(8, i) for i in range(1, 50)]
    o = np.array([p[0] for p in poses]) - (0.0, 1.1, 3.4)
    t = np.array([p[1] for p in poses]) - (0.0, 0.2, -2.0)
    assert np.all(np.abs(o) <= (0.15, 0.1, 0.15)) and np.all(np.abs(o).max(axis=0) > (0.1, 0.06, 0.1))
    assert np.all(np.abs(t) <= (0.3, 0.2, 0.0)) and np.all(t[:, 2] == 0)


def test_room_focus_is_fixed_at_the_base_pose():
    """The built-in room focuses at its target ("auto"): the job sets that distance explicitly, so a moved
    target does not move the focus (nor the kernels)."""
    from udc_render.dataset import DatasetJob, _shared, _views
    from udc_render.pipeline import SynthConfig
    from udc_render.scene import load_scene
    room = load_scene("room")
    assert room.lens.focus_distance_m is None
    job = DatasetJob(room, [], SynthConfig(use_cache=False), out=Path("unused"), split=(3, 0, 0))
    shared = _shared(job, Path("unused"))
    views = _views(job, shared)
    focus = float(np.linalg.norm(np.subtract(room.camera.target_m, room.camera.origin_m)))
    assert shared.scene.lens.focus_distance_m == pytest.approx(focus)
    assert views.origin_m == tuple(room.camera.origin_m) and views.target_jitter_m == DEFAULT_TARGET_JITTER_M


@pytest.mark.parametrize("argv, says", [
    (["--scene", "XML", "--builtin"], "--builtin is for a monitor scene; the mitsuba_xml scene"),
    (["--scene", "room", "--images", "."], "--images is for a monitor scene; the room scene"),
    (["--scene", "hdr", "--builtin"], "--builtin is for a monitor scene; the hdr scene"),
    ([], "one of the arguments --images --builtin is required"),
    (["--builtin", "--pose-jitter-m", "0.1,0.1,0.1"], "--pose-jitter-m is for a 3D scene"),
    (["--scene", "room", "--pose-jitter-m", "0.1,0.1"], "--pose-jitter-m must be three distances ≥ 0"),
    (["--scene", "room", "--target-jitter-m", "0,-1,0"], "--target-jitter-m must be three distances ≥ 0"),
])
def test_source_refusals_are_one_line(argv, says, scene, tmp_path, capsys):
    argv = [str(scene) if a == "XML" else a for a in argv]
    assert main(["dataset", "--count", "2", *argv, "--out", str(tmp_path / "out"), "--quiet"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert says in line, line
    assert not (tmp_path / "out").exists()
