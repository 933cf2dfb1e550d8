"""Degradation on the fly, in torch: the per-channel capture of udc_render's numpy synthesis, on any device.

For a clean linear image x [3, h + 2m, w + 2m] (camera RGB in units of the white level at gain 1, as gt.exr;
m = the kernel's half-width of scene around the crop), a panel of a kernel bank (udc_render.dataset.bank)
and the crop's place in its frame (the optical axis at the frame's centre):

    blur        y_c = (x_c ⊗ k_c)[m:−m, m:−m]                              d = 0 (optics.convolution)
                y_c = Σ_r B_cr ⊗ (W_cr x_c),  W_cr = Σ_q c_qr w_q(x) m_c(s(x))  d > 0 (optics.field, field_power)
    far field   y_c += x̄_c ⊗ F_c                      where the panel has one (optics.far_field; degrade_wide)
    electrons   e = γ_c / gain · y_c / (g / (gain R)) [· cos⁴]           per RGGB site (sensor.radiometry)
    haze        e ← (1 − h) e + h (e_frame ⊗ ρ)        where the panel has one (optics.stray; degrade_wide)
    sensor      FPN, Poisson–Gaussian noise, full well, quantisation, levels, defect pixels (restore.degrade_sensor)

The far field and the haze reach past a crop's margin: a panel that has them needs each crop's whole clean
frame (restore.degrade_wide.WideSource); restore.online gives it.

The convolution is linear with the numpy path's boundary handling: the FFT size per axis is fft_shape's
next_fast_len(max(n, n − m + S//2, S)) with the kernel wrapped around index 0, so wrap-around reaches only
the margin, which is cropped. For the same kernels, inputs and noise draw (restore.degrade_sensor.NoiseDraw)
the result equals `synth --form per_channel` (tests/restore/test_degrade.py: float64 to 1e-9 relative in the
electrons and to the DN after quantisation; float32 within the tolerances stated there). Everything runs in
torch on the input's device, but for the set-up computed with numpy: the 1-D phase weights of a crop (its rows
and columns), and once per panel and frame size the sensor's maps (FPN, defects) and the exact power map.
Degrader.degrade_batch takes a batch of crops, each through its own panel: on a GPU as one batch (blur_batch,
restore.degrade_sensor.expose_batch), each crop's numbers those of its own degradation.
"""
from __future__ import annotations

from collections import OrderedDict
from contextlib import contextmanager

import numpy as np
import torch

from psf.banding import power_lattice
from restore.degrade_sensor import FrameMaps, NoiseDraw, expose_batch, packed_sites
from restore.degrade_wide import WideLight, WideSource, wide_panel
from restore.tensors import host_to, per_crop
from udc_render.dataset.bank import Panel
from udc_render.optics import fft_shape, phase_weights

__all__ = ["Degrader", "NoiseDraw", "TorchPanel", "WideSource", "blur", "blur_batch", "normalised"]

# The d > 0 panels' power maps a Degrader keeps (float32 at 2048 × 1024 with 256-px margins: 47 MB per panel).
POWER_BUDGET_BYTES = 1.0e9
# CPU threads of a Degrader's ops: one. A crop's ~40 small sensor ops and its FFTs of ~768² gain nothing from a
# second thread and lose much when the cores are busy: on the loaded 2-core machine a d > 0 crop took 0.08 s with
# 1 thread and 0.54 s with 2 (the sensor stage 0.004 s and 0.33 s; benchmarks/bench_degrade.py --degrade-threads).
DEGRADE_THREADS = 1


@contextmanager
def cpu_threads(n: int | None):
    """torch's intra-op CPU threads set to n inside the block (None: unchanged)."""
    old = torch.get_num_threads()
    if n is not None:
        torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(old)


