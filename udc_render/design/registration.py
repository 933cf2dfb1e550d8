"""The bands of a periodic display averaged over its registration to the camera (issue 48).

A display of period p (a repeated cell, or an arranged tiling's K × K super-cell) sits at an unknown offset o from
the optical axis; shifting the display by o shifts its propagated intensity, so the power the lens passes at mask
shift s is the unshifted display's at s − o (tiling_power's module doc):
    P_o(s) = ∫ A(r) |u_d(r + s − o)|² dr = P_0(s − o).
The sensor sees the shifts |s_x| ≤ S_x, |s_y| ≤ S_y; where the period is not small against that span (the arranged
super-cell's 672 µm against S_y = 265 µm at d = 2 mm), the relative sd of P over it depends on o: one registration
of `veil130_arranged` reads 0.88 × to 1.11 × the repeated T-OLED's (study design-bands). The registered figure is
the root mean over every o on the raster in one period (o uniform: the panel's alignment to the camera is not
controlled) of the relative variance over the span,
    b = √( mean_o  var_{s ∈ span}(P_0(s − o)) / mean_{s ∈ span}(P_0(s − o))² ),
all offsets at once from one map of P_0 over the span widened by half the period a side, by box sums (integral
images) of P and P², centred on the map's mean (no cancellation in float64).
"""
from __future__ import annotations

import numpy as np
import torch

__all__ = ["widened_span_um", "offset_shifts", "offset_variance", "registered_rsd"]


def widened_span_um(span_um: tuple[float, float], period_um: float) -> tuple[float, float]:
    """The shifts' span plus half a period per axis: the window that holds every registration's shifts."""
    return tuple(s + period_um / 2 for s in span_um)


def offset_shifts(j: int, period_px: int) -> np.ndarray:
    """The shifts in samples −j − ⌊p/2⌋ … j + p − ⌊p/2⌋ − 1: the span ±j under every offset of one period p,
    centred."""
    half = period_px // 2
    return np.arange(-j - half, j + period_px - half)


def _box_sums(x: torch.Tensor, rows: int, cols: int) -> torch.Tensor:
    """Sums of x over every rows × cols window (valid positions), by a 2-D cumulative sum."""
    c = torch.nn.functional.pad(x.cumsum(0).cumsum(1), (1, 0, 1, 0))
    return c[rows:, cols:] - c[:-rows, cols:] - c[rows:, :-cols] + c[:-rows, :-cols]


def offset_variance(region: torch.Tensor, jy: int, jx: int) -> torch.Tensor:
    """[p_y, p_x]: var / mean² of P over the (2 jy + 1) × (2 jx + 1) span at each offset of one period, from P_0 on
    region [2 jy + p_y, 2 jx + p_x] (offset_shifts, p the period in samples per axis): one registration's squared
    relative sd per offset."""
    x = region.double()
    base = x.mean()
    x = x - base
    rows, cols = 2 * jy + 1, 2 * jx + 1
    m = rows * cols
    mean = _box_sums(x, rows, cols) / m
    var = _box_sums(x * x, rows, cols) / m - mean ** 2
    return var / (mean + base) ** 2


def registered_rsd(region: torch.Tensor, jy: int, jx: int) -> torch.Tensor:
    """b of the module doc: the root mean of offset_variance over the p_y × p_x offsets."""
    return offset_variance(region, jy, jx).mean().sqrt()
