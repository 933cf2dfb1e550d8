"""Exact area-weighted rasterisation of the shapes that make display masks and apertures.

Every function returns, for each cell of a rectilinear grid, the area (µm²) that a shape covers.
Area weighting (grey edge pixels) is 20-40x more accurate than binary rasters at equal pupil
sampling (docs/PHYSICS.md §3); here the areas are exact to floating-point rounding, not supersampled.
"""
from __future__ import annotations

import numpy as np

__all__ = ["interval_overlap", "unit_disc_cell_areas", "ellipse_areas", "rect_areas"]


def interval_overlap(edges: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Length of [lo, hi] ∩ [edges[i], edges[i+1]] for every cell i (same unit as `edges`)."""
    return np.clip(np.minimum(edges[1:], hi) - np.maximum(edges[:-1], lo), 0.0, None)


def _circle_primitive(x: np.ndarray) -> np.ndarray:
    """H(x) = ∫_0^x sqrt(1 - t²) dt for the unit circle, with x clipped to [-1, 1]."""
    x = np.clip(x, -1.0, 1.0)
    return 0.5 * (x * np.sqrt(1.0 - x * x) + np.arcsin(x))


def _clipped_height_integral(x0, x1, a, b):
    """∫_{x0}^{x1} clip(h(x), a, b) dx with h(x) = sqrt(1 - x²) on |x| ≤ 1 and 0 outside.

    h is unimodal, so the integrand is piecewise a constant or h itself between the breakpoints
    {0, ±1, ±sqrt(1-a²), ±sqrt(1-b²)}; each piece is integrated in closed form.
    """
    def roots(level):
        inside = (level >= 0) & (level < 1)
        r = np.sqrt(np.clip(1.0 - level * level, 0.0, None))
        return np.where(inside, r, 0.0)

    ra, rb = roots(a), roots(b)
    zeros = np.zeros_like(x0)
    pts = np.stack([x0, x1, zeros, zeros - 1, zeros + 1, ra, -ra, rb, -rb], axis=-1)
    pts = np.sort(np.clip(pts, x0[..., None], x1[..., None]), axis=-1)
    s, t = pts[..., :-1], pts[..., 1:]
    mid = 0.5 * (s + t)
    h = np.sqrt(np.clip(1.0 - mid * mid, 0.0, None))
    a_, b_ = a[..., None], b[..., None]
    width = t - s
    piece = np.where(h <= a_, a_ * width,
                     np.where(h >= b_, b_ * width, _circle_primitive(t) - _circle_primitive(s)))
    return piece.sum(axis=-1)


def unit_disc_cell_areas(x0, x1, y0, y1):
    """Exact area of the unit disc inside the rectangles [x0,x1]×[y0,y1] (broadcast arrays).

    Uses |[-h, h] ∩ [y0, y1]| = clip(h, y0, y1) + clip(h, -y1, -y0) for h ≥ 0.
    """
    x0, x1, y0, y1 = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x0, x1, y0, y1)))
    return _clipped_height_integral(x0, x1, y0, y1) + _clipped_height_integral(x0, x1, -y1, -y0)


def ellipse_areas(x_edges, y_edges, cx, cy, rx, ry) -> np.ndarray:
    """Exact area (µm²) of the ellipse ((x-cx)/rx)² + ((y-cy)/ry)² ≤ 1 in every grid cell.

    Returns an array of shape [len(y_edges)-1, len(x_edges)-1]. Only the cells that the
    ellipse's boundary crosses are integrated; cells fully inside get their whole area.
    """
    xe = (np.asarray(x_edges, dtype=np.float64) - cx) / rx
    ye = (np.asarray(y_edges, dtype=np.float64) - cy) / ry
    out = np.zeros((ye.size - 1, xe.size - 1))
    ix = np.nonzero((xe[1:] > -1) & (xe[:-1] < 1))[0]
    iy = np.nonzero((ye[1:] > -1) & (ye[:-1] < 1))[0]
    if ix.size == 0 or iy.size == 0:
        return out
    X0, X1 = xe[ix][None, :], xe[ix + 1][None, :]
    Y0, Y1 = ye[iy][:, None], ye[iy + 1][:, None]
    near = np.minimum(X0 ** 2, X1 ** 2) * ((X0 > 0) | (X1 < 0)) + np.minimum(Y0 ** 2, Y1 ** 2) * ((Y0 > 0) | (Y1 < 0))
    far = np.maximum(X0 ** 2, X1 ** 2) + np.maximum(Y0 ** 2, Y1 ** 2)
    block = np.where(far <= 1.0, (X1 - X0) * (Y1 - Y0), 0.0)
    edge = (near < 1.0) & (far > 1.0)
    if edge.any():
        jy, jx = np.nonzero(edge)
        block[jy, jx] = unit_disc_cell_areas(X0[0, jx], X1[0, jx], Y0[jy, 0], Y1[jy, 0])
    out[np.ix_(iy, ix)] = block * rx * ry
    return out


def rect_areas(x_edges, y_edges, cx, cy, width, height) -> np.ndarray:
    """Exact area (µm²) of an axis-aligned rectangle in every grid cell (separable product)."""
    ox = interval_overlap(np.asarray(x_edges, float), cx - width / 2, cx + width / 2)
    oy = interval_overlap(np.asarray(y_edges, float), cy - height / 2, cy + height / 2)
    return np.outer(oy, ox)
