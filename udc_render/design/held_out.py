"""The design's objective over many held-out D4 tilings, paired with the T-OLED the simulator takes (issue 48).

A turned tiling's kernels are one random draw of quarter-turns and flips, so one draw's objective J is a sample:
over 16 draws the committed designs' J spreads by 0.02–0.04 dB (sd; `study held-out`), and the search fits the one
draw it lowers (by 0.016 dB on the default objective: `study design` part g). `design.json`'s "final" is one
held-out draw; this module scores n more (stream keys 'design', 'held_out', k), the same draws for every cell, and
pairs each cell with two T-OLEDs:
- 'toled_squares': the preset T-OLED on the design's feature squares (`--init toled`, starts.toled_cell), the
  search's start and its former reference;
- 'toled_preset': the preset T-OLED exactly (cells.reference_cell: a binary raster with its edges on the grid, 2520²
  squares at 168 µm and 20 %), slit at the tile's edge, at its own transmission: the T-OLED `study layout-trained`
  compares with (toled168_20.toml@edge@turned, which the simulator tiles from the preset's Fourier series:
  psf.turned). Before, the simulator took a raster of the preset's intensities on 1 µm squares (amplitudes √I) and
  this reference an amplitude raster on ≈ 2 µm squares: both score about 0.2 dB above the exact T-OLED (their grey
  edges keep light inside the kernel window; docs/guides/design.md);
- with simulator=True (`study held-out`), one more group, 'engine': the simulator's own tiling (the engine's
  quarter-turns for SIMULATOR_TILE_SEED).
The paired difference per draw (cell − T-OLED, dB) has a far smaller spread than either (the draws are shared), so
its mean and standard error say whether a design leads in expectation.
"""
from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np
import torch

from psf import layouts
from psf.micrograph import quarter_turns
from udc_render.design import torch_psf as tp
from udc_render.design.cells import SIMULATOR_TILE_SEED, frame_cell, reference_cell
from udc_render.design.config import DesignConfig
from udc_render.design.optimise import Designer
from udc_render.design.starts import toled_cell

__all__ = ["HELD_OUT_TILINGS", "applies", "held_out_draws", "engine_draw", "objective_on_draws", "psnr_on_draws",
           "preset_toled", "held_out_comparison"]

HELD_OUT_TILINGS = 16  # the paired difference's se ≈ 0.025 dB / √n: 0.006 dB at 16 (committed veil designs)


def held_out_draws(designer: Designer, n: int, flips: bool = True) -> list[np.ndarray]:
    """n tilings of the designer's tiles (stream keys 'design', 'held_out', k): neither the search's nor 'final';
    flips: the 8 D4 elements (the search's), else the 4 quarter-turns (the engine's tile_rotation)."""
    return [tp.tile_transforms(designer.tiles, designer.config.seed, flips, keys=("design", "held_out", k))
            for k in range(n)]


def engine_draw(designer: Designer) -> np.ndarray:
    """The simulator's own tiling of the designer's tiles: the engine's quarter-turns per tile for
    SIMULATOR_TILE_SEED (psf.micrograph.quarter_turns: a micrograph's and a turned preset's, which torch_psf's
    tests match), mirrored too for a point-symmetric design (its design_turned.toml's tile_flip)."""
    return quarter_turns(SIMULATOR_TILE_SEED, designer.tiles, designer.tiles, flips=designer.config.tile_flips)


def _scoring(config: DesignConfig, pixel_um: float) -> DesignConfig:
    """The design's objective settings at a reference cell's pixel, no search options."""
    return replace(config, feature_um=pixel_um, init="scatter", upc_floor=None, banding_ceiling=None, kicks=0,
                   search_tilings=1, scatters=1, reference=True)


@lru_cache(maxsize=4)
def _framed_toled(cell_um: float, open_fraction: float) -> tuple[np.ndarray, float]:
    """(the preset T-OLED's reference cell, slit at the tile's edge, read-only; its pixel in µm), made once per cell
    and open area (reference_cell rasters up to 2520² squares: a second a call; the studies ask for it per row)."""
    raster, pixel_um = reference_cell(layouts.toled(pitch_um=cell_um, open_fraction=open_fraction))
    framed = frame_cell(raster, "edge")
    framed.flags.writeable = False
    return framed, pixel_um


