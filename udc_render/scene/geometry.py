"""The camera of a scene: pose, projection and the render grid (sensor plus margin).

The lens is a thin lens of focal length f focused at distance u; the sensor sits at the image
distance v = 1 / (1/f − 1/u), so a sensor point x_s (µm, from the axis) sees the direction
x_s / v. The render grid covers the sensor plus a margin on every side, at the sensor pitch divided
by the supersampling factor. For the virtual MCIS the camera sits on the monitor's centre line at the
distance whose magnification m = v/u fits the monitor in the sensor (`fit`, the paper's
"adjusted to cover the full monitor range") or fills the sensor with it (`fill`): u = f (1 + 1/m).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from udc_render.scene.model import Monitor, Scene, SceneError


@dataclass(frozen=True)
class CameraGeometry:
    origin_m: tuple[float, float, float]
    target_m: tuple[float, float, float]
    up: tuple[float, float, float]
    focus_distance_m: float
    image_distance_um: float
    pitch_um: float  # render pixel pitch on the sensor
    margin_px: int  # render pixels of margin on each side
    width_px: int  # render grid, margin included
    height_px: int
    fov_x_deg: float

    @property
    def forward(self) -> np.ndarray:
        d = np.subtract(self.target_m, self.origin_m)
        return d / np.linalg.norm(d)

    def describe(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def monitor_distance_m(scene: Scene) -> float:
    """Camera-to-monitor distance for the framing (thin lens, focused on the monitor)."""
    mon: Monitor = scene.content
    w_m, h_m = mon.size_m
    s = scene.sensor
    ratios = (s.width_px * s.pitch_um * 1e-6 / w_m, s.height_px * s.pitch_um * 1e-6 / h_m)
    m = min(ratios) if mon.framing == "fit" else max(ratios)
    return scene.lens.focal_length_mm * 1e-3 * (1 + 1 / m)


def camera_geometry(scene: Scene) -> CameraGeometry:
    s, r, lens = scene.sensor, scene.render, scene.lens
    if isinstance(scene.content, Monitor):
        dist = monitor_distance_m(scene)
        origin, target, up = (0.0, 0.0, dist), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)
    else:
        if scene.camera.origin_m is None:
            how = (" (a Mitsuba XML scene's own camera: resolve it first with udc_render.render.resolve_xml_camera)"
                   if getattr(scene.content, "use_xml_camera", False) else "")
            raise SceneError(f"{scene.source}: camera.origin_m is required for content.type = "
                             f"{scene.content_type}{how}")
        origin, target, up = scene.camera.origin_m, scene.camera.target_m, scene.camera.up
        dist = float(np.linalg.norm(np.subtract(target, origin)))
    focus = lens.focus_distance_m or dist
    f_um = lens.focal_length_mm * 1e3
    v_um = 1.0 / (1.0 / f_um - 1.0 / (focus * 1e6))
    margin_sensor_px = math.ceil(r.margin_um / s.pitch_um - 1e-9)
    width = (s.width_px + 2 * margin_sensor_px) * r.supersample
    height = (s.height_px + 2 * margin_sensor_px) * r.supersample
    pitch = s.pitch_um / r.supersample
    fov_x = 2 * math.degrees(math.atan(width * pitch / 2 / v_um))
    return CameraGeometry(origin_m=tuple(map(float, origin)), target_m=tuple(map(float, target)),
                          up=tuple(map(float, up)), focus_distance_m=float(focus), image_distance_um=v_um,
                          pitch_um=pitch, margin_px=margin_sensor_px * r.supersample, width_px=width,
                          height_px=height, fov_x_deg=fov_x)


def axial_depth_m(geom: CameraGeometry, position_m: np.ndarray) -> np.ndarray:
    """Distance along the optical axis, (p − origin) · forward, of world points [..., 3]."""
    return (position_m - np.asarray(geom.origin_m)) @ geom.forward


def projection_px(geom: CameraGeometry, points_m: np.ndarray) -> np.ndarray:
    """Render-grid pixel coordinates (x right, y down, pixel centres at integer + 0.5) of world
    points [..., 3]: the pinhole projection through the lens centre onto the sensor at v."""
    fwd = geom.forward
    right = np.cross(fwd, geom.up)
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    rel = np.asarray(points_m, float) - np.asarray(geom.origin_m)
    z = rel @ fwd
    x_um = (rel @ right) / z * geom.image_distance_um
    y_um = (rel @ up) / z * geom.image_distance_um
    return np.stack([geom.width_px / 2 + x_um / geom.pitch_um, geom.height_px / 2 - y_um / geom.pitch_um], -1)


@dataclass(frozen=True)
class RenderGrid:
    """The render's grid, a fact of the scene (no render needed): pixel pitch on the sensor (µm,
    sensor pitch / supersample), margin on every side (render pixels) and band edges (nm). Kernels
    are planned on it, so they can be computed before or beside the render."""
    pitch_um: float
    margin_px: int
    edges_nm: tuple[float, ...]

    @property
    def centres_nm(self) -> np.ndarray:
        e = np.asarray(self.edges_nm, float)
        return (e[:-1] + e[1:]) / 2

    @property
    def kernel_size_px(self) -> int:
        """Largest odd kernel the margin allows without wrap-around: 2·margin + 1."""
        return 2 * int(self.margin_px) + 1


def sensor_kernel_px(scene: Scene) -> int:
    """The largest odd kernel at the sensor pitch that the render margin allows: 2 (margin // supersample) + 1
    (a kernel bank's default size: `udc-render bank`, the robustness study, the UNet (randomized) row)."""
    return 2 * (camera_geometry(scene).margin_px // scene.render.supersample) + 1


def render_grid(scene: Scene) -> RenderGrid:
    geom = camera_geometry(scene)
    return RenderGrid(pitch_um=float(geom.pitch_um), margin_px=int(geom.margin_px),
                      edges_nm=tuple(float(e) for e in scene.bands.edges_nm))


def psf_lens(scene: Scene, object_distance_m: float | None = None):
    """The psf.Lens of the scene's camera (µm), focused at the scene's focus distance, with the object
    at `object_distance_m` (None: at the focus distance, in focus), with the lens's aberrations (zernike_waves)."""
    from psf import Lens
    geom = camera_geometry(scene)
    focus_mm = geom.focus_distance_m * 1000.0
    obj_mm = focus_mm if object_distance_m is None else object_distance_m * 1000.0
    f_um = scene.lens.focal_length_mm * 1000.0
    return Lens(focal_length_um=f_um, aperture_um=f_um / scene.lens.f_number, focus_distance_mm=focus_mm,
                object_distance_mm=obj_mm, zernike_waves=scene.lens.zernike_waves)
