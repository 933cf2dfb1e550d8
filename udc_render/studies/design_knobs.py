"""`udc-render study design`: error against run time of the design's knobs (issue 48).

    udc-render study design --out DIR [--quick]

(a) The torch PSF's sampling: pupil samples across the aperture (udc_render.design.torch_psf.cell_grid's
pupil_samples; the engine's n samples per cell follow), on the optimiser's rig (psf.Lens(), 3.1 µm pixels, 127 px,
640 / 520 / 450 nm), turned tilings (seed 0, D4), for two 168 µm cells of 8 µm squares at 20 % open area: the
T-OLED's slit (the preset's raster, framed at the tile's edge) and a scatter of 88 open squares (udc_render.streams;
the kind of cell the designer makes). Against the finest setting: the error of the Wiener PSNR (dB, the largest
over R, G, B; udc_render.design.metrics.restorability, the transmission the cell's open area) and the relative
error of the mean of ring means and of ring minima (the largest over channels; metrics.ring_summary). Cost: CPU
seconds (time.process_time, all threads) of the kernels, and of kernels plus the gradient to the cell (what one
optimiser step pays for its PSF).
(b) The search's steps: one `udc-render design` run (udc_render.design.optimise.DesignConfig's defaults), its cell
after 0, 10, 20, 40, 80 and 150 steps (accepted swaps) scored as design.json's 'final' (the mean Wiener MSE over
channels on the held-out tiling, and its PSNR), with the search's CPU seconds so far; 0 steps is the initial
random scatter, the baseline the search has to beat.
(c) The sampled banding's raster step (udc_render.studies.tiling_power's sample_um: the layout study's banding of a
turned tiling), on the rig's lens at d = 2 mm over the paper sensor's shifts, for both cells: the repeated tiling's
relative P(s) against the exact power series (psf.banding.PowerSeries; the largest |P/P̄ − S/S̄| over the shifts
and the relative error of the peak-to-peak), and the turned tiling's peak-to-peak and sd against the finest step
(the same tiles at every step: layout_banding.DRAW_TILES); CPU seconds of both tilings (3 channels).

Outputs: study_design.json (every figure), study_design.csv (one row per setting), study_design.md,
study_design.png (error against CPU time; objective against steps; banding error against CPU time). quick: a 96 µm
cell, 31-px kernels, three settings and 2 and 4 steps from 128 pupil samples, raster steps of 8 and 4 µm (a smoke
run).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from psf import layouts
from psf.banding import PowerSeries, power_grid
from psf.lens import Lens
from psf.micrograph import MicrographLayout
from udc_render.design import metrics, torch_psf as tp
from udc_render.design.cells import frame_cell
from udc_render.design.optimise import RIG_WAVELENGTHS_NM, DesignConfig, Designer
from udc_render.streams import stream
from udc_render.studies.design_knobs_report import write
from udc_render.studies.layout_banding import sampled_banding
from udc_render.studies.tiling_power import band_figures, shift_span_um, tiling_power

__all__ = ["FULL", "QUICK", "cells", "sampling_rows", "steps_rows", "banding_rows", "run_study"]

FULL = {"cell_um": 168.0, "kernel_px": 127, "samples": (128, 256, 384, 512, 768, 1024, 2048),
        "steps": (10, 20, 40, 80, 150), "design_pupil_samples": DesignConfig().pupil_samples,
        "sample_um": (8.0, 4.0, 2.0, 1.0)}
QUICK = {"cell_um": 96.0, "kernel_px": 31, "samples": (64, 128, 256), "steps": (2, 4), "design_pupil_samples": 128,
         "sample_um": (8.0, 4.0)}
FEATURE_UM = 8.0
OPEN = 0.20
SEED = 0
BANDING_DISTANCE_UM = 2000.0


def cells(cell_um: float) -> dict:
    """{name: amplitude cell [c, c]} of 8 µm squares at OPEN: the T-OLED's slit at the tile's edge, a scatter."""
    c = round(cell_um / FEATURE_UM)
    slit = frame_cell(tp.preset_cell(layouts.toled(pitch_um=cell_um, open_fraction=OPEN), c), "edge")
    flat = np.zeros(c * c)
    flat[stream(SEED, "study", "design", "scatter").permutation(c * c)[: round(OPEN * c * c)]] = 1.0
    return {"toled_edge": slit, "scatter": flat.reshape(c, c)}


def _timed(fn):
    start = time.process_time()
    value = fn()
    return value, time.process_time() - start


def _scores(cell: np.ndarray, grid) -> tuple[dict, float, float]:
    """(restorability and ring summary of the turned kernels, CPU s forward, CPU s forward + gradient)."""
    transforms = tp.tile_transforms(grid.tiles, SEED)
    with torch.no_grad():
        k, forward_s = _timed(lambda: tp.kernels(torch.tensor(cell), grid, transforms).numpy())
    x = torch.tensor(cell, requires_grad=True)
    _, grad_s = _timed(lambda: tp.kernels(x, grid, transforms).sum().backward())
    rings = metrics.ring_summary(k, grid.size_px // 2)
    psnr = metrics.restorability(k, float(np.mean(cell)))["wiener_psnr_db"]  # open area: squares area-weighted
    return {"psnr_db": psnr, "ring_means": rings["mean_of_ring_means"],
            "ring_minima": rings["mean_of_ring_minima"]}, forward_s, grad_s


def sampling_rows(cfg: dict, progress=None) -> list[dict]:
    """Part (a): one row per cell and pupil-sample setting, errors against the cell's finest setting."""
    rows = []
    for name, cell in cells(cfg["cell_um"]).items():
        found = []
        for i, samples in enumerate(cfg["samples"]):
            grid = tp.cell_grid(cell.shape[0], FEATURE_UM, Lens(), RIG_WAVELENGTHS_NM, 3.1, cfg["kernel_px"], samples)
            if i == 0:
                _scores(cell, grid)  # untimed: torch's first calls at a size pay set-up costs
            s, forward_s, grad_s = _scores(cell, grid)
            found.append({"part": "sampling", "cell": name, "pupil_samples": samples, "samples_per_cell": grid.n,
                          **s, "cpu_s": forward_s, "cpu_gradient_s": grad_s})
            if progress:
                progress(1)
        ref = found[-1]
        for r in found:
            r["error_psnr_db"] = float(np.max(np.abs(np.subtract(r["psnr_db"], ref["psnr_db"]))))
            for key in ("ring_means", "ring_minima"):
                r[f"error_{key}_rel"] = float(np.max(np.abs(np.divide(r[key], ref[key]) - 1)))
        rows += found
    return rows


