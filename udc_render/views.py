"""The electrons of every view of one render (the ground truth through glass, then each display), through
the render's depth layers (optics.layers), with very bright pixels convolved apart.

One layer (the monitor, a scene within the defocus tolerance of focus): each view is one optics pass,
channel_electrons, the band spectra shared by the views that convolve the plain bands (d = 0).
Several layers, near to far: each layer's masked bands α_l x are transformed once and serve every
d = 0 view (and the ground truth); each view's blurred layer Y_l is added under the visibility left by the
nearer layers (optics.layers.Compositor: Hasinoff & Kutulakos' occlusion, Ikoma et al.'s normalisation),
the silhouettes α_l and their normalisers blurred with k̄, the layer's kernels weighted per camera channel
by the view's band weights and the image's mean spectrum (one kernel per channel, not per band, and the
mean kernel over the field phases at d > 0: the occlusion's approximations beyond the model's own).
The far field (optics.far_field: the light past the kernel window, a veil over the frame) is added once per
view, from the whole render, after the layers are composited (its occlusion by nearer layers is not modelled).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from udc_render.optics import BrightPixels, FieldBasis, PowerMap, apply_kernels, band_spectra, convolve_bands, fft_shape
from udc_render.optics.apply import far_field_images
from udc_render.optics.far_field import FarField
from udc_render.optics.field_planes import PlaneBasis
from udc_render.optics.field_power import power_deviation
from udc_render.optics.layers import Compositor, DepthLayers, occluder_kernels
from udc_render.optics.primaries import Primaries, plane_spectra
from udc_render.render import BandImage
from udc_render.sensor import SensorConfig, band_electron_weights, cos4_map
from udc_render.sensor.radiometry import checked_nonnegative

# Bright pixels: a float32 FFT convolution's round-off per pixel is at most ROUNDOFF_FACTOR · ε32 · ‖x‖₂ / √N
# (measured 0.60 for a point source on a 768 × 1280 grid with a 511-px kernel; ‖x‖₂ over the N pixels), times
# ROUNDOFF_SAFETY for the K bands summed per channel and the kernels' own round-off; pixels are split off,
# brightest first, until it stays below ROUNDOFF_TARGET of the read noise.
ROUNDOFF_FACTOR = 0.6
ROUNDOFF_SAFETY = 4.0
ROUNDOFF_TARGET = 0.1


@dataclass(frozen=True)
class View:
    """One view's optics in one layer: its name ('gt' for the ground truth), band kernels, T(λ_k) (None:
    1), rank-r field basis (d > 0, compacted kernels) and far field (None: the light past the window is lost)."""
    name: str
    kernel_set: object
    transmission: np.ndarray | None
    field_basis: FieldBasis | None = None
    far_field: FarField | None = None
    power_map: PowerMap | None = None  # d > 0: the exact-power map made once (synth_kernels.store_power_maps)
    field_print: dict | None = None  # d > 0: field_print's verdict; 'prints' False: the mean kernel, no field blend
    spectra: Callable | None = None  # (blends, FFT shape, precision) -> its kernels' spectra or None (kernel_spectra)
    field_planes: PlaneBasis | None = None  # d > 0: its blend's weight maps in one basis (store_field_planes)

    @property
    def blends(self) -> bool:
        """Convolves with the field blend (d > 0, unless field_print left it out)."""
        has_field = self.field_basis is not None or self.kernel_set.field_kernels is not None
        return has_field and self.kernel_set.distance_mm > 0 and (self.field_print or {}).get("prints", True)

    @property
    def plain(self) -> bool:
        """Convolves the plain bands (d = 0, glass, or a field blend left out), so it can share their spectra."""
        return not self.blends


def field_print(band_image: BandImage, view: View, sensor: SensorConfig, spread_l1: np.ndarray | None,
                sigmas: float | None) -> dict | None:
    """Whether the field blend of a d > 0 view can change any pixel by more than `sigmas` σ of the read noise (the
    least noise of any pixel under Poisson noise), and the bound it was judged by (None: the view has no blend).

    With gains g_k, band maxima x̂_k, the electron weights w_ck, the phase kernels' spread s_k = max_q ‖k_q − k̄‖₁
    (optics.field.phase_spread_l1) and the power's deviation δ_k ≥ max |m_k − 1| (optics.field_power.power_deviation):
    y_blend − y_mean = g Σ_q (k_q − k̄) ⊗ (w_q m x) + g k̄ ⊗ ((m − 1) x), and a kernel difference of zero sum acting
    on 0 ≤ x ≤ x̂ gives at most x̂ ‖k_q − k̄‖₁ / 2, so every pixel's electrons move by at most
    Δ_c = Σ_k w_ck g_k x̂_k (s_k (1 + δ_k) / 2 + δ_k). The blend is left out when max_c Δ_c ≤ sigmas · σ_read."""
    ks = view.kernel_set
    if not (view.field_basis is not None or ks.field_kernels is not None) or ks.distance_mm <= 0:
        return None
    why = ("always blended (field_print_sigma None)" if sigmas is None else "judged under Poisson noise only"
           if sensor.noise != "poisson" else "no phase spread planned (plan_kernels)" if spread_l1 is None else None)
    if why is not None:
        return {"prints": True, "rule": why, "threshold_sigma": sigmas}
    t = np.ones(ks.kernels.shape[0]) if view.transmission is None else np.asarray(view.transmission, float)
    gains = t * np.asarray(ks.transmittance, float) * (1.0 - np.asarray(ks.energy_outside, float))
    peak = band_image.bands.max(axis=(1, 2)).astype(np.float64)
    dev = power_deviation(ks)
    bound = float((band_electron_weights(band_image.edges_nm, sensor) @ (
        gains * peak * (np.asarray(spread_l1) * (1.0 + dev) / 2 + dev))).max())
    return {"prints": bool(bound > sigmas * sensor.read_noise_e), "bound_e": bound,
            "read_noise_e": float(sensor.read_noise_e), "threshold_sigma": sigmas,
            "rule": "left out when the bound on any pixel's change ≤ threshold_sigma · read noise (views.field_print)"}


def bin_pixels(a: np.ndarray, pitch_um: float, sensor_pitch_um: float) -> np.ndarray:
    """Block mean [..., H·s, W·s] -> [..., H, W] where s = sensor pitch / render pitch (render.supersample)."""
    s = int(round(sensor_pitch_um / pitch_um))
    if s == 1:
        return a
    *lead, h, w = a.shape
    return a.reshape(*lead, h // s, s, w // s, s).mean(axis=(-3, -1))


def _band_norms_sq(band_image: BandImage) -> np.ndarray:
    """‖x_k‖² of every band [K] (float64): from the planes' Gram matrix when the bands are made of three planes,
    ‖Σ_c M_ck r_c‖² = Σ_cd M_ck M_dk ⟨r_c, r_d⟩ (6 products of planes in place of K; equal but for the bands'
    float32 rounding), else from the bands."""
    r, m = band_image.primaries_image, band_image.primaries_matrix
    if r is None or m is None:
        return np.einsum("khw,khw->k", band_image.bands, band_image.bands, dtype=np.float64)
    gram = np.einsum("chw,dhw->cd", r, r, dtype=np.float64)
    m = np.asarray(m, np.float32).astype(np.float64)  # the matrix the bands were made with (BandImage.of_primaries)
    return np.maximum(np.einsum("ck,cd,dk->k", m, gram, m), 0.0)


def bright_pixels(band_image: BandImage, sensor: SensorConfig) -> BrightPixels | None:
    """The pixels to convolve apart in float64 (module doc, ROUNDOFF_*), from their electrons at gain 1,
    e = max_c Σ_k w_ck x_k: none unless ‖e‖₂ exceeds the budget target · σ_read · √N / (factor · safety · ε32)."""
    x = band_image.bands
    w = band_electron_weights(band_image.edges_nm, sensor)
    n = x.shape[1] * x.shape[2]
    budget = ROUNDOFF_TARGET * sensor.read_noise_e * np.sqrt(n) / (
        ROUNDOFF_FACTOR * ROUNDOFF_SAFETY * np.finfo(np.float32).eps)
    band_norms = np.sqrt(_band_norms_sq(band_image))
    if float(np.abs(w).max(axis=0) @ band_norms) <= budget:  # ‖Σ_k w_k x_k‖ ≤ Σ_k |w_k| ‖x_k‖: nothing to split
        return None
    e = np.einsum("ck,khw->chw", w.astype(np.float32), x, optimize=True).max(axis=0).astype(np.float64)
    flat = np.sort(e.ravel())
    below = np.cumsum(flat ** 2)  # ‖e‖² of the pixels up to each value
    keep = int(np.searchsorted(below, budget ** 2, side="right"))  # the dimmest `keep` pixels stay in the FFTs
    if keep >= flat.size:
        return None
    return BrightPixels.of_mask(e > flat[keep - 1] if keep > 0 else np.ones(e.shape, bool))


def _optics(band_image: BandImage, view: View, sensor: SensorConfig, cfg, spectra, bright,
            far_blocks: dict | None = None, primaries: Primaries | None = None) -> tuple[np.ndarray, dict]:
    """One optics pass: electrons [3, h, w] (float64, render pitch, before binning) and its record."""
    w = band_electron_weights(band_image.edges_nm, sensor)
    blends = view.blends
    shape = fft_shape(band_image.bands.shape[1:], view.kernel_set.size_px, band_image.margin_px)
    spectra_k = (view.spectra(blends, shape, cfg.precision) if view.spectra is not None
                 and (cfg.blend == "source" or not blends) else None)
    kw = dict(blend=cfg.blend, field_rank=cfg.field_rank, field_basis=view.field_basis if blends else None,
              bright=bright, far_field=view.far_field, power_map=view.power_map if blends else None, field=blends,
              kernel_spectra=spectra_k, far_blocks=far_blocks, primaries=primaries,
              field_planes=(view.field_planes, cfg.field_planes_rank) if blends and view.field_planes is not None
              and cfg.field_planes_rank is not None else None)
    if cfg.blend == "source":
        optics = apply_kernels(band_image, view.kernel_set, view.transmission, cfg.precision, channel_weights=w,
                               spectra=spectra, **kw)
        e = optics.images.astype(np.float64)
    else:
        optics = apply_kernels(band_image, view.kernel_set, view.transmission, cfg.precision, **kw)
        e = np.einsum("ck,khw->chw", w, optics.images, dtype=np.float64, optimize=True)
    applied = dict(optics.applied)
    if view.field_print is not None:
        applied["field_print"] = view.field_print
        if not blends:
            bound, sigmas = view.field_print["bound_e"], view.field_print["threshold_sigma"]
            applied["skipped"] = [f"field-dependent blur: it changes no pixel by more than {bound:.3g} e- ≤ "
                                  f"{sigmas:g} σ of the read noise (field_print)"]
    return e, {**applied, "gains": optics.gains.tolist(), "transmission": optics.transmission.tolist()}


def _finish(e: np.ndarray, band_image: BandImage, sensor: SensorConfig, applied: dict) -> tuple[np.ndarray, dict]:
    """Binned to the sensor pitch, round-off negatives clamped (real ones refused: checked_nonnegative), cos⁴."""
    e, clamped = checked_nonnegative(bin_pixels(e, band_image.pitch_um, sensor.pitch_um), "channel electrons")
    if sensor.cos4_falloff:
        e *= cos4_map(*e.shape[1:], sensor.pitch_um, sensor.focal_length_um)
    return e, {**applied, "negative_electrons_clamped": clamped}


def channel_electrons(band_image: BandImage, view: View, sensor: SensorConfig, cfg, spectra=None,
                      bright: BrightPixels | None = None, far_blocks: dict | None = None,
                      primaries: Primaries | None = None) -> tuple[np.ndarray, dict]:
    """Mean electrons [3, H, W] (float64, sensor pitch, cos⁴ included) that an R, G and B pixel would
    collect through one view: e_c = cos⁴ · bin(Σ_k w_ck g_k (x_k ⊗ k_k)), w = band_electron_weights.
    The band sum is taken in Fourier space (apply_kernels' channel_weights: three inverse FFTs, not K);
    blend 'output' sums the K blurred bands instead. far_blocks: the far field's block means of these bands, kept
    for the next view (optics.far_field.far_light). primaries: the band image's planes (shared_primaries)."""
    e, applied = _optics(band_image, view, sensor, cfg, spectra, bright, far_blocks, primaries)
    return _finish(e, band_image, sensor, applied)


def shared_primaries(band_image: BandImage, views: list[View], cfg, bright=None) -> Primaries | None:
    """The render's three planes and their spectra (optics.primaries), made once for every view, when the band
    image keeps them (a monitor: BandImage.primaries_image) and the optics can take them (spectral form, blend
    'source', no bright pixels); else None."""
    planes = band_image.primaries_image
    if planes is None or cfg.form != "spectral" or cfg.blend != "source" or bright is not None:
        return None
    spectra = None
    if any(v.plain for v in views):
        spectra = plane_spectra(planes, views[0].kernel_set.size_px, band_image.margin_px, cfg.precision)
    return Primaries(planes, band_image.primaries_matrix, spectra)


def shared_spectra(band_image: BandImage, views: list[View], cfg, bright=None):
    """The band images' spectra (optics.band_spectra), computed once when more than one view convolves
    the plain bands (spectral form); else None (each view transforms its own)."""
    if cfg.form != "spectral" or sum(v.plain for v in views) < 2:
        return None
    size = views[0].kernel_set.size_px
    return band_spectra(band_image.bands, size, band_image.margin_px, cfg.precision, bright=bright)


def silhouette_covers(masks: np.ndarray, kernels: np.ndarray, margin_px: int, precision: str) -> np.ndarray:
    """k_c ⊗ mask_i for each mask [n, H, W] and channel kernel [C, S, S]: [n, C, h, w] (frame; float64)."""
    n, C = masks.shape[0], kernels.shape[0]
    spec = band_spectra(masks, kernels.shape[-1], margin_px, precision)
    return np.stack([convolve_bands(np.broadcast_to(masks[i], (C,) + masks.shape[1:]), kernels, margin_px, None,
                                    precision, spectra=np.broadcast_to(spec[i], (C,) + spec.shape[1:]))
                     for i in range(n)]).astype(np.float64)


def layered_electrons(band_image: BandImage, layers: DepthLayers, views_of_layer, sensor: SensorConfig, cfg,
                      bright: BrightPixels | None = None) -> dict[str, tuple[np.ndarray, dict]]:
    """{view name: (electrons [3, H, W], record)} of every view through the layers (module doc).
    views_of_layer(l) gives the views with layer l's kernels (layers far to near, as DepthLayers)."""
    if layers.labels is None:
        views = views_of_layer(0)
        primaries = shared_primaries(band_image, views, cfg, bright)
        spectra, blocks = None if primaries is not None else shared_spectra(band_image, views, cfg, bright), {}
        return {v.name: channel_electrons(band_image, v, sensor, cfg, spectra, bright, blocks, primaries)
                for v in views}
    w = band_electron_weights(band_image.edges_nm, sensor)
    mean_bands = band_image.frame(band_image.bands).mean(axis=(1, 2), dtype=np.float64)
    comp, records, far = {}, {}, {}
    behind = np.ones(band_image.bands.shape[1:], np.float32)  # this layer and every farther one
    for i in reversed(range(layers.count)):  # near to far
        alpha = layers.alpha(i)
        layer = replace(band_image, bands=band_image.bands * alpha)
        layer_bright = None if bright is None else BrightPixels.of_mask(bright.mask & (alpha > 0))
        views = views_of_layer(i)
        spectra = shared_spectra(layer, views, cfg, layer_bright)
        for v in views:
            far[v.name] = v
            y, records[v.name] = _optics(layer, replace(v, far_field=None), sensor, cfg, spectra if v.plain else None,
                                         layer_bright)
            g = np.asarray(records[v.name]["gains"])
            kbar = occluder_kernels(v.kernel_set.kernels, w * g[None] * mean_bands[None]).astype(np.float32)
            cover, cover_behind = silhouette_covers(np.stack([alpha, behind]), kbar, band_image.margin_px,
                                                    cfg.precision)
            comp.setdefault(v.name, Compositor()).add(y, cover if i > 0 else None, cover_behind)
        behind -= alpha
        del layer, spectra
    blocks = {}
    return {name: _finish(c.result() + _far_electrons(band_image, far[name], w, records[name], blocks), band_image,
                          sensor, records[name]) for name, c in comp.items()}


def _far_electrons(band_image: BandImage, view: View, w: np.ndarray, record: dict, blocks: dict):
    """The far field's electrons [3, h, w] of the whole render through one view (0 without one; module doc),
    noted in its record."""
    if view.far_field is None:
        return 0.0
    t = np.ones(len(w[0])) if view.transmission is None else np.asarray(view.transmission, float)
    record["far_field"] = {**view.far_field.describe(),
                           "layers": "added once, after compositing, from the whole render"}
    return far_field_images(band_image.bands, view.far_field, band_image.margin_px,
                            t * np.asarray(view.kernel_set.transmittance, float), w, blocks)


def per_channel_blur(rgb: np.ndarray, layers: DepthLayers, kernels_of_layer, margin_px: int, precision: str,
                     bright: BrightPixels | None = None) -> np.ndarray:
    """The paper's per-channel blur x_c ⊗ k_c [3, h, w] through the layers (optics.layers.Compositor, the
    silhouettes blurred with the same channel kernels); kernels_of_layer(l) gives layer l's [3, S, S]."""
    if layers.labels is None:
        return convolve_bands(rgb, kernels_of_layer(0), margin_px, None, precision, bright=bright)
    comp = Compositor()
    behind = np.ones(rgb.shape[1:], np.float32)
    for i in reversed(range(layers.count)):
        alpha = layers.alpha(i)
        k = kernels_of_layer(i)
        lb = None if bright is None else BrightPixels.of_mask(bright.mask & (alpha > 0))
        light = convolve_bands(rgb * alpha, k, margin_px, None, precision, bright=lb).astype(np.float64)
        cover, cover_behind = silhouette_covers(np.stack([alpha, behind]), k, margin_px, precision)
        comp.add(light, cover if i > 0 else None, cover_behind)
        behind -= alpha
    return comp.result().astype(np.float32)
