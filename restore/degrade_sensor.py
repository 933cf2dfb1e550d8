"""The sensor of the online degradation (restore.degrade), in torch: udc_render.sensor's capture of mean electrons,
in the packed RGGB layout [4, h/2, w/2] (R, Gr, Gb, B) of a crop of a frame.

    q = e · (1 + PRNU z) + D t,  o = DSNU u + σ_row r_i + σ_col c_j           fixed-pattern noise (sensor.fpn)
    poisson:  DN = black + g · min(Poisson(q) + σ_read N + o, FW)
    gaussian: w = g q / R,  DN = black + R · min(w + N √(λ_read + λ_shot w) + g o / R, g FW / R)
    none:     DN = black + g · min(q + o, FW)
    DN rounded (half to even, as numpy's rint), clipped to [0, white]; dead pixels read black, hot ones add
    g · hot_dark_e_per_s · t, capped at min(white, black + g FW)                     (sensor.noise, sensor.defects)

One model: every formula above is udc_render.sensor.readout's, the very functions the numpy synthesis runs (on
any array namespace); this module lays a batch's per-crop parameters out as columns, draws the random numbers
from each crop's torch generator on its device (or takes an explicit NoiseDraw: the numpy path's own draws, for
the equality tests) and holds the frame maps.

The FPN maps and the defect map are the sensor's, of the whole frame: the standard normals of
sensor.fpn.fpn_normals and the classes of sensor.defects.defect_map (numpy, once per frame size and seed:
FrameMaps, packed; the tests check they equal those functions' maps), each crop taking its region. A panel
whose maps are drawn per crop (Panel.maps == 'crop': a capture of its own, restore.captures) has maps of the
crop's own size from its own seeds instead, drawn for the crop and not kept.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from restore.tensors import host_to, per_crop
from udc_render.dataset.bank import Panel
from udc_render.sensor import (
    SITES,
    DefectConfig,
    FpnConfig,
    defect_levels,
    defect_map,
    fpn_normals,
    noise_lambdas,
    readout,
)


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


def _packed(a: np.ndarray, device, dtype) -> torch.Tensor:
    return packed_sites(torch.as_tensor(np.ascontiguousarray(a), device=device).to(dtype))


class FrameMaps:
    """The sensor's frame maps on a device, packed [4, H/2, W/2] once per frame size and seed (a crop takes a slice):
    the FPN's standard normals (sensor.fpn.fpn_normals) and the defect classes (sensor.defects.defect_map); a
    panel whose maps are drawn per crop (Panel.maps 'crop') gets maps of the crop's size, not kept."""

    def __init__(self, device: torch.device, dtype: torch.dtype):
        self.device, self.dtype = device, dtype
        self._fpn: dict = {}
        self._defects: dict = {}

    def _fpn_normals(self, size_hw: tuple[int, int], seed: int) -> tuple:
        """(z, u [4, H/2, W/2], rows [4, H/2, 1], columns [4, 1, W/2]) packed, of a sensor of size_hw."""
        h, w = size_hw
        z, u, r, c = fpn_normals(h, w, seed)
        rows, cols = np.broadcast_to(r[:, None], (h, 2)), np.broadcast_to(c[None, :], (2, w))
        return tuple(_packed(a, self.device, self.dtype) for a in (z, u, rows, cols))

    def _normals_of(self, crop, size_hw, seed: int, own: bool) -> tuple:
        """The crop's FPN normals: its region of the frame's (kept), or its own (own: maps of the crop's size)."""
        (frame_hw, origin_yx) = crop
        if own:
            return self._fpn_normals(tuple(size_hw), seed)
        key = (tuple(frame_hw), seed)
        if key not in self._fpn:
            self._fpn[key] = self._fpn_normals(tuple(frame_hw), seed)
        z, u, r, c = self._fpn[key]
        ys, xs = _packed_slices(origin_yx, size_hw)
        return z[:, ys, xs], u[:, ys, xs], r[:, ys], c[:, :, xs]

    def fpn(self, crops: list, size_hw, fpns: list[FpnConfig], own: list[bool] | None = None
            ) -> tuple[torch.Tensor, torch.Tensor]:
        """(gain (1 + PRNU z)⁺, offset DSNU u + σ_row r_i + σ_col c_j in e⁻) [B, 4, h/2, w/2] of crops
        [(frame_hw, origin_yx)] of size_hw, packed, each with its sensor's FpnConfig (own[b]: the crop's own
        maps; sensor.readout.fpn_gain, fpn_offset_e)."""
        own = own or [False] * len(crops)
        z, u, r, c = (torch.stack(a) for a in zip(*(self._normals_of(crop, size_hw, f.seed, o)
                                                     for crop, f, o in zip(crops, fpns, own))))
        prnu, dsnu, rows, cols = per_crop([(f.prnu, f.dsnu_e, f.row_offset_e, f.column_offset_e) for f in fpns],
                                          z).unbind(1)
        return (readout.fpn_gain(z, prnu[:, None]),
                readout.fpn_offset_e(u, r, c, dsnu[:, None], rows[:, None], cols[:, None]))

    def defect_classes(self, crops: list, size_hw, defects: list[DefectConfig], own: list[bool] | None = None
                       ) -> torch.Tensor:
        """The crops' defect classes [B, 4, h/2, w/2], packed int8: 0 good, 1 dead, 2 hot
        (sensor.defects.defect_map of the frame, its region; own[b]: of the crop's own size)."""
        own = own or [False] * len(crops)
        out = []
        for (frame_hw, origin_yx), d, o in zip(crops, defects, own):
            if o:
                out.append(packed_sites(torch.tensor(defect_map(*size_hw, d), device=self.device)))
                continue
            key = (tuple(frame_hw), d.seed, d.dead_fraction, d.hot_fraction)
            if key not in self._defects:
                self._defects[key] = packed_sites(torch.tensor(defect_map(*frame_hw, d), device=self.device))
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
    torch generator (a uniform, then a standard normal, per channel or one for all: sensor.readout.brooks_lambdas)."""
    if sensor.lambda_source != "brooks":
        return noise_lambdas(sensor, None)
    n = 4 if sensor.brooks_per_channel else 1
    u = torch.rand(n, generator=generator, device=device, dtype=torch.float64)
    read, shot = readout.brooks_lambdas(u, torch.randn(n, generator=generator, device=device, dtype=torch.float64))
    read, shot = (v.cpu().numpy().repeat(4 // n) for v in (read, shot))
    return tuple(map(float, read)), tuple(map(float, shot))


def _kind(panel: Panel) -> tuple:
    """What decides a crop's sensor operations (not their numbers): crops alike are exposed as one batch."""
    return panel.sensor.noise, panel.fpn is None, panel.defects is None


