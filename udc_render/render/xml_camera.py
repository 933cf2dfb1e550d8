"""A user's Mitsuba XML scene (`content.type = "mitsuba_xml"`): loading it, and its camera pose.

    scene = resolve_xml_camera(load_scene("mine.toml"))   # before plan_kernels / render_scene / synthesize

`resolve_xml_camera` is the one place where the pose of the file's first sensor enters the scene
(`use_xml_camera = true`): camera.origin_m / target_m / up from the sensor's to_world, and, unless the
scene sets lens.focus_distance_m, the focus distance of a thinlens sensor, else the distance to its
lookat target, else infinity. Only the pose and the focus are taken: the scene's [lens] and [sensor]
keep the focal length, f-number, sensor size and pitch, so the render's field of view is the
scene's (the render builds its own sensor; the XML's film, field of view and a thin lens's aperture
are not used: defocus comes from the wave optics at the rendered depth). What was taken is recorded
in `content.xml_camera` (and the render's metadata, hence synth.json).

Refused with one line naming the file, the element and what is allowed: a file Mitsuba cannot load,
no sensor, a sensor other than perspective or thinlens, a to_world that is not a rigid pose (scale,
shear, mirror), an off-axis principal point.

A loaded file is kept (one at a time, by path, modification time, size and variant), so the render
does not load it a second time.
"""
from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np

from udc_render.render.errors import RenderError
from udc_render.scene import MitsubaXML, Scene, XMLCamera

SUPPORTED = {"PerspectiveCamera": "perspective", "ThinLensCamera": "thinlens"}
OTHER_SENSORS = {"OrthographicCamera": "orthographic", "RadianceMeter": "radiancemeter",
                 "IrradianceMeter": "irradiancemeter", "DistantSensor": "distant", "BatchSensor": "batch"}
_LOADED: dict = {}  # {(path, mtime_ns, size, variant): the loaded Mitsuba scene}: the last one only


def xml_path(scene: Scene) -> Path:
    """The XML file of a mitsuba_xml scene (relative to the scene file), which must exist."""
    content = scene.content
    xml = scene.resolve(content.file)
    if not xml.is_file():
        raise RenderError(f"{scene.source}: content.file = {content.file!r}: no such file {xml}")
    return xml


def load_xml(scene: Scene, mi):
    """The Mitsuba scene of `scene`'s XML file, loaded in the current variant (kept: see the module doc)."""
    xml = xml_path(scene)
    st = xml.stat()
    key = (str(xml.resolve()), st.st_mtime_ns, st.st_size, mi.variant())
    if key not in _LOADED:
        try:
            loaded = mi.load_file(str(xml))
        except Exception as e:  # Mitsuba raises RuntimeError with a long message
            # its message, on one line, without the source location: "[parser.cpp:444] While loading ...:\n - ..."
            text = " ".join(t.strip() for t in str(e).splitlines() if t.strip())
            text = re.sub(r"^\[[\w.]+:\d+\]\s*", "", text) or type(e).__name__
            raise RenderError(f"{scene.source}: content.file = {scene.content.file!r}: Mitsuba cannot load {xml}: "
                              f"{text}") from None
        _LOADED.clear()
        _LOADED[key] = loaded
    return _LOADED[key]


