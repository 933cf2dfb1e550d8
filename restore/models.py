"""Restoration networks: packed RAW [N, 4, h, w] in, full-resolution RGB [N, 3, 2h, 2w] out.

- `UNet`: the paper's baseline (Zhou et al. 2021, §4 "UNet"): the SID UNet (Chen et al. 2018,
  "Learning to See in the Dark") with its encoder split into two sub-encoders.
- `WideFineUNet` ('unet-wide-fine'): the same, wider at its two finest levels only (the capacity study).
- `ResNet`: EDSR (Lim et al. 2017) with 16 residual blocks of 64 features, no batch norm.
- `WienerUNet` ('wiener-unet', restore/models_conditioned.py): conditioned on the panel's description.

A config is a dict whose `type` picks the model in `MODELS` and whose other keys are its keyword
arguments (`build_model`); `model_config(model)` gives back the config a model was built from, so a
checkpoint can store how to rebuild it. Parameter and MAC counts: restore/counting.py.
"""
from __future__ import annotations

import importlib
import types
import typing
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from udc_render.errors import UdcError
from udc_render.io.files import read_toml


class ModelConfigError(UdcError):
    """A bad model config: one line naming the source, key, value and what is allowed."""


def _require(ok: bool, key: str, value, allowed: str) -> None:
    if not ok:
        raise ModelConfigError(f"{key} = {value!r}: expected {allowed}")


def _conv_block(in_channels: int, out_channels: int, negative_slope: float) -> nn.Sequential:
    """Two 3 × 3 convolutions, each followed by LeakyReLU (SID's level)."""
    return nn.Sequential(nn.Conv2d(in_channels, out_channels, 3, padding=1), nn.LeakyReLU(negative_slope),
                         nn.Conv2d(out_channels, out_channels, 3, padding=1), nn.LeakyReLU(negative_slope))


class UNet(nn.Module):
    """SID UNet with two sub-encoders; packed RAW [N, 4, h, w] → RGB [N, 3, 2h, 2w].

    Level i (0 ≤ i < depth) has width·2^i channels and two 3 × 3 convolutions + LeakyReLU(0.2);
    2 × 2 max-pool down; decoder: ConvTranspose2d(2 × 2, stride 2) up, concatenation with the skip,
    two 3 × 3 convolutions; a 1 × 1 convolution to 4·out_channels and PixelShuffle(2). No batch norm.

    Sub-encoders (paper: one learns the content, the other residual details to add). The second
    runs in parallel on the same input, with its own weights, over the first `second_encoder_levels`
    levels; the two encoders' features are summed at each of those skips and, where the second stops
    before the bottleneck, their max-pooled last outputs are summed as the bottleneck's input.
    The paper's counts fix this (its "GFLOPs" are MACs, see counting.py; input 4 × 512 × 1024):
    - "Single Encoder" = the SID UNet, sub_encoders=1: 7.76 M, 97.09 G (here 7.761 M, 96.91 G);
    - "Double Width" = the same at width 64: 31.03 M, 386.37 G (here 31.033 M, 386.01 G);
    - baseline: 8.93 M, 124.36 G. Its increment over the single encoder, 1.17 M and 27.3 G, is
      exactly levels 0–3 (4 → 256 channels) of a second encoder: second_encoder_levels = depth − 1,
      the default (here 8.933 M, 124.08 G). Two full copies of the 32 → 512 encoder
      (second_encoder_levels = depth, bottleneck outputs summed) give 12.47 M, 131.3 G: no row.

    The input is padded (bottom and right; reflect, or replicate where the input is too small to
    reflect) to a multiple of 2^(depth − 1) and the output cropped back to [2h, 2w].
    """

    TYPE = "unet"

    def __init__(self, in_channels: int = 4, out_channels: int = 3, width: int = 32, depth: int = 5,
                 sub_encoders: int = 2, second_encoder_levels: int | None = None, negative_slope: float = 0.2):
        super().__init__()
        for key, value in (("in_channels", in_channels), ("out_channels", out_channels), ("width", width),
                           ("depth", depth)):
            _require(value >= 1, key, value, "an integer >= 1")
        _require(sub_encoders in (1, 2), "sub_encoders", sub_encoders, "1 or 2")
        if sub_encoders == 1:
            _require(second_encoder_levels is None, "second_encoder_levels", second_encoder_levels,
                     "no value with sub_encoders = 1")
        else:
            second_encoder_levels = max(depth - 1, 1) if second_encoder_levels is None else second_encoder_levels
            _require(1 <= second_encoder_levels <= depth, "second_encoder_levels", second_encoder_levels,
                     f"1 to depth = {depth}")
        _require(negative_slope >= 0, "negative_slope", negative_slope, "a number >= 0")
        self.config = {"type": self.TYPE, "in_channels": in_channels, "out_channels": out_channels, "width": width,
                       "depth": depth, "sub_encoders": sub_encoders, "negative_slope": negative_slope}
        if second_encoder_levels is not None:
            self.config["second_encoder_levels"] = second_encoder_levels
        unet_levels(self, in_channels, out_channels, self.level_widths(width, depth), second_encoder_levels or 0,
                    negative_slope)

    def level_widths(self, width: int, depth: int) -> list[int]:
        """The channels of each level: width · 2^i."""
        return [width * 2 ** i for i in range(depth)]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return unet_pass(self, x)


