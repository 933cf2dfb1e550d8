"""A preset's cell tiled with a random quarter-turn per tile, exactly (issue 48's turned T-OLED).

A turned tiling has no period, so the engine rasters its window tile by tile (psf.pupil.tile_mask): each tile is the
cell's band-limited raster, turned. A micrograph gives that raster from its pixels; a preset (psf.layouts) from its
exact Fourier series, so TurnedLayout tiles the preset itself: no raster of the cell enters, and the light past the
kernel window is the preset's. A raster of intensities √I on 1 µm squares (the former route of `study
layout-trained`) keeps 0.7 points more of the T-OLED's light inside a 129-px window of 6.2 µm (1.55 / 1.76 / 2.23 %
outside at 450 / 520 / 640 nm against the preset's 2.25 / 2.47 / 2.95 %; tests/psf/test_turned.py).
The turns are MicrographLayout's for the same seed (micrograph.quarter_turns).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .layouts import LayoutError, PeriodicLayout
from .micrograph import quarter_turns

__all__ = ["TurnedLayout", "edge_framed"]


def edge_framed(layout: PeriodicLayout) -> PeriodicLayout:
    """The layout shifted along x so that its leftmost opening starts at the cell's edge x = 0 (the framing
    udc_render.design.cells.frame_cell gives a raster: its first open column at column 0)."""
    shift = -min(o.left_um for o in layout.openings)
    return replace(layout, openings=tuple(replace(o, cx_um=o.cx_um + shift) for o in layout.openings))


@dataclass(frozen=True)
class TurnedLayout:
    """base's square cell, each tile turned by a random quarter-turn drawn from seed (MicrographLayout's draw)."""
    base: PeriodicLayout
    seed: int = 0
    random_rotation: bool = True

    def __post_init__(self):
        if self.base.pitch_x_um != self.base.pitch_y_um:
            raise LayoutError(f"layout {self.base.name}: quarter-turns need a square cell, got "
                              f"{self.base.pitch_x_um} × {self.base.pitch_y_um} µm")

    @property
    def name(self) -> str:
        return self.base.name

    @property
    def period_um(self) -> tuple[float, float]:
        return self.base.period_um

    @property
    def open_fraction(self) -> float:
        return self.base.open_fraction

    @property
    def power_transmittance(self) -> float:
        return self.base.power_transmittance

    @property
    def periodic(self) -> bool:
        return not self.random_rotation

    def cell_raster(self, nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
        return self.base.cell_raster(nx, ny)

    def fourier_coefficients(self, kx: np.ndarray, ky: np.ndarray) -> np.ndarray:
        return self.base.fourier_coefficients(kx, ky)

    def tile_rotations(self, tiles_x: int, tiles_y: int) -> np.ndarray:
        """Quarter turns (0..3) for every tile (all 0 without rotation)."""
        if not self.random_rotation:
            return np.zeros((tiles_y, tiles_x), dtype=int)
        return quarter_turns(self.seed, tiles_x, tiles_y)

    def describe(self) -> dict:
        return {"kind": "turned", "base": self.base.describe(), "random_rotation": self.random_rotation,
                "seed": self.seed}
