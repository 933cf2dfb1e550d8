"""Wide spread functions of stray light on the sensor plane, and their convolution with a frame.

Two families, each a density ρ(r) per µm² of the light one point sends to distance r on the sensor:

- **scatter tail** (display haze, lens veiling glare): light scattered at the pupil into angle θ from
  its ray with intensity I(θ) = c θ⁻² for θ₁ ≤ θ ≤ 90°: the slope −2 of the stray-light point-spread
  function of thin transparent layers ("Stray light of spectacle lenses compared with stray light in the
  eye", Optometry and Vision Science: PSF = a₁₀ (θ/10°)^b, b ≈ −2 on average for 4–30°, like the eye's)
  and of a Harvey surface-scatter BSDF of slope −2. It lands at
  r = f tan θ with ρ(r) = I(θ) cos³θ / f² (dΩ/dA); c normalises ∫ I dΩ over the hemisphere to 1, so the
  share that lands on the frame is what the frame reaches (the rest leaves it).
- **disc** (a ghost): ρ = 1/(π R²) for r ≤ R, a defocused copy.

The frame [3, H, W] is convolved on a grid b times coarser (b a power of two, at most the spread's
inner radius / 16 px, dividing H and W; b = 1 for small radii): each coarse cell's electrons are summed,
convolved (FFT, linear: the kernel reaches every displacement inside the frame), and interpolated back to
the pixels (linear between cell centres, rescaled so that the light added is exactly Σ x · landing share).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

SUBSAMPLES = 4  # per axis and coarse cell, to integrate ρ over each cell
COARSE_PER_RADIUS = 16  # the coarse cell is at most the inner radius / this


@dataclass(frozen=True)
class Spread:
    """A radially symmetric spread: kind 'tail' (θ₁ = inner_deg) or 'disc' (radius_um)."""
    kind: str
    focal_length_um: float
    inner_deg: float = 0.0
    radius_um: float = 0.0

    def inner_radius_um(self) -> float:
        """The radius inside which the spread holds no light (tail) or its radius (disc)."""
        if self.kind == "disc":
            return self.radius_um
        return self.focal_length_um * math.tan(math.radians(self.inner_deg))

    def density(self, r_um: np.ndarray) -> np.ndarray:
        """ρ(r) per µm² (module doc)."""
        r = np.asarray(r_um, float)
        if self.kind == "disc":
            return np.where(r <= self.radius_um, 1.0 / (math.pi * self.radius_um ** 2), 0.0)
        f = self.focal_length_um
        theta = np.arctan(r / f)
        inside = theta >= math.radians(self.inner_deg)
        safe = np.where(inside, theta, 1.0)
        return np.where(inside, tail_constant(self.inner_deg) / safe ** 2 * np.cos(safe) ** 3 / f ** 2, 0.0)

    def share_within(self, radius_um: float) -> float:
        """The share of a point's light landing within radius_um of it (a check on the density's norm)."""
        if self.kind == "disc":
            return min(1.0, (radius_um / self.radius_um) ** 2)
        hi = math.atan(radius_um / self.focal_length_um)
        return _tail_integral(self.inner_deg, hi) * tail_constant(self.inner_deg)


def _tail_integral(inner_deg: float, hi_rad: float, n: int = 200_001) -> float:
    """∫ 2π sinθ / θ² dθ from θ₁ to hi (trapezoid on a geometric grid; relative error < 1e-9)."""
    lo = math.radians(inner_deg)
    if hi_rad <= lo:
        return 0.0
    t = np.geomspace(lo, hi_rad, n)
    return float(np.trapezoid(2 * np.pi * np.sin(t) / t ** 2, t))


def tail_constant(inner_deg: float) -> float:
    """c of I(θ) = c θ⁻² with ∫ I dΩ = 1 over θ₁ ≤ θ ≤ 90°."""
    return 1.0 / _tail_integral(inner_deg, math.pi / 2)


def coarse_factor(height_px: int, width_px: int, inner_px: float) -> int:
    """The largest power of two ≤ inner_px / COARSE_PER_RADIUS dividing both sides (≥ 1)."""
    b = 1
    while (2 * b <= inner_px / COARSE_PER_RADIUS and height_px % (2 * b) == 0 and width_px % (2 * b) == 0
           and 2 * b <= min(height_px, width_px) // 4):
        b *= 2
    return b


def _cell_shares(spread: Spread, cells: tuple[int, int], cell_um: float) -> np.ndarray:
    h, w = cells
    s = SUBSAMPLES
    offs = (np.arange(s) + 0.5) / s - 0.5
    y = (np.arange(-(h - 1), h)[:, None] + offs[None, :]).ravel() * cell_um
    x = (np.arange(-(w - 1), w)[:, None] + offs[None, :]).ravel() * cell_um
    rho = spread.density(np.hypot(y[:, None], x[None, :]))
    return rho.reshape(2 * h - 1, s, 2 * w - 1, s).mean(axis=(1, 3)) * cell_um ** 2


def kernel(spread: Spread, cells: tuple[int, int], cell_um: float) -> np.ndarray:
    """[2h − 1, 2w − 1] share of a cell's light landing in each cell at every displacement inside an h × w
    grid of cells of side cell_um (ρ integrated over the target cell, SUBSAMPLES² points; a disc scaled so
    that its cells sum to 1, the sampling of its rim being the coarser error)."""
    k = _cell_shares(spread, cells, cell_um)
    if spread.kind == "disc":
        n = int(math.ceil(spread.radius_um / cell_um)) + 2
        norm = _cell_shares(spread, (n, n), cell_um).sum()
        if norm > 0:
            k = k / norm
        else:  # a disc below the sampling: a point
            k = np.zeros_like(k)
            k[cells[0] - 1, cells[1] - 1] = 1.0
    return k


def convolve(x: np.ndarray, spread: Spread, pitch_um: float) -> tuple[np.ndarray, float, int]:
    """(x ⊗ ρ on the frame [3, H, W], the landing share of the frame's total, the coarse factor b): light
    spread beyond the frame is gone (module doc)."""
    from scipy import fft
    c, h, w = x.shape
    b = coarse_factor(h, w, spread.inner_radius_um() / pitch_um)
    hc, wc = h // b, w // b
    cells = x.reshape(c, hc, b, wc, b).sum(axis=(2, 4), dtype=np.float64)
    k = kernel(spread, (hc, wc), b * pitch_um)
    shape = (fft.next_fast_len(3 * hc - 2, real=True), fft.next_fast_len(3 * wc - 2, real=True))
    out = fft.irfft2(fft.rfft2(cells, shape) * fft.rfft2(k, shape), shape)[:, hc - 1:2 * hc - 1, wc - 1:2 * wc - 1]
    out = np.clip(out, 0.0, None)  # FFT round-off around zero
    total = float(cells.sum())
    landed = float(out.sum()) / total if total > 0 else 0.0
    return spread_back(out, b), landed, b


def spread_back(cells: np.ndarray, b: int) -> np.ndarray:
    """Coarse cell sums [C, h, w] → pixels [C, h·b, w·b]: the cell densities interpolated linearly between
    cell centres (clamped at the edges), scaled so that the total is the cells' (exact). Bilinear is separable:
    U_y · d · U_xᵀ with two weights a row in U (two sparse products a channel, not four gathers of the frame)."""
    if b == 1:
        return cells
    c, h, w = cells.shape
    uy, ux = _linear_weights(h, b), _linear_weights(w, b)
    fine = np.stack([(ux @ (uy @ (d / (b * b))).T).T for d in cells])
    total, got = cells.sum(axis=(1, 2)), fine.sum(axis=(1, 2))
    scale = np.divide(total, got, out=np.zeros_like(total), where=got > 0)
    return fine * scale[:, None, None]


def _linear_weights(n: int, b: int):
    """[n·b, n] (scipy.sparse CSR): linear interpolation from n cell centres to the n·b pixel centres (cell units
    (i + ½)/b − ½, clamped to [0, n − 1])."""
    t = np.clip((np.arange(n * b) + 0.5) / b - 0.5, 0, n - 1)
    i0 = np.minimum(t.astype(int), n - 2 if n > 1 else 0)
    i1 = np.minimum(i0 + 1, n - 1)
    rows = np.arange(n * b)
    return sp.csr_matrix((np.concatenate([1 - (t - i0), t - i0]), (np.tile(rows, 2), np.concatenate([i0, i1]))),
                         shape=(n * b, n))  # duplicates (i0 = i1) summed
