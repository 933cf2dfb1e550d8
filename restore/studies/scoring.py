"""The scores of `udc-render results`: input, DeP and the trained rows on a dataset's test split, resumed
by a stamp of what decides them (evaluation_stamp), and each row's error per octave band of spatial
frequency (restore.studies.error_bands).
"""
from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
import time
from pathlib import Path

import numpy as np

from restore.data import dataset_displays, list_pairs
from restore.evaluate import BUILTIN_METHODS, EvalSettings, evaluate, results_csv, results_markdown
from restore.studies.budgets import DISPLAYS
from restore.studies.error_bands import display_transfer, method_bands, plot
from restore.train import data_fingerprint
from udc_render.io.files import save_json, save_text

BAND_ITEMS, BAND_CROP_PX = 6, 512  # the error bands' val frames and central crop (a diagnosis, not a score)


def error_band_rows(data: Path, models: dict, folder: Path) -> dict:
    """{display: {"bands": {row: [bands] MSE}, "transfer": [bands] mean |OTF|}} of input, DeP and the
    display's trained rows on the val split's central crops (restore.studies.error_bands); plots in `folder`."""
    res = {}
    for d in DISPLAYS:
        methods = {**{m: m for m in BUILTIN_METHODS}, **{row: str(p) for (row, md), p in models.items() if md == d}}
        transfer = display_transfer(data, d)
        bands = method_bands(data, d, methods, "val", BAND_ITEMS, BAND_CROP_PX)
        plot(bands, transfer, folder / f"error_bands_{d}.png",
             f"{d}: error by spatial frequency (val, {BAND_ITEMS} frames, central {BAND_CROP_PX} px)")
        res[d] = {"bands": bands, "transfer": transfer}
    return res


SCORING_MODULES = ("restore.evaluate", "restore.metrics", "restore.dep", "restore.known", "restore.lpips",
                   "restore.data", "restore.models", "restore.train", "udc_render.metrics")
"""The code a score depends on beyond the data and the checkpoint: its source is part of evaluation_stamp."""


def training_levels(data: Path) -> dict[str, float]:
    """Display → the median over the training captures of their mean green level (fraction of white − black,
    the captures' summary.json): the exposure range the models learnt on."""
    return {d: float(np.median([json.loads((p.folder / "summary.json").read_text())["views"][d]["mean_level"]["Gr"]
                                for p in list_pairs(data, "train", [d])])) for d in DISPLAYS}


def evaluation_stamp(data: Path, method: str) -> str:
    """sha256 of what decides a row's scores: the dataset's manifest (restore.train.data_fingerprint), the
    method (BUILTIN_METHODS' names, or the checkpoint's bytes) and the source of SCORING_MODULES. Deeper code (the
    optics behind DeP's known kernels) is not in it: a change there needs `rm -r <out>/eval*`."""
    h = hashlib.sha256(data_fingerprint(data).encode())
    h.update(method.encode() if method in BUILTIN_METHODS else Path(method).read_bytes())
    h.update(_scoring_source())
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=1)
def _scoring_source() -> bytes:
    """The source of SCORING_MODULES, read once per process: the code this process scores with."""
    return b"".join(Path(importlib.util.find_spec(name).origin).read_bytes() for name in SCORING_MODULES)


def evaluate_rows(data: Path, models: dict, ev: Path, progress: bool) -> dict:
    """Input, DeP and every trained row on `data`'s test split into `ev`; returns its results.json, holding
    these rows only. Resumes: a row whose evaluation_stamp matches the one recorded in `ev`/stamps.json when
    it was scored, and whose displays are all in results.json, is not scored again. The seconds each row's
    scoring took go to `ev`/row_seconds.json (evaluation_hours)."""
    path, stamps_path, seconds_path = ev / "results.json", ev / "stamps.json", ev / "row_seconds.json"
    stamps = json.loads(stamps_path.read_text()) if stamps_path.is_file() and path.is_file() else {}
    seconds = json.loads(seconds_path.read_text()) if seconds_path.is_file() else {}
    rows = [(m, m, dataset_displays(data)) for m in BUILTIN_METHODS]
    rows += [(row, str(p), [d]) for (row, d), p in models.items()]
    scored = json.loads(path.read_text())["methods"] if path.is_file() else {}  # before this call's rows
    for name, method, displays in rows:
        stamp = evaluation_stamp(data, method)
        if stamps.get(method) == stamp and all(d in scored.get(name, {}).get("displays", {}) for d in displays):
            continue
        t = time.perf_counter()
        builtin = method in BUILTIN_METHODS  # a model is scored on its row's display (an online one: not its panels)
        evaluate(data, method, ev, EvalSettings(name=None if builtin else name,
                                                displays=None if builtin else tuple(displays)), progress=progress)
        seconds[name] = time.perf_counter() - t
        stamps[method] = stamp
        save_json(seconds_path, seconds)
        save_json(stamps_path, stamps)
    results = json.loads(path.read_text())
    names = {name for name, _, _ in rows}
    if set(results["methods"]) - names:  # rows of an earlier budget or model list
        results["methods"] = {k: v for k, v in results["methods"].items() if k in names}
        save_json(path, results)
        save_text(ev / "results.md", results_markdown(results))
        save_text(ev / "results.csv", results_csv(results))
    return results
