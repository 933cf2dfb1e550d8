"""The sensor of the online degradation (restore.degrade), in torch: udc_render.sensor's capture of mean electrons,
in the packed RGGB layout [4, h/2, w/2] (R, Gr, Gb, B) of a crop of a frame.

    q = e · (1 + PRNU z) + D t,  o = DSNU u + σ_row r_i + σ_col c_j           fixed-pattern noise (sensor.fpn)
    poisson:  DN = black + g · min(Poisson(q) + σ_read N + o, FW)
    gaussian: w = g q / R,  DN = black + R · min(w + N √(λ_read + λ_shot w) + g o / R, g FW / R)
    none:     DN = black + g · min(q + o, FW)
    DN rounded (half to even, as numpy's rint), clipped to [0, white]; dead pixels read black, hot ones add
    g · hot_dark_e_per_s · t, capped at min(white, black + g FW)                     (sensor.noise, sensor.defects)

The FPN maps and the defect map are the sensor's, of the whole frame: drawn with the seeds and generators of
sensor.fpn.fpn_maps and sensor.defects.defect_map (numpy, once per frame size and seed: FrameMaps, packed; the
tests check they equal those functions' maps), each crop taking its region. The noise comes from a torch generator
on the crop's device, or from an explicit NoiseDraw (the numpy path's own draws, for the equality tests).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from udc_render.dataset.bank import Panel
from udc_render.sensor.bayer import SITES
from udc_render.sensor.defects import DEAD, HOT, DefectConfig, defect_map
from udc_render.sensor.fpn import CHARGE_CAP_E, FpnConfig
from udc_render.sensor.noise import (BROOKS_LOG_SHOT_RANGE, BROOKS_READ_INTERCEPT, BROOKS_READ_SIGMA,
                                     BROOKS_READ_SLOPE, noise_lambdas)


def packed_sites(a: torch.Tensor) -> torch.Tensor:
    """[3, h, w] camera RGB → [4, h/2, w/2] the value of each RGGB site's colour at that site (R, Gr, Gb, B);
    a [1, h, w] or [h, w] map → its four site planes."""
    if a.dim() == 2:
        a = a[None]
    colour = (0, 1, 1, 2) if a.shape[0] == 3 else (0, 0, 0, 0)
    return torch.stack([a[c, i::2, j::2] for c, (i, j) in zip(colour, SITES)])


@dataclass(frozen=True)
class NoiseDraw:
    """An explicit noise draw of one capture, packed [4, h/2, w/2]: shot_e, the Poisson counts (noise 'poisson');
    normal, the standard normals (the read noise of 'poisson', the Gaussian model's N); lambdas, the Gaussian
    model's (λ_read [4], λ_shot [4]) when drawn ('brooks'). None: not needed, or drawn from the generator."""
    shot_e: torch.Tensor | None = None
    normal: torch.Tensor | None = None
    lambdas: tuple | None = None


class FrameMaps:
    """The sensor's frame maps on a device, packed [4, H/2, W/2] once per frame size and seed (a crop takes a slice):
    the FPN's standard normals (sensor.fpn.fpn_maps' draws) and the defect classes (sensor.defects.defect_map's)."""

    def __init__(self, device: torch.device, dtype: torch.dtype):
        self.device, self.dtype = device, dtype
        self._fpn: dict = {}
        self._defects: dict = {}

    def _fpn_normals(self, frame_hw: tuple[int, int], seed: int) -> tuple:
        """(z, u [4, H/2, W/2], rows [4, H/2, 1], columns [4, 1, W/2]) packed."""
        key = (tuple(frame_hw), seed)
        if key not in self._fpn:  # sensor.fpn.fpn_maps' draws
            h, w = frame_hw
            rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4)]
            z, u = rngs[0].standard_normal((h, w)), rngs[1].standard_normal((h, w))
            r, c = rngs[2].standard_normal(h), rngs[3].standard_normal(w)
            rows, cols = np.broadcast_to(r[:, None], (h, 2)), np.broadcast_to(c[None, :], (2, w))
            self._fpn[key] = tuple(packed_sites(torch.as_tensor(np.ascontiguousarray(a), device=self.device)
                                                .to(self.dtype)) for a in (z, u, rows, cols))
        return self._fpn[key]

    def fpn(self, frame_hw, origin_yx, size_hw, fpn: FpnConfig) -> tuple[torch.Tensor, torch.Tensor]:
        """(gain 1 + PRNU z ≥ 0, offset DSNU u + σ_row r_i + σ_col c_j in e⁻) of the crop, packed."""
        z, u, r, c = self._fpn_normals(frame_hw, fpn.seed)
        ys, xs = _packed_slices(origin_yx, size_hw)
        gain = torch.clamp_min(1.0 + fpn.prnu * z[:, ys, xs], 0.0)
        return gain, fpn.dsnu_e * u[:, ys, xs] + fpn.row_offset_e * r[:, ys] + fpn.column_offset_e * c[:, :, xs]

    def defect_classes(self, frame_hw, origin_yx, size_hw, defects: DefectConfig) -> torch.Tensor:
        """The crop's defect classes, packed int8: 0 good, 1 dead, 2 hot (sensor.defects.defect_map)."""
        key = (tuple(frame_hw), defects.seed, defects.dead_fraction, defects.hot_fraction)
        if key not in self._defects:
            classes = defect_map(*frame_hw, defects)
            self._defects[key] = packed_sites(torch.as_tensor(classes, device=self.device))
        return self._defects[key][(slice(None),) + _packed_slices(origin_yx, size_hw)]


