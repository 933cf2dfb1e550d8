"""γ per RGGB channel: a white square at code levels 0, 10, …, 250; the mean of a central region with
the display against the mean through glass, slope of a least-squares line.

The rgb_matrix render is linear in the drive levels, so one render of the square at full drive is
scaled by the decoded level (exact); every level gets its own noisy capture. Honest measurement: the
square is as tall as the panel and the region's side is at most square − (kernel size − 1), so every
region pixel collects the whole kernel window. Truth: optics.gamma's γ (the project's one γ), its kernel
gains τ (1 − o) raised by τ a, a the share of the far field (optics.far_field: the light past the window)
that the region collects from the square, evaluated from the far kernels (far_square_share).
"""
from __future__ import annotations

import numpy as np

from udc_render.calibration.rig import CHANNELS, Rig, check
from udc_render.content.monitor_image import decode
from udc_render.optics.far_field import far_square_share
from udc_render.optics.gamma import channel_gamma, kernel_gain, white_weights
from udc_render.pipeline import SynthError
from udc_render.sensor import pack_rggb, rgb_to_rggb

GAMMA_LEVELS = tuple(range(0, 256, 10))
GAMMA_TOL = 0.02


def true_gamma(rig: Rig, band_image, square_px: tuple[float, float] = (0.0, 0.0), region_px: int = 0) -> np.ndarray:
    """The truth: γ (R, Gr, Gb, B) of the display for the rendered monitor white (optics.gamma), with the far
    field's share from a white square (x, y render px; far_square_share) around the region."""
    gains = {}
    for d in (rig.display, rig.glass):
        ks, far = rig.kernels[d.name], rig.far.get(d.name)
        extra = 0.0 if far is None else np.asarray(ks.transmittance) * far_square_share(far, *square_px, region_px)
        gains[d.name] = kernel_gain(ks) + extra
    w = white_weights(band_image.edges_nm, rig.sensors[rig.glass.name].camera, band_image.white_bands())
    g = channel_gamma(w, rig.display, gains[rig.display.name], gains[rig.glass.name], band_image.edges_nm)
    return np.array(rgb_to_rggb(g))


def _region_px(rig: Rig, side: float) -> int:
    """The measured region's side: at most the square less a kernel, a multiple of 4 (it starts on an R site)."""
    region = int(min(rig.spec.region_px, side - 2 * rig.half_kernel() - 2, rig.spec.height_px)) // 4 * 4
    if region < 8:
        raise SynthError(f"calibration rig: a {side:.0f}-px square leaves no {2 * rig.half_kernel() + 1}-px "
                         "kernel room")
    return region


def calibrate_gamma(rig: Rig) -> dict:
    """γ per RGGB channel from the white-square protocol (module doc)."""
    code = np.zeros((270, 480))
    code[:, 105:375] = 255  # 270 × 270: a square as tall as the panel
    b = rig.render(rig.pattern_file("gamma_square.png", code))
    side = min(rig.monitor_px())
    region = _region_px(rig, side)
    H, W = rig.spec.height_px, rig.spec.width_px
    rows = slice(H // 2 - region // 2, H // 2 + region // 2)
    cols = slice(W // 2 - region // 2, W // 2 + region // 2)
    views = {d.name: rig.optics(b, d) for d in (rig.glass, rig.display)}
    means = {name: [] for name in views}
    clipped = np.zeros((len(GAMMA_LEVELS), 4), bool)
    for i, level in enumerate(GAMMA_LEVELS):
        drive = float(decode(np.array(level / 255.0), rig.scene.content.transfer))
        for j, d in enumerate((rig.glass, rig.display)):
            cap = rig.capture(views[d.name] * np.float32(drive), b, d, 1000 + 2 * i + j)
            s = rig.sensors[d.name]
            raw = pack_rggb(cap.mosaic_dn[rows, cols]).reshape(4, -1)
            clipped[i] |= ((raw <= s.black_level_dn) | (raw >= s.white_level_dn)).any(axis=1)
            means[d.name].append((raw.mean(axis=1) - s.black_level_dn) / s.range_dn)
    x, y = np.array(means[rig.glass.name]), np.array(means[rig.display.name])  # [levels, 4]
    used = ~clipped
    slope = np.array([np.polyfit(x[used[:, c], c], y[used[:, c], c], 1)[0] for c in range(4)])
    grid_rows = H + 2 * b.margin_px  # a square reaching the render grid's edges is continued past them (far_field)
    truth = true_gamma(rig, b, (side, side if side < grid_rows else np.inf), region)
    return {"levels": list(GAMMA_LEVELS), "region_px": region, "square_px": side,
            "kernel_px": 2 * rig.half_kernel() + 1, "glass_mean_w": x, "display_mean_w": y, "used": used,
            "gamma": slope, "truth": truth,
            "checks": [check(f"gamma {c}", slope[k], truth[k], GAMMA_TOL) for k, c in enumerate(CHANNELS)]}
