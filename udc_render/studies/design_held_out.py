"""`udc-render study held-out --designs DIR,DIR`: committed designs re-scored on many held-out tilings, paired with
the T-OLED the simulator takes (udc_render.design.held_out with simulator=True; issue 48).

The first folder's design.json gives the objective's settings (the search's own options: start, budget, floor,
ceiling, kicks, are left out: they do not change the objective; --pixel-um scores it at another sensor pitch, the
kernel's window kept in µm: at_pitch), and every design's cell (the same squares and open
area) is scored by it on the same draws beside the two T-OLEDs, so the designs rank on one objective. Writes
study_held_out.{json,csv,md,png}: per design, its objective's mean over the draws and its paired difference to the
preset T-OLED (exact, as the simulator takes it) and to the T-OLED on the squares (mean ± se, the draws it leads), on
the search's D4 draws, on the engine's quarter-turns and on the simulator's own tiling (one draw: what `study
layout-trained` sees); the figure draws the paired differences per design.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, fields, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from udc_render.design.far_light import light_shares
from udc_render.errors import UdcError
from udc_render.io.files import save_json
from udc_render.studies.report import md_table, pyplot, save_plot, write_tables

__all__ = ["NAME", "QUICK_TILINGS", "saved_design", "objective_config", "at_pitch", "check", "run_study"]

NAME = "study_held_out"
QUICK_TILINGS = 2
SEARCH_ONLY = {"init": "scatter", "steps": 1, "candidates": 1, "scatters": 1, "upc_floor": None,
               "floor_channels": "G", "floor_uncropped": False, "banding_ceiling": None, "kicks": 0,
               "kick_swaps": 1, "search_tilings": 1}  # the options that do not change the objective
GROUPS = ("d4", "quarter_turns", "engine")  # the held-out D4 draws, quarter-turns, the simulator's own tiling
TOLEDS = ("toled_preset", "toled_squares")


def saved_design(folder: Path, arranged: bool = False):
    """(the DesignConfig of design.json's settings in a `udc-render design` folder less the search's own, SEARCH_ONLY
    (its start may name a file gone since), and its cell), refused in one line when the folder holds no design.json;
    an arranged design refused unless `arranged`, then its cell is its super-cell (its period:
    udc_render.design.job.supercell)."""
    from udc_render.design.cells import read_cell
    from udc_render.design.config import DesignConfig
    path = folder / "design.json"
    if not path.is_file():
        raise UdcError(f"--designs {folder}: no design.json there; expected a `udc-render design` output folder")
    saved = json.loads(path.read_text())
    known = {f.name for f in fields(DesignConfig)}
    config = DesignConfig(**{k: v for k, v in saved["config"].items() if k in known and k not in SEARCH_ONLY})
    if config.tiling == "arranged" and not arranged:
        raise UdcError(f"--designs {folder}: its tiling is arranged (one periodic tiling, not draws); its design.json "
                       "holds its comparison with the T-OLED's draws and its bands; expected a turned design")
    cell = read_cell(str(folder / "cell.png"), config.cell_px, config.open_squares)
    if config.tiling == "arranged":
        from udc_render.design.job import supercell
        cell = supercell(cell, np.asarray(saved["arrangement"]))
    return config, cell


def objective_config(folder: Path):
    """The DesignConfig of a design folder's objective (design.json's settings, SEARCH_ONLY's reset), and its cell."""
    from udc_render.design.held_out import applies
    saved, cell = saved_design(folder)
    config = replace(saved, **SEARCH_ONLY)
    if not applies(config):
        raise UdcError(f"--designs {folder}: its design is {config.objective} in --optics {config.optics}, "
                       f"--tiling {config.tiling}; expected --objective wiener or crop, --optics rig, --tiling turned")
    return config, cell


