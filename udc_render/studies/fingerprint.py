"""Fingerprints of what made a resumable study's logged rows (issue 45).

A study that logs its rows to resume (study gap's rows_*.jsonl, study robustness's scores.jsonl, …) writes
beside each row the fingerprint of the settings that made it and of the models it scores (a model by the sha256
of its file's bytes). A resumed run keeps a logged row only when its fingerprint is the one the run computes
now; any other logged row of the run's grid (made with other settings or models, or by an older log format
without a fingerprint) is recomputed, and the run says how many in one line (stale_note). The code is not in
a fingerprint: after changing the code behind a score, delete the log.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

FIELD = "fingerprint"  # a logged row's (or entry's) key for its fingerprint


def _plain(value):
    return value.tolist() if isinstance(value, np.ndarray) else str(value)


def digest(value) -> str:
    """sha256 (16 hex digits) of a JSON value: keys sorted, arrays as lists, anything else (paths) as str."""
    text = json.dumps(value, sort_keys=True, default=_plain)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def file_digest(path: Path | str) -> str:
    """sha256 (16 hex digits) of a file's bytes (a model: retrained, it is another model)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:16]


def stale_note(study: str, stale: int, log: Path) -> str | None:
    """One line for a resumed run that recomputes `stale` logged rows (None when there are none)."""
    if not stale:
        return None
    return (f"{study}: {stale} logged row{'s' if stale != 1 else ''} in {log} made with other settings or models "
            f"(or logged without a fingerprint): recomputed")
