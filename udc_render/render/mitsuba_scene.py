"""Mitsuba scene dictionaries for the rig and the built-in content (metres, W·sr⁻¹·m⁻²·nm⁻¹).

Only this module and `render` import mitsuba; they are called after `variants.set_variant`.
"""
from __future__ import annotations

import math

import numpy as np

from psf import colour_tables
from udc_render.content import spectra
from udc_render.scene import HDRRoom, Lens, Room
from udc_render.scene.geometry import CameraGeometry


def spectrum(values: np.ndarray) -> dict:
    """A Mitsuba 'irregular' spectrum of values on spectra.GRID_NM (spectral variants only)."""
    return {"type": "irregular", "wavelengths": ", ".join(f"{w:g}" for w in spectra.GRID_NM),
            "values": ", ".join(f"{v:.9g}" for v in values)}


def box_response(lo_nm: float, hi_nm: float) -> dict:
    """specfilm channel response: height exactly 1 on [lo, hi] (docs/RENDERING.md: any other height
    misplaces wavelengths); the film value is then ∫ L dλ over the band."""
    return {"type": "regular", "wavelength_min": float(lo_nm), "wavelength_max": float(hi_nm), "values": "1, 1"}


def sensor(mi, geom: CameraGeometry, lens: Lens, film: dict, sampler: dict) -> dict:
    d = {"type": "perspective", "fov": geom.fov_x_deg, "fov_axis": "x",
         "to_world": mi.ScalarTransform4f().look_at(origin=list(geom.origin_m), target=list(geom.target_m),
                                                    up=list(geom.up)),
         "film": film, "sampler": sampler}
    if lens.model == "thinlens":
        d.update(type="thinlens", aperture_radius=lens.aperture_mm * 1e-3 / 2,
                 focus_distance=min(geom.focus_distance_m, 1e9))
    return d


def band_film(geom: CameraGeometry, edges_nm) -> dict:
    film = {"type": "specfilm", "width": geom.width_px, "height": geom.height_px, "rfilter": {"type": "box"},
            "component_format": "float32"}
    for k, (a, b) in enumerate(zip(edges_nm[:-1], edges_nm[1:])):
        film[f"band{k:03d}"] = box_response(a, b)
    return film


def rgb_film(geom: CameraGeometry) -> dict:
    return {"type": "hdrfilm", "width": geom.width_px, "height": geom.height_px, "rfilter": {"type": "box"},
            "pixel_format": "rgb", "component_format": "float32"}


def depth_sensor(mi, geom: CameraGeometry, lens: Lens) -> dict:
    """One ray per pixel through its centre (stratified, no jitter), for the position AOV."""
    film = {"type": "hdrfilm", "width": geom.width_px, "height": geom.height_px, "rfilter": {"type": "box"},
            "pixel_format": "luminance", "component_format": "float32"}
    pinhole = Lens(lens.focal_length_mm, lens.f_number, lens.focus_distance_m, "pinhole")
    return sensor(mi, geom, pinhole, film, {"type": "stratified", "sample_count": 1, "jitter": False})


# ---------------------------------------------------------------- the monitor


def monitor_shape(mi, size_m: tuple[float, float], drive: np.ndarray, primaries: np.ndarray | None) -> dict:
    """The monitor's active area in the plane z = 0, facing +z, centred on the axis.

    `drive` [3, rows, cols] linear drive levels; each panel pixel is a uniform square (nearest
    lookup). With `primaries` None (RGB variant) the emitted RGB is the drive itself; with
    primaries [3, G] (spectral variant) the radiance is Σ_c drive_c · primary_c(λ)."""
    # rows flipped: the uv origin is at the bottom
    bitmap = mi.Bitmap(np.ascontiguousarray(drive.transpose(1, 2, 0)[::-1], dtype=np.float32))
    tex = {"type": "bitmap", "bitmap": bitmap, "raw": True, "filter_type": "nearest", "wrap_mode": "clamp"}
    if primaries is not None:
        register_panel_texture(mi)
        tex = {"type": "panel", "drive": tex, **{f"primary{c}": spectrum(primaries[c]) for c in range(3)}}
    w, h = size_m
    return {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale([w / 2, h / 2, 1.0]),
            "emitter": {"type": "area", "radiance": tex}}