def expose_batch(e: torch.Tensor, panels: list[Panel], maps: FrameMaps, crops: list,
                 generators: list | None = None, draws: list | None = None) -> torch.Tensor:
    """Packed DN [B, 4, h/2, w/2] of the mean electrons e [B, 4, h/2, w/2] of crops [(frame_hw, origin_yx)], crop b
    behind panels[b]'s sensor, its noise from generators[b] (on e's device) or the explicit draws[b] (module doc;
    sensor.noise.expose and sensor.defects.apply_defects through sensor.readout). Crops whose sensors work alike
    (_kind) go through as one batch, their numbers per crop; a crop's draws come from its own generator alone, so
    that a crop gets the same numbers in any batch."""
    n = e.shape[0]
    generators, draws = generators or [None] * n, [d or NoiseDraw() for d in (draws or [None] * n)]
    groups: dict = {}
    for b, p in enumerate(panels):
        groups.setdefault(_kind(p), []).append(b)
    if len(groups) == 1:
        return _expose_alike(e, panels, maps, crops, generators, draws)
    out = torch.empty_like(e)
    for members in groups.values():
        idx = host_to(torch.tensor(members), e.device)
        p, c, g, d = ([seq[b] for b in members] for seq in (panels, crops, generators, draws))
        out[idx] = _expose_alike(e[idx], p, maps, c, g, d)
    return out


