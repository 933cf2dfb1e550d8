"""The brute-force reference of the layered synthesis, and the test scene it is measured on.

reference_electrons: every distinct depth (β to REFERENCE_STEP_PX) gets its own wave-optics kernels, and
every source pixel spreads its light with them by direct summation (no FFT, no layers): y_c = Σ_p
Σ_k w_ck g_k x_k(p) k_{z(p),k}(· − p), under the same occlusion model (optics.layers.Compositor) at
per-pixel depth resolution: pixels nearer than p hide it through their blurred silhouettes. The layered synthesis
(views.layered_electrons) tends to it as the defocus tolerance goes to 0; their difference is the error
of the layers. Glass (d = 0) only: the field-dependent kernels of d > 0 would need a kernel set per depth
and phase.

near_over_far: a textured background at one distance and, in front, a square whose distance ramps
across it (so that its blur varies continuously), on a small frame.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from udc_render.optics.layers import Compositor, DefocusGeometry, occluder_kernels
from udc_render.render import BandImage
from udc_render.scene.geometry import camera_geometry
from udc_render.sensor import band_electron_weights

REFERENCE_STEP_PX = 0.02  # β resolution of the reference's depths (render px of blur diameter)


def near_over_far(scene, far_m: float, near_m: tuple[float, float], seed: int = 0) -> BandImage:
    """Band radiance [K, H, W] and depth of a textured far plane and a nearer textured square (its middle
    third of the frame) whose distance runs linearly from near_m[0] (left) to near_m[1] (right)."""
    g = camera_geometry(scene)
    edges = np.asarray(scene.bands.edges_nm, float)
    K, H, W = edges.size - 1, g.height_px, g.width_px
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W]
    far = 0.5 + 0.4 * np.sign(np.sin(2 * np.pi * xx / 23.0) * np.sin(2 * np.pi * yy / 17.0))
    near = 0.3 + 0.6 * rng.random((H, W)) ** 2
    box = (slice(H // 3, H - H // 3), slice(W // 3, W - W // 3))
    depth = np.full((H, W), float(far_m))
    depth[box] = np.linspace(near_m[0], near_m[1], box[1].stop - box[1].start)[None, :]
    tint = np.linspace(0.6, 1.2, K)
    radiance = np.where(depth < far_m, near, far)[None] * tint[:, None, None] * 1e-2
    return BandImage(bands=radiance.astype(np.float32), edges_nm=edges, pitch_um=g.pitch_um, margin_px=g.margin_px,
                     depth_m=depth.astype(np.float32), meta={"content": "near_over_far (studies.layers_reference)"})


def reference_electrons(band_image: BandImage, geometry: DefocusGeometry, kernels_at, sensor,
                        step_px: float = REFERENCE_STEP_PX) -> np.ndarray:
    """Electrons [3, h, w] (render pitch, frame) of the glass view, each distinct depth with its own kernels
    (module doc; float64 direct-sized FFT convolutions of scipy.signal, not the synthesis' FFT path).
    kernels_at(z_m) gives the glass KernelSet for objects at z_m."""
    from scipy.signal import fftconvolve
    x = band_image.bands.astype(np.float64)
    K, H, W = x.shape
    m = band_image.margin_px
    w = band_electron_weights(band_image.edges_nm, sensor)
    mean_bands = band_image.frame(x).mean(axis=(1, 2))
    levels = np.round(geometry.beta_px(band_image.depth_m) / step_px).astype(np.int64)
    comp = Compositor()
    behind = np.ones((H, W))
    frame = (slice(m, H - m), slice(m, W - m))

    def blur(img, kernel):
        return fftconvolve(img, kernel, mode="same")[frame]

    for level in np.unique(levels)[::-1]:  # near (β large) to far
        ks = kernels_at(geometry.depth_m(level * step_px))
        k = ks.kernels.astype(np.float64)
        g = ks.transmittance * (1.0 - ks.energy_outside)
        alpha = (levels == level).astype(np.float64)
        bands = [blur(alpha * x[j], k[j]) for j in range(K)]
        light = np.einsum("ck,khw->chw", w * g, np.stack(bands))
        kbar = occluder_kernels(k, w * g[None] * mean_bands[None])
        cover = np.stack([blur(alpha, kc) for kc in kbar])
        cover_behind = np.stack([blur(behind, kc) for kc in kbar])
        comp.add(light, cover, cover_behind)
        behind -= alpha
    return comp.result()


def edge_region(depth_m: np.ndarray, far_m: float, margin_px: int, radius_px: int) -> np.ndarray:
    """Frame pixels within radius_px of the near object's outline (bool [h, w])."""
    from scipy import ndimage
    near = depth_m < far_m
    ring = ndimage.binary_dilation(near, iterations=radius_px) & ~ndimage.binary_erosion(near, iterations=radius_px)
    return ring[margin_px:near.shape[0] - margin_px, margin_px:near.shape[1] - margin_px]


def with_focus(scene, focus_m: float):
    """The scene focused at focus_m (m)."""
    return replace(scene, lens=replace(scene.lens, focus_distance_m=float(focus_m)))
