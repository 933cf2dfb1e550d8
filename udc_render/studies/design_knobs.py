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
(b) The search's steps: one `udc-render design` run (udc_render.design.config.DesignConfig's defaults), its cell
after 0, 10, 20, 40, 80 and 150 steps (accepted swaps) scored as design.json's 'final' (the mean Wiener MSE over
channels on the held-out tiling, and its PSNR), with the search's CPU seconds so far; 0 steps is the initial
random scatter, the baseline the search has to beat.
(c) The sampled banding's raster step (udc_render.design.tiling_power's sample_um: the layout study's banding of a
turned tiling), on the rig's lens at d = 2 mm over the paper sensor's shifts, for both cells: the repeated tiling's
relative P(s) against the exact power series (psf.banding.PowerSeries; the largest |P/P̄ − S/S̄| over the shifts
and the relative error of the peak-to-peak), and the turned tiling's peak-to-peak and sd against the finest step
(the same tiles at every step: tiling_power.DRAW_TILES); CPU seconds of both tilings (3 channels).

(d) The engine's field phases of a turned tiling (psf.engine.compute_kernels' field_phases P for a
psf.MicrographLayout with random quarter-turns, seed 0), on the rig's lens at d = 2 mm over the paper sensor, at
520 nm: the relative power the field blend prints, Σ_q w_q(s) P_q (bilinear in phase, clamped:
optics.field.phase_weights), against the engine window's exact P(s) at every whole-sample shift between the outer
phases (tiling_power.raster_power: the same tiles). Also what engine version psf-4 printed for the same tiling:
P phases over one tile, interpolated periodically. Each P is its own window (its margin holds its shifts), so its
own draw of turns. CPU seconds of the kernels (one wavelength).

(e) The banding ceiling's draws (udc_render.design.bands.BANDING_DRAWS): the relative sd of P of each cell on the
ceiling's raster (the cell's own squares), as the root mean variance over N D4 draws of the window's tiles, and the
ratio scatter / T-OLED the ceiling holds, against the same over all M = `ceiling_truth` draws: the RMS over disjoint
blocks of N draws of the relative error, times √(M / (M − N)) (a block is part of the M draws: its error against
them is √(1 − N / M) of its error against the expectation), the largest over R, G, B; CPU seconds of one forward
pass over N draws (the scatter, 3 channels).

(f) The search's kicks (udc_render.design.optimise's iterated local search): the run of part (b) (DesignConfig's
defaults) with kicks of 2, 4 and 8 random swaps, its best cell after 0, 1, 2, 4, 8 and 16 kicks scored as
design.json's 'final' (held-out tiling) and on the search's own tiling, with the search's CPU seconds so far and its
exact scores; 0 kicks is part (b)'s converged cell.

