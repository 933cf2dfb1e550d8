"""The light a crop receives from the whole frame, in torch: a bank panel's far field and its display's haze
(udc_render.dataset.bank PanelFar, PanelHaze), for restore.degrade. Both reach further than a crop's margin, so
they are made from the crop's whole clean frame (WideSource), on coarse grids, and sampled at the crop's pixels.

Far field (optics.far_field.far_light, per channel, in the blur's units): the frame with the panel's margin m
(the image mirrored beyond its edges, as a crop's margin), its c × c block means x̄ (the last blocks' rows and
columns held), continued as their edge by the far kernel's half-width + 1, convolved with F_c (a linear FFT of
far_light's shape), the coarse samples of blocks −1 … n interpolated linearly at the crop's pixels:
y_c += x̄_c ⊗ F_c. It equals far_light on the same input (tests: float64, 4e-14 of the peak).

Haze (optics.stray.apply, effect d): e ← (1 − h) e + h V, V = e_frame ⊗ ρ, on the b × b cells of
optics.stray.spread.convolve (b its coarse_factor; ρ its cell kernel of the θ⁻² tail from inner_deg; the light
beyond the frame gone), spread back as spread.spread_back (linear between cell centres, scaled to the cells'
total). The torch path holds the blurred electrons of the crop only, so the veil's source is made on the cells:
the clean frame's cells (with a mirrored margin) through the panel's mean kernel binned to the cells (bin_kernel:
where a cell's light lands, for light spread evenly over the source cell), plus the far field's light, times cos⁴
at the cell centres; γ is applied after, as to the crop. At b = 1 (small frames) that is the exact source of a
d = 0 panel; at b > 1 light moves by whole-cell expectations and the field's banding (a percent of the power) is
left out of the veil's source (tests/restore/test_degrade_wide.py measures what it costs).

A crop turned by restore.data.dihedral gets its wide light turned the same way, its place in the frame unchanged
(as its field). A frame's coarse sums (WideSource.key: its far field's block means, its veil's cells) are the
same through every panel and are made once (prepare: before worker processes fork); its maps through a panel
once per panel; both kept within WIDE_BUDGET_BYTES, least recently used dropped. The brightness scales them.
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import torch
from scipy.fft import next_fast_len

from restore.data import dihedral
from restore.tensors import host_to, region
from udc_render.dataset.bank import Panel
from udc_render.optics.stray import Spread
from udc_render.optics.stray.spread import coarse_factor, kernel

# The coarse sums and maps kept, at 2048 × 1024 in float32 (far field 15-px blocks, veil 8-px cells): ~1 MB per
# frame (its sums) and ~0.6 MB per frame and panel (its maps)
WIDE_BUDGET_BYTES = 1.0e9


@dataclass(frozen=True)
class WideSource:
    """A crop's whole clean frame [3, H, W] (unscaled linear RGB, on the degradation's device), the key its coarse
    maps are kept under, the brightness the crop's clean image was scaled by and the crop's transform (the mode of
    restore.data.dihedral)."""
    key: object
    frame: torch.Tensor
    brightness: float = 1.0
    mode: int = 0


def interpolation(t: np.ndarray, n: int) -> np.ndarray:
    """[len(t), n]: the weights of linear interpolation at fractional sample indices t in [0, n − 1]."""
    t = np.asarray(t, float)
    i0 = np.minimum(np.floor(t).astype(int), max(n - 2, 0))
    out = np.zeros((t.size, n))
    rows = np.arange(t.size)
    out[rows, i0] = 1.0 - (t - i0)
    out[rows, np.minimum(i0 + 1, n - 1)] += t - i0
    return out


def far_rows(n_out: int, start: int, n_blocks: int, coarse: int) -> np.ndarray:
    """far_light's upsampling: render pixels start … start + n_out − 1 from the samples of blocks −1 … n_blocks."""
    return interpolation((np.arange(start, start + n_out) - (coarse - 1) / 2) / coarse + 1.0, n_blocks + 2)


