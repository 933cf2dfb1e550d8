"""The design guide's section on the pitch: its tables are the committed runs' (docs/figures/design/symmetric/pitch/:
`study held-out` at 3.1, 6.2 and 12.4 µm, `study layout-trained --pitch-um 3.1`) and the committed runs' own study
rows (DeP at the study's 6.2 µm rig). Consistency checks of the guide against the committed data, not of the
physics; the physics of the pitch is tests/udc_render/test_design_torch_psf.py's block sums and
test_design_optimise.py's objective on the engine's kernels at another pitch."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from restore.studies.layout_trained import paired
from tests.udc_render.test_design_symmetric import _pm

FIGURES = Path(__file__).resolve().parents[2] / "docs" / "figures" / "design"
PITCH = FIGURES / "symmetric" / "pitch"
GUIDE = Path(__file__).resolve().parents[2] / "docs" / "guides" / "design.md"
HEADING = "## Why the objective misjudged the point-symmetric designs"
DESIGNS = ("c2_scene", "c2_veil", "c2_veil_scene", "veil130")
STUDY_RUNS = {"c2_scene": "symmetric/layout_trained", "c2_veil": "symmetric/layout_trained",
              "c2_veil_scene": "symmetric/layout_trained_from_veil"}
# veil130's study ran alone (training seed 0), as did the T-OLED at 88 / 441 it pairs with: the same images and draws
ALONE = ("four_seeds/veil130_seed0", "four_seeds/toled88_seed0")
FINE = ("c2_scene", "c2_veil", "veil130")


def _section() -> list[str]:
    text = GUIDE.read_text()
    start = text.index(HEADING)
    return text[start:text.index("\n## ", start + 1)].splitlines()


def _rows(name: str) -> list[str]:
    return [line for line in _section() if line.startswith(f"| `{name}` |")]


def _json(folder: Path, name: str) -> dict:
    return json.loads((folder / name).read_text())


@pytest.mark.parametrize("name", DESIGNS)
def test_the_pitch_tables_row_is_the_committed_runs(name):
    row = _rows(name)[0]
    cells = []
    for pitch in ("3.1", "6.2", "12.4"):
        doc = _json(PITCH / f"held_out_{pitch}um", "study_held_out.json")
        assert doc["toleds"]["objective"]["pixel_um"] == float(pitch)
        r = next(r for r in doc["rows"] if Path(r["design"]).name == name)
        cells.append(_pm(r["d4_toled_preset"], r["d4_toled_preset_se"], 3))
    if name in STUDY_RUNS:
        dep = _json(FIGURES / STUDY_RUNS[name], "study_layout_trained.json")["paired"][f"{name}_turned"]["dep"]
    else:
        design, toled = (_json(FIGURES / f, "study_layout_trained.json")["rows"][0]["per_image_db"]["dep"]
                         for f in ALONE)
        dep = paired(design, toled)
    cells.append(_pm(dep["mean_db"], dep["se_db"], 2))
    assert row.startswith(f"| `{name}` | " + " | ".join(cells) + " |")


@pytest.mark.parametrize("name", FINE)
def test_the_fine_rigs_row_is_the_committed_run(name):
    doc = _json(PITCH / "layout_trained_3.1um", "study_layout_trained.json")
    assert doc["budget"]["pitch_um"] == 3.1 and doc["budget"]["sensor_px"] == [512, 256]
    paired = doc["paired"][f"{name}_turned"]
    row = _rows(name)[1]
    for key in ("dep", "dep_noiseless", "unet"):
        assert _pm(paired[key]["mean_db"], paired[key]["se_db"], 2) in row