(g) The search's tilings (DesignConfig's search_tilings M: the objective the search lowers is the mean over M fixed
D4 draws): part (b)'s run to its local optimum with M = 1, 2, 4 and 8, its cell scored on `held_tilings` held-out
draws (udc_render.design.held_out: neither the search's nor 'final'): the mean PSNR of the mean Wiener MSE over the
draws, the paired difference to M = 1's cell (mean and se over the draws), the search's own score on its M draws
(what it overfits: its excess over the held-out mean), the search's CPU seconds and exact scores.

(h) The arranged tiling's K (udc_render.studies.design_arrangement): random K × K patterns of each cell's D4
elements, the objective's gap to the cell turned and the bands over the repeated T-OLED, against K and CPU seconds.

(i) The blur floor's rig (udc_render.studies.design_blur): its blur error against pupil samples, window, wavelengths.

Outputs: study_design.json (every figure), study_design.csv (one row per setting), study_design.md,
study_design.png (error against CPU time; objective against steps; banding error against CPU time; field phases;
the ceiling's draws; the kicks; the search's tilings; the arrangement's K; the blur floor's rig).
A part already in OUT's study_design.json with the same settings is kept (the study resumes part by part).
quick (a smoke run): a 96 µm cell, 31-px kernels, three settings and 2 and 4 steps from 128 pupil samples, raster
steps of 8 and 4 µm, 2 field phases, 1 and 2 of 4 draws, 1 and 2 kicks of 2 swaps, 1 and 2 search tilings on 2
held-out draws, the blur's knobs at two settings each.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import torch
from scipy.ndimage import map_coordinates
from tqdm import tqdm

from psf import compute_kernels, layouts
from psf.banding import PowerSeries, power_grid
from psf.lens import Lens
from psf.micrograph import MicrographLayout
from psf.plan import PAPER_SENSOR_UM, make_plan
from udc_render.design import metrics, torch_psf as tp
from udc_render.design.cells import frame_cell
from udc_render.design.config import DesignConfig
from udc_render.design.held_out import held_out_draws, objective_on_draws
from udc_render.design.optimise import RIG_WAVELENGTHS_NM, Designer
from udc_render.design.options import RIG_PIXEL_UM
from udc_render.design.tiling_power import band_figures, raster_power, sampled_banding, shift_span_um, tiling_power
from udc_render.optics.field import phase_weights
from udc_render.streams import stream
from udc_render.studies.design_arrangement import arrangement_rows
from udc_render.studies.design_blur import blur_rows, blur_settings
from udc_render.studies.design_knobs_report import write

__all__ = ["FULL", "QUICK", "cells", "sampling_rows", "steps_rows", "banding_rows", "field_profiles", "field_rows",
           "ceiling_rows", "kicks_rows", "tilings_rows", "run_study"]

FULL = {"cell_um": 168.0, "kernel_px": 127, "samples": (128, 256, 384, 512, 768, 1024, 2048),
        "steps": (10, 20, 40, 80, 150), "design_pupil_samples": DesignConfig().pupil_samples,
        "sample_um": (8.0, 4.0, 2.0, 1.0), "phases": (2, 3, 4, 6, 8), "ceiling_draws": (1, 2, 4, 8, 16),
        "ceiling_truth": 32, "kicks": (1, 2, 4, 8, 16), "kick_swaps": (2, 4, 8), "search_tilings": (1, 2, 4, 8),
        "held_tilings": 16, "arrangement": (1, 2, 3, 4, 6, 8), "arrangement_draws": 8,
        "blur_pupil": (512, 768, 1024, 1536, 2048), "blur_px": (65, 129, 257), "blur_step_nm": (40, 20, 10),
        "blur_draws": 8, "blur_patterns": 4, "blur_tiles": 16}
QUICK = {"cell_um": 96.0, "kernel_px": 31, "samples": (64, 128, 256), "steps": (2, 4), "design_pupil_samples": 128,
         "sample_um": (8.0, 4.0), "phases": (2,), "ceiling_draws": (1, 2), "ceiling_truth": 4, "kicks": (1, 2),
         "kick_swaps": (2,), "search_tilings": (1, 2), "held_tilings": 2, "arrangement": (1, 2), "arrangement_draws": 2,
         "blur_pupil": (128, 256), "blur_px": (31, 65), "blur_step_nm": (40,),
         "blur_draws": 2, "blur_patterns": 2, "blur_tiles": 2}
FEATURE_UM, OPEN, SEED = 8.0, 0.20, 0  # the cells' squares (µm), their open area, the draws' seed
BANDING_DISTANCE_UM = 2000.0
FIELD_WAVELENGTH_NM = 520.0
PART_KEYS = {"sampling": ("samples",), "steps": ("steps", "design_pupil_samples"), "banding": ("sample_um",),
             "field": ("phases",), "ceiling": ("ceiling_draws", "ceiling_truth"),
             "kicks": ("kicks", "kick_swaps", "design_pupil_samples"),
             "tilings": ("search_tilings", "held_tilings", "design_pupil_samples"),
             "arrangement": ("arrangement", "arrangement_draws", "held_tilings", "design_pupil_samples"),
             "blur": ("blur_pupil", "blur_px", "blur_step_nm", "blur_draws", "blur_patterns", "blur_tiles")}
# besides the shared keys: what decides each part (run_study resumes by them)
SHARED_KEYS = ("cell_um", "kernel_px", "feature_um", "open_fraction", "seed", "wavelengths_nm", "threads",
               "banding_distance_mm")


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
            grid = tp.cell_grid(cell.shape[0], FEATURE_UM, Lens(), RIG_WAVELENGTHS_NM, RIG_PIXEL_UM, cfg["kernel_px"],
                                samples)
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


def kicks_rows(cfg: dict, progress=None) -> list[dict]:
    """Part (f): per kick size, one kicked run (part (b)'s settings, steps uncapped in practice), its best cell after
    each kick count: the best of that many + 1 local optima, scored held out and on the search's tiling."""
    rows = []
    for swaps in cfg["kick_swaps"]:
        config = DesignConfig(cell_um=cfg["cell_um"], kernel_px=cfg["kernel_px"], steps=100_000,
                              pupil_samples=cfg["design_pupil_samples"], kicks=max(cfg["kicks"]), kick_swaps=swaps)
        designer, cpu_s = Designer(config), 0.0
        for kicks in (0, *cfg["kicks"]):
            start = time.process_time()
            while not designer.finished and designer.kicks_done <= kicks:
                designer.step()
            cpu_s += time.process_time() - start
            rows.append({"part": "kicks", "kick_swaps": swaps, "kicks": kicks, "steps_done": designer.step_done,
                         **designer.score(designer.best_cell), "search_psnr_db": float(-10 * np.log10(designer.best)),
                         "cpu_s": cpu_s, "evaluations": designer.evaluations})
            if progress:
                progress(1)
    return rows


def tilings_rows(cfg: dict, progress=None) -> list[dict]:
    """Part (g): per M, part (b)'s run with search_tilings M to its local optimum, its cell on the held-out draws
    (paired with M = 1's cell), the search's own score and CPU seconds."""
    rows, first = [], None
    for m in cfg["search_tilings"]:
        designer = Designer(DesignConfig(cell_um=cfg["cell_um"], kernel_px=cfg["kernel_px"], search_tilings=m,
                                         pupil_samples=cfg["design_pupil_samples"]))
        start = time.process_time()
        while not designer.finished:
            designer.step()
        cpu_s = time.process_time() - start
        j = objective_on_draws(designer, designer.best_cell, held_out_draws(designer, cfg["held_tilings"]))
        psnr, per_draw = float(-10 * np.log10(np.mean(j))), [float(-10 * np.log10(v)) for v in j]
        first = first or per_draw
        diff = np.subtract(per_draw, first)
        rows.append({"part": "tilings", "search_tilings": m, "steps_done": designer.step_done,
                     "converged": designer.converged, "held_psnr_db": psnr, "held_draws_psnr_db": per_draw,
                     "gain_db": float(diff.mean()), "gain_se_db": float(diff.std(ddof=1) / np.sqrt(len(diff))),
                     "search_psnr_db": float(-10 * np.log10(designer.best)), "cpu_s": cpu_s,
                     "evaluations": designer.evaluations})
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


def _turned(cell: np.ndarray) -> MicrographLayout:
    return MicrographLayout("cell", FEATURE_UM, "amplitude", True, SEED, cell)


def field_profiles(display, ks, plan, power_map: np.ndarray) -> dict:
    """Part (d)'s relative powers [2 J_y + 1, 2 J_x + 1] over the whole-sample shifts between the outer phases:
    'exact' (the window's P(s), raster_power), 'blend' (the kernel set's phases interpolated as the render does)
    and 'one_tile' (psf-4: P phases over one tile of the same window, interpolated periodically)."""
    P, shifts, g = plan.phases, plan.shifts, plan.grid
    z, d = plan.lens.image_distance_um, plan.d_um
    jx, jy = int(np.abs(shifts[..., 0]).max() // g.dx_um), int(np.abs(shifts[..., 1]).max() // g.dy_um)
    sx, sy = np.arange(-jx, jx + 1) * g.dx_um, np.arange(-jy, jy + 1) * g.dy_um
    ny, nx = power_map.shape
    exact = power_map[np.ix_(np.arange(-jy, jy + 1) % ny, np.arange(-jx, jx + 1) % nx)]
    px, py = display.period_um
    weights = [phase_weights(sy * z / d, shifts[:, 0, 1], d, z, py, False),
               phase_weights(sx * z / d, shifts[0, :, 0], d, z, px, False)]
    blend = weights[0].T @ np.asarray(ks.field_power[0], np.float64) @ weights[1]
    ox, oy = np.arange(P) / P * px, np.arange(P) / P * py
    at = np.stack(np.broadcast_arrays(oy[:, None] / g.dy_um, ox[None, :] / g.dx_um))
    tile_p = map_coordinates(power_map, at, order=1, mode="grid-wrap")
    one_tile = (phase_weights(sy * z / d, oy, d, z, py, True).T @ tile_p
                @ phase_weights(sx * z / d, ox, d, z, px, True))
    return {k: v / v.mean() for k, v in (("exact", exact), ("blend", blend), ("one_tile", one_tile))}


def field_rows(cfg: dict, progress=None) -> list[dict]:
    """Part (d): one row per cell and phase count P (module doc)."""
    rows, lens, wl = [], Lens(), np.array([FIELD_WAVELENGTH_NM])
    for name, cell in cells(cfg["cell_um"]).items():
        display = _turned(cell)
        for P in cfg["phases"]:
            ks, cpu_s = _timed(lambda: compute_kernels(display, lens, wl, RIG_PIXEL_UM, cfg["kernel_px"],
                                                       BANDING_DISTANCE_UM / 1000, P))
            plan = make_plan(display, lens, wl, RIG_PIXEL_UM, cfg["kernel_px"], BANDING_DISTANCE_UM / 1000, P, "mft",
                             None, "float64", True, "band_limited", PAPER_SENSOR_UM, [])
            prof = field_profiles(display, ks, plan, raster_power(plan, FIELD_WAVELENGTH_NM))
            exact = prof["exact"]
            row = {"part": "field", "cell": name, "phases": P, "cpu_s": cpu_s,
                   "phase_step_um": [float(np.diff(plan.shifts[0, :, 0])[0]) if P > 1 else 0.0,
                                     float(np.diff(plan.shifts[:, 0, 1])[0]) if P > 1 else 0.0],
                   "shifts_um": [float(exact.shape[1] // 2 * plan.grid.dx_um),
                                 float(exact.shape[0] // 2 * plan.grid.dy_um)]}
            for key, m in prof.items():
                row[f"{key}_sd"] = float(m.std())
                row[f"{key}_peak_to_peak"] = float(m.max() - m.min())
                if key != "exact":
                    row[f"{key}_error_rms"] = float(np.sqrt(np.mean((m - exact) ** 2)))
            rows.append(row)
            if progress:
                progress(1)
    return rows


def _draw_sds(ceiling, cell: np.ndarray, draws: int) -> np.ndarray:
    """[draws, channels] the relative sd of P of the cell on each of the ceiling's raster draws (keys 'study', k)."""
    from udc_render.design.bands import relative_sd
    with torch.no_grad():
        return np.array([[float(relative_sd(p)) for p in ceiling.power(torch.tensor(cell), tp.tile_transforms(
            ceiling.tiles, SEED, keys=("design", "banding", "study", k)))] for k in range(draws)])


def _block_error(var: np.ndarray, n: int, ref_var: np.ndarray | None = None) -> float:
    """The RMS over disjoint blocks of n draws of the relative error of √(mean variance) (of the ratio to ref_var's,
    on the same draws, when given) against all M draws', times √(M / (M − n)), the largest over the channels."""
    def estimate(rows: slice) -> np.ndarray:
        e = np.sqrt(var[rows].mean(0))
        return e if ref_var is None else e / np.sqrt(ref_var[rows].mean(0))
    full = estimate(slice(None))
    errors = [estimate(slice(b * n, (b + 1) * n)) / full - 1 for b in range(len(var) // n)]
    return float(np.max(np.sqrt(np.mean(np.square(errors), axis=0) * len(var) / (len(var) - n))))


def ceiling_rows(cfg: dict, progress=None) -> list[dict]:
    """Part (e): one row per draw count N (module doc)."""
    from udc_render.design.bands import BandingCeiling
    cs = cells(cfg["cell_um"])
    ceiling = BandingCeiling(1.0, cs["scatter"].shape[0], cfg["cell_um"], OPEN, RIG_WAVELENGTHS_NM, SEED, True)
    var = {name: _draw_sds(ceiling, cell, cfg["ceiling_truth"]) ** 2 for name, cell in cs.items()}
    rows = []
    for n in cfg["ceiling_draws"]:
        _, cpu_s = _timed(lambda: _draw_sds(ceiling, cs["scatter"], n))
        rows.append({"part": "ceiling", "draws": n, "blocks": cfg["ceiling_truth"] // n, "cpu_s": cpu_s,
                     "error_toled_rel": _block_error(var["toled_edge"], n),
                     "error_scatter_rel": _block_error(var["scatter"], n),
                     "error_ratio_rel": _block_error(var["scatter"], n, var["toled_edge"])})
        if progress:
            progress(1)
    return rows


def _kept_parts(out: Path, config: dict) -> dict:
    """The parts of OUT's study_design.json made with these settings (PART_KEYS and SHARED_KEYS)."""
    try:
        old = json.loads((out / "study_design.json").read_text())
    except (OSError, ValueError):
        return {}
    shared = all(old["config"].get(k) == config[k] for k in SHARED_KEYS)
    return {part: old[part] for part, keys in PART_KEYS.items()
            if shared and part in old and all(old["config"].get(k) == config[k] for k in keys)}


def run_study(out: Path, quick: bool = False) -> dict:
    """The nine parts, written to out (udc_render.studies.design_knobs_report); parts already there with the same
    settings are kept."""
    cfg = QUICK if quick else FULL
    config = json.loads(json.dumps({**cfg, "feature_um": FEATURE_UM, "open_fraction": OPEN, "seed": SEED,
                                    "wavelengths_nm": RIG_WAVELENGTHS_NM, "threads": torch.get_num_threads(),
                                    "banding_distance_mm": BANDING_DISTANCE_UM / 1000,
                                    "field_wavelength_nm": FIELD_WAVELENGTH_NM}))
    kept = _kept_parts(Path(out), config)
    makers = {"sampling": (sampling_rows, 2 * len(cfg["samples"])), "steps": (steps_rows, len(cfg["steps"]) + 1),
              "banding": (banding_rows, 2 * len(cfg["sample_um"])), "field": (field_rows, 2 * len(cfg["phases"])),
              "ceiling": (ceiling_rows, len(cfg["ceiling_draws"])),
              "kicks": (kicks_rows, len(cfg["kick_swaps"]) * (len(cfg["kicks"]) + 1)),
              "tilings": (tilings_rows, len(cfg["search_tilings"])),
              "arrangement": (lambda c, p: arrangement_rows(c, cells(c["cell_um"]), SEED, p),
                              2 * (len(cfg["arrangement"]) + 1)),
              "blur": (lambda c, p: blur_rows(c, cells(c["cell_um"]), p), 2 * len(blur_settings(cfg)))}
    total = sum(n for part, (_, n) in makers.items() if part not in kept)
    with tqdm(total=total, desc="study design") as bar:
        doc = {"config": config, **{part: kept[part] if part in kept else make(cfg, bar.update)
                                    for part, (make, _) in makers.items()}}
    write(doc, out)
    return doc