def cell_rows(n_cells: int, b: int) -> np.ndarray:
    """spread_back's interpolation [n_cells · b, n_cells]: pixel centres between cell centres, clamped at the edges."""
    return interpolation(np.clip((np.arange(n_cells * b) + 0.5) / b - 0.5, 0, n_cells - 1), n_cells)


def bin_kernel(k: np.ndarray, b: int) -> np.ndarray:
    """[3, n, n] the share of a b × b cell's light that kernel k [3, S, S] sends to each cell at offsets −n//2 …
    n//2, for the light spread evenly over the source cell: A k Aᵀ with A[J, δ] = #{s < b: ⌊(s + δ)/b⌋ = J} / b."""
    half = k.shape[-1] // 2
    j = (np.arange(b)[:, None] + np.arange(-half, half + 1)[None, :]) // b  # [b, S]
    a = np.zeros((2 * (-j.min()) + 1, k.shape[-1]))
    np.add.at(a, (j - j.min(), np.broadcast_to(np.arange(k.shape[-1]), j.shape)), 1.0 / b)
    return np.einsum("jy,cyx,ix->cji", a, np.asarray(k, np.float64), a)


def _fft_conv(x: torch.Tensor, spectrum: torch.Tensor, shape) -> torch.Tensor:
    return torch.fft.irfft2(torch.fft.rfft2(x, s=shape) * spectrum, s=shape)


def _nbytes(v) -> int:
    """Bytes of a tensor, or of the tensors in a (nested) tuple."""
    if isinstance(v, torch.Tensor):
        return v.numel() * v.element_size()
    return sum(_nbytes(u) for u in v if isinstance(u, (torch.Tensor, tuple)))


