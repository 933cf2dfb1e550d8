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


def fit_gains(layout, far_field: bool = True, use_cache: bool = True) -> np.ndarray:
    """[30] g_k of `layout` (None: the bare lens) on the default rig (module doc); far_field False: τ (1 − o)."""
    from psf import compute_kernels
    from psf.cache import cached
    from psf.far import CACHE_NAME, order_kernels
    lens = psf_lens(load_scene("monitor"))
    wl = 0.5 * (FIT_EDGES_NM[1:] + FIT_EDGES_NM[:-1])
    core, _ = cached(compute_kernels, "mono", layout, lens, use_cache, wavelengths_nm=wl, pixel_um=FIT_PIXEL_UM,
                     size_px=FIT_SIZE_PX, sensor_um=FIT_FRAME_UM)
    if not far_field:
        return kernel_gain(core)
    coarse = DEFAULT_FAR_FIELD_COARSE
    size, _ = far_window_px(FIT_FRAME_UM, (FIT_SIZE_PX // 2) * FIT_PIXEL_UM, coarse * FIT_PIXEL_UM)
    far, _ = cached(order_kernels, CACHE_NAME, layout, lens, use_cache, wavelengths_nm=wl,
                    pixel_um=coarse * FIT_PIXEL_UM, size_px=size)
    ff = make_far_field(core, far, coarse, acceptance_um(FIT_FRAME_UM), DEFAULT_FAR_FIELD_THRESHOLD)
    return kernel_gain(core) + np.asarray(core.transmittance) * far_square_share(ff, FIT_SQUARE_PX, FIT_SQUARE_PX,
                                                                                  FIT_REGION_PX)
