"""The design guide's section on the packed planes: its tables are the committed runs' (docs/figures/design/symmetric/
pitch/: `study held-out` of eight designs at 3.1 µm, on 12.4 µm squares and on the packed planes of 6.2 µm; the
packed searches' design.json; `study layout-trained` of `c2_packed_veil` and of the T-OLED the same day; `study
design-bands`), and its DeP margins the committed study runs' per-image rows. Consistency checks of the guide against
the committed data, not of the physics; the physics of the packed kernel is test_design_torch_psf.py's (equal to the
restorer's packed_from_sensor) and test_design_optimise.py's (the objective on the engine's kernels packed)."""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import spearmanr

from restore.studies.layout_trained import paired
from tests.udc_render.test_design_study import _per_image
from tests.udc_render.test_design_symmetric import _pm

FIGURES = Path(__file__).resolve().parents[2] / "docs" / "figures" / "design"
PITCH = FIGURES / "symmetric" / "pitch"
GUIDE = Path(__file__).resolve().parents[2] / "docs" / "guides" / "design.md"
HEADING = "## The objective on DeP's packed planes"
RUNS = ("held_out_all_3.1um", "held_out_all_12.4um", "held_out_packed_6.2um")
TOLED88 = "toled168_88of441_edge_turned"
# the packed searches' banding runs and their draws below the repeated T-OLED's (of 32, G), as the guide says
# (folders under docs/figures/design/symmetric)
BANDS = {"c2_veil": ("design_bands", 32), "c2_packed_veil": ("pitch/design_bands_packed", 32),
         "b55_packed": ("pitch/design_bands_b55_packed", 18), "b55_veil130": ("pitch/design_bands_b55_veil130", 22)}
# design: (its study run, its layout there, the reference layout there, or None: the T-OLED at 88 / 441 run alone,
# four_seeds/toled88_seed0, whose DeP rows the runs of the point-symmetric designs repeat to the bit)
DEP = {"c2_scene": ("symmetric/layout_trained", "c2_scene_turned", None),
       "c2_veil": ("symmetric/layout_trained", "c2_veil_turned", None),
       "c2_veil_scene": ("symmetric/layout_trained_from_veil", "c2_veil_scene_turned", None),
       "veil130": ("four_seeds/veil130_seed0", "veil130_turned", None),
       "veil128_b100": ("four_seeds/seed2", "veil128_b100_turned", None),
       "spec_veil_b95": ("four_seeds/seed2", "spec_veil_b95_turned", None),
       "spec_f95": ("four_seeds/seed2", "spec_f95_turned", None),
       "veil_b55": ("layout_trained_b55", "design_turned", "toled168_20_edge_turned")}


def _section() -> list[str]:
    text = GUIDE.read_text()
    start = text.index(HEADING)
    return text[start:text.index("\n## ", start + 1)].splitlines()


def _row(label: str) -> str:
    return next(line for line in _section() if line.startswith(f"| {label} |"))


@lru_cache(maxsize=None)
def _dep(name: str) -> np.ndarray:
    run, layout, ref = DEP[name]
    rows = _per_image(run)
    reference = rows[ref]["dep"] if ref else _per_image("four_seeds/toled88_seed0")[TOLED88]["dep"]
    return np.subtract(rows[layout]["dep"], reference)


@lru_cache(maxsize=None)
def _objective() -> dict:
    """{run: {design: (mean, se) of design − the preset T-OLED}}."""
    out = {}
    for run in RUNS:
        doc = json.loads((PITCH / run / "study_held_out.json").read_text())
        out[run] = {Path(r["design"]).name: (r["d4_toled_preset"], r["d4_toled_preset_se"]) for r in doc["rows"]}
    return out


@pytest.mark.parametrize("name", DEP)
def test_the_calibration_tables_row_is_the_committed_runs(name):
    objective, d = _objective(), _dep(name)
    cells = [_pm(*objective[run][name], 3) for run in RUNS]
    cells.append(_pm(d.mean(), d.std(ddof=1) / np.sqrt(d.size), 2))
    assert _row(f"`{name}`") == f"| `{name}` | " + " | ".join(cells) + " |"


