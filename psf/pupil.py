"""Pupil-plane sampling: the grid, the display mask raster on it, and the aperture crop.

The grid is commensurate with the display period (δx = pitch_x / n, window = whole periods), so
the mask raster is exactly periodic over the window: FFT propagation and phase-ramp shifts are
then exact for the infinite periodic display, with no padding. A bare lens gets δ = D / N.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .lens import Lens

__all__ = ["MASK_RASTERS", "PupilGrid", "aperture_slices", "lens_grid", "display_grid", "cell_raster", "tile_mask"]


@dataclass(frozen=True)
class PupilGrid:
    """A rectilinear window of nx × ny cells of dx_um × dy_um, from (x0_um, y0_um)."""
    nx: int
    ny: int
    dx_um: float
    dy_um: float
    x0_um: float
    y0_um: float

    @property
    def x_edges_um(self) -> np.ndarray:
        return self.x0_um + self.dx_um * np.arange(self.nx + 1)

    @property
    def y_edges_um(self) -> np.ndarray:
        return self.y0_um + self.dy_um * np.arange(self.ny + 1)

    @property
    def x_um(self) -> np.ndarray:
        return self.x0_um + self.dx_um * (np.arange(self.nx) + 0.5)

    @property
    def y_um(self) -> np.ndarray:
        return self.y0_um + self.dy_um * (np.arange(self.ny) + 0.5)

    def crop(self, sy: slice, sx: slice) -> "PupilGrid":
        return PupilGrid(sx.stop - sx.start, sy.stop - sy.start, self.dx_um, self.dy_um,
                         self.x0_um + sx.start * self.dx_um, self.y0_um + sy.start * self.dy_um)


def aperture_slices(grid: PupilGrid, diameter_um: float) -> tuple[slice, slice]:
    """Index ranges of the window cells that the aperture disc touches."""
    r = diameter_um / 2

    def rng(edges):
        idx = np.nonzero((edges[1:] > -r) & (edges[:-1] < r))[0]
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return rng(grid.y_edges_um), rng(grid.x_edges_um)


def lens_grid(lens: Lens, pupil_samples: int) -> PupilGrid:
    """Window for a bare lens: δ = D / N, one guard cell on each side, centred on the axis."""
    d = lens.aperture_um / pupil_samples
    n = pupil_samples + 2
    return PupilGrid(n, n, d, d, -n * d / 2, -n * d / 2)


def _odd_up(v: int) -> int:
    """v if odd, else v + 1."""
    return v + 1 - v % 2


def display_grid(period_um: tuple[float, float], lens: Lens, pupil_samples: int,
                 margin_um: float = 0.0) -> tuple[PupilGrid, tuple[int, int], tuple[int, int]]:
    """Window of whole display periods covering the aperture (+ margin) on each side of the axis.

    Returns the grid, the samples per period (nx, ny) and the number of tiles (tx, ty).
    δ = pitch / n with n the smallest odd integer giving δ ≤ D / pupil_samples (odd n: the
    band-limited raster has no ambiguous Nyquist order and stays real).
    """
    px, py = period_um
    target = lens.aperture_um / pupil_samples
    nx, ny = (_odd_up(max(3, math.ceil(p / target))) for p in (px, py))
    half = lens.aperture_um / 2 + margin_um
    mx, my = math.ceil(half / px), math.ceil(half / py)
    grid = PupilGrid(2 * mx * nx, 2 * my * ny, px / nx, py / ny, -mx * px, -my * py)
    return grid, (nx, ny), (2 * mx, 2 * my)


MASK_RASTERS = ("band_limited", "area")


def cell_raster(layout, nx: int, ny: int, mask_raster: str) -> tuple[np.ndarray, float]:
    """One period of the amplitude on nx × ny cell-centred samples, and its exact mean intensity.

    'band_limited': the layout's exact Fourier series truncated to the grid's band (ideal
    low-pass: the raster's spectrum equals the true one for |ν| < 1/2δ, nothing aliases in).
    'area': exact area-weighted averages (box filter: spectrum × sinc(δν), high orders alias).
    """
    mean_intensity = layout.power_transmittance
    if mask_raster == "area":
        amp, _ = layout.cell_raster(nx, ny)
        return amp, mean_intensity
    kx = np.rint(np.fft.fftfreq(nx, 1 / nx)).astype(int)
    ky = np.rint(np.fft.fftfreq(ny, 1 / ny)).astype(int)
    c = layout.fourier_coefficients(kx, ky) * np.exp(1j * np.pi * (kx[None, :] / nx + ky[:, None] / ny))
    amp = np.fft.ifft2(c) * (nx * ny)
    if np.abs(amp.imag).max() <= 1e-9 * max(np.abs(amp).max(), 1.0):  # odd n, Hermitian c: real mask
        amp = amp.real
    return amp, mean_intensity


def tile_mask(layout, cell_n: tuple[int, int], tiles: tuple[int, int], mask_raster: str = "band_limited"
              ) -> tuple[np.ndarray, float]:
    """Amplitude raster over the window, and κ = exact mean intensity / mean |raster|².

    κ ≥ 1 restores the power that the raster cannot carry (orders beyond its band or lost to box
    filtering): that light leaves at angles outside the alias-free field, so the transmitted power
    and hence energy_outside are exact (docs/PHYSICS.md §6: zero-order energy = open fraction).
    """
    nx, ny = cell_n
    amp, mean_intensity = cell_raster(layout, nx, ny, mask_raster)
    power = float(np.mean(np.abs(amp) ** 2))
    if power <= 0.0 or mean_intensity <= 0.0:
        raise ValueError(f"display {layout.name}: the mask is fully opaque; nothing is transmitted")
    kappa = mean_intensity / power
    tx, ty = tiles
    rot = layout.tile_rotations(tx, ty) if hasattr(layout, "tile_rotations") else None
    if rot is None or not rot.any():
        return np.tile(amp, (ty, tx)), kappa
    variants = [np.rot90(np.fliplr(amp) if k >= 4 else amp, k % 4) for k in range(8)]  # quarter_turns' D4 numbering
    rows = [np.concatenate([variants[k] for k in rot[j]], axis=1) for j in range(ty)]
    return np.concatenate(rows, axis=0), kappa
