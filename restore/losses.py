"""Training losses: L1 (the paper's) and L1 + (1 − SSIM) at 1:1 (the paper's ablation).

SSIM (Wang et al. 2004): 11 × 11 Gaussian window, σ = 1.5, C1 = (0.01 L)², C2 = (0.03 L)², population
statistics, valid region only (no padding); the same as skimage.metrics.structural_similarity with
gaussian_weights=True, use_sample_covariance=False on the window-free interior.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

LOSSES = ("l1", "l1+ssim")


def _gaussian_window(channels: int, size: int, sigma: float, like: torch.Tensor) -> torch.Tensor:
    x = torch.arange(size, dtype=like.dtype, device=like.device) - (size - 1) / 2
    g = torch.exp(-x ** 2 / (2 * sigma ** 2))
    g = g / g.sum()
    return (g[:, None] * g[None, :]).expand(channels, 1, size, size).contiguous()


def ssim(x: torch.Tensor, y: torch.Tensor, data_range: float = 1.0, size: int = 11, sigma: float = 1.5) -> torch.Tensor:
    """Mean SSIM of [N, C, H, W] images over channels and the valid region (module doc)."""
    if min(x.shape[-2:]) < size:
        raise ValueError(f"ssim: image {tuple(x.shape[-2:])} smaller than the {size} × {size} window")
    w = _gaussian_window(x.shape[1], size, sigma, x)
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    mu_x, mu_y = F.conv2d(x, w, groups=x.shape[1]), F.conv2d(y, w, groups=x.shape[1])
    sxx = F.conv2d(x * x, w, groups=x.shape[1]) - mu_x ** 2
    syy = F.conv2d(y * y, w, groups=x.shape[1]) - mu_y ** 2
    sxy = F.conv2d(x * y, w, groups=x.shape[1]) - mu_x * mu_y
    s = ((2 * mu_x * mu_y + c1) * (2 * sxy + c2)) / ((mu_x ** 2 + mu_y ** 2 + c1) * (sxx + syy + c2))
    return s.mean()


def loss_fn(name: str):
    """The training loss `name` (LOSSES) as f(output, target) -> scalar tensor."""
    if name == "l1":
        return F.l1_loss
    if name == "l1+ssim":
        return lambda out, target: F.l1_loss(out, target) + (1 - ssim(out, target))
    raise ValueError(f"loss = {name!r}: expected one of {', '.join(LOSSES)}")
