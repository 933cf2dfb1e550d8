"""Where the training step may run in bfloat16 (`autocast = 'bf16'`, restore.train.TrainSettings): natively on a
CUDA GPU that supports it and on a CPU with oneDNN's bf16 kernels (AVX-512 core or AMX); emulated, and so refused,
elsewhere (benchmarks/README.md, 'bfloat16 where it is emulated')."""
from __future__ import annotations

import torch

from udc_render.errors import UdcError


class PrecisionError(UdcError):
    """A training precision this device cannot run at its speed."""


def bf16_native(device: torch.device) -> bool:
    """Whether bfloat16 convolutions run natively on `device`: a CUDA GPU that supports them, or a CPU on which
    oneDNN has bf16 kernels (AVX-512 core or AMX). On an AVX2-only CPU they are emulated: a UNet step in bf16 took
    13× float32's at the cpu budget's batch (15.4 s against 1.19 s; 22-30× on 128-px crops; 2026-11-28, AMD EPYC
    with AVX2, 2 threads; benchmarks/README.md, 'bfloat16 where it is emulated')."""
    if device.type == "cuda":
        return torch.cuda.is_bf16_supported()
    return device.type == "cpu" and bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())


def check_autocast(autocast: str | None, device: torch.device) -> None:
    """Refuse autocast 'bf16' at once where it is emulated (bf16_native): days of training instead of hours."""
    if autocast == "bf16" and not bf16_native(device):
        what = f"this CPU ({torch.backends.cpu.get_cpu_capability()})" if device.type == "cpu" else f"{device}"
        raise PrecisionError(f"autocast = 'bf16': {what} has no native bfloat16, so a step would run 13-30× slower "
                             "than in float32; train in float32 (leave --autocast out) or on a CPU with AVX-512 or "
                             "a GPU")