def at_pitch(config, pixel_um: float | None, packed: bool = False):
    """The objective at another sensor pitch (None: as saved), its kernel window kept in µm: the smallest odd
    kernel_px whose window covers the saved one (255 px of 3.1 µm: 129 of 6.2 and 65 of 12.4, the bank kernels of
    `study layout-trained` at 6.2 µm and their packed planes); packed: scored on the packed planes of that pitch
    (DesignConfig.packed)."""
    if pixel_um is not None:
        size = 2 * math.ceil((config.kernel_px * config.pixel_um / pixel_um - 1) / 2) + 1
        config = replace(config, pixel_um=float(pixel_um), kernel_px=int(size))
    return replace(config, packed=True) if packed else config


def check(folders: list[Path]):
    """(the first folder's objective config, {folder: cell}): every folder read and its cell matched to the first's
    (one line on the first that fails)."""
    config = objective_config(folders[0])[0]
    return config, {str(f): _cell(f, config) for f in folders}


def _light(cell: np.ndarray, pixel_um: float, designer) -> dict:
    """The shares of the cell's light past the objective's kernel window and beyond the lens's acceptance (the
    simulator's far field keeps the light between them) at the rig's wavelengths (design.far_light, closed form)."""
    from udc_render.design.optimise import RIG_WAVELENGTHS_NM
    from udc_render.optics.far_field import PAPER_FRAME_UM, acceptance_um
    g = designer.grid
    shares = [light_shares(cell, pixel_um, lam / 1000, g.image_distance_um, g.size_px * g.pixel_um / 2,
                           acceptance_um(PAPER_FRAME_UM)) for lam in RIG_WAVELENGTHS_NM]
    return {"past_window": [1 - s["window"] for s in shares],
            "beyond_acceptance": [1 - s["acceptance"] for s in shares]}


def _rows(config, cells: dict, n: int, progress) -> tuple[list[dict], dict]:
    """(one row per design, the T-OLEDs' means and the preset T-OLED's light shares), every cell scored by the first
    folder's objective."""
    from udc_render.design.held_out import held_out_comparison, preset_toled
    from udc_render.design.optimise import Designer
    designer = Designer(config)
    doc = held_out_comparison(designer, cells, n, progress, simulator=True)
    toled, scoring = preset_toled(config)
    rows = []
    for name in cells:
        row = {"design": name, "psnr_db": doc["d4"]["mean"][name], **_light(cells[name], config.feature_um, designer)}
        for g in GROUPS:
            for ref, v in doc[g]["vs"][name].items():
                row.update({f"{g}_{ref}": v["mean"], f"{g}_{ref}_se": v["se"], f"{g}_{ref}_leads": v["leads"]})
        rows.append({**row, "draws": doc["d4"]["psnr_db"][name]})
    toleds = {f"{g}_{t}": doc[g]["mean"][t] for g in GROUPS for t in TOLEDS}
    return rows, {"objective": {k: v for k, v in asdict(config).items() if k not in SEARCH_ONLY}, **toleds,
                  "toled_preset_light": _light(toled, scoring.feature_um, designer)}


def _cell(folder: Path, config) -> np.ndarray:
    """A folder's cell, refused in one line when its cell differs from the objective's (size, squares, open area)."""
    other, cell = objective_config(folder)
    if (other.cell_um, other.feature_um, other.open_squares) != (config.cell_um, config.feature_um,
                                                                 config.open_squares):
        raise UdcError(f"--designs {folder}: its cell ({other.cell_um:g} µm of {other.feature_um:g} µm squares, "
                       f"{other.open_squares} open) differs from the first design's ({config.cell_um:g} µm of "
                       f"{config.feature_um:g} µm, {config.open_squares} open); expected the same cell")
    return cell


def _pm(row: dict, key: str) -> str:
    return f"{row[key]:+.3f} ± {row[key + '_se']:.3f} ({row[key + '_leads']})"


def _shares(light: dict) -> str:
    return "; ".join(" / ".join(f"{100 * v:.2f}" for v in light[k]) for k in ("past_window", "beyond_acceptance"))