def unet_levels(net: nn.Module, in_channels: int, out_channels: int, ch: list[int], second_levels: int,
                negative_slope: float) -> None:
    """net's encoder, residual_encoder (its first `second_levels` levels), up, decoder and to_rgb for level widths
    `ch` (UNet's class doc), registered in that order."""
    depth, cin = len(ch), [in_channels] + ch[:-1]
    net.encoder = nn.ModuleList(_conv_block(cin[i], ch[i], negative_slope) for i in range(depth))
    net.residual_encoder = nn.ModuleList(_conv_block(cin[i], ch[i], negative_slope) for i in range(second_levels))
    net.up = nn.ModuleList(nn.ConvTranspose2d(ch[i + 1], ch[i], 2, stride=2) for i in range(depth - 1))
    net.decoder = nn.ModuleList(_conv_block(2 * ch[i], ch[i], negative_slope) for i in range(depth - 1))
    net.to_rgb = nn.Sequential(nn.Conv2d(ch[0], 4 * out_channels, 1), nn.PixelShuffle(2))


class WideFineUNet(UNet):
    """The paper's UNet (UNet) with its `fine_levels` finest levels `fine_extra_width` channels wider, every other
    level, the sub-encoders and the pass unchanged: capacity where the T-OLED's lost band (1/16–1/8 cycle/px) is
    carried, and nowhere else (issue 47, item 1; the blind twin of wiener-unet's backbone). Its defaults, levels
    64/96/128/256/512: 9.485 M parameters, 242.93 G MACs at 4 × 512 × 1024 (the paper's UNet: 8.933 M, 124.08 G):
    1.06× the parameters, 1.96× the arithmetic, nearly all of it at the packed scale."""

    TYPE = "unet-wide-fine"

    def __init__(self, in_channels: int = 4, out_channels: int = 3, width: int = 32, depth: int = 5,
                 fine_levels: int = 2, fine_extra_width: int = 32, sub_encoders: int = 2,
                 second_encoder_levels: int | None = None, negative_slope: float = 0.2):
        _require(0 <= fine_levels <= depth, "fine_levels", fine_levels, f"0 to depth = {depth}")
        _require(fine_extra_width >= 0, "fine_extra_width", fine_extra_width, "an integer >= 0")
        self.fine_levels, self.fine_extra_width = fine_levels, fine_extra_width
        super().__init__(in_channels, out_channels, width, depth, sub_encoders, second_encoder_levels, negative_slope)
        self.config.update(type=self.TYPE, fine_levels=fine_levels, fine_extra_width=fine_extra_width)

    def level_widths(self, width: int, depth: int) -> list[int]:
        """width · 2^i, plus fine_extra_width at the fine_levels finest levels."""
        return [c + (self.fine_extra_width if i < self.fine_levels else 0)
                for i, c in enumerate(super().level_widths(width, depth))]


def _as_is(kind: str, i: int, a: torch.Tensor) -> torch.Tensor:
    return a