class WideLight:
    """The far field and veil of crops through a bank's panels on one device and precision (module doc)."""

    def __init__(self, panels: list[Panel], margin_px: int, device: torch.device, dtype: torch.dtype,
                 budget_bytes: float = WIDE_BUDGET_BYTES):
        self.panels, self.margin_px, self.device, self.dtype = panels, margin_px, device, dtype
        self.budget_bytes = budget_bytes
        self._kernels: dict = {}  # far kernels, binned kernels, veil cell kernels: made once
        self._maps: OrderedDict = OrderedDict()

    def _spectrum(self, key, make) -> torch.Tensor:
        """make() (a complex numpy spectrum) on the device in the complex type of the precision, made once."""
        if key not in self._kernels:
            cdtype = torch.complex128 if self.dtype == torch.float64 else torch.complex64
            self._kernels[key] = torch.as_tensor(make(), device=self.device).to(cdtype)
        return self._kernels[key]

    def crops(self, indices: list[int], crops: list, sources: list, size_hw) -> tuple[list, list]:
        """([far [3, h, w] or None], [veil [3, h, w] or None]) of crops through panels[indices] at crops (frame_hw,
        origin_yx), from their sources (WideSource), in the blur's units (the veil with cos⁴; γ not applied)."""
        far, veil = [], []

        def at(rows, cols, a):  # rows · a · colsᵀ on the device
            return (host_to(torch.from_numpy(rows), self.device, self.dtype) @ a
                    @ host_to(torch.from_numpy(cols), self.device, self.dtype).T)
        for i, (frame_hw, origin), src in zip(indices, crops, sources):
            p = self.panels[i]
            if src is None or tuple(src.frame.shape[1:]) != tuple(frame_hw):
                raise ValueError(f"panel {p.name} carries the far field or the haze: each crop needs its whole clean "
                                 f"frame of {frame_hw[0]} × {frame_hw[1]} px (sources)")
            maps = self._frame_maps(i, src)
            (y0, x0), (h, w) = origin, size_hw
            f = None if maps[0] is None else at(maps[0][1][y0:y0 + h], maps[0][2][x0:x0 + w], maps[0][0])
            v = None if maps[1] is None else at(maps[1][1][y0:y0 + h], maps[1][2][x0:x0 + w], maps[1][0])
            far.append(None if f is None else dihedral(f * src.brightness, src.mode))
            veil.append(None if v is None else dihedral(v * src.brightness, src.mode))
        return far, veil

    def prepare(self, sources: list[WideSource]) -> None:
        """Make and keep the frames' coarse sums that the panels need (a frame's are the same through every panel):
        done once before worker processes fork, they inherit them."""
        for src in sources:
            for i, p in enumerate(self.panels):
                if p.far is not None:
                    self._block_means(src, p.far.coarse_px)
                if p.haze is not None:
                    self._cells(src, *self._veil_grid(i, src.frame.shape[1:])[:2])

    def _kept(self, key, make):
        """make() kept under key (the frame's sums, a frame's maps through a panel) within the budget."""
        if key in self._maps:
            self._maps.move_to_end(key)
            return self._maps[key]
        self._maps[key] = value = make()
        while len(self._maps) > 1 and sum(_nbytes(v) for v in self._maps.values()) > self.budget_bytes:
            self._maps.popitem(last=False)
        return value

    def _frame_maps(self, i: int, src: WideSource) -> tuple:
        """((far coarse samples, rows, columns) or None, (veil cell densities, rows, columns) or None) of the frame
        through panel i."""
        def make():
            far = self._far_map(i, src) if self.panels[i].far is not None else None
            return far, self._veil_map(i, src, far) if self.panels[i].haze is not None else None
        return self._kept((src.key, "maps", i), make)

    def _mirrored(self, frame: torch.Tensor, pad: int) -> torch.Tensor:
        """The frame with `pad` pixels mirrored around it (restore.tensors.region; one reflection: torch's pad)."""
        H, W = frame.shape[1:]
        if pad < min(H, W):
            return torch.nn.functional.pad(frame.to(self.dtype)[None], (pad,) * 4, mode="reflect")[0]
        return region(frame.to(self.dtype), -pad, -pad, H + 2 * pad, W + 2 * pad)

    def _block_means(self, src: WideSource, c: int) -> torch.Tensor:
        """far_light's c × c block means of the frame with the margin (mirrored), the last blocks held."""
        def make():
            m, (H, W) = self.margin_px, src.frame.shape[1:]
            nby, nbx = -(-(H + 2 * m) // c), -(-(W + 2 * m) // c)
            held = torch.nn.functional.pad(self._mirrored(src.frame, m)[None],
                                           (0, nbx * c - W - 2 * m, 0, nby * c - H - 2 * m), mode="replicate")
            return held[0].reshape(3, nby, c, nbx, c).mean(dim=(2, 4))
        return self._kept((src.key, "blocks", c), make)

    def _far_map(self, i: int, src: WideSource) -> tuple:
        """far_light's coarse samples [3, nby + 2, nbx + 2] of the frame with its margin, and the interpolation
        matrices of the frame's rows and columns."""
        f, m = self.panels[i].far, self.margin_px
        c, p = f.coarse_px, f.kernels.shape[-1] // 2
        H, W = src.frame.shape[1:]
        means = self._block_means(src, c)
        nby, nbx = means.shape[1:]
        xs = torch.nn.functional.pad(means[None], (p + 1,) * 4, mode="replicate")[0]
        shape = tuple(next_fast_len(n + 2 * (p + 1) + 2 * p, real=True) for n in (nby, nbx))
        spectrum = self._spectrum(("far", i, shape), lambda: np.fft.rfft2(f.kernels, s=shape))
        y = _fft_conv(xs, spectrum, shape)[:, 2 * p:2 * p + nby + 2, 2 * p:2 * p + nbx + 2].clamp_min(0)
        return y, far_rows(H, m, nby, c), far_rows(W, m, nbx, c)

    def _veil_grid(self, i: int, frame_hw) -> tuple[int, int, Spread]:
        """(b, J, ρ): the veil's cells of b × b pixels (optics.stray.spread.coarse_factor), the binned kernel's
        half-width in cells (bin_kernel) and the spread of panel i's haze."""
        p, (H, W) = self.panels[i], frame_hw
        spread = Spread("tail", p.sensor.focal_length_um, inner_deg=p.haze.inner_deg)
        b = coarse_factor(H, W, spread.inner_radius_um() / p.pitch_um)
        return b, -(-(p.kernel_px // 2) // b), spread

    def _cells(self, src: WideSource, b: int, J: int) -> torch.Tensor:
        """The b × b cell sums [3, H/b + 2J, W/b + 2J] of the frame with J cells mirrored around it."""
        def make():
            H, W = src.frame.shape[1:]
            return self._mirrored(src.frame, J * b).reshape(3, H // b + 2 * J, b, W // b + 2 * J, b).sum(dim=(2, 4))
        return self._kept((src.key, "cells", b, J), make)

    def _veil_map(self, i: int, src: WideSource, far) -> tuple:
        """The veil's cell densities [3, H/b, W/b] of the frame through panel i (scaled as spread_back scales
        them), and the interpolation matrices of the frame's rows and columns."""
        p, (H, W) = self.panels[i], src.frame.shape[1:]
        s = p.sensor
        b, J, spread = self._veil_grid(i, (H, W))
        hc, wc = H // b, W // b
        source = self._veil_source(i, self._cells(src, b, J), far, b)
        shape = tuple(next_fast_len(3 * n - 2, real=True) for n in (hc, wc))
        rho = self._spectrum(("rho", H, W, s.focal_length_um, p.pitch_um, p.haze.inner_deg, shape),
                             lambda: np.fft.rfft2(kernel(spread, (hc, wc), b * p.pitch_um), s=shape))
        out = _fft_conv(source, rho, shape)[:, hc - 1:2 * hc - 1, wc - 1:2 * wc - 1].clamp_min(0)
        rows, cols = cell_rows(hc, b), cell_rows(wc, b)
        d = out / (b * b)
        sy, sx = (torch.as_tensor(a.sum(axis=0), device=self.device).to(self.dtype) for a in (rows, cols))
        got = torch.einsum("y,cyx,x->c", sy, d, sx)
        scale = torch.where(got > 0, out.sum(dim=(1, 2)) / got, torch.zeros_like(got))
        return d * scale[:, None, None], rows, cols

    def _veil_source(self, i: int, cells: torch.Tensor, far, b: int) -> torch.Tensor:
        """The cells [3, H/b, W/b] of the frame's blurred light (with the far field's, times cos⁴; module doc) from
        the frame's cells with J around them."""
        p = self.panels[i]
        J = -(-(p.kernel_px // 2) // b)
        hc, wc = cells.shape[1] - 2 * J, cells.shape[2] - 2 * J
        shape = (next_fast_len(hc + 4 * J, real=True), next_fast_len(wc + 4 * J, real=True))
        kb = self._spectrum(("bin", i, b, shape), lambda: np.fft.rfft2(bin_kernel(p.kernels, b), s=shape))
        source = _fft_conv(cells, kb, shape)[:, 2 * J:2 * J + hc, 2 * J:2 * J + wc]
        if far is not None:
            y, rows, cols = far
            by, bx = (torch.as_tensor(a.reshape(-1, b, a.shape[1]).sum(axis=1), device=self.device).to(self.dtype)
                      for a in (rows, cols))
            source = source + by @ y @ bx.T
        if p.sensor.cos4_falloff:
            yy = (torch.arange(hc, device=self.device, dtype=torch.float64) + 0.5 - hc / 2) * b * p.pitch_um
            xx = (torch.arange(wc, device=self.device, dtype=torch.float64) + 0.5 - wc / 2) * b * p.pitch_um
            f2 = p.sensor.focal_length_um ** 2
            source = source * (1.0 / (1.0 + (yy[:, None] ** 2 + xx[None, :] ** 2) / f2) ** 2).to(self.dtype)
        return source.clamp_min(0)


def wide_panel(panel: Panel) -> bool:
    """Whether a panel needs its crops' whole frames (a far field or a haze)."""
    return panel.far is not None or panel.haze is not None
