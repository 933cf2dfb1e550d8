"""A layout's cell as the designer and the layout study take it: a preset's or a micrograph's amplitude cell, framed
(the tile D4 turns), resampled to UPC's 21 × 21 (udc_render.design.upc), and UPC's ring count."""
from __future__ import annotations

import imageio.v3 as iio
import numpy as np

from psf.micrograph import MicrographLayout
from udc_render.design import torch_psf as tp, upc

RINGS = 147  # k = 0 … 146, UPC's
EXACT_MAX_PX = 4096  # reference_cell's largest raster side (the T-OLED at 168 µm and 20 %: 2520, edges on 1/15 µm)
SIMULATOR_TILE_SEED = 0  # the tile seed of study layout-trained's @turned (the engine's quarter-turns per tile)


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


def reference_cell(layout) -> tuple[np.ndarray, float]:
    """(amplitude cell [c, c], its pixel in µm): a preset on the coarsest raster that puts every edge of its openings on
    the grid, binary, so that the raster is the preset exactly (its Fourier series, as psf.turned tiles it for the
    simulator); c a multiple of the pitch in µm up to EXACT_MAX_PX. A preset with no such raster (curved or irrational
    edges) gets the finest of them, area-weighted: grey edges of ≤ 1/24 µm (the T-OLED's rasters converge to it as the
    square: 0.02 dB above the exact one at 1/8 µm in the veil objective, docs/guides/design.md)."""
    pitch = layout.pitch_x_um
    sizes = range(round(pitch), EXACT_MAX_PX + 1, max(1, round(pitch)))
    for c in sizes:
        amp = tp.preset_cell(layout, c)
        if np.all((amp < 1e-9) | (amp > 1 - 1e-9)):
            return np.round(amp), pitch / c
    return amp, pitch / sizes[-1]


def frame_cell(cell: np.ndarray, frame: str = "as_given") -> np.ndarray:
    """The cell as given, or ('edge') rolled so that its first open column is column 0: the framing of the tile
    that D4 turns about its centre, which reproduces UPC's turned T-OLED (docs/guides/design.md)."""
    if frame == "as_given":
        return cell
    return np.roll(cell, -int(np.argmax(cell.sum(axis=0) > 1e-9 * cell.sum())), axis=1)


def upc_cell(cell: np.ndarray) -> np.ndarray:
    """The cell resampled (exact area weighting of its squares) to UPC's 21 × 21."""
    w = resample_matrix(cell.shape[0])
    return w @ cell @ w.T


def toled_reference(cell_um: float, open_fraction: float, px: int = upc.CELL_PX) -> np.ndarray:
    """The preset T-OLED at the open area in a cell_um cell, its slit at the tile's edge, on px × px squares (UPC's
    21 × 21 by default): the reference of the design's UPC ratios (job.upc_comparison, floor.UpcFloor) and of its
    banding (bands.BandingCeiling)."""
    from psf import layouts
    toled, _ = layout_cell(layouts.toled(pitch_um=cell_um, open_fraction=open_fraction))
    w = resample_matrix(toled.shape[0], px)
    return w @ frame_cell(toled, "edge") @ w.T


def resample_matrix(c: int, px: int = upc.CELL_PX) -> np.ndarray:
    """[px, c] W with W cell Wᵀ the cell on px × px squares (exact area weighting; upc_cell's at px = 21)."""
    edges_in, edges_out = np.linspace(0, 1, c + 1), np.linspace(0, 1, px + 1)
    return np.clip(np.minimum(edges_out[1:, None], edges_in[None, 1:])
                   - np.maximum(edges_out[:-1, None], edges_in[None, :-1]), 0, None) * px


def read_cell(path: str, cell_px: int, open_squares: int) -> np.ndarray:
    """A binary cell from a PNG, 0 (opaque) or 255 (open): a former design's cell.png as the search's start (design
    --init PATH), of cell_px² pixels, or of a coarser design's squares (a side that divides cell_px: each square
    split into k × k), with open_squares open."""
    try:
        image = np.asarray(iio.imread(path))
    except (OSError, ValueError) as err:
        raise tp.DesignError(f"--init {path}: not scatter or toled, and not a readable cell PNG ({err})") from None
    side = image.shape[0] if image.ndim == 2 and image.shape[0] == image.shape[1] else 0
    if not (side and cell_px % side == 0 and np.isin(image, (0, 255)).all()):
        raise tp.DesignError(f"--init {path}: expected a square grey PNG of 0 and 255 (a design's cell.png) of "
                             f"{cell_px} px or a side that divides it, got shape {image.shape}")
    cell = np.kron((image == 255).astype(np.float64), np.ones((cell_px // side,) * 2))
    if int(cell.sum()) != open_squares:
        raise tp.DesignError(f"--init {path}: {int(cell.sum())} open squares on the {cell_px}² cell; the open area "
                             f"needs {open_squares}")
    return cell