def unet_pass(net: nn.Module, x: torch.Tensor, after=_as_is) -> torch.Tensor:
    """UNet's pass (class doc) over net's encoder, residual_encoder, up, decoder and to_rgb; after(kind, i, a):
    each encoder ('encoder', i) and decoder ('decoder', i) level's output goes through it (restore.
    models_conditioned.WienerUNet's FiLM; the UNet's own: as it is)."""
    h, w = x.shape[-2:]
    m = 2 ** (len(net.encoder) - 1)
    ph, pw = -h % m, -w % m
    if ph or pw:
        x = F.pad(x, (0, pw, 0, ph), mode="reflect" if ph < h and pw < w else "replicate")
    levels = len(net.residual_encoder)
    skips, a, b = [], x, x
    for i, block in enumerate(net.encoder):
        if i:
            a = F.max_pool2d(a, 2)
            if i <= levels:
                b = F.max_pool2d(b, 2)
            if i == levels:                     # the second encoder stopped: add its pooled output
                a = a + b
        a = after("encoder", i, block(a))
        if i < levels:
            b = net.residual_encoder[i](b)
        skips.append(a + b if i < levels else a)
    y = skips.pop()
    for i in reversed(range(len(net.up))):
        y = after("decoder", i, net.decoder[i](torch.cat([net.up[i](y), skips[i]], dim=1)))
    return net.to_rgb(y)[..., :2 * h, :2 * w]


class _ResidualBlock(nn.Module):
    """x + res_scale · conv(ReLU(conv(x))) (EDSR's block: no batch norm)."""

    def __init__(self, features: int, res_scale: float):
        super().__init__()
        self.body = nn.Sequential(nn.Conv2d(features, features, 3, padding=1), nn.ReLU(),
                                  nn.Conv2d(features, features, 3, padding=1))
        self.res_scale = res_scale

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.res_scale * self.body(x)


class ResNet(nn.Module):
    """EDSR (Lim et al. 2017) on packed RAW [N, 4, h, w] → RGB [N, 3, 2h, 2w]; no batch norm.

    Head 3 × 3 conv to `features`; `blocks` residual blocks (conv-ReLU-conv, scaled by res_scale);
    a 3 × 3 body conv and the global skip; tail up-sampling 2× at `features` channels:
    - tail "edsr" (EDSR's ×2 up-sampler): 3 × 3 conv to 4·features, PixelShuffle(2), 3 × 3 conv to
      out_channels at full resolution. 16 × 64: 1.37 M parameters, 719.9 G MACs at 4 × 512 × 1024,
      the paper's ResNet row (1.37 M, 721.76 G);
    - tail "shuffle": 3 × 3 conv to 4·out_channels, PixelShuffle(2): 1.23 M, 642.6 G.
    No mean shift (the input is RAW, not sRGB). Fully convolutional at one scale: any h, w ≥ 1.
    """

    TYPE = "resnet"
    TAILS = ("edsr", "shuffle")

    def __init__(self, in_channels: int = 4, out_channels: int = 3, features: int = 64, blocks: int = 16,
                 res_scale: float = 1.0, tail: str = "edsr"):
        super().__init__()
        for key, value in (("in_channels", in_channels), ("out_channels", out_channels), ("features", features)):
            _require(value >= 1, key, value, "an integer >= 1")
        _require(blocks >= 0, "blocks", blocks, "an integer >= 0")
        _require(res_scale > 0, "res_scale", res_scale, "a number > 0")
        _require(tail in self.TAILS, "tail", tail, f"one of {', '.join(self.TAILS)}")
        self.config = {"type": self.TYPE, "in_channels": in_channels, "out_channels": out_channels,
                       "features": features, "blocks": blocks, "res_scale": res_scale, "tail": tail}
        self.head = nn.Conv2d(in_channels, features, 3, padding=1)
        self.body = nn.Sequential(*(_ResidualBlock(features, res_scale) for _ in range(blocks)),
                                  nn.Conv2d(features, features, 3, padding=1))
        if tail == "edsr":
            self.tail = nn.Sequential(nn.Conv2d(features, 4 * features, 3, padding=1), nn.PixelShuffle(2),
                                      nn.Conv2d(features, out_channels, 3, padding=1))
        else:
            self.tail = nn.Sequential(nn.Conv2d(features, 4 * out_channels, 3, padding=1), nn.PixelShuffle(2))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.head(x)
        return self.tail(h + self.body(h))


