"""Tensors the online degradation moves to its device (restore.degrade, restore.degrade_sensor, restore.online):
per-crop numbers as one column for the whole batch, host copies that do not make the device wait, integer seeds (a
torch generator's) from named streams, and a region of an image mirrored beyond its edges."""
from __future__ import annotations

import numpy as np
import torch

from udc_render.streams import seed_sequence


def stream_seed(seed: int, *keys: int | str) -> int:
    """A 63-bit integer seed (a torch generator's, a draw's) from the named stream (seed, *keys)
    (udc_render.streams.seed_sequence)."""
    return int(seed_sequence(seed, *keys).generate_state(1, np.uint64)[0] >> 1)


def per_crop(values, like: torch.Tensor) -> torch.Tensor:
    """Per-crop numbers [B] or [B, K] (Python floats, computed in double as the scalars they stand for) as a tensor
    [B, 1, 1, 1] or [B, K, 1, 1] on like's device and in its precision: one copy for the whole batch."""
    t = host_to(torch.tensor(values, dtype=torch.float64), like.device, like.dtype)
    return t.reshape(t.shape[0], -1, 1, 1)


def host_to(t: torch.Tensor, device: torch.device, dtype: torch.dtype | None = None) -> torch.Tensor:
    """A host tensor on the device (in dtype), without waiting for the device: on a GPU copied from pinned memory
    asynchronously (a pageable copy waits for the stream, and each wait let the GPU run dry: benchmarks/
    profile_online.py)."""
    if device.type == "cuda":
        t = t.pin_memory().to(device, non_blocking=True)
    return t.to(device, dtype)


def region(img: torch.Tensor, y0: int, x0: int, rows: int, cols: int) -> torch.Tensor:
    """img[:, y0:y0 + rows, x0:x0 + cols] of a tensor [C, H, W] (on its own device) with the image mirrored beyond
    its edges (edge pixels not repeated: numpy's 'reflect'). Axis by axis: inside the image a slice; a mirror
    within one reflection, flipped slices joined; else a gather (a 768² crop of a 2048 × 1024 tensor mirrored on
    one side: 0.6 ms, where one 2-D fancy index took 7 ms). The rows first where they are a slice, else the
    columns first on the rows read, so that no intermediate spans the frame's width (a crop mirrored at the top:
    10 → 2.5 ms on the loaded 2-core machine)."""
    def axis(a: torch.Tensor, dim: int, start: int, n: int) -> torch.Tensor:
        size = a.shape[dim]
        if 0 <= start and start + n <= size:
            return a.narrow(dim, start, n)
        lo, hi = max(start, 0), min(start + n, size)
        if hi > lo and -start < size and start + n - size < size:
            parts = [a.narrow(dim, 1, -start).flip(dim)] if start < 0 else []
            parts.append(a.narrow(dim, lo, hi - lo))
            if start + n > size:
                parts.append(a.narrow(dim, 2 * size - 1 - start - n, start + n - size).flip(dim))
            return torch.cat(parts, dim)
        i = np.abs(np.arange(start, start + n))
        period = 2 * (size - 1)
        i %= max(period, 1)
        i = np.where(i >= size, period - i, i)
        return a.index_select(dim, torch.as_tensor(i, device=a.device))
    def read(size: int, start: int, n: int) -> tuple[int, int]:
        """The rows a cut mirrored at one edge within one reflection reads, bounds of a view that keeps its mirror
        (from 0 when it mirrors at 0, to size when at the end); else the whole axis."""
        if start < 0 <= start + n <= size and -start < size:
            return 0, max(start + n, 1 - start)
        if 0 <= start < size < start + n < 2 * size:
            return min(start, 2 * size - 1 - start - n), size
        return 0, size
    if 0 <= y0 and y0 + rows <= img.shape[1]:  # the rows a view: cut first, then the columns, one copy
        return axis(axis(img, 1, y0, rows), 2, x0, cols)
    r0, r1 = read(img.shape[1], y0, rows)  # else the columns first, on the rows read: no full-width copy
    return axis(axis(img[:, r0:r1], 2, x0, cols), 1, y0 - r0, rows)
