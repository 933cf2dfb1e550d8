"""The exact transmitted power of the d > 0 field blend at every pixel's own mask shift (docs/PHYSICS.md §4).

The field blend (optics.field) takes the kernels k_q and their powers P_q at a few field phases q and
weights them bilinearly in phase, w_q(x). With the sampled powers its power modulation is Σ_q w_q(x) P_q,
a linear interpolation of P(s) that keeps sinc²(h/P) of harmonic h (0.81 of the first at the default P = 4)
and folds harmonics P ± h onto it: the T-OLED's first harmonic at d = 9.6 mm came out 0.77 of the exact one.
Here the kernels' shape still comes from the phases, their power from the exact series at each pixel:

    y = g · Σ_q k_q ⊗ (w_q(x) · m(s(x)) · x)      (blend 'source'; 'output': g · Σ_q w_q m (k_q ⊗ x))
    m(s) = P(s) / P̄ = Re Σ_k γ_k ŵ_k e^{−2πi k·s/p},   ŵ_k = b_k(d) Â(k/p) / P̄   (psf.banding)

with s(x) = x · d / z_i, γ_k = 2 for k_x > 0 (the half k_x ≥ 0 of the Hermitian weights: KernelSet.field_series)
and P̄ the phases' mean power, which the gain g carries (g ∝ P̄). Why this form:
- exact for the power: m(s_q) = P_q at the phases, and every pixel gets P at its own shift, every harmonic
  (up to the orders box of psf.banding.SERIES_RTOL: |m − m_box| ≤ 1e-5 of the mean);
- conserving: Σ_q w_q = 1, so the weighted source carries exactly m(s(x)) · x and blend 'source' keeps
  Σ y = g Σ x m(s(x)); over a period g · m averages to T · w_0 / P_bare, the exact mean power (k = 0 term);
- cheap: the render grid's shifts form a lattice (x0 + i·dx, y0 + j·dy), on which m costs two chirp
  z-transforms per band (psf.banding.power_lattice, O(N log N)), one multiply into the phase weight maps.
Fourier interpolation of the P phase samples instead keeps only |h| < P/2 and aliases the rest (not exact
for a display with sharp edges); more phases cost P² kernels each.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from psf.banding import power_lattice
from udc_render.optics.convolution import OpticsError


@dataclass(frozen=True, eq=False)
class PowerMap:
    """m_k on the render grid [H, W]: the series [K, 2n+1, m+1] (KernelSet.field_series) on the lattice of
    mask shifts x0 + i·dx (columns), y0 + j·dy (rows), µm; maps [K, H, W] float32: every band's m_k made
    once (stored(); a dataset worker keeps them, pipeline.compact_kernels), None: made per call."""
    series: np.ndarray
    period_um: tuple[float, float]
    x0_um: float
    dx_um: float
    width_px: int
    y0_um: float
    dy_um: float
    height_px: int
    maps: np.ndarray | None = None

    def band(self, k: int, dtype=np.float32) -> np.ndarray:
        """m_k(s(x)) [H, W] of band k, in dtype (the stored map when there is one)."""
        if self.maps is not None:
            return self.maps[k].astype(dtype, copy=False)
        return power_lattice(self.series[k], self.period_um, self.x0_um, self.dx_um, self.width_px, self.y0_um,
                             self.dy_um, self.height_px).astype(dtype)

    def stored(self) -> "PowerMap":
        """This map with every band's m_k computed now and kept (float32: K · H · W · 4 bytes)."""
        if self.maps is not None:
            return self
        return replace(self, maps=np.stack([self.band(k) for k in range(self.series.shape[0])]))

    def same_lattice(self, other: "PowerMap") -> bool:
        """True when both maps are of the same series on the same lattice of shifts (so either may serve)."""
        geometry = ("period_um", "x0_um", "dx_um", "width_px", "y0_um", "dy_um", "height_px")
        return (all(getattr(self, a) == getattr(other, a) for a in geometry)
                and np.array_equal(self.series, other.series))


def power_deviation(kernel_set) -> np.ndarray:
    """[K] a bound on max_s |m_k(s) − 1| over every mask shift: |γ_0 ŵ_0 − 1| + Σ_{k ≠ 0} γ_k |ŵ_k| of the
    series (the triangle inequality), or without one max_q |P_q − 1| of the phases' powers (which the blend
    then interpolates)."""
    series = kernel_set.field_series
    if series is None:
        power = np.asarray(kernel_set.field_power, np.float64)
        return np.abs(power - 1.0).reshape(power.shape[0], -1).max(axis=1)
    a = np.abs(np.asarray(series)) * np.where(np.arange(series.shape[2]) > 0, 2.0, 1.0)
    c = series.shape[1] // 2
    return a.sum(axis=(1, 2)) - a[:, c, 0] + np.abs(np.asarray(series)[:, c, 0] - 1.0)


def field_power_map(kernel_set, shape_hw, pitch_um: float, distance_mm: float, image_distance_um: float,
                    period_um: tuple[float, float]) -> PowerMap | None:
    """The PowerMap of a render grid of shape (H, W) (pixel centres from the optical axis at the grid centre,
    as optics.field.field_weights places them), or None when the kernel set has no series (an aperiodic
    display, or kernels made before it: the blend then interpolates the phases' powers)."""
    if kernel_set.field_series is None:
        return None
    H, W = shape_hw
    step_um = pitch_um * distance_mm * 1000.0 / image_distance_um
    return PowerMap(np.asarray(kernel_set.field_series), tuple(period_um), -(W - 1) / 2 * step_um, step_um, int(W),
                    -(H - 1) / 2 * step_um, step_um, int(H))


def stored_or_fresh(stored: PowerMap | None, fresh: PowerMap | None) -> PowerMap | None:
    """The stored map (PowerMap.stored, made once for this grid) in place of the fresh one, which it must equal
    (same series, same lattice); the fresh one when none is stored."""
    if stored is None:
        return fresh
    if fresh is None or not stored.same_lattice(fresh):
        raise OpticsError("power_map: the stored exact-power map is not this kernel set's on this grid "
                          f"({stored.height_px} × {stored.width_px} px): make it for this grid (field_power_map)")
    return stored
