"""DeP given the panel's far field: the light past the kernel window, which DeP's kernel does not hold, taken out
of DeP's estimate by a fixed point (issue 48; the far field: optics.far_field, udc_render.dataset.bank.PanelFar).

A capture through a panel with a far field is y = k ⊗ x + F(x), F(x) = x̄ ⊗ F_c: the c × c block means of the
frame, convolved with the far kernels F_c (relative to the core's light; γ scales both) and interpolated back to
the pixels. DeP inverts k (unit sum); F(x) is smooth on the scale of c pixels and passes DeP's Wiener filter at
its DC gain of 1, so DeP's output is w ≈ x + F(x). The estimate solves x = w − F(x) by

    x₀ = w,  x_{n+1} = max(w − F(x_n), 0),

F the degrader's own far light of the whole frame (restore.degrade_wide.WideLight: its mirrored margin, edge
continuation and interpolation). F is linear and positive, and its gain on any frame is at most the share
s = max_c Σ F_c (the bank's far_field.share_rgb), so the error contracts by s a step:
‖x_n − x‖∞ ≤ s^(n+1) ‖x‖∞ (the clamp at 0 only brings x_n nearer a non-negative x). ITERATIONS = 4 leaves
s⁵ ≤ 2e-6 of the peak at the designs' s ≈ 7 %, far below DeP's own error (≈ 7 % rms at 23 dB).

What it does not take out: the display's haze (PanelHaze: a veil over the frame's electrons), which no bank panel
of the layout studies carries, and the part of F(x) that DeP's Wiener filter does not pass at unit gain (its
regularisation at the frequencies F still holds: F's kernel spans ≥ c = 15 px, so only the lowest).
"""
from __future__ import annotations

import numpy as np
import torch

from restore.degrade import Degrader
from restore.degrade_wide import WideSource
from udc_render.dataset.bank import Panel

ITERATIONS = 4


def subtract_far(rgb: np.ndarray, panel: Panel, iterations: int = ITERATIONS) -> np.ndarray:
    """x solving x = rgb − F(x) (module doc) for DeP's output rgb [3, H, W] of a whole frame through `panel` (linear
    RGB at the capture's brightness); rgb itself (as float32) where the panel has no far field."""
    w = np.asarray(rgb, np.float64)
    if panel.far is None:
        return w.astype(np.float32)
    wide = Degrader([panel], "cpu", torch.float64).wide
    size = w.shape[1:]
    x = w
    for n in range(iterations):  # WideLight keeps a frame's maps under its key: one key per iterate
        far, _ = wide.crops([0], [(size, (0, 0))], [WideSource(("subtract_far", n), torch.from_numpy(x))], size)
        x = np.maximum(w - far[0].numpy(), 0.0)
    return x.astype(np.float32)
