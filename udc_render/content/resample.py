"""Separable resampling matrices (scipy.sparse) shared by the monitor image and the analytic render.

    overlap_matrix  box (area) integration of cells over pixels: exact for piecewise-constant data
    resize_matrix   the panel's scaler along one axis: linear interpolation when enlarging (as
                    skimage.transform.resize, order 1, mode 'reflect'), area averaging when shrinking

An image [rows, cols] is resampled as A_y · img · A_xᵀ: two sparse products, a few non-zeros per row.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def overlap_matrix(edges_px: np.ndarray, n_pixels: int) -> sp.csr_matrix:
    """[n_pixels, len(edges) − 1] overlap lengths of pixels [j, j + 1] with cells [e_q, e_q+1] (all in
    pixel units, edges increasing): a[j, q] = max(0, min(j + 1, e_q+1) − max(j, e_q))."""
    edges_px = np.asarray(edges_px, dtype=np.float64)
    lo, hi = edges_px[:-1], edges_px[1:]
    span = int(np.ceil(np.max(hi - lo))) + 1  # pixels a cell can touch
    rows, cols, vals = [], [], []
    cells = np.arange(lo.size)
    for t in range(span + 1):
        j = np.floor(lo).astype(np.int64) + t
        overlap = np.minimum(j + 1, hi) - np.maximum(j, lo)
        keep = (overlap > 0) & (j >= 0) & (j < n_pixels)
        rows.append(j[keep])
        cols.append(cells[keep])
        vals.append(overlap[keep])
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n_pixels, lo.size))


def resize_matrix(n_in: int, n_out: int) -> sp.csr_matrix:
    """[n_out, n_in] weights of one axis of a resize to n_out samples. Enlarging: linear interpolation at
    s_j = (j + ½)·n_in/n_out − ½, mirrored about the end samples (skimage's 'reflect'). Shrinking: the
    mean of the input over the output pixel (overlap_matrix with input edges at q·n_out/n_in)."""
    if n_out < n_in:
        return overlap_matrix(np.arange(n_in + 1) * (n_out / n_in), n_out)
    src = (np.arange(n_out) + 0.5) * (n_in / n_out) - 0.5
    if n_in > 1:
        src = np.abs(src)
        src = np.where(src > n_in - 1, 2 * (n_in - 1) - src, src)
    i0 = np.clip(np.floor(src).astype(np.int64), 0, n_in - 1)
    i1 = np.minimum(i0 + 1, n_in - 1)
    f = src - i0
    j = np.arange(n_out)
    return sp.csr_matrix((np.concatenate([1 - f, f]), (np.concatenate([j, j]), np.concatenate([i0, i1]))),
                         shape=(n_out, n_in))


def resample(image: np.ndarray, ay: sp.csr_matrix, ax: sp.csr_matrix) -> np.ndarray:
    """A_y · image · A_xᵀ for every plane of image [C, rows, cols] (float64)."""
    return np.stack([ay @ (ax @ np.asarray(p, np.float64).T).T for p in image])