def register_panel_texture(mi) -> None:
    """Register 'panel': radiance Σ_c drive_c(uv) · S_c(λ), traced into the llvm kernel."""

    class Panel(mi.Texture):
        def __init__(self, props):
            mi.Texture.__init__(self, props)
            self.drive = props["drive"]
            self.primaries = [props[f"primary{c}"] for c in range(3)]

        def eval(self, si, active=True):
            d = self.drive.eval_3(si, active)
            p = [s.eval(si, active) for s in self.primaries]
            return d.x * p[0] + d.y * p[1] + d.z * p[2]

        def mean(self):
            return 1.0

        def traverse(self, callback):
            pass

        def to_string(self):
            return "Panel[]"

    mi.register_texture("panel", lambda props: Panel(props))


# ---------------------------------------------------------------- 3D rooms


def _diffuse(reflectance: np.ndarray) -> dict:
    return {"type": "diffuse", "reflectance": spectrum(reflectance)}


def _rect(mi, centre, size, rotate=None, bsdf=None, emitter=None) -> dict:
    """A rectangle of size (w, h) m, normal +z before `rotate` = [(axis, deg), ...]."""
    t = mi.ScalarTransform4f().translate(list(centre))
    for axis, deg in rotate or []:
        t = t @ mi.ScalarTransform4f().rotate(axis, deg)
    d = {"type": "rectangle", "to_world": t @ mi.ScalarTransform4f().scale([size[0] / 2, size[1] / 2, 1.0])}
    if bsdf:
        d["bsdf"] = bsdf
    if emitter:
        d["emitter"] = emitter
    return d


def _box(mi, centre, size, yaw_deg, reflectance) -> dict:
    t = (mi.ScalarTransform4f().translate(list(centre)) @ mi.ScalarTransform4f().rotate([0, 1, 0], yaw_deg)
         @ mi.ScalarTransform4f().scale([s / 2 for s in size]))
    return {"type": "cube", "to_world": t, "bsdf": _diffuse(reflectance)}


def _sphere(centre, radius, bsdf=None, emitter=None) -> dict:
    d = {"type": "sphere", "center": list(centre), "radius": radius}
    if bsdf:
        d["bsdf"] = bsdf
    if emitter:
        d["emitter"] = emitter
    return d


ROOM_X, ROOM_Y, ROOM_Z = (-2.0, 2.0), (0.0, 2.6), (-2.0, 3.5)


