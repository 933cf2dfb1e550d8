"""The `udc-render dataset` command on a tiny scene: layout and manifest, resuming after a kill
(byte-identical to an uninterrupted run, no duplicates, stale temporary folders removed), the
job-parameter check, a 2-process pool and a Dask cluster giving the same bytes, and bad input
answered with one line and exit status 2."""
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np
import pytest

from psf.cache import ENGINE_VERSION
from udc_render.cli import main
from udc_render.dataset import executors, plan as dataset
from udc_render.dataset.store import check_job

pytestmark = pytest.mark.usefixtures("render_cache")

SPLIT = ["--split", "2,1,1", "--shard-size", "1", "--field-phases", "2"]  # the default profile, d > 0: cheap kernels
FOLDERS = ["train/shard_0000/item_000000", "train/shard_0001/item_000001", "val/shard_0000/item_000002",
           "test/shard_0000/item_000003"]


@pytest.fixture(scope="module")
def scene(tiny_dataset_scene):
    return tiny_dataset_scene


def args(scene, out, *extra):
    return ["dataset", "--builtin", "--scene", str(scene), "--display", "toled", *SPLIT, "--out", str(out),
            "--quiet", *extra]


@pytest.fixture(scope="module")
def reference(scene, tmp_path_factory):
    """An uninterrupted in-process run (4 items, one per shard)."""
    out = tmp_path_factory.mktemp("ref") / "data"
    assert main(args(scene, out)) == 0
    return out


def tree(out: Path) -> dict:
    """Every file's bytes by relative path, less the run log and the lock."""
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*"))
            if p.is_file() and p.name not in ("timing.jsonl", ".lock")}


def assert_same_files(out: Path, reference: Path) -> None:
    a, b = tree(out), tree(reference)
    assert sorted(a) == sorted(b)
    assert [k for k in a if a[k] != b[k]] == []


def manifest(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "manifest.jsonl").read_text().splitlines()]


def one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("udc-render: error: ") and "Traceback" not in err
    return lines[0]


@pytest.mark.fallback
def test_layout_manifest_job_and_timing(reference):
    items = sorted(p.relative_to(reference).as_posix() for p in reference.glob("*/shard_*/*"))
    assert items == sorted(FOLDERS)
    m = manifest(reference)
    assert [e["item"] for e in m] == [0, 1, 2, 3]
    assert [e["folder"] for e in m] == FOLDERS and [e["split"] for e in m] == ["train", "train", "val", "test"]
    assert [e["image"] for e in m] == ["builtin:astronaut", "builtin:coffee", "builtin:chelsea", "builtin:rocket"]
    assert len({e["render_seed"] for e in m}) == 4
    for e in m:
        folder = reference / e["folder"]
        assert e["displays"] == ["glass", "toled"]
        assert e["files"] == sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())
        assert {"gt.exr", "item.json", "synth.json", "glass/raw.dng", "toled/raw.dng",
                "toled/capture.json"} <= set(e["files"])
        assert not any(f.endswith(("preview.png", "raw.png", "packed.tiff")) for f in e["files"])  # previews off
        record = json.loads((folder / "item.json").read_text())
        assert record == {k: v for k, v in e.items() if k != "files"}
        assert json.loads((folder / "synth.json").read_text())["item"] == e["item"]  # the noise stream's item
    job = json.loads((reference / "job.json").read_text())
    assert job["count"] == 4 and job["split"] == {"train": 2, "val": 1, "test": 1} and job["shard_size"] == 1
    log = [json.loads(line) for line in (reference / "timing.jsonl").read_text().splitlines()]
    assert sorted(r["item"] for r in log) == [0, 1, 2, 3] and all(r["seconds"] > 0 for r in log)


def test_rerun_makes_nothing_and_changes_nothing(scene, reference, tmp_path, capsys):
    out = tmp_path / "data"
    shutil.copytree(reference, out)
    before = tree(out)
    assert main(args(scene, out)) == 0
    assert "0 made now" in capsys.readouterr().out
    assert tree(out) == before and len((out / "timing.jsonl").read_text().splitlines()) == 4


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
    complete = [p for p in out.glob("*/shard_*/item_*")]
    assert len(complete) < 4
    stale = out / "test/shard_0000/.tmp-item_000003-abcd"
    stale.mkdir(parents=True)
    (stale / "gt.exr").write_bytes(b"half")
    capsys.readouterr()
    assert main(args(scene, out)) == 0
    assert f"{4 - len(complete)} made now" in capsys.readouterr().out
    assert not list(out.glob("*/shard_*/.tmp-*"))
    assert_same_files(out, reference)
    log = [json.loads(line)["item"] for line in (out / "timing.jsonl").read_text().splitlines()]
    assert len(log) == len(set(log)) == 4 - len(complete)  # the killed run logged nothing it did not finish


