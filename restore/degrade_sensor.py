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

from restore.tensors import host_to, per_crop
from udc_render.dataset.bank import Panel
from udc_render.sensor.bayer import SITES
from udc_render.sensor.defects import DEAD, HOT, DefectConfig, defect_map
from udc_render.sensor.fpn import CHARGE_CAP_E, FpnConfig
from udc_render.sensor.noise import (BROOKS_LOG_SHOT_RANGE, BROOKS_READ_INTERCEPT, BROOKS_READ_SIGMA,
                                     BROOKS_READ_SLOPE, noise_lambdas)


def packed_sites(a: torch.Tensor) -> torch.Tensor:
    """[..., 3, h, w] camera RGB → [..., 4, h/2, w/2] the value of each RGGB site's colour at that site (R, Gr, Gb,
    B); a [..., 1, h, w] or [h, w] map → its four site planes."""
    if a.dim() == 2:
        a = a[None]
    colour = (0, 1, 1, 2) if a.shape[-3] == 3 else (0, 0, 0, 0)
    return torch.stack([a[..., c, i::2, j::2] for c, (i, j) in zip(colour, SITES)], dim=-3)


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

    def fpn(self, crops: list, size_hw, fpns: list[FpnConfig]) -> tuple[torch.Tensor, torch.Tensor]:
        """(gain 1 + PRNU z ≥ 0, offset DSNU u + σ_row r_i + σ_col c_j in e⁻) [B, 4, h/2, w/2] of crops
        [(frame_hw, origin_yx)] of size_hw, packed, each with its sensor's FpnConfig."""
        parts = []
        for (frame_hw, origin_yx), fpn in zip(crops, fpns):
            z, u, r, c = self._fpn_normals(frame_hw, fpn.seed)
            ys, xs = _packed_slices(origin_yx, size_hw)
            parts.append((z[:, ys, xs], u[:, ys, xs], r[:, ys], c[:, :, xs]))
        z, u, r, c = (torch.stack(a) for a in zip(*parts))
        prnu, dsnu, rows, cols = per_crop([(f.prnu, f.dsnu_e, f.row_offset_e, f.column_offset_e) for f in fpns],
                                          z).unbind(1)
        gain = torch.clamp_min(1.0 + prnu[:, None] * z, 0.0)
        return gain, dsnu[:, None] * u + rows[:, None] * r + cols[:, None] * c

    def defect_classes(self, crops: list, size_hw, defects: list[DefectConfig]) -> torch.Tensor:
        """The crops' defect classes [B, 4, h/2, w/2], packed int8: 0 good, 1 dead, 2 hot
        (sensor.defects.defect_map)."""
        out = []
        for (frame_hw, origin_yx), d in zip(crops, defects):
            key = (tuple(frame_hw), d.seed, d.dead_fraction, d.hot_fraction)
            if key not in self._defects:
                classes = defect_map(*frame_hw, d)
                self._defects[key] = packed_sites(torch.as_tensor(classes, device=self.device))
            out.append(self._defects[key][(slice(None),) + _packed_slices(origin_yx, size_hw)])
        return torch.stack(out)


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


def _kind(panel: Panel) -> tuple:
    """What decides a crop's sensor operations (not their numbers): crops alike are exposed as one batch."""
    return panel.sensor.noise, panel.fpn is None, panel.defects is None


def expose_batch(e: torch.Tensor, panels: list[Panel], maps: FrameMaps, crops: list,
                 generators: list | None = None, draws: list | None = None) -> torch.Tensor:
    """Packed DN [B, 4, h/2, w/2] of the mean electrons e [B, 4, h/2, w/2] of crops [(frame_hw, origin_yx)], crop b
    behind panels[b]'s sensor, its noise from generators[b] (on e's device) or the explicit draws[b] (module doc;
    sensor.noise.expose and sensor.defects.apply_defects in torch). Crops whose sensors work alike (_kind) go
    through as one batch, their numbers per crop; a crop's draws come from its own generator alone, so that a crop
    gets the same numbers in any batch."""
    n = e.shape[0]
    generators, draws = generators or [None] * n, [d or NoiseDraw() for d in (draws or [None] * n)]
    groups: dict = {}
    for b, p in enumerate(panels):
        groups.setdefault(_kind(p), []).append(b)
    if len(groups) == 1:
        return _expose_alike(e, panels, maps, crops, generators, draws)
    out = torch.empty_like(e)
    for members in groups.values():
        pick = lambda seq: [seq[b] for b in members]  # noqa: E731
        idx = host_to(torch.tensor(members), e.device)
        out[idx] = _expose_alike(e[idx], pick(panels), maps, pick(crops), pick(generators), pick(draws))
    return out


