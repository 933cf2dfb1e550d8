"""The design search's cells besides its swaps (udc_render.design.optimise): where it starts (a random scatter, the
T-OLED on the squares, a former design's cell); the kicks of its iterated local search are
udc_render.design.symmetry.kicked_orbits."""
from __future__ import annotations

import numpy as np

from udc_render.design import torch_psf as tp
from udc_render.design.cells import frame_cell, read_cell
from udc_render.design.config import DesignConfig
from udc_render.design.symmetry import symmetric_scatter
from udc_render.streams import stream

__all__ = ["scatter", "toled_cell", "initial_cell"]


def scatter(config: DesignConfig, *keys) -> np.ndarray:
    """A random binary cell of config.open_squares open squares, from stream(seed, 'design', *keys)."""
    c = config.cell_px
    flat = np.zeros(c * c)
    flat[stream(config.seed, "design", *keys).permutation(c * c)[: config.open_squares]] = 1.0
    return flat.reshape(c, c)


def toled_cell(config: DesignConfig) -> np.ndarray:
    """The preset T-OLED (psf.layouts.toled) in the config's cell at its open area, on the feature squares: the
    config.open_squares squares of the largest area-weighted amplitude (ties in raster order), its slit moved to
    the tile's edge (cells.frame_cell: the framing that reproduces UPC's turned T-OLED)."""
    from psf import layouts
    raster = tp.preset_cell(layouts.toled(pitch_um=config.cell_um, open_fraction=config.open_fraction),
                            config.cell_px)
    flat = np.zeros(raster.size)
    flat[np.argsort(-raster.ravel(), kind="stable")[: config.open_squares]] = 1.0
    return frame_cell(flat.reshape(raster.shape), "edge")


def initial_cell(config: DesignConfig) -> np.ndarray:
    """The search's start by config.init: a random scatter (stream 'design', 'init'; with symmetry c2 a random
    point-symmetric one), the T-OLED (toled_cell), or a cell PNG (cells.read_cell: a former design's cell.png)."""
    if config.init == "toled":
        return toled_cell(config)
    if config.init == "scatter" and config.symmetry == "c2":
        return symmetric_scatter(config.cell_px, config.open_squares, stream(config.seed, "design", "init", "c2"))
    return scatter(config, "init") if config.init == "scatter" else read_cell(config.init, config.cell_px,
                                                                               config.open_squares)
