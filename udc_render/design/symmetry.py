"""The cell's point symmetry for `udc-render design --symmetry` (issue 48): the search's moves on orbits of squares.

A turned tiling bands as sd² ≈ sd_0² + κ |μ|², μ the centroid of a tile's light about its centre (the dipole law,
docs/guides/design.md). A cell equal to itself turned by 180° (c2: a(r) = a(−r)) has μ = 0 exactly, whatever else
it holds, so its turned tiling keeps only sd_0. Such a cell still has four distinct D4 images (the identity, a
quarter-turn and their mirrors), which decorrelate the tiles. The search keeps the symmetry by moving orbits of
squares under the group: 'none' — each square its own orbit (the plain swaps); 'c2' — the square and its 180°
image, the centre of an odd cell alone (its state is fixed by the parity of the open squares)."""
from __future__ import annotations

import numpy as np

from udc_render.design import torch_psf as tp
from udc_render.design.options import SYMMETRIES

__all__ = ["SYMMETRIES", "orbits", "check_symmetric", "symmetric_scatter", "orbit_swaps", "kicked_orbits"]


def orbits(cell_px: int, symmetry: str) -> list[np.ndarray]:
    """The orbits of the c × c squares (flat indices), ordered by their smallest square."""
    flat = np.arange(cell_px * cell_px)
    if symmetry == "none":
        return [flat[i:i + 1] for i in flat]
    partner = np.rot90(flat.reshape(cell_px, cell_px), 2).ravel()
    return [np.unique([i, partner[i]]) for i in flat if i <= partner[i]]


def check_symmetric(cell: np.ndarray, symmetry: str, option: str) -> None:
    """Refuse in one line a cell that the symmetry does not leave unchanged."""
    if symmetry == "c2" and not np.array_equal(cell, np.rot90(cell, 2)):
        raise tp.DesignError(f"{option}: the cell is not point-symmetric (equal to itself turned by 180°), as "
                             "--symmetry c2 needs; start from scatter or a point-symmetric cell.png")


def symmetric_scatter(cell_px: int, open_squares: int, rng: np.random.Generator) -> np.ndarray:
    """A random c2 cell of open_squares: the centre open if their number is odd, and random pairs."""
    groups = orbits(cell_px, "c2")
    pairs = [g for g in groups if len(g) == 2]
    flat = np.zeros(cell_px * cell_px)
    if open_squares % 2:
        flat[(cell_px * cell_px) // 2] = 1.0
    for k in rng.permutation(len(pairs))[: open_squares // 2]:
        flat[pairs[k]] = 1.0
    return flat.reshape(cell_px, cell_px)


def orbit_swaps(cell: np.ndarray, groups: list[np.ndarray], grad: np.ndarray):
    """(open orbits, opaque orbits, predicted change [open, opaque]): closing orbit i and opening orbit j changes J
    by ≈ Σ_j g − Σ_i g to first order; swaps of orbits of unequal size (which would change the open area) +inf."""
    flat = cell.ravel()
    opened = [g for g in groups if flat[g[0]] > 0.5]
    closed = [g for g in groups if flat[g[0]] < 0.5]
    g_open = np.array([grad[g].sum() for g in opened])
    g_closed = np.array([grad[g].sum() for g in closed])
    size_open, size_closed = np.array([len(g) for g in opened]), np.array([len(g) for g in closed])
    predicted = g_closed[None, :] - g_open[:, None]
    return opened, closed, np.where(size_open[:, None] == size_closed[None, :], predicted, np.inf)


def kicked_orbits(cell: np.ndarray, groups: list[np.ndarray], swaps: int, rng: np.random.Generator) -> np.ndarray:
    """The cell with `swaps` random open orbits of the largest size closed and as many opaque ones opened."""
    size = max(len(g) for g in groups)
    flat = cell.ravel().copy()
    opened = [g for g in groups if len(g) == size and flat[g[0]] > 0.5]
    closed = [g for g in groups if len(g) == size and flat[g[0]] < 0.5]
    for k in rng.choice(len(opened), swaps, replace=False):
        flat[opened[k]] = 0.0
    for k in rng.choice(len(closed), swaps, replace=False):
        flat[closed[k]] = 1.0
    return flat.reshape(cell.shape)
