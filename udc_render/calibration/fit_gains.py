"""The kernel gains the presets' T(λ) are fitted on (optics.displays.fit_toled_transmission,
fit_poled_transmission; the randomized P-OLED's table, dataset.randomize.panels): the default rig.

The rig: the monitor scene's lens (6 mm, f/1.8), 30 bands of 10 nm from 400 to 700 nm, 511-px kernels at
1.55 µm on the paper's frame (2048 × 1024 px), d = 0. A band's gain is the share of the bare aperture's power
that the virtual γ calibration's white square brings to its region (calibration.gamma, the default rig:
FIT_SQUARE_PX, FIT_REGION_PX):

    g_k = τ_k (1 − o_k) + τ_k a_k,   a_k = optics.far_field.far_square_share(f_k, square, square, region)

the core window's light plus the far field's (optics.far_field, at the synthesis' default threshold and coarse
factor), as the captures have it. So T(λ) is fitted to what the calibration measures (the paper's γ is a
measurement: l.261). Without a_k (g = τ (1 − o)), the P-OLED's measured γ R came out 1.6 % above the paper's in
`study realism`: its orders past the 511-px window reach the region. A full-frame white (a = Σ f) would give
8 % more on the P-OLED: the measured γ depends on the square's size, and the paper's (256 × 256 monitor pixels,
l.210, l.261; ≈ 137 sensor px if the monitor spans the frame) is smaller than the virtual rig's, which keeps
the region a kernel's width inside the square.
"""
from __future__ import annotations

import numpy as np

from udc_render.optics.far_field import acceptance_um, far_square_share, far_window_px, make_far_field
from udc_render.optics.gamma import kernel_gain
from udc_render.scene import load_scene
from udc_render.scene.geometry import psf_lens
from udc_render.synth_config import DEFAULT_FAR_FIELD_COARSE, DEFAULT_FAR_FIELD_THRESHOLD

FIT_EDGES_NM = np.arange(400.0, 701.0, 10.0)
FIT_PIXEL_UM, FIT_SIZE_PX = 1.55, 511
FIT_FRAME_UM = (2048 * 1.55, 1024 * 1.55)
# calibration.rig RIGS['default'] (the monitor filling 1024 × 256 px, a 270-row square: calibrate_gamma's
# square_px and region_px; tests/udc_render/test_synth.py checks them)
FIT_SQUARE_PX, FIT_REGION_PX = 576.0, 60


def square_gains(layout, lens, wavelengths_nm, pixel_um: float, size_px: int, frame_um: tuple[float, float],
                 square_xy_px: tuple[float, float] | None, region_xy_px: tuple[int, int], use_cache: bool = True):
    """[K] g_k of `layout` (None: the bare lens) at the wavelengths (module doc), its kernels size_px of pixel_um
    on a frame_um sensor, for a white square of square_xy_px (x, y) sensor px around a region of region_xy_px;
    square None: the core alone, τ (1 − o)."""
    from psf import compute_kernels
    from psf.cache import cached
    from psf.far import CACHE_NAME, order_kernels
    wl = np.asarray(wavelengths_nm, float)
    core, _ = cached(compute_kernels, "mono", layout, lens, use_cache, wavelengths_nm=wl, pixel_um=pixel_um,
                     size_px=size_px, sensor_um=frame_um)
    if square_xy_px is None:
        return kernel_gain(core)
    coarse = DEFAULT_FAR_FIELD_COARSE
    size, _ = far_window_px(frame_um, (size_px // 2) * pixel_um, coarse * pixel_um)
    far, _ = cached(order_kernels, CACHE_NAME, layout, lens, use_cache, wavelengths_nm=wl, pixel_um=coarse * pixel_um,
                    size_px=size)
    ff = make_far_field(core, far, coarse, acceptance_um(frame_um), DEFAULT_FAR_FIELD_THRESHOLD)
    return kernel_gain(core) + np.asarray(core.transmittance) * far_square_share(ff, *square_xy_px, *region_xy_px)


def fit_gains(layout, far_field: bool = True, use_cache: bool = True) -> np.ndarray:
    """[30] g_k of `layout` (None: the bare lens) on the default rig (module doc); far_field False: τ (1 − o)."""
    wl = 0.5 * (FIT_EDGES_NM[1:] + FIT_EDGES_NM[:-1])
    return square_gains(layout, psf_lens(load_scene("monitor")), wl, FIT_PIXEL_UM, FIT_SIZE_PX, FIT_FRAME_UM,
                        (FIT_SQUARE_PX, FIT_SQUARE_PX) if far_field else None, (FIT_REGION_PX, FIT_REGION_PX),
                        use_cache)
