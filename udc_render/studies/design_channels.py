"""`udc-render study channel-step --designs DIR,DIR`: the design objective's wavelengths against run time (issue 48).

The rig's objectives see one wavelength per channel (640 / 520 / 450 nm, `design --channel-step 0`) or the camera's
channels: its band sampled at a step, summed with the weights S_c(λ) D65(λ) δλ (`--channel-step NM`, the kernels
`study layout-trained`'s bank takes; udc_render.design.optimise.objective_wavelengths). Each design's cell (the
first folder's objective, its channel step set per row) and the simulator's T-OLED (held_out.preset_toled, exact) are
scored on the simulator's own tiling (held_out.engine_draw), and each design's margin over that T-OLED (dB) is taken
against the finest step's: the error of the approximation. CPU seconds are one objective's, the mean over the
designs. Writes study_channel_step.{json,csv,md,png}.
"""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from udc_render.io.files import save_json
from udc_render.studies.design_held_out import check
from udc_render.studies.report import annotated_loglog, finish_axes, md_table, pyplot, save_plot, write_tables

__all__ = ["NAME", "STEPS_NM", "QUICK_STEPS_NM", "run_study"]

NAME = "study_channel_step"
STEPS_NM = (0.0, 80.0, 40.0, 20.0, 10.0, 5.0)  # 0: one wavelength per channel; the last, the finest, is the reference
QUICK_STEPS_NM = (0.0, 80.0, 40.0)


def _row(config, cells: dict, step_nm: float) -> dict:
    """One step: the T-OLED's PSNR, each design's margin over it, one objective's CPU seconds."""
    from udc_render.design.held_out import engine_draw, preset_toled, psnr_on_draws
    from udc_render.design.optimise import Designer
    cfg = replace(config, channel_step_nm=step_nm)
    designer = Designer(cfg)
    draw = engine_draw(designer)
    toled, scoring = preset_toled(cfg)
    reference = psnr_on_draws(Designer(scoring), toled, [draw], float(np.mean(toled ** 2)))[0]
    start = time.process_time()
    margins = {name: psnr_on_draws(designer, c, [draw])[0] - reference for name, c in cells.items()}
    return {"channel_step_nm": step_nm, "wavelengths": len(designer.grid.wavelengths_nm),
            "cpu_s": (time.process_time() - start) / len(cells), "toled_psnr_db": reference, "margins_db": margins}


def _with_errors(rows: list[dict]) -> list[dict]:
    """Each row's error: the largest |margin − the finest step's margin| over the designs (dB)."""
    finest = rows[-1]["margins_db"]
    return [{**r, "error_db": max(abs(m - finest[k]) for k, m in r["margins_db"].items())} for r in rows]


def _markdown(doc: dict) -> str:
    rows = [{**r, "step": "one λ per channel" if not r["channel_step_nm"] else f"{r['channel_step_nm']:g} nm",
             **{Path(k).name: f"{m:+.3f}" for k, m in r["margins_db"].items()}} for r in doc["rows"]]
    names = [Path(k).name for k in doc["rows"][0]["margins_db"]]
    lines = ["# The design objective's wavelengths: error against CPU time", "",
             "Each design's margin over the simulator's T-OLED (dB, the first design's objective) on the simulator's "
             "own tiling, per channel step; the error is the largest difference to the finest step's margin.", ""]
    lines += md_table(rows, [("step", "channel step"), ("wavelengths", "wavelengths"),
                             ("cpu_s", "CPU s / objective"), ("error_db", "error (dB)"),
                             ("toled_psnr_db", "T-OLED (dB)")] + [(n, f"{n} − T-OLED") for n in names],
                      {"cpu_s": lambda v: f"{v:.2f}", "error_db": lambda v: f"{v:.4f}",
                       "toled_psnr_db": lambda v: f"{v:.3f}"})
    return "\n".join(lines) + "\n"


def _figure(doc: dict, out: Path) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    rows = doc["rows"][:-1]  # the reference's error is 0
    annotated_loglog(ax, [r["cpu_s"] for r in rows], [max(r["error_db"], 1e-4) for r in rows],
                     ["1 λ" if not r["channel_step_nm"] else f"{r['channel_step_nm']:g} nm" for r in rows],
                     "largest margin error over the designs", 1.5)
    finish_axes(ax, f"against {doc['rows'][-1]['channel_step_nm']:g} nm", "CPU s per objective (one thread)",
                "margin error (dB, floor 1e-4)")
    save_plot(fig, out / f"{NAME}.png")


def run_study(out: Path, designs: list[Path], quick: bool = False) -> dict:
    """Every folder read (a bad one refused) before any scoring; then the module doc's files."""
    config, cells = check(designs)
    steps = QUICK_STEPS_NM if quick else STEPS_NM
    rows = []
    for step in tqdm(steps, desc="study channel-step"):
        rows.append(_row(config, cells, step))
    doc = {"rows": _with_errors(rows), "designs": list(cells), "draw": "the simulator's own tiling (tile seed 0)"}
    save_json(out / f"{NAME}.json", doc)
    flat = [{k: v for k, v in r.items() if k != "margins_db"} | {f"margin_{Path(k).name}": m
                                                                 for k, m in r["margins_db"].items()}
            for r in doc["rows"]]
    write_tables(out, NAME, flat, list(flat[0]), _markdown(doc))
    _figure(doc, out)
    return doc
