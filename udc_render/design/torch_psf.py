"""A differentiable PSF in torch of a free-form display cell, at the engine's exact sampling (psf.engine).

The cell is a c × c image of amplitude transmissions of c_pixel_um squares (a micrograph, psf.MicrographLayout),
tiled plainly or with each tile turned by a quarter-turn and optionally mirrored (the dihedral group D4:
transform t = 0…7 is np.rot90(·, t % 4) of the cell, mirrored left-right first when t ≥ 4). What the engine
does at d = 0, in focus, with its default band-limited raster, and so does this module:

    raster   amp = B a Bᵀ, B[j, m] = (1/c) Σ_k sinc(k/c) cos(2πk((j+½)/n − (m+½)/c)), k = −(n−1)/2…(n−1)/2:
             the cell's exact Fourier series truncated to the pupil grid's band (psf.pupil.cell_raster),
             n odd samples per period (psf.pupil.display_grid);
    pupil    g = tiled raster over the aperture crop × the area-weighted disc (psf.pupil.aperture_slices);
    lags     R = ifft2(|FFT(g, 2n)|²), the autocorrelation (the OTF);
    kernel   K(v, u) = Σ_Δ R(Δ) sinc(ρΔyδ/λz) sinc(ρΔxδ/λz) cos(2π(Δy δ v + Δx δ u)/λz): exact pixel integration
             on the sensor grid (psf.fourier.PixelMFT), normalised to unit sum in the window.

Everything is a torch op on the cell, so gradients flow to it (CPU or GPU, float32 or float64).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from psf.lens import Lens
from psf.plan import auto_pupil_samples
from psf.pupil import aperture_slices, display_grid
from udc_render.errors import UdcError
from udc_render.streams import stream

__all__ = ["DesignError", "CellGrid", "cell_grid", "raster_matrix", "tile_transforms", "arranged", "tiled_mask",
           "kernels", "kernels_and_window", "channel_sum", "packed", "preset_cell", "transform_tile", "tile"]


class DesignError(UdcError):
    """A bad layout-design request (one line naming the value and what is allowed)."""


@dataclass(frozen=True)
class CellGrid:
    """The engine's pupil sampling of a square cell: n samples per period (odd), tiles × tiles periods over the
    window, the aperture crop (rows, cols) and its area-weighted disc, the sensor grid, the wavelengths."""
    cell_px: int
    cell_pixel_um: float
    n: int
    tiles: int
    rows: slice
    cols: slice
    aperture: np.ndarray
    step_um: float
    wavelengths_nm: tuple
    pixel_um: float
    size_px: int
    image_distance_um: float

    @property
    def period_um(self) -> float:
        return self.cell_px * self.cell_pixel_um


def cell_grid(cell_px: int, cell_pixel_um: float, lens: Lens | None = None, wavelengths_nm=(450.0, 520.0, 640.0),
              pixel_um: float = 3.1, size_px: int = 255, pupil_samples: int | None = None) -> CellGrid:
    """The sampling psf.compute_kernels chooses for a square cell of cell_px × cell_pixel_um (d = 0)."""
    lens = lens or Lens()
    if lens.focus_distance_mm != lens.object_distance_mm or lens.zernike_waves:
        raise DesignError("lens: the torch PSF is in focus and unaberrated; got a defocus or Zernike terms")
    if not (isinstance(cell_px, int) and cell_px >= 1 and cell_pixel_um > 0):
        raise DesignError(f"cell: expected ≥ 1 pixels of > 0 µm, got {cell_px} of {cell_pixel_um} µm")
    wl = tuple(float(v) for v in np.atleast_1d(wavelengths_nm))
    n_pupil = pupil_samples or auto_pupil_samples(lens, min(wl), pixel_um, size_px)
    period = cell_px * cell_pixel_um
    grid, (n, _), (tiles, _) = display_grid((period, period), lens, n_pupil)
    rows, cols = aperture_slices(grid, lens.aperture_um)
    pg = grid.crop(rows, cols)
    return CellGrid(cell_px, float(cell_pixel_um), n, tiles, rows, cols,
                    lens.aperture_area_fraction(pg.x_edges_um, pg.y_edges_um), grid.dx_um, wl, float(pixel_um),
                    int(size_px), lens.image_distance_um)


def raster_matrix(n: int, c: int) -> np.ndarray:
    """B [n, c]: the band-limited raster of c constant pixels on n cell-centred samples (module doc; n odd)."""
    k = np.arange(n) - (n - 1) // 2
    phase = (np.arange(n)[:, None, None] + 0.5) / n - (np.arange(c)[None, :, None] + 0.5) / c
    return (np.sinc(k / c) * np.cos(2 * np.pi * k * phase)).sum(axis=-1) / c


def tile_transforms(tiles: int, seed: int | None, flips: bool = True, keys: tuple = ()) -> np.ndarray:
    """[tiles, tiles] D4 transforms (module doc): zeros for a plain tiling (seed None), else uniform over the
    8 (flips) or the 4 quarter-turns, from udc_render.streams.stream(seed, 'layout', 'tiles', *keys)."""
    if seed is None:
        return np.zeros((tiles, tiles), dtype=int)
    return stream(seed, "layout", "tiles", *keys).integers(0, 8 if flips else 4, size=(tiles, tiles))


def arranged(arrangement: np.ndarray, tiles: int) -> np.ndarray:
    """[tiles, tiles] D4 transforms of an arranged tiling: the K × K arrangement repeated (periodic, K tiles a
    period), from the window's first tile."""
    reps = -(-tiles // arrangement.shape[0])
    return np.tile(np.asarray(arrangement, int), (reps, reps))[:tiles, :tiles]


def transform_tile(t: torch.Tensor, k: int) -> torch.Tensor:
    """D4 element k of a square tile: np.rot90(·, k % 4), mirrored left-right first when k ≥ 4."""
    return torch.rot90(torch.flip(t, (1,)) if k >= 4 else t, k % 4, (0, 1))


def tiled_mask(cell: torch.Tensor, grid: CellGrid, transforms: np.ndarray | None = None) -> torch.Tensor:
    """The amplitude over the aperture crop: the cell's raster tiled (each tile transformed), cropped."""
    b = torch.as_tensor(raster_matrix(grid.n, grid.cell_px), dtype=cell.dtype, device=cell.device)
    amp = b @ cell @ b.T
    plain = transforms is None or not np.any(transforms)
    mask = amp.repeat(grid.tiles, grid.tiles) if plain else tile(amp, transforms)
    return mask[grid.rows, grid.cols]


def tile(t: torch.Tensor, transforms: np.ndarray) -> torch.Tensor:
    """The square tile t [n, n] tiled as transforms [R, C] (D4 elements, transform_tile): [R n, C n], one gather."""
    variants = torch.stack([transform_tile(t, k) for k in range(8)])
    rows, cols = transforms.shape
    n = t.shape[0]
    picked = variants[torch.as_tensor(transforms, device=t.device).reshape(-1)].reshape(rows, cols, n, n)
    return picked.permute(0, 2, 1, 3).reshape(rows * n, cols * n)


def _mft_matrices(grid: CellGrid, lags: int, lam_um: float, dtype, device) -> tuple[torch.Tensor, torch.Tensor]:
    """cos and sin of 2π Δ δ u / λz × the pixel's sinc(ρΔδ/λz), [S, 2 lags − 1], Δ = −(lags−1)…(lags−1)."""
    scale = lam_um * grid.image_distance_um
    d = np.arange(-(lags - 1), lags) * grid.step_um
    u = (np.arange(grid.size_px) - grid.size_px // 2) * grid.pixel_um
    theta = 2 * np.pi * np.outer(u, d) / scale
    w = np.sinc(grid.pixel_um * d / scale)
    return (torch.as_tensor(np.cos(theta) * w, dtype=dtype, device=device),
            torch.as_tensor(np.sin(theta) * w, dtype=dtype, device=device))


def kernels(cell: torch.Tensor, grid: CellGrid, transforms: np.ndarray | None = None) -> torch.Tensor:
    """[K, S, S] unit-sum kernels at grid.wavelengths_nm of the cell's amplitudes [c, c] (module doc)."""
    return kernels_and_window(cell, grid, transforms)[0]


def kernels_and_window(cell: torch.Tensor, grid: CellGrid, transforms: np.ndarray | None = None
                       ) -> tuple[torch.Tensor, torch.Tensor]:
    """(the unit-sum kernels [K, S, S], the fraction [K] of the transmitted power inside the window: the
    engine's 1 − energy_outside). Window power (ρ/λz)² δ⁴ Σ_j K_j over the transmitted power κ δ² Σ |m|² A (mask m, the
    aperture's area fraction A: the engine's raster sum, psf.engine._wavelength), κ the cell's mean |a|² over its
    raster's (psf.pupil.tile_mask: the power the band-limited raster cannot carry)."""
    if cell.shape != (grid.cell_px, grid.cell_px):
        raise DesignError(f"cell: expected shape {(grid.cell_px, grid.cell_px)}, got {tuple(cell.shape)}")
    aperture = torch.as_tensor(grid.aperture, dtype=cell.dtype, device=cell.device)
    mask = tiled_mask(cell, grid, transforms)
    g = mask * aperture
    ny, nx = g.shape
    power = torch.fft.fft2(g, s=(2 * ny, 2 * nx)).abs() ** 2
    r = torch.fft.ifft2(power).real  # lag Δ at index Δ mod 2n
    r = torch.roll(r, (ny - 1, nx - 1), (0, 1))[: 2 * ny - 1, : 2 * nx - 1]
    b = torch.as_tensor(raster_matrix(grid.n, grid.cell_px), dtype=cell.dtype, device=cell.device)
    kappa = (cell ** 2).mean() / ((b @ cell @ b.T) ** 2).mean()
    out, inside = [], []
    for lam_nm in grid.wavelengths_nm:
        cy, sy = _mft_matrices(grid, ny, lam_nm * 1e-3, cell.dtype, cell.device)
        cx, sx = (cy, sy) if nx == ny else _mft_matrices(grid, nx, lam_nm * 1e-3, cell.dtype, cell.device)
        k = cy @ r @ cx.T - sy @ r @ sx.T
        scale = (grid.pixel_um * grid.step_um / (lam_nm * 1e-3 * grid.image_distance_um)) ** 2
        inside.append(k.sum() * scale / (kappa * (mask ** 2 * aperture).sum()))
        out.append(k / k.sum())
    return torch.stack(out), torch.stack(inside)


def preset_cell(layout, cell_px: int) -> np.ndarray:
    """A preset layout (psf.layouts) as a free-form cell: its exact area-weighted amplitude on cell_px² squares
    (the layout must be square)."""
    if layout.pitch_x_um != layout.pitch_y_um:
        raise DesignError(f"layout {layout.name}: a cell must be square, got {layout.pitch_x_um} × "
                          f"{layout.pitch_y_um} µm")
    return layout.cell_raster(cell_px, cell_px)[0]


def channel_sum(kernels: torch.Tensor, inside: torch.Tensor, weights: torch.Tensor
                ) -> tuple[torch.Tensor, torch.Tensor]:
    """psf.spectral.combine for a cell (its transmittance the same at every λ): the channel kernels
    Σ_k w_ck f_k k_k / Σ_k w_ck f_k and shares inside Σ_k w_ck f_k / Σ_k w_ck, from kernels [K, S, S], shares f [K]
    and weights w [C, K] (S_c(λ) E(λ) δλ: psf.spectral.channel_weights)."""
    ww = weights.to(kernels.dtype) * inside[None, :]
    total = ww.sum(dim=1)
    return torch.einsum("ck,kij->cij", ww, kernels) / total[:, None, None], total / weights.to(total.dtype).sum(dim=1)



def packed(kernels: torch.Tensor) -> torch.Tensor:
    """[..., k, k] unit-sum kernels at a Bayer camera's packed planes of [..., S, S] at the sensor pitch (S odd,
    centre c = S // 2, k = 2 (c // 2) + 1): the kernel DeP deconvolves with (udc_render.description.packed_window,
    restore.known.packed_from_sensor),
        k[i, j] ∝ Σ_{a, b ∈ {−1, 0, 1}} h(a) h(b) K[c + 2i + a, c + 2j + b],  h = (½, 1, ½)."""
    p = torch.nn.functional.pad(kernels, (1, 1, 1, 1))
    box = 0.5 * p[..., :-2, :] + p[..., 1:-1, :] + 0.5 * p[..., 2:, :]
    box = 0.5 * box[..., :-2] + box[..., 1:-1] + 0.5 * box[..., 2:]
    c = kernels.shape[-1] // 2
    k = box[..., c % 2::2, c % 2::2]
    return k / k.sum(dim=(-2, -1), keepdim=True)