def _own_maps(panels) -> list[bool]:
    return [p.maps == "crop" for p in panels]


def _expose_alike(e, panels, maps, crops, generators, draws) -> torch.Tensor:
    """expose_batch for crops of one _kind."""
    s0, sensors = panels[0].sensor, [p.sensor for p in panels]
    size = (2 * e.shape[-2], 2 * e.shape[-1])
    g, black, fw = (per_crop([getattr(s, k) for s in sensors], e) for k in ("dn_per_electron", "black_level_dn",
                                                                             "full_well_e"))
    e = readout.finite_electrons(e)
    off = None
    if panels[0].fpn is not None:
        gain_map, off = maps.fpn(crops, size, [p.fpn for p in panels], _own_maps(panels))
        e = readout.mean_charge_e(e, gain_map, per_crop([p.fpn.dark_charge_e(p.sensor.exposure_s) for p in panels], e))
    if s0.noise == "poisson":
        sig = _poisson(e, sensors, generators, draws, off, g, black, fw)
    elif s0.noise == "gaussian":
        sig = _gaussian(e, sensors, generators, draws, off, g, black, fw)
    else:
        sig = readout.read_noiseless(e, off, fw, g, black)
    white = per_crop([s.white_level_dn for s in sensors], e)
    dn = readout.quantised(sig, white)
    return dn if panels[0].defects is None else _defects(dn, panels, maps, crops, size, black, white)


def _poisson(e, sensors, generators, draws, off, g, black, fw) -> torch.Tensor:
    """Signal DN of the Poisson model: each crop's counts and normals from its generator or draw."""
    caps = [readout.poisson_cap_e(s.full_well_e, s.read_noise_e) for s in sensors]
    n = torch.stack([d.shot_e.to(e.device, e.dtype) if d.shot_e is not None
                     else torch.poisson(torch.clamp_max(eb, cap), generator=gen)
                     for eb, cap, gen, d in zip(e, caps, generators, draws)])
    normal = None
    if any(s.read_noise_e > 0 for s in sensors):
        normal = torch.stack([_normal(eb.shape, eb, gen, d.normal) if s.read_noise_e > 0 else torch.zeros_like(eb)
                              for eb, gen, d, s in zip(e, generators, draws, sensors)])
    return readout.read_poisson(n, normal, per_crop([s.read_noise_e for s in sensors], e), off, fw, g, black)


def _gaussian(e, sensors, generators, draws, off, g, black, fw) -> torch.Tensor:
    """Signal DN of the Gaussian model: each crop's λ (drawn first when 'brooks') and normals."""
    lam = [d.lambdas or gaussian_lambdas(s, gen, e.device) for s, gen, d in zip(sensors, generators, draws)]
    cap = per_crop([readout.gaussian_cap(s.dn_per_electron * s.full_well_e / s.range_dn, max(lr), max(ls))
                    for s, (lr, ls) in zip(sensors, lam)], e)
    lr, ls = (per_crop([v[i] for v in lam], e) for i in (0, 1))
    normal = torch.stack([_normal(eb.shape, eb, gen, d.normal) for eb, gen, d in zip(e, generators, draws)])
    return readout.read_gaussian(e, normal, lr, ls, off, g, per_crop([s.range_dn for s in sensors], e), fw, black,
                                 cap)


def _defects(dn: torch.Tensor, panels, maps: FrameMaps, crops, size, black, white) -> torch.Tensor:
    """Dead pixels at black, hot ones + g · hot charge, capped (sensor.defects.apply_defects)."""
    kind = maps.defect_classes(crops, size, [p.defects for p in panels], _own_maps(panels))
    hot, top = (per_crop(v, dn) for v in zip(*(defect_levels(p.sensor, p.defects) for p in panels)))
    return readout.with_defects(dn, kind, black, hot, top, white)
