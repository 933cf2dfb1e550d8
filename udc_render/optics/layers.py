"""Depth layers: the object distance of every pixel quantised into the few layers a defocus tolerance
allows, and the occlusion-aware sum of their blurred images.

Defocus coordinate. A point at axial distance z, the lens (aperture D) focused at z_f with the sensor at
z_i, blurs (geometric optics) into a disc of diameter b = D · z_i · |1/z − 1/z_f| on the sensor. In render
pixels of pitch δ, the signed β = D · z_i · (1/z − 1/z_f) / δ (β > 0: nearer than focus; z = ∞ is
1/z = 0).

Layers (choose_layers). The occupied β of the render grid are covered by intervals of width 2·tol (tol:
the defocus tolerance, in render pixels of blur-circle diameter): first [−tol, tol] about focus, then
greedily outwards on each side (each interval starts at the first uncovered β; greedy covering is the
fewest intervals of that width). A layer's kernels are computed at the centre of its occupied β (at
focus exactly for the focus interval), so no pixel's blur diameter is off by more than tol. A flat scene
has one layer; a scene within tol of focus has one, at focus: the in-focus kernels of before.

Compositing (Compositor). The layered occlusion model of Hasinoff & Kutulakos, "A Layer-Based
Restoration Framework for Variable-Aperture Photography" (ICCV 2007), with the normalisation of Ikoma,
Nguyen, Metzler, Peng & Wetzstein, "Depth from Defocus with Learned Optics for Imaging and
Occlusion-aware Depth Estimation" (ICCP 2021, their image formation model), layers l near to far:

    y = Σ_l Ĉ_l · Π_{m nearer than l} (1 − Â_m),   Ĉ_l = k_l ⊗ (α_l x) / B_l,   Â_l = k_l ⊗ α_l / B_l,
    B_l = k_l ⊗ (α_l + every farther α)

α_l is 1 where the pinhole render sees layer l. The nearer layers' blurred silhouettes hide the light
behind them; the normalisation B_l fills what the render could not see behind a blurred foreground
edge with the layer's own blurred colour, and keeps a continuous surface cut into two layers seamless
(uniform light through two adjacent layers of one kernel sums to itself: without B, a seam of −25 %).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from udc_render.errors import UdcError

MAX_LAYERS = 64  # uint8 labels; more would cost minutes per capture: refused with the tolerance that fits


class LayerError(UdcError):
    """A depth map or tolerance the layered synthesis cannot honour; one line."""


@dataclass(frozen=True)
class DefocusGeometry:
    """What turns a distance into a blur: aperture D, lens-to-sensor z_i (µm), focus distance z_f (m),
    render pitch δ (µm)."""
    aperture_um: float
    image_distance_um: float
    focus_m: float
    pitch_um: float

    def beta_px(self, depth_m) -> np.ndarray:
        """Signed geometric blur diameter β = D z_i (1/z − 1/z_f) / δ in render pixels (z = ∞ allowed)."""
        z = np.asarray(depth_m, dtype=np.float64)
        with np.errstate(divide="ignore"):
            inv = np.where(np.isinf(z), 0.0, 1.0 / z)
        return self.aperture_um * self.image_distance_um * (inv - 1.0 / self.focus_m) * 1e-6 / self.pitch_um

    def depth_m(self, beta_px: float) -> float:
        """The distance of blur β (inverse of beta_px; ∞ where 1/z reaches 0; the focus distance itself,
        exactly, at β = 0, so the in-focus kernels are the same computation as without layers)."""
        if beta_px == 0:
            return float(self.focus_m)
        inv = beta_px * self.pitch_um / (self.aperture_um * self.image_distance_um * 1e-6) + 1.0 / self.focus_m
        return math.inf if inv <= 1e-15 else 1.0 / inv


@dataclass(frozen=True)
class DepthLayers:
    """The layers of one render, far to near: depths_m[l] (the kernels' object distance, m), beta_px[l]
    (their signed blur diameter), labels [H, W] (the layer of each render pixel; None: one layer, every
    pixel), and the tolerance that chose them."""
    depths_m: tuple
    beta_px: tuple
    labels: np.ndarray | None
    tolerance_px: float | None
    reason: str

    @property
    def count(self) -> int:
        return len(self.depths_m)

    def alpha(self, layer: int) -> np.ndarray | None:
        """α_l: 1 where the render sees layer l (float32); None for the only layer (every pixel)."""
        return None if self.labels is None else (self.labels == layer).astype(np.float32)

    def describe(self) -> dict:
        shares = ([1.0] if self.labels is None else
                  (np.bincount(self.labels.ravel(), minlength=self.count) / self.labels.size).tolist())
        return {"count": self.count, "depths_m": list(self.depths_m), "blur_diameter_px": list(self.beta_px),
                "pixel_share": shares, "tolerance_px": self.tolerance_px, "reason": self.reason,
                "compositing": "Hasinoff & Kutulakos 2007 layered occlusion (optics.layers)"}


def one_layer(depth_m: float, geometry: DefocusGeometry, reason: str, tolerance_px: float | None = None) -> DepthLayers:
    """Every pixel at one distance (the monitor's plane; a scene without depth)."""
    return DepthLayers((float(depth_m),), (float(geometry.beta_px(depth_m)),), None, tolerance_px, reason)


def _occupied(beta: np.ndarray, step: float) -> np.ndarray:
    """The sorted occupied β: the exact smallest and largest of each histogram bin of width `step` (a
    histogram keeps this O(pixels) and its list short; the extremes keep the intervals exact)."""
    bins, inverse = np.unique(np.floor(beta.ravel() / step).astype(np.int64), return_inverse=True)
    lo = np.full(bins.size, np.inf)
    hi = np.full(bins.size, -np.inf)
    np.minimum.at(lo, inverse, beta.ravel())
    np.maximum.at(hi, inverse, beta.ravel())
    return np.unique(np.concatenate([lo, hi]))


def _cover(values: np.ndarray, width: float) -> list[tuple[float, float]]:
    """Greedy intervals [lo, hi] (hi − lo ≤ width) of sorted values: each starts at the first uncovered one."""
    out, i = [], 0
    while i < values.size:
        j = int(np.searchsorted(values, values[i] + width, side="right")) - 1
        out.append((float(values[i]), float(values[j])))
        i = j + 1
    return out


def choose_layers(depth_m: np.ndarray, geometry: DefocusGeometry, tolerance_px: float, window_px: int) -> DepthLayers:
    """The layers of a depth map [H, W] (module doc). Refused at once (LayerError): a tolerance ≤ 0, more
    than MAX_LAYERS layers, or a layer blurred wider than the kernel window (its light would be lost)."""
    if not (tolerance_px > 0 and math.isfinite(tolerance_px)):
        raise LayerError(f"defocus tolerance {tolerance_px!r} px: expected a positive number of pixels")
    beta = geometry.beta_px(depth_m)
    if not np.all(np.isfinite(beta)):
        raise LayerError("depth map: NaN or negative distances; expected axial distances > 0 m or inf")
    values = _occupied(beta, tolerance_px / 64)
    near_focus = np.abs(values) <= tolerance_px
    intervals = ([(0.0, 0.0)] if near_focus.any() else [])
    intervals += [(lo, hi) for lo, hi in _cover(values[values > tolerance_px], 2 * tolerance_px)]
    intervals += [(-hi, -lo) for lo, hi in _cover(np.sort(-values[values < -tolerance_px]), 2 * tolerance_px)]
    if len(intervals) > MAX_LAYERS:
        raise LayerError(f"defocus tolerance {tolerance_px:g} px needs {len(intervals)} depth layers for blur "
                         f"diameters {values.min():.3g} … {values.max():.3g} px; allowed ≤ {MAX_LAYERS}: "
                         f"use a tolerance ≥ {(values.max() - values.min()) / (2 * MAX_LAYERS):.3g} px")
    centres = sorted((lo + hi) / 2 for lo, hi in intervals)  # far (β small) to near
    widest = max(abs(c) for c in centres) + tolerance_px
    if widest > window_px:
        z = geometry.depth_m(max(centres, key=abs))
        raise LayerError(f"objects at {z:.3g} m blur to {widest:.0f} px, wider than the {window_px}-px kernel "
                         f"window: raise render.margin_um, or focus nearer to them")
    mids = (np.asarray(centres[:-1]) + np.asarray(centres[1:])) / 2
    labels = np.searchsorted(mids, beta).astype(np.uint8)  # the nearest centre (≤ tol away: module doc)
    depths = tuple(geometry.depth_m(c) for c in centres)
    if len(centres) == 1:
        return DepthLayers(depths, tuple(centres), None, tolerance_px, "the depth map lies within one tolerance")
    return DepthLayers(depths, tuple(centres), labels, tolerance_px,
                       f"{len(centres)} layers cover blur diameters {values.min():.3g} … {values.max():.3g} px")


NORMALIZE_FLOOR = 1e-3  # B_l below this: nothing of layer l or behind it reaches the pixel (Ikoma et al.'s ε)


class Compositor:
    """y = Σ_l Ĉ_l Π_{m nearer} (1 − Â_m) (module doc), fed one layer at a time, near to far: add(Y_l,
    k_l ⊗ α_l, B_l), each [C, h, w] (the cover of the farthest layer is not used and may be None)."""

    def __init__(self):
        self.acc = None
        self.vis = None

    def add(self, light, cover, cover_behind) -> None:
        inv = np.divide(1.0, cover_behind, out=np.zeros(np.shape(cover_behind)), where=cover_behind > NORMALIZE_FLOOR)
        shown = light * inv if self.vis is None else self.vis * light * inv
        self.acc = shown if self.acc is None else self.acc + shown
        if cover is not None:
            hide = 1.0 - np.clip(cover * inv, 0.0, 1.0)
            self.vis = hide if self.vis is None else self.vis * hide

    def result(self) -> np.ndarray:
        return self.acc


def occluder_kernels(kernels: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Channel-effective kernels [C, S, S] of one layer for its silhouette, k̄_c = Σ_k ŵ_ck k_k with
    ŵ_ck = weights[c, k] / Σ_k weights[c, k] (unit sum: an opaque silhouette blocks all light)."""
    w = np.asarray(weights, dtype=np.float64)
    w = w / np.maximum(w.sum(axis=1, keepdims=True), 1e-300)
    return np.einsum("ck,kij->cij", w, np.asarray(kernels, dtype=np.float64))
