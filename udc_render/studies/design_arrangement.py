"""Part (h) of `udc-render study design`: the arranged tiling's K, the trade between restoration and banding.

An arranged display (`design --tiling arranged --arrangement K`) repeats a K × K pattern of the cell's D4 elements:
its bands are those of a period of K × c µm, and its MTF nears the turned tiling's as K grows. For each of the
study's two cells (the T-OLED's slit at the tile's edge, a scatter of 20 % open squares) and each K, `draws` random
patterns (udc_render.streams keys 'study', 'arrangement', K, p; uniform over the 8 D4 elements) are scored as the
search scores them (DesignConfig's defaults, tiling 'arranged'):

- the objective's PSNR, −10 log10 J (udc_render.design.optimise.Designer.objective), its mean over the patterns and
  its best, and the mean's gap to the same cell turned (the mean PSNR over `held_tilings` held-out D4 draws:
  design.held_out.held_out_draws), the restoration an arranged tiling gives up;
- the bands at d = 2 mm over the repeated T-OLED's, R / G / B (design.bands.BandingCeiling on the cell's squares,
  both periodic displays registered over their periods: the ratio `--banding-ceiling` holds), the mean over the
  patterns; the turned cell's (its 8 draws) over the same repeated T-OLED;
- CPU seconds (time.process_time) of one score and of one banding figure, and what a sweep of the pattern costs
  (7 K² of each: design.optimise's coordinate descent).

A random pattern is not a searched one: the committed searches (docs/guides/design.md, the arranged tiling) give
the searched points; this part gives the trend they sit on.
"""
from __future__ import annotations

import numpy as np
import torch

from udc_render.design import torch_psf as tp
from udc_render.design.config import DesignConfig
from udc_render.design.held_out import held_out_draws, psnr_on_draws
from udc_render.design.optimise import Designer
from udc_render.studies.report import timed

__all__ = ["arrangement_rows"]


def _designer(cfg: dict, tiling: str, tiles: int = 1) -> Designer:
    """The study's objective (DesignConfig's defaults at its cell and kernel) with the bands of the tiling."""
    return Designer(DesignConfig(cell_um=cfg["cell_um"], kernel_px=cfg["kernel_px"],
                                 pupil_samples=cfg["design_pupil_samples"], tiling=tiling, arrangement=tiles,
                                 banding_ceiling=1.0))


def _pattern_row(designer: Designer, cell: np.ndarray, pattern: np.ndarray) -> dict:
    """One pattern's PSNR, bands over the repeated T-OLED (R, G, B) and the CPU seconds of each."""
    x = torch.tensor(cell, dtype=torch.float64)
    psnr = timed(lambda: psnr_on_draws(designer, cell, [tp.arranged(pattern, designer.tiles)])[0], 1)
    with torch.no_grad():
        bands = timed(lambda: designer.ceiling.ratios(x, "final", pattern).tolist(), 1)
    return {"psnr_db": psnr.result, "bands": bands.result, "score_s": psnr.cpu_seconds[0],
            "bands_s": bands.cpu_seconds[0]}


def _turned_row(cfg: dict, designer: Designer, name: str, cell: np.ndarray, repeated_ref: torch.Tensor) -> dict:
    """The cell turned (designer: the turned tiling's): its mean PSNR over the held-out draws and its bands over the
    repeated T-OLED."""
    psnr = float(np.mean(psnr_on_draws(designer, cell, held_out_draws(designer, cfg["held_tilings"]))))
    with torch.no_grad():
        bands = designer.ceiling.bands(torch.tensor(cell, dtype=torch.float64), "final") / repeated_ref
    return {"part": "arrangement", "cell": name, "tiles": None, "psnr_db": psnr, "gap_db": 0.0,
            "bands_over_repeated": bands.tolist()}


def _tiles_row(cfg: dict, designer: Designer, name: str, cell: np.ndarray, turned_psnr: float, seed: int) -> dict:
    """K's row (designer: the arranged tiling's of K): the random patterns' figures, their mean and best PSNR, the gap
    of the mean to the turned cell."""
    k = designer.config.arrangement
    designer.objective(torch.tensor(cell, dtype=torch.float64), tp.arranged(designer.arrangement, designer.tiles))
    found = [_pattern_row(designer, cell, tp.tile_transforms(k, seed, keys=("study", "arrangement", k, p)))
             for p in range(cfg["arrangement_draws"])]  # the first call above: torch's set-up, untimed
    psnr = [f["psnr_db"] for f in found]
    score_s, bands_s = (float(np.median([f[key] for f in found])) for key in ("score_s", "bands_s"))
    return {"part": "arrangement", "cell": name, "tiles": k, "period_um": k * cfg["cell_um"],
            "psnr_db": float(np.mean(psnr)), "psnr_draws_db": psnr, "best_psnr_db": float(np.max(psnr)),
            "gap_db": float(np.mean(psnr)) - turned_psnr,
            "bands_over_repeated": np.mean([f["bands"] for f in found], axis=0).tolist(),
            "bands_draws": [f["bands"] for f in found], "cpu_s": score_s, "cpu_bands_s": bands_s,
            "sweep_cpu_s": 7 * k * k * (score_s + bands_s)}


def arrangement_rows(cfg: dict, cells: dict, seed: int, progress=None) -> list[dict]:
    """Part (h): per cell of {name: amplitudes}, its turned row, then one row per K of cfg['arrangement'], the
    patterns drawn from seed (module doc)."""
    turned_designer = _designer(cfg, "turned")
    arranged = {k: _designer(cfg, "arranged", k) for k in cfg["arrangement"]}  # made once, for every cell
    reference = _designer(cfg, "arranged", 1).ceiling
    with torch.no_grad():
        repeated_ref = reference.bands(reference.reference, "final")  # the T-OLED repeated, registered
    rows = []
    for name, cell in cells.items():
        turned = _turned_row(cfg, turned_designer, name, cell, repeated_ref)
        rows.append(turned)
        if progress:
            progress(1)
        for designer in arranged.values():
            rows.append(_tiles_row(cfg, designer, name, cell, turned["psnr_db"], seed))
            if progress:
                progress(1)
    return rows