class TorchPanel:
    """A bank's panel on a device, in a precision: its kernels (or field bases) and their spectra per FFT shape
    (made once per shape: a training run's crops share one), the coefficient matrices of its field."""

    def __init__(self, panel: Panel, device: torch.device | str = "cpu", dtype: torch.dtype = torch.float32):
        self.panel, self.device, self.dtype = panel, torch.device(device), dtype
        f = panel.field
        bases = panel.kernels[:, None] if f is None else f.bases  # [3, R, S, S]
        self.bases = torch.as_tensor(np.asarray(bases), device=self.device).to(dtype)
        self.size_px = int(bases.shape[-1])
        self.margin_px = self.size_px // 2
        self._spectra: dict = {}
        if f is not None:
            power = np.ones(f.field_power.shape) if f.series is not None else f.field_power  # exact map: m replaces P
            c = np.zeros((3, f.rank, f.shifts_y_um.size, f.shifts_x_um.size))
            for q, (j, i) in enumerate(f.live):
                c[:, :, j, i] = f.coeffs[:, q, :] * power[:, j, i][:, None]
            self.coeff_maps = torch.as_tensor(c, device=self.device).to(dtype)  # [3, R, Py, Px]

    def spectra(self, shape: tuple[int, int]) -> torch.Tensor:
        """rfft2 of the bases [3, R, S, S] wrapped around index 0 (centre S//2 → 0), padded to `shape`."""
        if shape not in self._spectra:
            S, half = self.size_px, self.margin_px
            buf = torch.zeros(self.bases.shape[:2] + tuple(shape), dtype=self.dtype, device=self.device)
            buf[..., :S, :S] = self.bases
            self._spectra[shape] = torch.fft.rfft2(torch.roll(buf, (-half, -half), dims=(-2, -1)))
        return self._spectra[shape]

    def positions_um(self, n: int, start_px: int, frame_px: int) -> np.ndarray:
        """Sensor positions of n pixels from frame index start_px on (pixel centres from the frame's centre)."""
        return (np.arange(n) + start_px - (frame_px - 1) / 2) * self.panel.pitch_um

    def phase_weights(self, rows: int, cols: int, frame_hw: tuple[int, int],
                      origin_yx: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """(wy [Py, rows], wx [Px, cols]) of the crop's input whose first pixel is frame pixel origin − margin, so
        that W_cr = wyᵀ (C_cr wx) (module doc; the bilinear phase weights of optics.field.phase_weights, the phase
        powers in C = coeff_maps where the panel has no series)."""
        f, m = self.panel.field, self.margin_px
        py = self.positions_um(rows, origin_yx[0] - m, frame_hw[0])
        px = self.positions_um(cols, origin_yx[1] - m, frame_hw[1])
        d_um, z = f.distance_mm * 1000, f.image_distance_um
        return (phase_weights(py, f.shifts_y_um, d_um, z, f.period_um[1], f.periodic[0]),
                phase_weights(px, f.shifts_x_um, d_um, z, f.period_um[0], f.periodic[1]))

    def power_frame(self, frame_hw: tuple[int, int]) -> torch.Tensor | None:
        """m_c(s(x)) [3, H + 2m, W + 2m] of the whole frame with its margins, the lattice of optics.field_power's
        field_power_map (psf.banding.power_lattice: two chirp z-transforms per channel); None without a series."""
        f = self.panel.field
        if f is None or f.series is None:
            return None
        rows, cols = frame_hw[0] + 2 * self.margin_px, frame_hw[1] + 2 * self.margin_px
        step = self.panel.pitch_um * f.distance_mm * 1000.0 / f.image_distance_um
        maps = np.stack([power_lattice(f.series[c], f.period_um, -(cols - 1) / 2 * step, step, cols,
                                       -(rows - 1) / 2 * step, step, rows) for c in range(3)])
        return torch.as_tensor(maps, device=self.device).to(self.dtype)


def blur(x: torch.Tensor, panel: TorchPanel, frame_hw: tuple[int, int], origin_yx: tuple[int, int],
         power_frame: torch.Tensor | None = None) -> torch.Tensor:
    """The panel's blur of one crop x [3, h + 2m, w + 2m] (its output pixel (0, 0) at frame pixel origin_yx):
    [3, h, w] (module doc). power_frame: the panel's power_frame(frame_hw), made once (None: made here)."""
    if power_frame is None and panel.panel.field is not None:
        power_frame = panel.power_frame(frame_hw)
    return blur_batch(x[None], [panel], [(frame_hw, origin_yx)], [power_frame])[0]


def blur_batch(x: torch.Tensor, panels: list[TorchPanel], crops: list, powers: list) -> torch.Tensor:
    """blur of each crop x[b] [3, h + 2m, w + 2m] through panels[b] (one kernel size), at crops[b] = (frame_hw,
    origin_yx) with powers[b] its panel's power_frame (None where d = 0 or without a series): [B, 3, h, w]. The
    batch's transforms run as one, each spectrum multiplying the run of consecutive crops of its panel (a crop's
    numbers are those of its own blur; Degrader sorts a batch by panel)."""
    flat = [b for b, p in enumerate(panels) if p.panel.field is None]
    nf = len(flat)
    if flat != list(range(nf)):  # the d = 0 crops first, then back in the callers' order
        order = flat + [b for b, p in enumerate(panels) if p.panel.field is not None]
        y = blur_batch(x[host_to(torch.tensor(order), x.device)], [panels[b] for b in order],
                       [crops[b] for b in order], [powers[b] for b in order])
        return y[host_to(torch.from_numpy(np.argsort(order)), x.device)]
    m, S = panels[0].margin_px, panels[0].size_px
    rows, cols = x.shape[-2:]
    shape = fft_shape((rows, cols), S, m)
    parts = []
    if nf:
        y = torch.fft.rfft2(x[:nf], s=shape)
        for tp, run in _runs(panels[:nf]):
            y[run].mul_(tp.spectra(shape)[:, 0])
        parts.append(y)
    if nf < len(panels):
        parts.append(_field_spectra(x[nf:], panels[nf:], crops[nf:], powers[nf:], shape))
    y = parts[0] if len(parts) == 1 else torch.cat(parts)
    # the inverse transform by axes, the rows cropped between them: 1 + (rows − 2m) / rows of irfft2's work
    return torch.fft.irfft(torch.fft.ifft(y, dim=-2)[..., m:rows - m, :], n=shape[1], dim=-1)[..., m:cols - m]


def _runs(panels: list[TorchPanel]) -> list[tuple[TorchPanel, slice]]:
    """(panel, slice) of each run of consecutive crops through one panel."""
    runs, start = [], 0
    for b in range(1, len(panels) + 1):
        if b == len(panels) or panels[b] is not panels[start]:
            runs.append((panels[start], slice(start, b)))
            start = b
    return runs


def _field_spectra(x, panels, crops, powers, shape) -> torch.Tensor:
    """Σ_r FFT(W_cr x_c) · FFT(B_cr) [B, 3, …] of d > 0 crops x [B, 3, rows, cols] (module doc): one basis at a
    time, the batch's weights W_r = wyᵀ (C_r wx) made by two batched products and its weighted images transformed
    together. Panels of other field shapes (rank, phases) go one crop at a time."""
    if len({tp.coeff_maps.shape for tp in panels}) > 1:
        return torch.cat([_field_spectra(x[b:b + 1], panels[b:b + 1], crops[b:b + 1], powers[b:b + 1], shape)
                          for b in range(len(panels))])
    rows, cols = x.shape[-2:]
    if any(p is not None for p in powers):
        x = torch.stack([xb if p is None else xb * p[:, y0:y0 + rows, x0:x0 + cols]
                         for xb, p, (_, (y0, x0)) in zip(x, powers, crops)])
    wy, wx = (host_to(torch.from_numpy(np.stack(w)), x.device, panels[0].dtype)
              for w in zip(*(tp.phase_weights(rows, cols, *crop) for tp, crop in zip(panels, crops))))
    runs = _runs(panels)
    coeffs = torch.stack([tp.coeff_maps for tp in panels]) if len(runs) > 1 else panels[0].coeff_maps[None]
    cw = coeffs @ wx[:, None, None]  # [B, 3, R, Py, cols]
    wyt = wy.transpose(-1, -2)[:, None]  # [B, 1, rows, Py]
    y = None
    for r in range(cw.shape[2]):  # one basis at a time: 3B weighted images in memory, not 3RB
        terms = torch.fft.rfft2((wyt @ cw[:, :, r]).mul_(x), s=shape)
        for tp, run in runs:
            terms[run].mul_(tp.spectra(shape)[:, r])
        y = terms if y is None else y.add_(terms)
    return y


def normalised(dn: torch.Tensor, panel: Panel | list[Panel]) -> torch.Tensor:
    """The restorers' input: (DN − black) / (white − black) (udc_render.io.capture.load_packed); a batch [B, …]
    with a list of its crops' panels."""
    if isinstance(panel, Panel):
        s = panel.sensor
        return (dn - s.black_level_dn) / float(s.white_level_dn - s.black_level_dn)
    sensors = [p.sensor for p in panel]
    return ((dn - per_crop([s.black_level_dn for s in sensors], dn))
            / per_crop([float(s.white_level_dn - s.black_level_dn) for s in sensors], dn))


class Degrader:
    """The bank's panels on one device and precision, with the sensor's frame maps (FPN, defects) and the d > 0
    panels' power maps made once per frame size (the power maps of the panels used last, within
    power_budget_bytes): degrade(x, i, ...) is the capture of crop x through panel i as packed DN [4, h/2, w/2]."""

    def __init__(self, panels: list[Panel], device: torch.device | str = "cpu", dtype: torch.dtype = torch.float32,
                 power_budget_bytes: float = POWER_BUDGET_BYTES, threads: int | None = DEGRADE_THREADS,
                 batched: bool | None = None):
        self.panels = [TorchPanel(p, device, dtype) for p in panels]
        self.device, self.dtype = torch.device(device), dtype
        self.threads = threads if self.device.type == "cpu" else None
        self.batched = self.device.type != "cpu" if batched is None else batched  # degrade_batch's doc
        self.maps = FrameMaps(self.device, dtype)
        self.wide = WideLight(panels, self.margin_px, self.device, dtype) if any(map(wide_panel, panels)) else None
        self.power_budget_bytes = power_budget_bytes
        self._power: OrderedDict = OrderedDict()

    @property
    def margin_px(self) -> int:
        return max(p.margin_px for p in self.panels)

    def power_frame(self, index: int, frame_hw: tuple[int, int]) -> torch.Tensor | None:
        """Panel `index`'s power_frame(frame_hw), kept (least recently used dropped beyond the budget)."""
        key = (index, tuple(frame_hw))
        if key in self._power:
            self._power.move_to_end(key)
            return self._power[key]
        power = self.panels[index].power_frame(frame_hw)
        if power is not None:
            self._power[key] = power
            while len(self._power) > 1 and sum(t.numel() * t.element_size() for t in self._power.values()) > \
                    self.power_budget_bytes:
                self._power.popitem(last=False)
        return power

    def degrade(self, x: torch.Tensor, index: int, frame_hw: tuple[int, int], origin_yx: tuple[int, int],
                generator: torch.Generator | None = None, draw: NoiseDraw | None = None,
                source: WideSource | None = None) -> torch.Tensor:
        """Packed DN [4, h/2, w/2] (R, Gr, Gb, B; whole numbers) of crop x [3, h + 2m, w + 2m] whose output starts
        at frame pixel origin_yx (even: an R site) of a frame_hw sensor, through panel `index`; the noise from
        `generator` (on this device), or the explicit `draw`; the crop's whole clean frame `source` where the panel
        has a far field or a haze: degrade_batch of one crop."""
        return self.degrade_batch(x[None], [index], [(frame_hw, origin_yx)], [generator], [draw], sources=[source])[0]

    def degrade_batch(self, x: torch.Tensor, indices: list[int], crops: list, generators: list | None = None,
                      draws: list | None = None, captures: list[Panel] | None = None,
                      sources: list | None = None) -> torch.Tensor:
        """Packed DN [B, 4, h/2, w/2] of crops x [B, 3, h + 2m, w + 2m], crop b through panel indices[b] at crops[b]
        = (frame_hw, origin_yx) (as degrade), its noise from generators[b] or draws[b], behind the sensor, FPN and
        defects of captures[b] (restore.captures.captured_panel; default: its panel's), its far field and haze from
        sources[b] (restore.degrade_wide.WideSource: needed where the panel has them); on the CPU with
        self.threads threads. With self.batched (by default on a GPU) the batch's operations run as one where
        the crops allow it (their FFTs, the sensor of crops alike), in a fraction of the launches of one call per
        crop: the GPU's cost (half the time on an H100). Else crop by crop: on one CPU thread a batch's weighted
        images leave the cache (d > 0: 1.5× slower as one batch; benchmarks/README.md). Each crop's numbers are
        its own, the same DN either way (tests/restore/test_degrade.py)."""
        indices, crops = list(indices), list(crops)
        if not indices or len(crops) != len(indices) or x.shape[0] != len(indices):
            raise ValueError(f"degrade_batch: {x.shape[0]} crops, {len(indices)} panel indices and {len(crops)} "
                             "places: expected one of each per crop, at least one crop")
        generators, draws = generators or [None] * len(indices), draws or [None] * len(indices)
        sources = sources or [None] * len(indices)
        captures = captures or [self.panels[i].panel for i in indices]
        if len(captures) != len(indices):
            raise ValueError(f"degrade_batch: {len(captures)} captures for {len(indices)} crops")
        sizes = {self.panels[i].size_px for i in indices}
        if len(sizes) > 1:
            raise ValueError(f"a batch's panels have kernels of {sorted(sizes)} px: one size per batch")
        with cpu_threads(self.threads):
            if self.batched:  # sorted by panel, the d = 0 ones first (blur_batch's runs), then put back
                order = sorted(range(len(indices)), key=lambda b: (self.panels[indices[b]].panel.field is not None,
                                                                   indices[b]))
                if order == list(range(len(order))):
                    return self._degrade(x, indices, crops, generators, draws, captures, sources)
                x = x.to(self.device)[host_to(torch.tensor(order), self.device)]
                picked = ([seq[b] for b in order] for seq in (indices, crops, generators, draws, captures, sources))
                dn = self._degrade(x, *picked)
                return dn[host_to(torch.from_numpy(np.argsort(order)), self.device)]
            return torch.cat([self._degrade(x[b:b + 1], indices[b:b + 1], crops[b:b + 1], generators[b:b + 1],
                                            draws[b:b + 1], captures[b:b + 1], sources[b:b + 1])
                              for b in range(len(indices))])

    def _degrade(self, x, indices, crops, generators, draws, captures, sources) -> torch.Tensor:
        tps = [self.panels[i] for i in indices]
        m = tps[0].margin_px
        h, w = x.shape[-2] - 2 * m, x.shape[-1] - 2 * m
        for (frame_hw, (y0, x0)) in crops:
            if x.shape[1] != 3 or h < 2 or w < 2 or h % 2 or w % 2 or y0 % 2 or x0 % 2:
                raise ValueError(f"crop {tuple(x.shape[1:])} at {(y0, x0)}: expected [3, h + {2 * m}, w + {2 * m}] "
                                 "with h, w and the origin even (whole RGGB cells)")
            if y0 < 0 or x0 < 0 or y0 + h > frame_hw[0] or x0 + w > frame_hw[1]:
                raise ValueError(f"crop of {h} × {w} px at {(y0, x0)} leaves the {frame_hw[0]} × {frame_hw[1]} px "
                                 "frame")
        powers = [self.power_frame(i, frame) if tp.panel.field is not None else None
                  for i, tp, (frame, _) in zip(indices, tps, crops)]
        y = blur_batch(x.to(self.device, self.dtype), tps, crops, powers).clamp_min(0)
        far, veil = self._wide(indices, crops, sources, (h, w))
        if far is not None:
            y = y + far
        sensors = [c.sensor for c in captures]
        gamma = per_crop([s.gamma_rggb for s in sensors], y)
        per_e = per_crop([s.dn_per_electron / s.gain / s.range_dn for s in sensors], y)  # normalised units per e⁻
        e = gamma * packed_sites(y) / per_e
        if any(s.cos4_falloff for s in sensors):
            cos4 = torch.stack([self._cos4(h, w, frame, origin, s) if s.cos4_falloff else torch.ones_like(y[0, 0])
                                for s, (frame, origin) in zip(sensors, crops)])
            e = e * packed_sites(cos4[:, None])
        if veil is not None:  # the veil holds its cos⁴ (degrade_wide)
            h_share = per_crop([0.0 if tp.panel.haze is None else tp.panel.haze.share for tp in tps], e)
            e = (1 - h_share) * e + h_share * (gamma * packed_sites(veil) / per_e)
        return expose_batch(e, captures, self.maps, crops, generators, draws)

    def _wide(self, indices, crops, sources, size_hw) -> tuple:
        """(far [B, 3, h, w] or None, veil [B, 3, h, w] or None) of the crops (degrade_wide; zero where a crop's
        panel has none)."""
        wide = [b for b, i in enumerate(indices) if wide_panel(self.panels[i].panel)]
        if not wide:
            return None, None
        far, veil = self.wide.crops([indices[b] for b in wide], [crops[b] for b in wide], [sources[b] for b in wide],
                                    size_hw)
        out = []
        for maps in (far, veil):
            if all(m is None for m in maps):
                out.append(None)
                continue
            full = torch.zeros((len(indices), 3) + tuple(size_hw), device=self.device, dtype=self.dtype)
            for b, m in zip(wide, maps):
                if m is not None:
                    full[b] = m
            out.append(full)
        return tuple(out)

    def _cos4(self, h: int, w: int, frame_hw, origin_yx, s) -> torch.Tensor:
        """cos⁴θ [h, w] of the crop's pixels, r from the frame's centre (sensor.radiometry.cos4_map)."""

        def at(n, start, size):
            return (torch.arange(n, device=self.device, dtype=torch.float64) + start + 0.5 - size / 2) * s.pitch_um
        yy, xx = at(h, origin_yx[0], frame_hw[0]), at(w, origin_yx[1], frame_hw[1])
        return (1.0 / (1.0 + (yy[:, None] ** 2 + xx[None, :] ** 2) / s.focal_length_um ** 2) ** 2).to(self.dtype)
