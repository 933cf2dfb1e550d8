"""restore.tensors.region: a cut of an image mirrored beyond its edges, whatever the order its axes are cut in."""
from __future__ import annotations

import numpy as np
import torch

from restore.tensors import region


def _mirrored(n: int, start: int, count: int) -> np.ndarray:
    """The indices numpy's 'reflect' reads for count samples from start on an axis of n (period 2 (n − 1))."""
    i = np.abs(np.arange(start, start + count)) % (2 * (n - 1))
    return np.where(i >= n, 2 * (n - 1) - i, i)


def test_every_cut_is_the_reflected_image_at_those_indices():
    """Oracle: index arithmetic of the reflection, for cuts inside, across one edge, across both and past several
    reflections, of sizes smaller and larger than the image (the rows cut first where they are a slice, else the
    columns first: the same values)."""
    img = np.random.default_rng(0).random((3, 13, 21)).astype(np.float32)
    t = torch.from_numpy(img)
    for y0 in range(-30, 30, 2):
        for x0 in range(-45, 45, 4):
            for rows, cols in ((5, 9), (13, 21), (20, 30), (40, 50)):
                want = img[:, _mirrored(13, y0, rows)][:, :, _mirrored(21, x0, cols)]
                assert np.array_equal(region(t, y0, x0, rows, cols).numpy(), want), (y0, x0, rows, cols)
