"""The seconds a resumable job's stages took, summed over its re-runs, in one JSON file ({stage: seconds}):
the robustness study's times.json and the results run's banks/seconds.json; a training run's active time."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from udc_render.io.files import save_json


class StageTimes:
    """{stage: seconds} read from `path` (empty before the first stage) and written back at every add."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.seconds = json.loads(self.path.read_text()) if self.path.is_file() else {}

    def add(self, stage: str, seconds: float) -> None:
        self.seconds[stage] = round(self.seconds.get(stage, 0.0) + seconds, 2)
        save_json(self.path, self.seconds)


EPOCH_CAP_X_MEDIAN = 1.5  # an epoch counted at most this many times the median epoch (active_seconds)


def active_seconds(log: list[dict], cap_x_median: float = EPOCH_CAP_X_MEDIAN) -> float:
    """The run's time without its stalls: Σ_e min(t_e − t_{e−1}, cap · median_e(t_e − t_{e−1})) over the
    cumulative `seconds` of its loss log. A paused process (SIGSTOP) or a job sharing the cores stretches a
    few epochs by up to hours; a validated epoch is within 1.5× of one that is not (results logs: +10–25 %)."""
    t = np.array([0.0] + [r["seconds"] for r in log], dtype=np.float64)
    epochs = np.diff(t)
    if epochs.size == 0:
        return 0.0
    return float(np.minimum(epochs, cap_x_median * np.median(epochs)).sum())
