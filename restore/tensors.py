"""Tensors the online degradation moves to its device (restore.degrade, restore.degrade_sensor, restore.online):
per-crop numbers as one column for the whole batch, host copies that do not make the device wait, and integer
seeds (a torch generator's) from named streams."""
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
