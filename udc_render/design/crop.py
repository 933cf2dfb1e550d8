"""The Wiener (MMSE) estimate on a finite crop: a layout's restorability when the restorer sees only a crop of C px
and the kernel reaches m = S // 2 px past it (why the designed cell loses in DeP: docs/guides/design.md).

Model (torch, CPU or GPU): x on an L × L grid, L = C + 2m, a zero-mean Gaussian field of power spectrum P
(metrics.natural_spectrum: 1/|ν|², variance (c μ)², its mean taken as known); the capture y = M (t k ⊛ x) + n on the
C × C crop M at offset m, n white of variance N. No circular wrap reaches the crop, so y is the crop of a blur of an
unbounded scene. The posterior mean, in whitened form:

    x̂ = P^½ z,   B z = (I + (t²/N) P^½ Kᵀ M K P^½) z = (t/N) P^½ Kᵀ M y,

K the blur, P^½ the filter √P, solved by conjugate gradients preconditioned by the periodic operator
(I + (t²/N) P |H|²)⁻¹ (its spectrum starts at 1). The crop's error is |M (x̂ − x)|² / C², against the periodic
restorability (metrics.wiener_mse), which lets the restorer see every pixel the kernel reaches. The objective
'crop' of udc_render.design.optimise is near_window's stationary stand-in for it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from udc_render.design import metrics

__all__ = ["CG_ITERATIONS", "CropProblem", "crop_problem", "solve", "posterior_mean", "crop_mse", "scene_draws",
           "near_window", "split_kernel", "transfer"]

CG_ITERATIONS = 300  # preconditioned steps: the T-OLED's error within 0.01 dB of 800 steps' (contrast 1, 192 px)


def near_window(size_px: int, crop_px: int) -> np.ndarray:
    """w(Δ) = (1 − 2|Δy|/C)₊ (1 − 2|Δx|/C)₊ on a size_px² kernel grid (centre at size_px // 2): the share of a
    kernel offset Δ the objective 'crop' counts as the restorer's signal; the rest, (1 − w) k, is interference
    (metrics.wiener_mse's h_far). A stationary stand-in for the finite crop: against the posterior mean's error on
    192-px crops (crop_mse, two draws) it is within 1.4 dB for the designed cell, the T-OLED and the P-OLED at RMS
    contrasts 0.3 and 1, and orders them alike (docs/figures/design/layout_crop, docs/guides/design.md)."""
    d = np.abs(np.arange(size_px) - size_px // 2)
    w = np.clip(1 - 2 * d / crop_px, 0, None)
    return w[:, None] * w[None, :]


def split_kernel(kernel, window):
    """(near, far) = (w k, (1 − w) k) of a kernel [..., S, S] (numpy or torch) by near_window's w."""
    near = kernel * window
    return near, kernel - near


@dataclass(frozen=True)
class CropProblem:
    """The grid of one finite-crop estimate: crop C, margin m (the kernel's half size), L = C + 2m, the scene's
    spectrum's square root [L, L // 2 + 1] (rfft layout) and the crop's mask [L, L]."""
    crop_px: int
    margin_px: int
    size_px: int
    root_spectrum: torch.Tensor
    mask: torch.Tensor


def crop_problem(crop_px: int, kernel_px: int, variance: float, dtype=torch.float64, device="cpu") -> CropProblem:
    """The grid for a crop of crop_px and kernels of kernel_px (odd); variance: the scene's, (c μ)²."""
    m = kernel_px // 2
    size = crop_px + 2 * m
    root = torch.tensor(np.sqrt(metrics.natural_spectrum(size, variance))[:, : size // 2 + 1], dtype=dtype,
                        device=device)
    mask = torch.zeros((size, size), dtype=dtype, device=device)
    mask[m:m + crop_px, m:m + crop_px] = 1
    return CropProblem(int(crop_px), m, size, root, mask)


def _filter(v: torch.Tensor, f: torch.Tensor, size: int) -> torch.Tensor:
    return torch.fft.irfft2(torch.fft.rfft2(v) * f, s=(size, size))


def transfer(kernel: torch.Tensor, size: int) -> torch.Tensor:
    """rfft2 of the kernel [S, S] (centre at S // 2) placed at the origin of a size × size grid (size ≥ S)."""
    s = kernel.shape[-1]
    padded = torch.nn.functional.pad(kernel, (0, size - s, 0, size - s))
    return torch.fft.rfft2(torch.roll(padded, (-(s // 2), -(s // 2)), (0, 1)))


def _operator(p: CropProblem, h: torch.Tensor, t, noise):
    """B z = z + (t²/N) P^½ Kᵀ M K P^½ z (module doc)."""
    def apply(z):
        blurred = _filter(z, p.root_spectrum * h, p.size_px)
        return z + (t * t / noise) * _filter(p.mask * blurred, p.root_spectrum * h.conj(), p.size_px)
    return apply


def _preconditioner(p: CropProblem, h: torch.Tensor, t, noise):
    inverse = 1 / (1 + (t * t / noise) * p.root_spectrum ** 2 * h.abs() ** 2)
    return lambda v: _filter(v, inverse, p.size_px)


def solve(apply, b: torch.Tensor, precondition=None, iterations: int = CG_ITERATIONS) -> torch.Tensor:
    """`iterations` steps of preconditioned conjugate gradients for apply(z) = b (both operators symmetric positive
    definite). A fixed count: the residual's norm is no guide to the error here (at 1e-4 of |b| after 4 steps the
    T-OLED's error is still 3 dB from its limit)."""
    precondition = precondition or (lambda v: v)
    z = torch.zeros_like(b)
    r = b.clone()
    s = precondition(r)
    q = s.clone()
    rs = (r * s).sum()
    for _ in range(iterations):
        aq = apply(q)
        alpha = rs / (q * aq).sum()
        z = z + alpha * q
        r = r - alpha * aq
        s = precondition(r)
        rs, old = (r * s).sum(), rs
        if rs == 0:
            break
        q = s + (rs / old) * q
    return z


def _estimate(p: CropProblem, h: torch.Tensor, t, noise, y: torch.Tensor) -> torch.Tensor:
    """x̂ [L, L] from y [L, L] (zero outside the crop)."""
    rhs = (t / noise) * _filter(p.mask * y, p.root_spectrum * h.conj(), p.size_px)
    z = solve(_operator(p, h, t, noise), rhs, _preconditioner(p, h, t, noise))
    return _filter(z, p.root_spectrum, p.size_px)


@torch.no_grad()
def posterior_mean(p: CropProblem, kernel: torch.Tensor, t: float, noise: float, y_crop: torch.Tensor
                   ) -> torch.Tensor:
    """x̂ on the crop [C, C] (module doc) from the crop y [C, C] of t k ⊛ x + n (y's scene mean removed)."""
    y = torch.zeros((p.size_px, p.size_px), dtype=y_crop.dtype, device=y_crop.device)
    inner = slice(p.margin_px, p.margin_px + p.crop_px)
    y[inner, inner] = y_crop
    return _estimate(p, transfer(kernel, p.size_px), t, noise, y)[inner, inner]


def scene_draws(p: CropProblem, rng: np.random.Generator, dtype=torch.float64, device="cpu"):
    """(x [L, L]: a draw of the scene, zero mean, spectrum P; w [L, L]: unit white noise), from rng."""
    white = torch.tensor(rng.standard_normal((2, p.size_px, p.size_px)), dtype=dtype, device=device)
    return _filter(white[0], p.root_spectrum, p.size_px), white[1]


@torch.no_grad()
def crop_mse(p: CropProblem, kernel: torch.Tensor, t: float, noise: float, x: torch.Tensor, w: torch.Tensor
             ) -> float:
    """|M (x̂ − x)|² / C² for the scene draw x and unit noise w: y = M (t k ⊛ x) + √N w (module doc)."""
    h = transfer(kernel, p.size_px)
    y = p.mask * (t * _filter(x, h, p.size_px) + noise ** 0.5 * w)
    err = p.mask * (_estimate(p, h, t, noise, y) - x)
    return float((err * err).sum()) / p.crop_px ** 2
