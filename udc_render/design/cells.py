"""A layout's cell as the designer and the layout study take it: a preset's or a micrograph's amplitude cell, framed
(the tile D4 turns), resampled to UPC's 21 × 21 (udc_render.design.upc), and UPC's ring count."""
from __future__ import annotations

import numpy as np

from psf.micrograph import MicrographLayout
from udc_render.design import torch_psf as tp, upc

RINGS = 147  # k = 0 … 146, UPC's


def _cell_px(period_um: float, pixel_um: float) -> int:
    return max(3, int(round(period_um / pixel_um)))


def layout_cell(layout, pixel_um: float = 2.0) -> tuple[np.ndarray, float]:
    """(amplitude cell [c, c], its pixel in µm): a micrograph's own image, a preset's exact area-weighted raster
    on ≈ pixel_um squares (psf.layouts.PeriodicLayout.cell_raster)."""
    if isinstance(layout, MicrographLayout):
        h, w = layout.image.shape
        if h != w:
            raise tp.DesignError(f"micrograph {layout.path}: the layout study needs a square tile, got {w} × {h} px")
        return np.asarray(layout.image, np.float64), layout.pixel_um
    c = _cell_px(layout.pitch_x_um, pixel_um)
    return tp.preset_cell(layout, c), layout.pitch_x_um / c


def frame_cell(cell: np.ndarray, frame: str = "as_given") -> np.ndarray:
    """The cell as given, or ('edge') rolled so that its first open column is column 0: the framing of the tile
    that D4 turns about its centre, which reproduces UPC's turned T-OLED (docs/guides/design.md)."""
    if frame == "as_given":
        return cell
    return np.roll(cell, -int(np.argmax(cell.sum(axis=0) > 1e-9 * cell.sum())), axis=1)


def upc_cell(cell: np.ndarray) -> np.ndarray:
    """The cell resampled (exact area weighting of its squares) to UPC's 21 × 21."""
    c = cell.shape[0]
    edges_in, edges_out = np.linspace(0, 1, c + 1), np.linspace(0, 1, upc.CELL_PX + 1)
    w = np.clip(np.minimum(edges_out[1:, None], edges_in[None, 1:])
                - np.maximum(edges_out[:-1, None], edges_in[None, :-1]), 0, None) * upc.CELL_PX
    return w @ cell @ w.T