def test_other_parameters_on_the_same_folder_are_refused(scene, reference, capsys):
    before = tree(reference)
    for extra, key in ((["--display", "poled"], "displays"), (["--noise-seed", "1"], "synth"),
                       (["--spp", "4"], "scene"), (["--shard-size", "2"], "shard_size"), (["--previews"], "previews")):
        assert main(args(scene, reference, *extra)) == 2  # the later option wins
        line = one_error_line(capsys.readouterr().err)
        assert "holds a different job" in line and key in line
    assert tree(reference) == before


@pytest.mark.parametrize("drjit_loaded", [False, True])
def test_two_workers_give_the_same_bytes(scene, reference, tmp_path, monkeypatch, drjit_loaded):
    """Workers forked from this process, or spawned where it has loaded Dr.Jit (a stand-in module here;
    dataset.workers)."""
    if drjit_loaded:
        monkeypatch.setitem(sys.modules, "drjit", types.ModuleType("drjit"))
    else:
        monkeypatch.delitem(sys.modules, "drjit", raising=False)
    out = tmp_path / "data"
    assert main(args(scene, out, "--workers", "2")) == 0
    assert_same_files(out, reference)


def test_dask_cluster_gives_the_same_bytes(scene, reference, tmp_path):
    distributed = pytest.importorskip("distributed")
    out = tmp_path / "data"
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None) as c:
        assert main(args(scene, out, "--scheduler", c.scheduler_address)) == 0
    assert_same_files(out, reference)


def test_image_folder_is_cycled_with_new_seeds(scene, tmp_path):
    import imageio.v3 as iio
    images = tmp_path / "images"
    (images / "sub").mkdir(parents=True)
    rng = np.random.default_rng(0)
    for name in ("b.png", "sub/a.png", ".hidden.png"):
        iio.imwrite(images / name, rng.integers(0, 256, (24, 40, 3), dtype=np.uint8))
    (images / "notes.txt").write_text("not an image")
    out = tmp_path / "data"
    assert main(["dataset", "--images", str(images), "--scene", str(scene), "--display", "glass", "--count", "3",
                 "--out", str(out), "--quiet"]) == 0
    m = manifest(out)
    assert [e["image"] for e in m] == ["b.png", "sub/a.png", "b.png"]
    assert [e["folder"] for e in m] == [f"train/shard_0000/item_{i:06d}" for i in range(3)]
    raw = [(out / e["folder"] / "glass/raw.dng").read_bytes() for e in m]
    assert raw[0] != raw[2]  # same image, other render and noise seeds


def test_side_by_side_implies_previews(scene, tmp_path):
    out = tmp_path / "data"
    assert main(["dataset", "--builtin", "--scene", str(scene), "--display", "glass", "--count", "1", "--out", str(out),
                 "--quiet", "--side-by-side"]) == 0
    files = set(manifest(out)[0]["files"])
    assert {"side_by_side.png", "gt_preview.png", "glass/preview.png", "glass/raw.dng"} <= files
    job = json.loads((out / "job.json").read_text())
    assert job["previews"] is True and job["side_by_side"] is True and job["version"] == 2
    assert job["psf_engine"] == ENGINE_VERSION  # another engine's kernels: a new job, refused as a resume


def test_a_job_from_before_the_engine_was_recorded_resumes_only_without_aperiodic_displays(tmp_path):
    """job.json records psf_engine from psf-5 on, which changed only aperiodic displays' kernels: a job.json without
    the key is today's job unless a display, or a randomized job's drawn panel, is turned per tile; another engine's
    job is refused in one line."""
    params = {"count": 1, "psf_engine": ENGINE_VERSION,
              "displays": [{"name": "t", "layout": {"kind": "micrograph", "random_rotation": False}}]}
    for i, (old, refused) in enumerate((
            ({k: v for k, v in params.items() if k != "psf_engine"}, False),
            ({**params, "psf_engine": "psf-4"}, True),
            ({"count": 1, "displays": params["displays"],
              "randomize": {"panel_draws": [{"display": {"layout": {"random_rotation": True}}}]}}, True))):
        out = tmp_path / str(i)
        out.mkdir()
        (out / "job.json").write_text(json.dumps(old))
        new = {**params, "randomize": old["randomize"]} if "randomize" in old else params
        if refused:
            with pytest.raises(dataset.DatasetError, match=r"holds a different job \(differs in psf_engine\)"):
                check_job(out, new)
        else:
            check_job(out, new)