def _packed_slices(origin_yx, size_hw) -> tuple[slice, slice]:
    """The packed rows and columns of a crop starting on an R site (even origin)."""
    (y0, x0), (h, w) = origin_yx, size_hw
    return slice(y0 // 2, (y0 + h) // 2), slice(x0 // 2, (x0 + w) // 2)


def _normal(shape, like: torch.Tensor, generator, given: torch.Tensor | None) -> torch.Tensor:
    if given is not None:
        return given.to(like.device, like.dtype)
    return torch.randn(shape, generator=generator, device=like.device, dtype=like.dtype)


def gaussian_lambdas(sensor, generator, device) -> tuple[tuple, tuple]:
    """(λ_read [4], λ_shot [4]) of the Gaussian model (sensor.noise.noise_lambdas), Brooks et al.'s drawn from the
    torch generator (log λ_shot ~ U, log λ_read ~ N(2.18 log λ_shot + 1.20, 0.26²))."""
    if sensor.lambda_source != "brooks":
        return noise_lambdas(sensor, None)
    n = 4 if sensor.brooks_per_channel else 1
    lo, hi = BROOKS_LOG_SHOT_RANGE
    log_shot = lo + (hi - lo) * torch.rand(n, generator=generator, device=device, dtype=torch.float64)
    log_read = (BROOKS_READ_SLOPE * log_shot + BROOKS_READ_INTERCEPT
                + BROOKS_READ_SIGMA * torch.randn(n, generator=generator, device=device, dtype=torch.float64))
    read, shot = (torch.exp(v).cpu().numpy().repeat(4 // n) for v in (log_read, log_shot))
    return tuple(map(float, read)), tuple(map(float, shot))


def expose_packed(e: torch.Tensor, panel: Panel, maps: FrameMaps, frame_hw, origin_yx,
                  generator: torch.Generator | None = None, draw: NoiseDraw | None = None) -> torch.Tensor:
    """Packed DN [4, h/2, w/2] of the mean electrons e [4, h/2, w/2] of a crop at origin_yx of a frame_hw sensor
    (module doc; sensor.noise.expose and sensor.defects.apply_defects in torch)."""
    s, draw = panel.sensor, draw or NoiseDraw()
    g, black, R, fw = s.dn_per_electron, s.black_level_dn, s.range_dn, s.full_well_e
    size = (2 * e.shape[-2], 2 * e.shape[-1])
    e = torch.nan_to_num(e, nan=0.0, posinf=torch.finfo(e.dtype).max)
    off = None
    if panel.fpn is not None:
        gain_map, off = maps.fpn(frame_hw, origin_yx, size, panel.fpn)
        e = torch.clamp_max(e, CHARGE_CAP_E) * gain_map + panel.fpn.dark_charge_e(s.exposure_s)
    if s.noise == "poisson":
        cap = 2 * fw + 100 + 40 * s.read_noise_e
        n = (draw.shot_e if draw.shot_e is not None
             else torch.poisson(torch.clamp_max(e, cap), generator=generator)).to(e.device, e.dtype)
        if s.read_noise_e > 0:
            n = n + s.read_noise_e * _normal(e.shape, e, generator, draw.normal)
        if off is not None:
            n = n + off
        sig = black + g * torch.clamp_max(n, fw)
    elif s.noise == "gaussian":
        lam_read, lam_shot = draw.lambdas or gaussian_lambdas(s, generator, e.device)
        cap = 2 * (g * fw / R) + 1600 * max(lam_shot) + 40 * math.sqrt(max(lam_read))
        w = torch.clamp_max(g * e / R, cap)
        lr, ls = (torch.as_tensor(v, device=e.device, dtype=e.dtype)[:, None, None] for v in (lam_read, lam_shot))
        y = w + _normal(e.shape, e, generator, draw.normal) * torch.sqrt(lr + ls * w)
        if off is not None:
            y = y + (g / R) * off
        sig = black + R * torch.clamp_max(y, g * fw / R)
    else:
        sig = black + g * torch.clamp_max(e if off is None else e + off, fw)
    dn = torch.clamp(torch.round(sig), 0, s.white_level_dn)
    return dn if panel.defects is None else _defects(dn, panel.defects, s, maps, frame_hw, origin_yx, size)


def _defects(dn: torch.Tensor, defects: DefectConfig, s, maps: FrameMaps, frame_hw, origin_yx, size) -> torch.Tensor:
    """Dead pixels at black, hot ones + g · hot charge, capped (sensor.defects.apply_defects)."""
    kind = maps.defect_classes(frame_hw, origin_yx, size, defects)
    g = s.dn_per_electron
    top = min(float(s.white_level_dn), s.black_level_dn + g * s.full_well_e)
    level = torch.clamp(torch.round(torch.clamp_max(dn + g * defects.hot_charge_e(s.exposure_s), top)), 0,
                        s.white_level_dn)
    return torch.where(kind == DEAD, s.black_level_dn, torch.where(kind == HOT, level, dn))
