"""Parameter and multiply-accumulate counts of the restoration models, without running them.

Convention: one MAC is one multiply-add of a weight with an input, so a k × k convolution from C_in
to C_out channels costs C_in·C_out·k² MACs per output pixel, a ConvTranspose2d the same per input
pixel; biases, activations, pooling, additions and pixel shuffle are not counted. 1 MAC = 2 FLOPs:
`torch.utils.flop_counter.FlopCounterMode` counts FLOPs, halved here (fvcore, ptflops and thop
count MACs; thop counts ConvTranspose2d 4× too many). The paper's "GFLOPs" are MACs in this
convention, 0.1–0.25 % above these counts (about what counting one add per bias and output adds):
UNet 124.08 G (paper 124.36), single encoder 96.91 (97.09), double width 386.01 (386.37), ResNet
719.94 (721.76). The model is built on the `meta` device: no memory, no arithmetic.
"""
from __future__ import annotations

import torch
from torch import nn
from torch.utils.flop_counter import FlopCounterMode

from restore.models import build_model

PAPER_INPUT_SHAPE = (1, 4, 512, 1024)
"""N, C, h, w of the paper's counts: packed RAW of a 1024 × 2048 sensor ("512 × 1024 × 4")."""


def count_parameters(model: nn.Module) -> int:
    """Number of trainable parameters (weights and biases)."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


def _flop_counts(config: dict, input_shape) -> dict:
    with torch.device("meta"):
        model = build_model(config)
    from restore.conditioning import empty_description_tensors, needs_description, spec_kernel_px
    x = torch.empty(input_shape, device="meta")
    extra = [empty_description_tensors(input_shape[0], spec_kernel_px(model), "meta")] * needs_description(model)
    with FlopCounterMode(display=False) as counter:
        model(x, *extra)
    return counter.get_flop_counts()


def count_macs(config: dict, input_shape=PAPER_INPUT_SHAPE) -> int:
    """MACs of one forward pass of build_model(config) on a tensor of `input_shape` (module doc)."""
    return sum(_flop_counts(config, input_shape).get("Global", {}).values()) // 2


def mac_breakdown(config: dict, input_shape=PAPER_INPUT_SHAPE) -> dict[str, int]:
    """MACs per top-level child of the model (e.g. 'encoder', 'residual_encoder', 'up', 'decoder')."""
    counts = _flop_counts(config, input_shape)
    names = [k for k in counts if k != "Global"]
    leaves = [k for k in names if not any(o.startswith(k + ".") for o in names)]
    out: dict[str, int] = {}
    for k in leaves:
        child = k.split(".")[1]
        out[child] = out.get(child, 0) + sum(counts[k].values()) // 2
    return out
