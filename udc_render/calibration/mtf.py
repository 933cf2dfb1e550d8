"""MTF: pattern:sine_x / sine_y at frequencies f (cycles per 1.55 µm sensor pixel); per channel a
least-squares fit of offset + cos + sin at the known f to the region's profile; modulation m =
amplitude / offset (the displayed Michelson contrast is 1), display relative to glass. Region: the
frame, shrunk in x to stay one kernel half-width inside the panel's edges.
"""
from __future__ import annotations

import math

import numpy as np

from udc_render.calibration.rig import Rig

# cycles/px where the preset stripe's x-MTF has true nulls: shifts λ z ν / pixel in (w, p − w) with p = 317 µm,
# w = 74 µm, λ = 520 nm, z = 6 mm, 1.55 µm pixels: 0.037 … 0.12 (docs/PHYSICS.md §8)
TOLED_DIP_BAND = (0.03, 0.1)
TOLED_DIP_RATIO = 0.5  # MTF_x / MTF_y must fall below this somewhere in the band
# P-OLED relative MTF stays above this (no true nulls: its pentile dip near 0.0075 cyc/px reaches ~0.1;
# the T-OLED's nulls ~3e-4)
POLED_MIN_MTF = 0.05


def modulation(profile: np.ndarray, x: np.ndarray, f: float) -> float:
    """amplitude / offset of the least-squares fit offset + a cos(2π f x) + b sin(2π f x)."""
    A = np.stack([np.ones_like(x), np.cos(2 * np.pi * f * x), np.sin(2 * np.pi * f * x)], 1)
    c = np.linalg.lstsq(A, profile, rcond=None)[0]
    return float(math.hypot(c[1], c[2]) / c[0])


def channel_modulations(img: np.ndarray, axis: str, f: float) -> list[float]:
    """modulation at f of each RGGB plane of the normalised mosaic `img`, profiled along `axis`
    (the plane averaged across it; positions in sensor pixels)."""
    per_ch = []
    for (oy, ox) in ((0, 0), (0, 1), (1, 0), (1, 1)):
        plane = img[oy::2, ox::2]
        if axis == "x":
            prof, pos = plane.mean(axis=0), np.arange(plane.shape[1]) * 2 + ox
        else:
            prof, pos = plane.mean(axis=1), np.arange(plane.shape[0]) * 2 + oy
        per_ch.append(modulation(prof, pos.astype(np.float64), f))
    return per_ch


def calibrate_mtf(rig: Rig) -> dict:
    """Modulation of glass and display captures of sine gratings along x and y (module doc)."""
    W = rig.spec.width_px
    w_mon, h_mon = rig.monitor_px()
    out = {"frequencies": list(rig.spec.frequencies), "unit": "cycles per sensor pixel (1.55 um)"}
    for axis, extent in (("x", w_mon), ("y", h_mon)):
        res = {"glass": [], "display": []}
        for i, f in enumerate(rig.spec.frequencies):
            b = rig.render(f"pattern:sine_{axis}:{f * extent:.6g}", spp=rig.spec.pattern_spp)
            half = rig.half_kernel()
            cx = max(int(min(W / 2, w_mon / 2 - half - 2)), 8) // 2 * 2  # even: column 0 is an R/Gb site
            cols = slice(W // 2 - cx, W // 2 + cx)
            for j, (key, d) in enumerate((("glass", rig.glass), ("display", rig.display))):
                cap = rig.capture(rig.optics(b, d), b, d, 4000 + 100 * (axis == "y") + 2 * i + j)
                s = rig.sensors[d.name]
                img = (cap.mosaic_dn[:, cols].astype(np.float64) - s.black_level_dn) / s.range_dn
                res[key].append(channel_modulations(img, axis, f))
        g, dsp = np.array(res["glass"]), np.array(res["display"])  # [F, 4]
        out[axis] = {"glass": g, "display": dsp, "relative": dsp / g,
                     "relative_G": (dsp[:, 1] + dsp[:, 2]) / (g[:, 1] + g[:, 2])}
    out["checks"] = mtf_checks(rig.display, out)
    return out


def mtf_checks(display, mtf: dict) -> list:
    """The expected physics of the presets (docs/PHYSICS.md §2): T-OLED near-nulls along x, P-OLED none."""
    f = np.array(mtf["frequencies"])
    if display.name == "toled" and display.source == "preset":
        band = (f >= TOLED_DIP_BAND[0]) & (f <= TOLED_DIP_BAND[1])
        ratio = float(np.min(mtf["x"]["relative_G"][band] / mtf["y"]["relative_G"][band]))
        return [{"quantity": f"T-OLED min MTF_x/MTF_y, {TOLED_DIP_BAND[0]:g}-{TOLED_DIP_BAND[1]:g} cyc/px",
                 "recovered": ratio, "truth": None, "error": None, "tolerance": f"< {TOLED_DIP_RATIO:g}",
                 "pass": bool(ratio < TOLED_DIP_RATIO)}]
    if display.name == "poled" and display.source == "preset":
        low = float(min(mtf["x"]["relative_G"].min(), mtf["y"]["relative_G"].min()))
        return [{"quantity": "P-OLED min relative MTF (x, y)", "recovered": low, "truth": None, "error": None,
                 "tolerance": f"> {POLED_MIN_MTF:g}", "pass": bool(low > POLED_MIN_MTF)}]
    return []