MODELS: dict[str, type[nn.Module]] = {UNet.TYPE: UNet, ResNet.TYPE: ResNet, WideFineUNet.TYPE: WideFineUNet}


def _register_conditioned() -> None:
    """The restorers conditioned on the panel's description: restore.models_conditioned builds on this module's
    blocks and adds its models to MODELS (imported once the blocks exist, whichever module is imported first)."""
    importlib.import_module("restore.models_conditioned")


_register_conditioned()
UNET_CONFIG = {"type": "unet", "in_channels": 4, "out_channels": 3, "width": 32, "depth": 5, "sub_encoders": 2,
               "second_encoder_levels": 4, "negative_slope": 0.2}
"""The paper's baseline: 8.933 M parameters, 124.08 G MACs at 4 × 512 × 1024 (paper: 8.93 M, 124.36 G)."""
UNET_SINGLE_ENCODER_CONFIG = {"type": "unet", "in_channels": 4, "out_channels": 3, "width": 32, "depth": 5,
                              "sub_encoders": 1, "negative_slope": 0.2}
"""The paper's "Single Encoder" ablation (the SID UNet): 7.761 M, 96.91 G (paper: 7.76 M, 97.09 G)."""
UNET_WIDE_FINE_CONFIG = dict(UNET_CONFIG, type="unet-wide-fine", fine_levels=2, fine_extra_width=32)
"""The capacity study's UNet (restore.studies.capacity): the paper's, its two finest levels 32 channels wider."""
RESNET_CONFIG = {"type": "resnet", "in_channels": 4, "out_channels": 3, "features": 64, "blocks": 16,
                 "res_scale": 1.0, "tail": "edsr"}
"""The paper's ResNet (EDSR 16 × 64): 1.370 M, 719.94 G (paper: 1.37 M, 721.76 G)."""


def _type_ok(value, hint) -> bool:
    if isinstance(hint, types.UnionType):
        return any(_type_ok(value, h) for h in typing.get_args(hint))
    if hint is type(None):
        return value is None
    if isinstance(value, bool):
        return hint is bool
    return isinstance(value, (int, float)) if hint is float else isinstance(value, hint)


def _type_name(hint) -> str:
    if isinstance(hint, types.UnionType):
        return " or ".join(_type_name(h) for h in typing.get_args(hint) if h is not type(None)) + " (or absent)"
    return {int: "an integer", float: "a number", str: "a string", bool: "true or false"}.get(hint, str(hint))


def build_model(config: dict, source: str = "config") -> nn.Module:
    """The model `config["type"]` with the other keys as its keyword arguments.

    Unknown type or key, a value of the wrong type or out of range: ModelConfigError, one line
    naming `source` (e.g. the config file), the key, the value and what is allowed.
    """
    kind = config.get("type")
    if kind not in MODELS:
        raise ModelConfigError(f"{source}: type = {kind!r}: expected one of {', '.join(MODELS)}")
    cls = MODELS[kind]
    hints = typing.get_type_hints(cls.__init__)
    hints.pop("return", None)
    kwargs = {k: v for k, v in config.items() if k != "type"}
    for key, value in kwargs.items():
        if key not in hints:
            raise ModelConfigError(f"{source}: {key} = {value!r}: not an argument of {kind}; "
                                   f"expected keys {', '.join(['type', *hints])}")
        if not _type_ok(value, hints[key]):
            raise ModelConfigError(f"{source}: {key} = {value!r}: expected {_type_name(hints[key])}")
    try:
        return cls(**kwargs)
    except ModelConfigError as e:
        raise ModelConfigError(f"{source}: {e}") from None


def model_config(model: nn.Module) -> dict:
    """The config `model` was built from (build_model(model_config(m)) rebuilds its architecture)."""
    if not isinstance(getattr(model, "config", None), dict):
        raise ModelConfigError(f"model = {type(model).__name__}: expected one of {', '.join(MODELS)} "
                               f"(a module with a config)")
    return dict(model.config)


def load_config(path) -> dict:
    """A model config from a TOML file (top-level keys: `type` and the model's arguments), checked by
    building the model on the meta device (no memory, no compute)."""
    config = read_toml(path, ModelConfigError, "model config")
    with torch.device("meta"):
        build_model(config, source=str(Path(path)))
    return config