def steps_rows(cfg: dict, progress=None) -> list[dict]:
    """Part (b): one design run (DesignConfig's defaults, at most the largest step count), its cell after each step
    count scored as design.json's 'final' (held-out tiling, float64), with the search's CPU seconds so far (the
    scoring not counted); 0 steps: the initial random scatter, the baseline the search has to beat."""
    base = DesignConfig(cell_um=cfg["cell_um"], kernel_px=cfg["kernel_px"], pupil_samples=cfg["design_pupil_samples"],
                        steps=max(cfg["steps"]))
    designer, cpu_s, rows = Designer(base), 0.0, []
    for steps in (0, *cfg["steps"]):
        start = time.process_time()
        while designer.step_done < steps and not designer.finished:
            designer.step()
        cpu_s += time.process_time() - start
        rows.append({"part": "steps", "steps": steps, "steps_done": designer.step_done,
                     "converged": designer.converged, **designer.score(designer.cell), "cpu_s": cpu_s,
                     "evaluations": designer.evaluations, "pupil_samples": base.pupil_samples})
        if progress:
            progress(1)
    return rows


def _series_errors(cell: np.ndarray, sample_um: float) -> dict:
    """The repeated cell's sampled P(s) against its exact series, the largest over the channels (part c)."""
    layout = MicrographLayout("cell", FEATURE_UM, image=cell)
    span, profile, p2p = shift_span_um(Lens(), BANDING_DISTANCE_UM), 0.0, 0.0
    for wl in RIG_WAVELENGTHS_NM:
        power, step = tiling_power(cell, FEATURE_UM, Lens(), wl, BANDING_DISTANCE_UM, span, sample_um=sample_um)
        jy, jx = power.shape[0] // 2, power.shape[1] // 2
        xs, ys = np.arange(-jx, jx + 1) * step, np.arange(-jy, jy + 1) * step
        half = PowerSeries(layout, Lens(), wl * 1e-3, BANDING_DISTANCE_UM).truncated(1e-7)
        series = power_grid(half, layout.period_um, -xs, -ys)
        profile = max(profile, float(np.abs(power / power.mean() - series / series.mean()).max()))
        p2p = max(p2p, abs(band_figures(power)["peak_to_peak"] / band_figures(series)["peak_to_peak"] - 1))
    return {"error_profile_rel": profile, "error_peak_to_peak_rel": p2p}


def banding_rows(cfg: dict, progress=None) -> list[dict]:
    """Part (c): one row per cell and raster step; the turned figures' errors against the cell's finest step."""
    rows = []
    for name, cell in cells(cfg["cell_um"]).items():
        found = []
        for sample_um in cfg["sample_um"]:
            b, cpu_s = _timed(lambda: sampled_banding(cell, FEATURE_UM, Lens(), RIG_WAVELENGTHS_NM,
                                                      BANDING_DISTANCE_UM / 1000, SEED, sample_um))
            found.append({"part": "banding", "cell": name, "sample_um": sample_um, "cpu_s": cpu_s,
                          "turned_peak_to_peak": b["turned"]["peak_to_peak"], "turned_rms": b["turned"]["rms"],
                          **_series_errors(cell, sample_um)})
            if progress:
                progress(1)
        ref = found[-1]
        for r in found:
            r["error_turned_rel"] = float(max(np.max(np.abs(np.divide(r[k], ref[k]) - 1))
                                              for k in ("turned_peak_to_peak", "turned_rms")))
        rows += found
    return rows


def run_study(out: Path, quick: bool = False) -> dict:
    """The three parts, written to out (udc_render.studies.design_knobs_report)."""
    cfg = QUICK if quick else FULL
    total = 2 * len(cfg["samples"]) + len(cfg["steps"]) + 1 + 2 * len(cfg["sample_um"])
    with tqdm(total=total, desc="study design") as bar:
        doc = {"config": {**cfg, "feature_um": FEATURE_UM, "open_fraction": OPEN, "seed": SEED,
                          "wavelengths_nm": RIG_WAVELENGTHS_NM, "threads": torch.get_num_threads(),
                          "banding_distance_mm": BANDING_DISTANCE_UM / 1000},
               "sampling": sampling_rows(cfg, bar.update), "steps": steps_rows(cfg, bar.update),
               "banding": banding_rows(cfg, bar.update)}
    write(doc, out)
    return doc