def resolve_xml_camera(scene: Scene) -> Scene:
    """`scene` with the pose of its Mitsuba XML file's first sensor (module doc); other scenes, scenes
    already resolved and `use_xml_camera = false` unchanged (the file is loaded either way, so a file
    Mitsuba cannot read stops here, before any kernel is planned)."""
    content = scene.content
    if not isinstance(content, MitsubaXML) or content.xml_camera is not None:
        return scene
    from udc_render.render.variants import set_variant
    mi, _ = set_variant("spectral")  # the variant user XML is rendered in
    loaded = load_xml(scene, mi)
    if not content.use_xml_camera:
        return scene
    xml = xml_path(scene)
    where = f"{scene.source}: content.use_xml_camera = true: {xml}"
    if not loaded.sensors():
        raise RenderError(f"{scene.source}: content.use_xml_camera = true but {xml} has no sensor: expected a "
                          "<sensor type=\"perspective\"> (or thinlens), or use_xml_camera = false with "
                          "camera.origin_m")
    sensor = loaded.sensors()[0]
    cls = sensor.class_name()
    element = f"<sensor type=\"{SUPPORTED.get(cls) or OTHER_SENSORS.get(cls) or cls}\" id=\"{sensor.id()}\">"
    if cls not in SUPPORTED:
        raise RenderError(f"{where}: the first sensor {element} is not supported: expected type perspective or "
                          f"thinlens (the render's camera is a perspective projection through the scene's lens), or "
                          f"use_xml_camera = false with camera.origin_m")
    params = mi.traverse(sensor)
    for key in ("principal_point_offset_x", "principal_point_offset_y"):
        offset = scalar_param(params, key) if key in params else 0.0
        if abs(offset) > 1e-9:
            raise RenderError(f"{where}: {element} {key} = {offset:g}: expected 0 (the render's "
                              f"camera is centred on the optical axis)")
    m = np.array(sensor.world_transform().matrix, dtype=float).reshape(4, 4)
    rot = m[:3, :3]
    if not (np.allclose(rot.T @ rot, np.eye(3), atol=1e-5) and np.linalg.det(rot) > 0):
        raise RenderError(f"{where}: {element} to_world is not a rigid pose (it scales, shears or mirrors; "
                          f"singular values {np.round(np.linalg.svd(rot, compute_uv=False), 4).tolist()}, determinant "
                          f"{np.linalg.det(rot):.3g}): expected a lookat, rotations and translations")
    origin, forward, up = m[:3, 3], m[:3, 2], m[:3, 1]
    target = _lookat_target(xml, origin, forward)
    fov = scalar_param(params, "x_fov") if "x_fov" in params else None
    aperture = scalar_param(params, "aperture_radius") if "aperture_radius" in params else None
    if scene.lens.focus_distance_m is not None:
        focus, focus_from = scene.lens.focus_distance_m, "lens.focus_distance_m"
    elif cls == "ThinLensCamera":
        focus, focus_from = scalar_param(params, "focus_distance"), "thinlens focus_distance"
    elif target is not None:
        focus, focus_from = float(np.linalg.norm(target - origin)), "lookat target"
    else:
        focus, focus_from = math.inf, "infinity"
    if target is None:
        target = origin + forward
    f_m = scene.lens.focal_length_mm * 1e-3
    if not focus > f_m:
        raise RenderError(f"{where}: {element} focus distance {focus:g} m ({focus_from}): expected more than the "
                          f"focal length {f_m:g} m; set lens.focus_distance_m")
    record = XMLCamera(file=str(xml), sensor=SUPPORTED[cls], sensor_id=sensor.id(), origin_m=_vec(origin),
                       target_m=_vec(target), up=_vec(up), focus_distance_m=float(focus), focus_from=focus_from,
                       xml_fov_x_deg=fov, xml_aperture_radius_m=aperture)
    return replace(scene,
                   camera=replace(scene.camera, origin_m=record.origin_m, target_m=record.target_m, up=record.up),
                   lens=replace(scene.lens, focus_distance_m=record.focus_distance_m),
                   content=replace(content, xml_camera=record))


def scalar_param(params, key: str) -> float:
    """One number of a traversed Mitsuba object: the scalar variants give a Python float, the llvm ones
    a one-element Float array; anything else (a vector, a transform) is an error, not a silent first element."""
    return float(np.asarray(params[key], dtype=float).item())


def _vec(v) -> tuple[float, float, float]:
    return tuple(float(x) for x in v)


def _lookat_target(xml: Path, origin: np.ndarray, forward: np.ndarray) -> np.ndarray | None:
    """The target of the first sensor's to_world when it is a single literal <lookat> that agrees with the
    loaded pose (else None: the pose alone has no target distance)."""
    try:
        root = ET.parse(xml).getroot()
    except (ET.ParseError, OSError):
        return None
    first = next(root.iter("sensor"), None)
    if first is None:
        return None
    t = [e for e in first if e.tag == "transform" and e.get("name") == "to_world"]
    if len(t) != 1 or len(t[0]) != 1 or t[0][0].tag != "lookat":
        return None
    try:
        o, g = (np.array([float(x) for x in t[0][0].get(k, "").replace(",", " ").split()])
                for k in ("origin", "target"))
    except ValueError:  # $parameters and the like
        return None
    if o.shape != (3,) or g.shape != (3,) or not np.linalg.norm(g - o) > 0:
        return None
    d = (g - o) / np.linalg.norm(g - o)
    scale = max(1.0, float(np.abs(origin).max()))
    if not (np.allclose(o, origin, atol=1e-5 * scale) and np.allclose(d, forward, atol=1e-5)):
        return None
    return g
