"""UPC's ring statistic of the MTF in torch (differentiable): the design's objective 'rings' and its UPC floor
(udc_render.design.floor); metrics.ring_summary computes the same in numpy."""
from __future__ import annotations

import numpy as np
import torch

__all__ = ["spectrum", "ring_index", "mean_ring_minima"]


def spectrum(k: torch.Tensor) -> torch.Tensor:
    """The transfer function fft2 of centred kernels k [..., S, S] (DC at index 0)."""
    return torch.fft.fft2(torch.fft.ifftshift(k, dim=(-2, -1)))


def ring_index(size: int) -> torch.Tensor:
    """[size²] each MTF bin's ring k = round(|ν|) about the DC at size // 2 (metrics.ring_stats'), rings past
    size // 2 − 1 pooled into one index that the statistic drops."""
    i = np.abs(np.arange(size) - size // 2)
    dist = np.rint(np.hypot(i[None, :], i[:, None])).astype(np.int64).ravel()
    return torch.as_tensor(np.minimum(dist, size // 2))


def mean_ring_minima(k: torch.Tensor, rings: torch.Tensor) -> torch.Tensor:
    """[C] the mean over k = 1 … S/2 − 1 of each ring's minimum of the MTF |fft2| of unit-sum kernels k [C, S, S]
    (metrics.ring_summary's 'mean_of_ring_minima', in torch: differentiable at each ring's minimum)."""
    m = torch.fft.fftshift(spectrum(k), dim=(-2, -1)).abs().flatten(1)
    n = int(rings.max()) + 1
    index = rings.to(m.device).expand(m.shape[0], -1)
    minima = torch.full((m.shape[0], n), torch.inf, dtype=m.dtype, device=m.device)
    minima = minima.scatter_reduce(1, index, m, "amin", include_self=True)
    return minima[:, 1:-1].mean(dim=1)
