"""UPC's PSF in a mode that follows their sampling exactly (Yang & Sankaranarayanan, ICCP 2021, their released
`utils/computePSF_3.m` and `utils/load_aperture.m`, read for facts; design/upc_layout_metric.md).

    cell     21 × 21 transmissions of δ1 = 8 µm (168 µm), grey levels kept;
    grid     M_λ = 2 ⌊λ f / (2 δ1 δ2)⌋ samples, δ2 = 0.5 µm: 1524 / 1324 / 1174 at 610 / 530 / 470 nm, f = 10 mm;
             the display tiled from the corner of the red grid (⌈M δ1 / 168 µm⌉ tiles, each plain or turned
             and mirrored: their randomRot90 draws a quarter-turn, a left-right and an up-down mirror with
             probability ½ each, i.e. the 8 elements of D4 uniformly), times a hard 4 mm disc
             (x² + y² ≤ (D/2)², x = (−M/2 … M/2−1) δ1); green and blue take the central M_G², M_B² of it;
    psf      |FFT|² without padding (output pitch λ f / (M δ1) ≈ 0.5 µm), the central 1174², a 4 × 4 box
             average (MATLAB imfilter: zero padding, rows i−1 … i+2) decimated by 4 from the first row:
             294 × 294 at ≈ 2 µm, unit sum per channel.

Torch ops throughout, so the mode is differentiable in the cell (their loss, design's option).
"""
from __future__ import annotations

import math

import numpy as np
import torch

from udc_render.design.torch_psf import DesignError, tile

__all__ = ["WAVELENGTHS_NM", "CELL_PX", "PUPIL_UM", "FOCAL_UM", "APERTURE_UM", "CROP_PX", "BOX_PX", "PSF_PX",
           "TILES", "grid_sizes", "display", "psf", "kept_fraction", "psf_and_kept"]

WAVELENGTHS_NM = (610.0, 530.0, 470.0)
CELL_PX = 21
PUPIL_UM = 8.0
OUTPUT_UM = 0.5
FOCAL_UM = 10000.0
APERTURE_UM = 4000.0
CROP_PX = 1174
BOX_PX = 4
PSF_PX = -(-CROP_PX // BOX_PX)  # 294: the decimated PSF's side


def grid_sizes(wavelengths_nm=WAVELENGTHS_NM) -> tuple[int, ...]:
    """M_λ = 2 ⌊λ f / (2 δ1 δ2)⌋ per wavelength (module doc)."""
    return tuple(2 * math.floor(lam * 1e-3 * FOCAL_UM / PUPIL_UM / OUTPUT_UM / 2) for lam in wavelengths_nm)


def tiles_for(m: int) -> int:
    """⌈M δ1 / (21 δ1)⌉ tiles per side (load_aperture's repNum)."""
    return math.ceil(m * PUPIL_UM / (CELL_PX * PUPIL_UM))


TILES = tiles_for(grid_sizes()[0])  # the display's tiles per side over the red grid, which the others are cut from


def display(cell: torch.Tensor, m: int, transforms: np.ndarray | None = None) -> torch.Tensor:
    """The display over the M × M grid: the cell tiled from the corner (each tile D4-transformed), cropped."""
    if cell.shape != (CELL_PX, CELL_PX):
        raise DesignError(f"cell: UPC's mode takes a {CELL_PX} × {CELL_PX} cell of {PUPIL_UM:g} µm, got "
                          f"{tuple(cell.shape)}")
    n = tiles_for(m)
    if transforms is None or not np.any(transforms):
        return cell.repeat(n, n)[:m, :m]
    if transforms.shape != (n, n):
        raise DesignError(f"tile transforms: expected {n} × {n}, got {transforms.shape}")
    return tile(cell, transforms)[:m, :m]


def _disc(m: int, dtype, device) -> torch.Tensor:
    x = (torch.arange(m, dtype=dtype, device=device) - m // 2) * PUPIL_UM
    return ((x[None, :] ** 2 + x[:, None] ** 2) <= (APERTURE_UM / 2) ** 2).to(dtype)


def _box_decimate(p: torch.Tensor) -> torch.Tensor:
    """imfilter(p, ones(4)/16) (zero padding, rows i−1 … i+2) then p(1:4:end, 1:4:end)."""
    padded = torch.nn.functional.pad(p, (1, 2, 1, 2))
    c = padded.cumsum(0).cumsum(1)
    c = torch.nn.functional.pad(c, (1, 0, 1, 0))
    s = c[BOX_PX:, BOX_PX:] - c[:-BOX_PX, BOX_PX:] - c[BOX_PX:, :-BOX_PX] + c[:-BOX_PX, :-BOX_PX]
    return (s / BOX_PX ** 2)[::BOX_PX, ::BOX_PX]


def _powers(cell: torch.Tensor, transforms: np.ndarray | None, channels=(0, 1, 2)):
    """Per wavelength (those of channels, indices into R, G, B): (the power |FFT|² over the M × M grid, its central
    CROP_PX² crop)."""
    sizes = grid_sizes()
    m0 = sizes[0]
    field = display(cell, m0, transforms) * _disc(m0, cell.dtype, cell.device)
    for m in (sizes[c] for c in channels):
        a = (m0 - m) // 2
        p = torch.fft.fftshift(torch.fft.fft2(field[a:a + m, a:a + m])).abs() ** 2
        b = (m - CROP_PX) // 2
        yield p, p[b:b + CROP_PX, b:b + CROP_PX]


def psf_and_kept(cell: torch.Tensor, transforms: np.ndarray | None = None, channels=(0, 1, 2)
                 ) -> tuple[torch.Tensor, torch.Tensor]:
    """(psf, kept_fraction) from one pass of the FFTs, of the channels given (indices into R, G, B)."""
    out, kept = [], []
    for whole, crop in _powers(cell, transforms, channels):
        p = _box_decimate(crop)
        out.append(p / p.sum())
        kept.append(crop.sum() / whole.sum())
    return torch.stack(out), torch.stack(kept)


def psf(cell: torch.Tensor, transforms: np.ndarray | None = None) -> torch.Tensor:
    """[3, 294, 294] unit-sum PSFs at 610 / 530 / 470 nm of a 21 × 21 cell (module doc)."""
    return psf_and_kept(cell, transforms)[0]


def kept_fraction(cell: torch.Tensor, transforms: np.ndarray | None = None) -> torch.Tensor:
    """[3] the share of each wavelength's power inside the 1174² crop. The PSF is normalised after the crop, so its
    MTF at every frequency ≠ 0 is the uncropped one's over this share (a PSF's light thrown past the crop raises
    UPC's statistic). At 470 nm the crop is the whole grid (M = 1174): the share is 1."""
    return psf_and_kept(cell, transforms)[1]