def test_the_calibration_summary_is_the_committed_runs():
    """The rank correlation, the common offset and the scatter about it, per objective, over the eight designs."""
    objective = _objective()
    dep = np.array([_dep(n).mean() for n in DEP])
    rho, offset, rms = [], [], []
    for run in RUNS:
        o = np.array([objective[run][n][0] for n in DEP])
        rho.append(f"{spearmanr(o, dep).correlation:.2f}")
        offset.append(f"{np.mean(dep - o):+.2f}".replace("-", "−"))
        rms.append(f"{np.sqrt(np.mean((o + np.mean(dep - o) - dep) ** 2)):.2f}")
    assert _row("Spearman ρ with DeP over the eight").startswith("| Spearman ρ with DeP over the eight | "
                                                                 + " | ".join(rho) + " |")
    assert " | ".join(offset) + " |" in _row("DeP − objective, mean over the eight (the offset)")
    assert _row("RMS of DeP − objective − offset").startswith("| RMS of DeP − objective − offset | "
                                                              + " | ".join(rms) + " |")


def _bands(folder: Path, name: str) -> tuple[str, str]:
    row = next(r for r in json.loads((folder / "study_design_bands.json").read_text())["rows"]
               if Path(r["design"]).name == name)
    assert row["draws"] == 32 and row["over_repeated"]["below"][1] == BANDS[name][1]  # as the guide says
    return f"{row['mean'][1]:.2f}", f"{row['over_repeated']['mean'][1]:.2f}"


@pytest.mark.parametrize("name", ["c2_veil", "c2_packed_veil", "b55_packed", "b55_veil130"])
def test_the_packed_searchs_row_is_the_committed_runs(name):
    """The objective on 16 draws, the prediction (+ the offset), the simulator's margins, UPC's G and the bands."""
    objective = _objective()
    dep = np.array([_dep(n).mean() for n in DEP])
    offset = np.mean(dep - np.array([objective["held_out_packed_6.2um"][n][0] for n in DEP]))
    if name == "c2_veil":
        rows, folder = _per_image("symmetric/layout_trained"), FIGURES / "symmetric" / name
        design, toled = rows["c2_veil_turned"], rows[TOLED88]
        mean, se = objective["held_out_packed_6.2um"][name]
    else:
        run = PITCH / "layout_trained_packed"
        design, toled = (json.loads((run / f / "study_layout_trained.json").read_text())["rows"][0]["per_image_db"]
                         for f in (name, "toled88"))
        folder = PITCH / name
        v = json.loads((folder / "design.json").read_text())["held_out"]["d4"]["vs"]["design"]["toled_preset"]
        mean, se = v["mean"], v["se"]
    bands = _bands(FIGURES / "symmetric" / BANDS[name][0], name)
    upc = json.loads((folder / "design.json").read_text())["upc"]["turned"]["ratio"][1]
    cells = [_pm(mean, se, 3), f"{mean + offset:+.2f}".replace("-", "−")]
    for key in ("input", "dep", "dep_noiseless", "dep_far", "unet"):
        p = paired(design[key], toled[key])
        wins = f" ({p['wins']} of {p['n']})" if key in ("dep", "unet") else ""
        cells.append(_pm(p["mean_db"], p["se_db"], 2) + wins)
    cells += [f"{upc:.2f}", *bands]
    label = {"c2_veil": " (the start; committed before)", "b55_packed": ": no symmetry, bands held at 0.55 ×",
             "b55_veil130": ": the same from `veil130`"}
    assert _row(f"`{name}`" + label.get(name, "")).endswith(
        " | ".join(cells) + " |")


def test_the_small_dipoles_paragraph_is_the_committed_runs():
    """b55_packed's objective on the quarter turns and its bands over the repeated T-OLED's, as the guide prints."""
    text = " ".join("\n".join(_section()).split())
    q = json.loads((PITCH / "b55_packed" / "design.json").read_text())["held_out"]["quarter_turns"]["vs"]["design"]
    assert f"and {_pm(q['toled_preset']['mean'], q['toled_preset']['se'], 3)} on the quarter turns" in text
    row = json.loads((PITCH / "design_bands_b55_packed" / "study_design_bands.json").read_text())["rows"][0]
    over = row["over_repeated"]
    assert (f"bands {over['mean'][1]:.3f} ± {over['se'][1]:.3f} × the repeated T-OLED ({over['below'][1]} of 32 "
            "below: level)") in text