def preset_toled(config: DesignConfig) -> tuple[np.ndarray, DesignConfig]:
    """(the preset T-OLED's exact binary cell, slit at the tile's edge; the config that scores it)."""
    cell, pixel_um = _framed_toled(config.cell_um, config.open_fraction)
    return cell, _scoring(config, pixel_um)


def applies(config: DesignConfig) -> bool:
    """Whether the comparison takes the config: the rig's objectives 'wiener' and 'crop' on a turned or an arranged
    tiling (an arranged design scored on its one tiling against the T-OLEDs' draws)."""
    return config.optics == "rig" and config.objective in ("wiener", "crop") and config.tiling in ("turned",
                                                                                                  "arranged")


def objective_on_draws(designer: Designer, cell: np.ndarray, draws: list, transmission: float | None = None
                       ) -> list[float]:
    """The float64 objective J of a cell on each draw (Designer.objective; transmission: a grey cell's own)."""
    x = torch.tensor(cell, dtype=torch.float64, device=designer.device)
    with torch.no_grad():
        return [float(designer.objective(x, t, transmission)) for t in draws]


def psnr_on_draws(designer: Designer, cell: np.ndarray, draws: list, transmission: float | None = None
                  ) -> list[float]:
    """−10 log10 J of the cell on each draw (objective_on_draws), dB."""
    return [float(-10 * np.log10(j)) for j in objective_on_draws(designer, cell, draws, transmission)]


def _paired(a: list[float], b: list[float]) -> dict:
    d = np.subtract(a, b)
    se = float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else 0.0
    return {"mean": float(d.mean()), "se": se, "leads": int((d > 0).sum()), "n": len(d)}


def _compare(designer: Designer, cells: dict, references: dict, draws: list, progress) -> dict:
    """Every cell and reference T-OLED ({name: (grey cell, its scorer)}) on the draws, paired."""
    psnr, n = {}, len(draws)
    own = designer.transforms("final") if designer.config.tiling == "arranged" else None
    for name, c in cells.items():
        psnr[name] = psnr_on_draws(designer, c, draws) if own is None else psnr_on_draws(designer, c, [own]) * n
        progress(1)
    psnr["toled_squares"] = psnr_on_draws(designer, toled_cell(designer.config), draws)
    progress(1)
    for name, (cell, scorer) in references.items():
        psnr[name] = psnr_on_draws(scorer, cell, draws, float(np.mean(cell ** 2)))
        progress(1)
    refs = ("toled_squares", *references)
    return {"psnr_db": psnr, "mean": {k: float(np.mean(v)) for k, v in psnr.items()},
            "sd": {k: float(np.std(v, ddof=1)) if n > 1 else 0.0 for k, v in psnr.items()},
            "vs": {name: {ref: _paired(psnr[name], psnr[ref]) for ref in refs} for name in cells}}


def held_out_comparison(designer: Designer, cells: dict[str, np.ndarray], n: int = HELD_OUT_TILINGS,
                        progress=lambda k: None, simulator: bool = False) -> dict:
    """The objective as a PSNR (dB) of each named cell of the designer's squares and of the two T-OLEDs (module
    doc) on n held-out draws, of the 8 D4 elements (the search's, 'd4') and of the 4 quarter-turns (the engine's,
    'quarter_turns'): per draw, mean and sd, and each cell's paired difference to each T-OLED (mean, se, the draws
    it leads); with simulator, also on the simulator's own tiling ('engine', one draw). Takes the rig's objectives
    'wiener' and 'crop' on a turned tiling, or an arranged one (its cells on their one tiling, the same figure
    beside every draw: the difference's spread is the T-OLEDs'); progress(1) after each cell's draws."""
    config = designer.config
    if not applies(config):
        raise ValueError("held_out_comparison: takes --objective wiener or crop, --optics rig, --tiling turned or "
                         "arranged")
    cell, scoring = preset_toled(config)
    references = {"toled_preset": (cell, Designer(scoring, designer.sensor, designer.device))}
    out = {"n": n, "keys": ["design", "held_out", "k"], "toled_preset_transmission": float(np.mean(cell ** 2))}
    groups = {"d4": held_out_draws(designer, n, True), "quarter_turns": held_out_draws(designer, n, False)}
    if simulator:
        groups["engine"] = [engine_draw(designer)]
    for group, draws in groups.items():
        out[group] = _compare(designer, cells, references, draws, progress)
    return out
