"""Depth layers: the object distance of every pixel quantised into the few layers a defocus tolerance
allows, and the occlusion-aware sum of their blurred images.

Defocus coordinate. A point at axial distance z, the lens (aperture D) focused at z_f with the sensor at
z_i, blurs (geometric optics) into a disc of diameter b = D · z_i · |1/z − 1/z_f| on the sensor. In render
pixels of pitch δ, the signed β = D · z_i · (1/z − 1/z_f) / δ (β > 0: nearer than focus; z = ∞ is
1/z = 0).

Layers (choose_layers). Layer centres sit on a fixed grid of β, the multiples of 2·tol (tol: the defocus
tolerance, in render pixels of blur-circle diameter), and each pixel goes to the nearest: no pixel's blur
diameter is off by more than tol, the focus layer is at focus exactly (β = 0: the in-focus kernels of
before), and the same distances recur from render to render (a dataset's views of one scene share their
layers' kernels through the kernel cache). A scene whose pixels share one distance (a flat scene) has one
layer, at that distance exactly.

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
                "compositing": "layered occlusion, Hasinoff & Kutulakos 2007, normalised as Ikoma et al. 2021 "
                               "(optics.layers)"}


def one_layer(depth_m: float, geometry: DefocusGeometry, reason: str, tolerance_px: float | None = None) -> DepthLayers:
    """Every pixel at one distance (the monitor's plane; a scene without depth)."""
    return DepthLayers((float(depth_m),), (float(geometry.beta_px(depth_m)),), None, tolerance_px, reason)


def choose_layers(depth_m: np.ndarray, geometry: DefocusGeometry, tolerance_px: float, window_px: int) -> DepthLayers:
    """The layers of a depth map [H, W] (module doc). Refused at once (LayerError): a tolerance ≤ 0, more
    than MAX_LAYERS layers, or a layer blurred wider than the kernel window (its light would be lost)."""
    if not (tolerance_px > 0 and math.isfinite(tolerance_px)):
        raise LayerError(f"defocus tolerance {tolerance_px!r} px: expected a positive number of pixels")
    z = np.asarray(depth_m)
    bad = ~((z > 0) & ~np.isnan(z))
    if bad.any():
        raise LayerError(f"depth map: {int(bad.sum())} pixels at {float(z[bad].flat[0])!r} m; expected axial distances "
                         f"> 0 m (inf: no surface)")
    beta = geometry.beta_px(z)
    lo, hi = float(beta.min()), float(beta.max())
    if lo == hi:  # one distance: exactly it
        return DepthLayers((geometry.depth_m(lo),), (lo,), None, tolerance_px, "every pixel at one distance")
    step = 2.0 * tolerance_px
    cells = np.rint(beta / step).astype(np.int64)
    first, last = int(cells.min()), int(cells.max())
    if last - first + 1 > MAX_LAYERS:
        raise LayerError(f"defocus tolerance {tolerance_px:g} px needs up to {last - first + 1} depth layers for "
                         f"blur diameters {lo:.3g} … {hi:.3g} px; allowed ≤ {MAX_LAYERS}: use a tolerance ≥ "
                         f"{(hi - lo) / (2 * (MAX_LAYERS - 1)):.3g} px")
    used = np.unique(cells)  # far (β small) to near
    widest = float(np.abs(used).max()) * step + tolerance_px
    if widest > window_px:
        z = geometry.depth_m(float(used[np.argmax(np.abs(used))]) * step)
        raise LayerError(f"objects at {z:.3g} m blur to {widest:.0f} px, wider than the {window_px}-px kernel "
                         f"window: raise render.margin_um, or focus nearer to them")
    centres = tuple(float(c) * step for c in used)
    depths = tuple(geometry.depth_m(c) for c in centres)
    if used.size == 1:
        return DepthLayers(depths, centres, None, tolerance_px, "the depth map lies within one tolerance")
    labels = np.searchsorted(used, cells).astype(np.uint8)
    return DepthLayers(depths, centres, labels, tolerance_px,
                       f"{used.size} layers cover blur diameters {lo:.3g} … {hi:.3g} px")


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
