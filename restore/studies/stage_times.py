"""The seconds a resumable job's stages took, summed over its re-runs, in one JSON file ({stage: seconds}):
the robustness study's times.json and the results run's banks/seconds.json."""
from __future__ import annotations

import json
from pathlib import Path

from udc_render.io.files import save_json


class StageTimes:
    """{stage: seconds} read from `path` (empty before the first stage) and written back at every add."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.seconds = json.loads(self.path.read_text()) if self.path.is_file() else {}

    def add(self, stage: str, seconds: float) -> None:
        self.seconds[stage] = round(self.seconds.get(stage, 0.0) + seconds, 2)
        save_json(self.path, self.seconds)
