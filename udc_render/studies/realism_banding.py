"""Banding of a mid-grey field through a display at d > 0 (udc_render.studies.realism_capture, module
doc c): the Michelson contrast of the green power profile Σ_k a_k P_k(s(x)) over the per-pixel noise at
mid-grey, and its visibility class.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from psf.banding import PowerSeries
from udc_render.content.monitor_image import decode
from udc_render.optics.displays import Display
from udc_render.optics.gamma import white_weights
from udc_render.pipeline import EXPOSURE_FILL, sensor_for_scene
from udc_render.scene.geometry import psf_lens, render_grid
from udc_render.sensor import SensorConfig
from udc_render.sensor.noise import expose
from udc_render.studies.realism_paper import (
    PAPER_BANDING,
    default_scene,
    display_label,
    display_pitch_um,
    visibility_verdict,
)

MID_GREY_CODE = 128
BAND_GROUP = 3  # band centres per banding wavelength (realism_capture's module doc, c)
GRID_SAMPLES = 128
NOISE_PATCH_PX = 128


class _GPower:
    """The G-weighted transmitted power P(x, y) over the sensor (module doc, c), from psf.banding's
    PowerSeries at each band centre (weights trimmed to the orders that matter, |w| > 1e-12 max)."""

    def __init__(self, layout, lens, centres_nm, weights, distance_um: float):
        self.scale = distance_um / lens.image_distance_um  # mask shift per sensor µm
        self.terms = []
        for wl, w in zip(centres_nm, weights):
            if w <= 0:
                continue
            ps = PowerSeries(layout, lens, float(wl) * 1e-3, distance_um)
            a = np.abs(ps.weights)
            keep_y = a.max(axis=1) > 1e-12 * a.max()
            keep_x = a.max(axis=0) > 1e-12 * a.max()
            self.terms.append((w * ps.weights[np.ix_(keep_y, keep_x)], ps.kx[keep_x] / ps.period_um[0],
                               ps.ky[keep_y] / ps.period_um[1]))
        self.mean = sum(float(wk[fy == 0][:, fx == 0].real.sum()) for wk, fx, fy in self.terms)

    def grid(self, x_um: np.ndarray, y_um: np.ndarray) -> np.ndarray:
        """P on the grid [y, x] (sensor µm), relative to its mean over the display period."""
        out = np.zeros((y_um.size, x_um.size))
        for w, fx, fy in self.terms:
            ex = np.exp(-2j * np.pi * self.scale * np.outer(fx, x_um))  # [Kx, nx]
            ey = np.exp(-2j * np.pi * self.scale * np.outer(y_um, fy))  # [ny, Ky]
            out += (ey @ (w @ ex)).real
        return out / self.mean

    def line(self, pos_um: np.ndarray, axis: int) -> np.ndarray:
        """P along x (axis 0) or y (axis 1) through the centre, relative to its mean."""
        out = np.zeros(pos_um.size)
        for w, fx, fy in self.terms:
            coef, f = (w.sum(axis=0), fx) if axis == 0 else (w.sum(axis=1), fy)
            out += (np.exp(-2j * np.pi * self.scale * np.outer(pos_um, f)) @ coef).real
        return out / self.mean

    def strongest_harmonic(self, axis: int, period_um: float) -> int | None:
        """k > 0 of the strongest harmonic (|c_k| + |c_−k|) of P along x (axis 0) or y (axis 1) through
        the centre, in orders of the display's period; None when P is flat along that axis."""
        amp: dict[int, float] = {}
        for w, fx, fy in self.terms:
            coef, f = (w.sum(axis=0), fx) if axis == 0 else (w.sum(axis=1), fy)
            for k, c in zip(np.rint(f * period_um).astype(int), np.abs(coef)):
                if k != 0:
                    amp[abs(int(k))] = amp.get(abs(int(k)), 0.0) + float(c)
        if not amp or max(amp.values()) <= 1e-12 * abs(self.mean):
            return None
        return max(amp, key=amp.get)


def mid_grey_noise(display: Display, signal_e: float, sensor) -> float:
    """Relative RMS noise per pixel of a flat field of `signal_e` mean electrons through the sensor
    model (udc_render.sensor expose) at the display's gain: std / mean of (DN − black)."""
    s = replace(sensor, gain=display.gain)
    mosaic, _, _ = expose(np.full((NOISE_PATCH_PX, NOISE_PATCH_PX), signal_e), s, np.random.default_rng(0))
    v = mosaic.astype(np.float64) - s.black_level_dn
    return float(v.std() / v.mean()) if v.mean() > 0 else math.inf


