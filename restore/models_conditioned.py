"""A restorer conditioned on the panel's description (restore.conditioning): `WienerUNet`, type 'wiener-unet'.

Packed RAW x [N, 4, h, w] and the description's tensors in, RGB [N, 3, 2h, 2w] out. Three parts:

- **Deconvolved features** (deep Wiener deconvolution, Dong et al., NeurIPS 2020). Maps of the capture, each packed
  channel's own plane w_c and `wiener_features` learnt 3 × 3 filters of it (a grouped convolution), are
  deconvolved in the Fourier domain with that channel's kernel (R: kernel 0; Gr, Gb: kernel 1; B: kernel 2):
      X̂ = conj(K) U / (|K|² + NSR),   NSR(f) = var_c · |f|² / (s_m · μ_c²) + NSR_FLOOR,
  then divided by γ_c. var_c = λ_read,c + λ_shot,c · μ_c is the description's noise at the crop's mean level
  μ_c = mean(w_c); the signal's prior is a natural image's 1/|f|² spectrum (f in cycles per packed pixel) of
  scale s_m μ_c², a learnt s_m per map (log_prior, initialised at PRIOR_SCALE). A filter g scales the signal's
  and the white noise's spectra alike (|G|²), so every map of channel c has channel c's NSR up to s_m. The maps
  are mirrored by the kernel's half-width (K // 2) on every side before the transform (K ≥ the crop allowed: a
  64-px packed crop against the 129-px window) and cropped back: the circular transform then wraps the mirror,
  not the opposite edge.
- **Kernel codes** (DISCNet, Feng et al., CVPR 2021). A small encoder of log10 of the kernels and of their
  transfer functions' moduli (three stride-2 convolutions, 4 × 4 average pooling) and the scalars (log γ, log gain,
  log10 λ_read and λ_shot, log saturation, the share outside the window) gives a code of `code_dim`; at every level
  of the UNet it scales and shifts the features (FiLM: a · (1 + scale) + shift, zero at initialisation).
- **The backbone**: the paper's UNet topology (restore.models.UNet: SID levels, a second sub-encoder over the
  first depth − 1 levels) on [x / γ, the deconvolved features], its `fine_levels` finest levels
  `fine_extra_width` channels wider: the band of the T-OLED's horizontal null (0.037–0.121 cycle/px) is
  carried by those levels alone (issue 47, item 1).

`wiener` and `kernel_codes` switch the two conditionings off for the ablation (with both off the description gives
the input's level alone: x / γ). `kernel_px`: the
descriptions' kernel window (packed px, udc_render.description; 129 by default, smaller for a narrow blur).
`description_spec` (udc_render.description.DescriptionSpec as a dict) is what training records of its data
(restore.conditioning.described_spec); evaluation refuses a description made for another sensor or frame.
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from restore.models import MODELS, _conv_block, _require, unet_pass
from udc_render.description import DESCRIPTION_KERNEL_PX

KERNEL_OF_CHANNEL = (0, 1, 1, 2)  # packed R, Gr, Gb, B → the description's kernels R, G, B
PRIOR_SCALE = 0.01  # s: a 1/|f|² spectrum of variance ≈ 2π s ln(0.5 / f_min) ≈ (0.5 μ)² over 0.002–0.5 cycle/px
NSR_FLOOR = 1e-4  # |K|² + NSR ≥ 1e-4: a null of the kernel is amplified at most 50×
LOG_KERNEL_FLOOR = 1e-8  # log10 of the kernels from 1e-8 (−8) to 1 (0)
MTF_FLOOR = 1e-4  # log10 of |K(f)| from 1e-4 (−4) to 1 (0)
N_SCALARS = 17  # log γ [4], log gain, log10 λ_read [4], log10 λ_shot [4], log saturation, outside [3]


def mirror_index(n: int, pad: int, device=None) -> torch.Tensor:
    """Indices of -pad … n + pad − 1 mirrored into 0 … n − 1 (half-sample symmetric, any pad: period 2n)."""
    i = torch.arange(-pad, n + pad, device=device) % (2 * n)
    return torch.where(i >= n, 2 * n - 1 - i, i)


def kernel_spectra(kernels: torch.Tensor, shape: tuple[int, int]) -> torch.Tensor:
    """rfft2 of kernels [..., K, K] centred at K // 2, placed on a `shape` grid (≥ K) with the centre at (0, 0)."""
    k = kernels.shape[-1]
    grid = F.pad(kernels, (0, shape[1] - k, 0, shape[0] - k))
    return torch.fft.rfft2(torch.roll(grid, (-(k // 2), -(k // 2)), (-2, -1)))


def wiener_deconvolve(maps: torch.Tensor, spectra: torch.Tensor, nsr_scale: torch.Tensor) -> torch.Tensor:
    """X̂ = conj(K) U / (|K|² + nsr_scale · |f|² + NSR_FLOOR) of maps [B, M, h, w], mirrored by K // 2 and cropped
    back (module doc). spectra: [B, M, H, W // 2 + 1] of kernel_spectra on the mirrored grid (H = h + 2 (K // 2));
    nsr_scale [B, M]: var / (s μ²)."""
    h, w = maps.shape[-2:]
    big_h = spectra.shape[-2]
    pad = (big_h - h) // 2
    u = maps[..., mirror_index(h, pad, maps.device), :][..., mirror_index(w, pad, maps.device)]
    fy = torch.fft.fftfreq(u.shape[-2], device=maps.device)
    fx = torch.fft.rfftfreq(u.shape[-1], device=maps.device)
    f2 = fy[:, None] ** 2 + fx[None, :] ** 2
    nsr = nsr_scale[:, :, None, None] * f2 + NSR_FLOOR
    x = torch.fft.irfft2(spectra.conj() * torch.fft.rfft2(u) / (spectra.abs() ** 2 + nsr), s=u.shape[-2:])
    return x[..., pad:pad + h, pad:pad + w]


class WienerFeatures(nn.Module):
    """The capture's planes and `features` learnt filters of each, deconvolved with their channel's kernel and
    divided by its γ (module doc): [N, 4, h, w] → [N, 4 (1 + features), h, w]."""

    def __init__(self, features: int):
        super().__init__()
        self.extract = nn.Conv2d(4, 4 * features, 3, padding=1, groups=4, bias=False) if features else None
        channel = list(range(4)) + [c for c in range(4) for _ in range(features)]  # grouped outputs: by channel
        self.register_buffer("channel", torch.tensor(channel), persistent=False)
        self.log_prior = nn.Parameter(torch.full((len(channel),), math.log(PRIOR_SCALE)))

    @property
    def maps(self) -> int:
        return len(self.channel)

    def forward(self, x: torch.Tensor, description: dict) -> torch.Tensor:
        maps = x if self.extract is None else torch.cat([x, self.extract(x)], 1)
        with torch.autocast("cuda" if x.is_cuda else "cpu", enabled=False):  # the transforms in float32
            maps, c = maps.float(), self.channel
            mu = x.float().mean((-2, -1)).clamp_min(1e-4)  # [N, 4] the crop's level per channel
            var = description["lambda_read"] + description["lambda_shot"] * mu
            nsr_scale = (var / mu ** 2)[:, c] * torch.exp(-self.log_prior)
            k = description["kernels"]
            shape = (x.shape[-2] + 2 * (k.shape[-1] // 2), x.shape[-1] + 2 * (k.shape[-1] // 2))
            spectra = kernel_spectra(k.float(), shape)[:, list(KERNEL_OF_CHANNEL)][:, c]
            out = wiener_deconvolve(maps, spectra, nsr_scale)
            return out / description["gamma"][:, c, None, None].clamp_min(1e-6)


def description_scalars(description: dict) -> torch.Tensor:
    """[N, N_SCALARS]: log γ, log gain, log10 λ_read, log10 λ_shot (from 1e-12), log saturation, outside."""
    d = description
    return torch.cat([d["gamma"].clamp_min(1e-6).log(), d["gain"].clamp_min(1e-6).log()[:, None],
                      d["lambda_read"].clamp_min(1e-12).log10(), d["lambda_shot"].clamp_min(1e-12).log10(),
                      d["saturation"].clamp_min(1e-6).log()[:, None], d["outside"]], 1)


class KernelEncoder(nn.Module):
    """The description's code (module doc): the kernels [N, 3, K, K] as log10 k (from LOG_KERNEL_FLOOR) and log10
    of their transfer functions' moduli |K(f)| (from MTF_FLOOR, zero frequency at the centre), each scaled to
    [0, 1], and the scalars → [N, code_dim]."""

    def __init__(self, code_dim: int, negative_slope: float):
        super().__init__()
        act = nn.LeakyReLU(negative_slope)
        self.kernel = nn.Sequential(nn.Conv2d(6, 16, 5, stride=2, padding=2), act,
                                    nn.Conv2d(16, 32, 3, stride=2, padding=1), act,
                                    nn.Conv2d(32, 32, 3, stride=2, padding=1), act,
                                    nn.AdaptiveAvgPool2d(4), nn.Flatten())
        self.mlp = nn.Sequential(nn.Linear(32 * 16 + N_SCALARS, 128), act, nn.Linear(128, code_dim), act)

    def forward(self, description: dict) -> torch.Tensor:
        k = description["kernels"].float()
        logk = k.clamp_min(LOG_KERNEL_FLOOR).log10() / -math.log10(LOG_KERNEL_FLOOR) + 1
        mtf = torch.fft.fftshift(torch.fft.fft2(k).abs(), dim=(-2, -1))
        logm = mtf.clamp_min(MTF_FLOOR).log10() / -math.log10(MTF_FLOOR) + 1
        return self.mlp(torch.cat([self.kernel(torch.cat([logk, logm], 1)), description_scalars(description)], 1))


class FiLM(nn.Module):
    """a · (1 + scale) + shift with (scale, shift) a linear map of the code; zero at initialisation."""

    def __init__(self, code_dim: int, channels: int):
        super().__init__()
        self.linear = nn.Linear(code_dim, 2 * channels)
        nn.init.zeros_(self.linear.weight)
        nn.init.zeros_(self.linear.bias)

    def forward(self, a: torch.Tensor, code: torch.Tensor | None) -> torch.Tensor:
        if code is None:
            return a
        scale, shift = self.linear(code)[:, :, None, None].chunk(2, dim=1)
        return a * (1 + scale) + shift


class WienerUNet(nn.Module):
    """The paper's UNet topology on the capture and its deconvolved features, modulated by kernel codes, wider at
    its finest levels (module doc). packed RAW [N, 4, h, w] + description → RGB [N, 3, 2h, 2w]."""

    TYPE = "wiener-unet"
    NEEDS_DESCRIPTION = True

    def __init__(self, out_channels: int = 3, width: int = 32, depth: int = 5, fine_levels: int = 2,
                 fine_extra_width: int = 32, sub_encoders: int = 2, wiener: bool = True, wiener_features: int = 4,
                 kernel_codes: bool = True, code_dim: int = 64, negative_slope: float = 0.2,
                 kernel_px: int = DESCRIPTION_KERNEL_PX, description_spec: dict | None = None):
        super().__init__()
        for key, value in (("out_channels", out_channels), ("width", width), ("depth", depth),
                           ("code_dim", code_dim)):
            _require(value >= 1, key, value, "an integer >= 1")
        _require(0 <= fine_levels <= depth, "fine_levels", fine_levels, f"0 to depth = {depth}")
        for key, value in (("fine_extra_width", fine_extra_width), ("wiener_features", wiener_features)):
            _require(value >= 0, key, value, "an integer >= 0")
        _require(sub_encoders in (1, 2), "sub_encoders", sub_encoders, "1 or 2")
        _require(negative_slope >= 0, "negative_slope", negative_slope, "a number >= 0")
        _require(kernel_px >= 3 and kernel_px % 2 == 1, "kernel_px", kernel_px, "an odd integer >= 3")
        self.kernel_px = kernel_px
        self.config = {"type": self.TYPE, "out_channels": out_channels, "width": width, "depth": depth,
                       "fine_levels": fine_levels, "fine_extra_width": fine_extra_width, "sub_encoders": sub_encoders,
                       "wiener": wiener, "wiener_features": wiener_features, "kernel_codes": kernel_codes,
                       "code_dim": code_dim, "negative_slope": negative_slope, "kernel_px": kernel_px}
        self.description_spec = None
        if description_spec is not None:
            self.set_description_spec(description_spec)
        self.wiener = WienerFeatures(wiener_features) if wiener else None
        self.codes = KernelEncoder(code_dim, negative_slope) if kernel_codes else None
        ch = [width * 2 ** i + (fine_extra_width if i < fine_levels else 0) for i in range(depth)]
        cin = [4 + (self.wiener.maps if wiener else 0)] + ch[:-1]
        levels = max(depth - 1, 1) if sub_encoders == 2 else 0
        self.encoder = nn.ModuleList(_conv_block(cin[i], ch[i], negative_slope) for i in range(depth))
        self.residual_encoder = nn.ModuleList(_conv_block(cin[i], ch[i], negative_slope) for i in range(levels))
        self.up = nn.ModuleList(nn.ConvTranspose2d(ch[i + 1], ch[i], 2, stride=2) for i in range(depth - 1))
        self.decoder = nn.ModuleList(_conv_block(2 * ch[i], ch[i], negative_slope) for i in range(depth - 1))
        self.film_encoder = nn.ModuleList(FiLM(code_dim, c) for c in ch) if kernel_codes else None
        self.film_decoder = nn.ModuleList(FiLM(code_dim, c) for c in ch[:-1]) if kernel_codes else None
        self.to_rgb = nn.Sequential(nn.Conv2d(ch[0], 4 * out_channels, 1), nn.PixelShuffle(2))

    def set_description_spec(self, spec: dict) -> None:
        """The DescriptionSpec (as a dict) of the descriptions it is trained on: kept in its config."""
        self.description_spec = dict(spec)
        self.config["description_spec"] = dict(spec)

    def inputs(self, x: torch.Tensor, description: dict) -> torch.Tensor:
        """[x / γ, the deconvolved features] [N, 4 + maps, h, w]."""
        scaled = x / description["gamma"][:, :, None, None].clamp_min(1e-6)
        return scaled if self.wiener is None else torch.cat([scaled, self.wiener(x, description).to(x.dtype)], 1)

    def forward(self, x: torch.Tensor, description: dict) -> torch.Tensor:
        code = None if self.codes is None else self.codes(description)

        def film(kind: str, i: int, a: torch.Tensor) -> torch.Tensor:
            films = self.film_encoder if kind == "encoder" else self.film_decoder
            return a if films is None else films[i](a, code)
        return unet_pass(self, self.inputs(x, description), film)


MODELS[WienerUNet.TYPE] = WienerUNet
WIENER_UNET_CONFIG = {"type": "wiener-unet", "out_channels": 3, "width": 32, "depth": 5, "fine_levels": 2,
                      "fine_extra_width": 32, "sub_encoders": 2, "wiener": True, "wiener_features": 4,
                      "kernel_codes": True, "code_dim": 64, "negative_slope": 0.2, "kernel_px": DESCRIPTION_KERNEL_PX}
"""The conditioned restorer's defaults (parameters and MACs: tests/restore/test_models_conditioned.py)."""