def _shell(mi, window: tuple[float, float, float, float] | None = None) -> dict:
    """Floor, ceiling, four walls facing inwards; the back wall (z = −2) optionally with a window
    (x0, x1, y0, y1) cut out of it."""
    cc = spectra.colourchecker
    (x0, x1), (y0, y1), (z0, z1) = ROOM_X, ROOM_Y, ROOM_Z
    w, h, d = x1 - x0, y1 - y0, z1 - z0
    cx, cy, cz = (x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2
    parts = {
        "floor": _rect(mi, (cx, y0, cz), (w, d), [([1, 0, 0], -90)], _diffuse(cc("neutral 5 (.70 D)"))),
        "ceiling": _rect(mi, (cx, y1, cz), (w, d), [([1, 0, 0], 90)], _diffuse(cc("white 9.5 (.05 D)"))),
        "left": _rect(mi, (x0, cy, cz), (d, h), [([0, 1, 0], 90)], _diffuse(cc("moderate red"))),
        "right": _rect(mi, (x1, cy, cz), (d, h), [([0, 1, 0], -90)], _diffuse(cc("bluish green"))),
        "front": _rect(mi, (cx, cy, z1), (w, h), [([0, 1, 0], 180)], _diffuse(cc("neutral 8 (.23 D)"))),
    }
    back = _diffuse(cc("neutral 8 (.23 D)"))
    if window is None:
        parts["back"] = _rect(mi, (cx, cy, z0), (w, h), None, back)
    else:  # four panels around the opening
        wx0, wx1, wy0, wy1 = window
        parts["back_below"] = _rect(mi, (cx, (y0 + wy0) / 2, z0), (w, wy0 - y0), None, back)
        parts["back_above"] = _rect(mi, (cx, (wy1 + y1) / 2, z0), (w, y1 - wy1), None, back)
        parts["back_left"] = _rect(mi, ((x0 + wx0) / 2, (wy0 + wy1) / 2, z0), (wx0 - x0, wy1 - wy0), None, back)
        parts["back_right"] = _rect(mi, ((wx1 + x1) / 2, (wy0 + wy1) / 2, z0), (x1 - wx1, wy1 - wy0), None, back)
    return parts


def _objects(mi) -> dict:
    """Coloured diffuse objects on the floor and a 6 × 4 ColorChecker chart on the back wall."""
    cc = spectra.colourchecker
    names = list(colour_tables.names("colourchecker"))
    obj = {
        "sphere_red": _sphere((-0.9, 0.3, -0.6), 0.3, _diffuse(cc("red"))),
        "sphere_blue": _sphere((0.15, 0.22, -0.2), 0.22, _diffuse(cc("blue"))),
        "sphere_yellow": _sphere((0.55, 0.15, 0.35), 0.15, _diffuse(cc("yellow"))),
        "box_green": _box(mi, (0.95, 0.35, -0.9), (0.5, 0.7, 0.5), 25, cc("green")),
        "box_magenta": _box(mi, (-0.45, 0.2, -1.3), (0.6, 0.4, 0.4), -15, cc("magenta")),
        "box_cyan": _box(mi, (-1.3, 0.6, -1.5), (0.4, 1.2, 0.4), 10, cc("cyan")),
    }
    patch, gap = 0.12, 0.02
    for i, name in enumerate(names):
        r, c = divmod(i, 6)
        x = (c - 2.5) * (patch + gap)
        y = 0.70 - (r - 1.5) * (patch + gap)
        obj[f"chart_{i:02d}"] = _rect(mi, (x, y, ROOM_Z[0] + 0.005), (patch, patch), None, _diffuse(cc(name)))
    return obj


def room(mi, content: Room) -> dict:
    light = spectra.scaled_to_luminance(spectra.illuminant(content.illuminant), content.light_luminance_cd_m2)
    d = {"type": "scene", **_shell(mi), **_objects(mi)}
    d["ceiling_light"] = _rect(mi, (0.0, ROOM_Y[1] - 0.01, 0.5), (1.2, 1.2), [([1, 0, 0], 90)],
                               emitter={"type": "area", "radiance": spectrum(light)})
    return d


SUN_ANGULAR_DIAMETER_DEG = 0.53
WINDOW_M = (-0.5, 0.5, 1.15, 1.65)  # x0, x1, y0, y1 of the opening in the back wall
SUN_SEEN_AT_M = (0.3, 1.5, ROOM_Z[0])  # the camera sees the sun through this point of the window


def hdr_room(mi, content: HDRRoom, camera_origin_m) -> dict:
    """The room, dim, with a window (sky: a constant environment seen only through it; the sun: a
    sphere of 0.53° seen through the window from the camera) and two small lamps (2 cm spheres,
    illuminant A)."""
    d = {"type": "scene", **_shell(mi, WINDOW_M), **_objects(mi)}
    for name in [k for k in d if k.startswith("chart_")]:  # the chart would cover the window
        del d[name]
    sky = spectra.scaled_to_luminance(spectra.illuminant("D65"), content.sky_luminance_cd_m2)
    d["sky"] = {"type": "constant", "radiance": spectrum(sky)}
    sun_dir = np.subtract(SUN_SEEN_AT_M, camera_origin_m)
    sun_dir /= np.linalg.norm(sun_dir)
    dist = 1000.0
    sun = spectra.scaled_to_luminance(spectra.illuminant("D55"), content.sun_luminance_cd_m2)
    d["sun"] = _sphere(np.asarray(camera_origin_m) + dist * sun_dir,
                       dist * math.tan(math.radians(SUN_ANGULAR_DIAMETER_DEG / 2)),
                       emitter={"type": "area", "radiance": spectrum(sun)})
    lamp = spectrum(spectra.scaled_to_luminance(spectra.illuminant("A"), content.lamp_luminance_cd_m2))
    d["lamp_left"] = _sphere((-1.0, 1.25, -1.5), 0.02, emitter={"type": "area", "radiance": lamp})
    d["lamp_right"] = _sphere((1.0, 0.75, -0.9), 0.02, emitter={"type": "area", "radiance": lamp})
    if content.room_light_luminance_cd_m2 > 0:
        light = spectra.scaled_to_luminance(spectra.illuminant("A"), content.room_light_luminance_cd_m2)
        d["ceiling_light"] = _rect(mi, (0.0, ROOM_Y[1] - 0.01, 0.5), (1.2, 1.2), [([1, 0, 0], 90)],
                                   emitter={"type": "area", "radiance": spectrum(light)})
    return d