def banding(display: Display, scene=None, sensor=None) -> dict:
    """The banding observables of `display` at its distance_mm (module doc, c) for `scene` (default:
    the monitor scene at 2048 × 1024) and `sensor` (default: SensorConfig() with the scene's optics).
    Returns {'bands': False, 'reason'} at d = 0 / without a periodic layout, else period_px (x, y),
    nominal_period_px (z_i p / d), contrast, signal_e, noise_rel, visibility, verdict and the x
    profile through the centre (profile_x_px, profile_rel) over the field."""
    d_mm = float(display.distance_mm)
    if display.layout is None:
        return {"bands": False, "distance_mm": d_mm, "reason": "no display (glass)"}
    if not d_mm > 0:
        return {"bands": False, "distance_mm": d_mm, "reason": "no bands at d = 0"}
    if not getattr(display.layout, "periodic", True):
        return {"bands": False, "distance_mm": d_mm, "reason": "layout not periodic: no bands modelled"}
    scene = scene or default_scene()
    sensor = sensor_for_scene(sensor or SensorConfig(), scene)
    lens, grid = psf_lens(scene), render_grid(scene)
    edges, centres = np.asarray(grid.edges_nm, float), grid.centres_nm
    w = white_weights(edges, sensor.camera)  # [3, K] electrons of the panel's white per band
    wg = w[1] * display.transmission.band_means(edges)
    starts = np.arange(0, centres.size, BAND_GROUP)  # the middle centre of each group, its summed weight
    power = _GPower(display.layout, lens, centres[np.minimum(starts + BAND_GROUP // 2, centres.size - 1)],
                    np.add.reduceat(wg, starts), d_mm * 1000.0)
    pitch = float(scene.sensor.pitch_um)
    field = np.array([scene.sensor.width_px, scene.sensor.height_px], float) * pitch  # µm
    periods = np.asarray(display.layout.period_um, float) * lens.image_distance_um / (d_mm * 1000.0)  # µm
    axes = []
    for a in range(2):  # one period cell where the field holds more, else the field
        if field[a] >= periods[a]:
            axes.append(np.arange(GRID_SAMPLES) * periods[a] / GRID_SAMPLES)
        else:
            axes.append(np.linspace(-field[a] / 2, field[a] / 2, int(min(GRID_SAMPLES, max(8, field[a] / pitch)))))
    p2 = power.grid(axes[0], axes[1])
    contrast = float((p2.max() - p2.min()) / (p2.max() + p2.min()))
    harmonic = [power.strongest_harmonic(a, display.layout.period_um[a]) for a in range(2)]
    period_px = [None if k is None else float(periods[a] / k / pitch) for a, k in enumerate(harmonic)]
    # mid-grey G electrons through the display: auto exposure (white at EXPOSURE_FILL of the full well
    # in the brightest channel through glass) × the G-weighted T τ of the display (τ: mean power / bare)
    glass_white_e = EXPOSURE_FILL * sensor.full_well_e * w.sum(axis=1) / w.sum(axis=1).max()
    bare = math.pi * lens.aperture_um ** 2 / 4
    tau_g = power.mean / bare / float(w[1].sum())
    level = float(decode(np.array(MID_GREY_CODE / 255.0), scene.content.transfer))
    signal_e = level * float(glass_white_e[1]) * tau_g
    noise = mid_grey_noise(display, signal_e, sensor)
    vis = contrast / noise
    xs = np.linspace(-field[0] / 2, field[0] / 2, 1024)
    return {"bands": True, "distance_mm": d_mm, "period_px": tuple(period_px), "harmonic": tuple(harmonic),
            "nominal_period_px": tuple(float(p / pitch) for p in periods), "contrast": contrast,
            "mid_grey_level": level, "signal_e": signal_e, "stack_transmission_g": tau_g, "noise_rel": noise,
            "visibility": vis, "verdict": visibility_verdict(vis), "field_px": tuple(field / pitch),
            "profile_x_px": xs / pitch, "profile_rel": power.line(xs, 0)}


def banding_row(display: Display, base: dict | None = None, scene=None, sensor=None) -> tuple[dict, dict]:
    """(the banding row, the banding() dict) of `display` at its own distance (module doc, c)."""
    b = banding(display, scene, sensor)
    base = base or {"display": display_label(display), "pitch_um": display_pitch_um(display)}
    obs = f"bands at d = {b['distance_mm']:g} mm: period x/y, Michelson contrast (G), noise/px at mid-grey, visibility"
    if not b["bands"]:
        return dict(base, observable=obs, ours="none", paper=PAPER_BANDING, verdict=b["reason"], key="banding",
                    value=0.0), b

    def px(p):
        return "—" if p is None else f"{p:.1f}"
    longer = [a for a, n, f in zip("xy", b["nominal_period_px"], b["field_px"]) if n > f]
    field_note = f" (longer than the frame along {' and '.join(longer)})" if longer else ""
    ours = (f"{px(b['period_px'][0])} / {px(b['period_px'][1])} px{field_note}; C = {b['contrast']:.2%}; "
            f"σ = {b['noise_rel']:.2%}; V = {b['visibility']:.2f}")
    return dict(base, observable=obs, ours=ours, paper=PAPER_BANDING, verdict=b["verdict"], key="banding",
                value=b["visibility"]), b