def _markdown(doc: dict) -> str:
    n = doc["tilings"]
    shown = ("d4_toled_preset", "d4_toled_squares", "quarter_turns_toled_preset")
    rows = [{**r, **{k: _pm(r, k) for k in shown}, "light": _shares(r)} for r in doc["rows"]]
    lines = [f"# Designs on {n} held-out tilings, paired with the T-OLEDs", "",
             "Every design scored by the first design's objective: its PSNR (dB, mean over the D4 draws) and the "
             f"paired difference to each T-OLED, mean ± se (the draws of {n} where the design leads). The preset "
             "T-OLED is exact (a binary raster with its edges on the grid), as `study layout-trained` takes it.",
             ""]
    lines += md_table(rows, [("design", "design"), ("psnr_db", "objective (dB)"),
                             ("d4_toled_preset", "− preset T-OLED"), ("d4_toled_squares", "− T-OLED on squares"),
                             ("quarter_turns_toled_preset", "− preset T-OLED, quarter-turns"),
                             ("engine_toled_preset", "− preset T-OLED, the simulator's tiling"),
                             ("light", "past the window; beyond the acceptance (%, 640 / 520 / 450 nm)")],
                      {"psnr_db": lambda v: f"{v:.3f}", "engine_toled_preset": lambda v: f"{v:+.3f}"})
    t = doc["toleds"]
    lines += ["", f"The T-OLEDs (mean over the D4 draws): the preset {t['d4_toled_preset']:.3f} dB, on the squares "
              f"{t['d4_toled_squares']:.3f} dB; on the quarter-turns {t['quarter_turns_toled_preset']:.3f} and "
              f"{t['quarter_turns_toled_squares']:.3f} dB; on the simulator's own tiling "
              f"{t['engine_toled_preset']:.3f} dB; its light past the window, beyond the acceptance "
              f"{_shares(t['toled_preset_light'])} %. "
              "The objective (the first design's): "
              + ", ".join(f"{k} {v}" for k, v in t["objective"].items()) + "."]
    return "\n".join(lines) + "\n"


def _figure(doc: dict, out: Path) -> None:
    plt = pyplot()
    rows = doc["rows"]
    fig, ax = plt.subplots(figsize=(7, 0.45 * len(rows) + 1.5))
    y = np.arange(len(rows))
    for k, (key, label) in enumerate((("d4_toled_preset", "− the preset T-OLED (the simulator's)"),
                                      ("d4_toled_squares", "− the T-OLED on the squares (the search's start)"))):
        ax.errorbar([r[key] for r in rows], y + 0.15 * (2 * k - 1), xerr=[2 * r[key + "_se"] for r in rows],
                    fmt="o", label=label + ", ± 2 se")
    ax.axvline(0, color="0.5", lw=0.8)
    ax.set_xscale("symlog", linthresh=0.1)  # linear within ± 0.1 dB, where the margins that matter lie
    ax.margins(x=0.08)
    ax.set_yticks(y, [Path(r["design"]).name for r in rows])
    ax.set_xlabel(f"objective, design − T-OLED (dB, symlog), paired over {doc['tilings']} held-out D4 tilings")
    ax.legend(fontsize=8)
    save_plot(fig, out / f"{NAME}.png")


def run_study(out: Path, designs: list[Path], quick: bool = False, pixel_um: float | None = None,
              packed: bool = False) -> dict:
    """Every folder read (a bad one refused) before any scoring; then the module doc's files; pixel_um: the
    objective's sensor pitch (at_pitch; None: the first design's); packed: on its packed planes."""
    from udc_render.design.held_out import HELD_OUT_TILINGS
    config, cells = check(designs)
    config = at_pitch(config, pixel_um, packed)
    n = QUICK_TILINGS if quick else HELD_OUT_TILINGS
    start = time.perf_counter()
    with tqdm(total=len(GROUPS) * (len(designs) + len(TOLEDS)), desc="study held-out") as bar:
        rows, toleds = _rows(config, cells, n, bar.update)
    doc = {"tilings": n, "rows": rows, "toleds": toleds, "seconds": time.perf_counter() - start}
    save_json(out / f"{NAME}.json", doc)
    write_tables(out, NAME, rows, [k for k in rows[0] if k != "draws"], _markdown(doc))
    _figure(doc, out)
    return doc
