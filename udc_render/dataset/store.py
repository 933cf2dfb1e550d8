"""The dataset folder: one run at a time (a lock), the job's parameters (job.json), stale temporary
item folders, and the manifest of complete items."""
from __future__ import annotations

import contextlib
import json
import shutil
from pathlib import Path

from udc_render.dataset.plan import DatasetError, Task, pose_record
from udc_render.io.files import save_json, save_text

TMP_PREFIX = ".tmp-"


@contextlib.contextmanager
def locked(out: Path):
    """Hold an exclusive lock on OUT/.lock: one run at a time per folder."""
    import fcntl
    out.mkdir(parents=True, exist_ok=True)
    with open(out / ".lock", "w") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise DatasetError(f"--out {out}: another udc-render dataset run is writing there") from None
        yield


ENGINE_KEY = "psf_engine"  # recorded from engine psf-5 on, which changed only aperiodic displays' kernels


def _holds_aperiodic(record) -> bool:
    """Whether a JSON record holds a display whose layout tiles with a random turn per tile (random_rotation:
    the only aperiodic layout), at any depth (a job's displays, a randomized job's panel draws, a bank's)."""
    if isinstance(record, dict):
        return record.get("random_rotation") is True or any(_holds_aperiodic(v) for v in record.values())
    return isinstance(record, list) and any(_holds_aperiodic(v) for v in record)


def unrecorded_engine(old: dict) -> set[str]:
    """{ENGINE_KEY} for a job.json or bank.json made before the engine version was recorded that holds no
    aperiodic display: its kernels are today's (psf-5 changed only those), so the key is not compared; else none."""
    return {ENGINE_KEY} if ENGINE_KEY not in old and not _holds_aperiodic(old) else set()


def check_job(out: Path, params: dict) -> None:
    """Write OUT/job.json, or refuse when it holds a different job (a job.json from before the engine version was
    recorded: unrecorded_engine)."""
    path = out / "job.json"
    if path.exists():
        try:
            old = json.loads(path.read_text())
        except (OSError, ValueError):
            raise DatasetError(f"{path}: unreadable; use another --out or delete the folder") from None
        skip = unrecorded_engine(old)
        keys = sorted(k for k in params.keys() | old.keys() if k not in skip and old.get(k) != params.get(k))
        if keys:
            raise DatasetError(f"--out {out} holds a different job (differs in {', '.join(keys)}); "
                            "use another --out or delete the folder")
        return
    save_json(path, params)


def clean_stale(out: Path) -> int:
    """Remove temporary item folders left by an interrupted run; returns how many."""
    stale = [p for p in out.glob(f"*/shard_*/{TMP_PREFIX}*") if p.is_dir()]
    for p in stale:
        shutil.rmtree(p)
    return len(stale)


def item_record(task: Task, displays: list[str], noise_seed: int) -> dict:
    """item.json and the manifest's line (less the file list): nothing that depends on where OUT is."""
    what = {"image": task.label} if task.pose is None else {"pose": pose_record(task.pose)}
    if task.panel is not None:
        what["panel"] = task.panel
    return {"item": task.item, "split": task.split, "folder": task.folder, **what,
            "render_seed": task.render_seed, "noise_seed": f"SeedSequence([{noise_seed}, {task.item}, crc32(display)])",
            "displays": displays}


def write_manifest(out: Path, tasks: list[Task], displays: list[str], noise_seed: int) -> int:
    """OUT/manifest.jsonl: the complete items by id, each with its files; returns their number."""
    lines = []
    for t in tasks:
        folder = out / t.folder
        if folder.is_dir():
            files = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())
            lines.append(json.dumps({**item_record(t, displays, noise_seed), "files": files}, sort_keys=True))
    save_text(out / "manifest.jsonl", "".join(line + "\n" for line in lines))
    return len(lines)