def test_builtin_images_stay_distinct_past_the_list():
    images, _ = dataset.image_list(None)
    tasks = dataset.plan_tasks(40, (30, 5, 5), 8, images, True, 0)
    assert len({t.image for t in tasks}) == 40 and tasks[-1].image.startswith("pattern:dead_leaves_colour:")
    assert tasks[9].folder == "train/shard_0001/item_000009" and tasks[39].folder == "test/shard_0000/item_000039"
    assert len({t.render_seed for t in tasks}) == 40


@pytest.mark.parametrize("argv, says", [
    (["--builtin", "--images", "."], "not allowed with"),
    (["--count", "2"], "one of the arguments --images --builtin is required"),
    (["--builtin", "--count", "0"], "--count must be > 0"),
    (["--builtin"], "--count N is required"),
    (["--builtin", "--split", "1,2"], "--split must be three counts"),
    (["--builtin", "--split", "1,1,1", "--count", "4"], "sums to 3, but --count is 4"),
    (["--images", "MISSING", "--count", "2"], "no such folder"),
    (["--images", "EMPTY", "--count", "2"], "no images"),
    (["--builtin", "--count", "2", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "not allowed with"),
    (["--builtin", "--count", "2", "--scene", "room"], "--builtin is for a monitor scene; the room scene"),
    (["--builtin", "--count", "2", "--scheduler", "tcp://127.0.0.1:1"], "cannot reach the scheduler"),
    (["--builtin", "--count", "2", "--scheduler", "NO_DISTRIBUTED"], "needs the 'distributed' package"),
])
def test_bad_input_is_one_line(argv, says, tmp_path, monkeypatch, capsys):
    (tmp_path / "EMPTY").mkdir()
    (tmp_path / "EMPTY" / "readme.txt").write_text("no images here")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(executors, "CONNECT_TIMEOUT_S", 1.0)
    if "NO_DISTRIBUTED" in argv:
        monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed raises ImportError
    assert main(["dataset", *argv, "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert says in one_error_line(capsys.readouterr().err)
    assert not (tmp_path / "out" / "job.json").exists()


@pytest.mark.parametrize("drjit_first", [False, True])
def test_worker_threads_reach_drjit_when_it_loads_and_not_before(drjit_first):
    """set_worker_threads does not import drjit (a monitor's workers never load Mitsuba); Dr.Jit gets the count
    when set_variant loads it, or at once when it is already loaded."""
    code = ("import sys\n" + ("import drjit\n" if drjit_first else "")
            + "from udc_render.dataset.threads import set_worker_threads\nset_worker_threads(1)\n"
              "now = sys.modules['drjit'].thread_count() if 'drjit' in sys.modules else None\n"
              "from udc_render.render.variants import set_variant\nset_variant('rgb')\nimport drjit\n"
              "print(now, drjit.thread_count())")
    env = {**os.environ, "UDC_RENDER_VARIANT": "scalar"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env)
    assert out.stdout.split() == ["1" if drjit_first else "None", "1"]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
@pytest.mark.parametrize("tuned", [False, True])
def test_items_reuse_freed_pages(tuned):
    """keep_freed_memory: a 24 MB array allocated again after being freed reuses its pages (under 1 % of them
    faulted in again; glibc's default maps it afresh, every page faulted)."""
    code = ("import resource, numpy as np\nfrom udc_render.dataset.threads import keep_freed_memory\n"
            f"ok = keep_freed_memory() if {tuned} else True\n"
            "def faults():\n    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt\n"
            "    a = np.ones(3_000_000)\n    del a\n"
            "    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0\n"
            "faults()\nprint(ok, faults())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    ok, faults = out.stdout.split()
    pages = 3_000_000 * 8 // 4096
    assert ok == "True"
    assert (int(faults) < pages // 100) is tuned, faults