def _expose_alike(e, panels, maps, crops, generators, draws) -> torch.Tensor:
    """expose_batch for crops of one _kind."""
    s0, sensors = panels[0].sensor, [p.sensor for p in panels]
    size = (2 * e.shape[-2], 2 * e.shape[-1])
    g, black, fw = (per_crop([getattr(s, k) for s in sensors], e) for k in ("dn_per_electron", "black_level_dn",
                                                                             "full_well_e"))
    e = torch.nan_to_num(e, nan=0.0, posinf=torch.finfo(e.dtype).max)
    off = None
    if panels[0].fpn is not None:
        gain_map, off = maps.fpn(crops, size, [p.fpn for p in panels])
        dark = per_crop([p.fpn.dark_charge_e(p.sensor.exposure_s) for p in panels], e)
        e = torch.clamp_max(e, CHARGE_CAP_E) * gain_map + dark
    if s0.noise == "poisson":
        caps = [2 * s.full_well_e + 100 + 40 * s.read_noise_e for s in sensors]
        n = torch.stack([d.shot_e.to(e.device, e.dtype) if d.shot_e is not None
                         else torch.poisson(torch.clamp_max(eb, cap), generator=gen)
                         for eb, cap, gen, d in zip(e, caps, generators, draws)])
        if any(s.read_noise_e > 0 for s in sensors):
            normal = torch.stack([_normal(eb.shape, eb, gen, d.normal) if s.read_noise_e > 0 else torch.zeros_like(eb)
                                  for eb, gen, d, s in zip(e, generators, draws, sensors)])
            n = n + per_crop([s.read_noise_e for s in sensors], e) * normal
        if off is not None:
            n = n + off
        sig = black + g * torch.minimum(n, fw)
    elif s0.noise == "gaussian":
        lam = [d.lambdas or gaussian_lambdas(s, gen, e.device) for s, gen, d in zip(sensors, generators, draws)]
        R = per_crop([s.range_dn for s in sensors], e)
        cap = per_crop([2 * (s.dn_per_electron * s.full_well_e / s.range_dn) + 1600 * max(ls) + 40 * math.sqrt(max(lr))
                        for s, (lr, ls) in zip(sensors, lam)], e)
        w = torch.minimum(g * e / R, cap)
        lr, ls = (per_crop([v[i] for v in lam], e) for i in (0, 1))
        normal = torch.stack([_normal(eb.shape, eb, gen, d.normal) for eb, gen, d in zip(e, generators, draws)])
        y = w + normal * torch.sqrt(lr + ls * w)
        if off is not None:
            y = y + per_crop([s.dn_per_electron / s.range_dn for s in sensors], e) * off
        top = per_crop([s.dn_per_electron * s.full_well_e / s.range_dn for s in sensors], e)
        sig = black + R * torch.minimum(y, top)
    else:
        sig = black + g * torch.minimum(e if off is None else e + off, fw)
    white = per_crop([s.white_level_dn for s in sensors], e)
    dn = torch.clamp(torch.round(sig), torch.zeros_like(white), white)
    return dn if panels[0].defects is None else _defects(dn, panels, maps, crops, size, black, white)


def _defects(dn: torch.Tensor, panels, maps: FrameMaps, crops, size, black, white) -> torch.Tensor:
    """Dead pixels at black, hot ones + g · hot charge, capped (sensor.defects.apply_defects)."""
    kind = maps.defect_classes(crops, size, [p.defects for p in panels])
    sensors = [p.sensor for p in panels]
    hot = per_crop([s.dn_per_electron * p.defects.hot_charge_e(s.exposure_s) for s, p in zip(sensors, panels)], dn)
    top = per_crop([min(float(s.white_level_dn), s.black_level_dn + s.dn_per_electron * s.full_well_e)
                    for s in sensors], dn)
    level = torch.clamp(torch.round(torch.minimum(dn + hot, top)), torch.zeros_like(white), white)
    return torch.where(kind == DEAD, black, torch.where(kind == HOT, level, dn))
