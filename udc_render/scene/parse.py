"""Scene files: TOML (the built-in ones ship in the package udc_render.scenes) ──► a validated Scene.

    scene = load_scene("monitor")            # a built-in scene by name
    scene = load_scene("path/to/mine.toml")  # a user's file
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import replace
from importlib import resources
from pathlib import Path

from psf import colour_tables
from udc_render.scene.model import (
    CONTENT_TYPES,
    FRAMINGS,
    LENS_MODELS,
    MITSUBA_RANGE_NM,
    RENDER_PATHS,
    SAMPLERS,
    TRANSFERS,
    Bands,
    Camera,
    HDRRoom,
    Lens,
    MitsubaXML,
    Monitor,
    Render,
    Room,
    Scene,
    SceneError,
    Sensor,
)


def scenes_dir() -> Path:
    """The folder of the built-in scene files (package data of udc_render.scenes)."""
    return Path(str(resources.files("udc_render.scenes")))


class _Table:
    """One TOML table with typed getters that name file and key in their errors."""

    def __init__(self, source: str, name: str, data: dict, allowed: tuple[str, ...]):
        self.source, self.name, self.data = source, name, data
        if not isinstance(data, dict):
            self.fail(name, data, "a table")
        for key in data:
            if key not in allowed:
                self.fail(key, data[key], f"a known key ({', '.join(allowed)})")

    def key(self, k: str) -> str:
        return f"{self.name}.{k}" if self.name else k

    def fail(self, k: str, value, allowed: str):
        where = self.key(k) if k != self.name else k
        raise SceneError(f"{self.source}: {where} = {value!r}: expected {allowed}")

    def number(self, k, default, lo=None, hi=None, lo_open=False, integer=False, optional=False):
        if k not in self.data:
            return default
        v = self.data[k]
        if optional and v == "auto":
            return None
        kind = "an integer" if integer else "a number"
        ok_type = isinstance(v, int) if integer else isinstance(v, (int, float))
        if isinstance(v, bool) or not ok_type or not math.isfinite(v):
            self.fail(k, v, kind + (" or \"auto\"" if optional else ""))
        lo_ok = lo is None or (v > lo if lo_open else v >= lo)
        if not lo_ok or (hi is not None and v > hi):
            rng = f"{'(' if lo_open else '['}{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}]"
            self.fail(k, v, f"{kind} in {rng}")
        return int(v) if integer else float(v)

    def string(self, k, default, choices=None):
        if k not in self.data:
            return default
        v = self.data[k]
        if not isinstance(v, str) or (choices is not None and v not in choices):
            self.fail(k, v, "one of " + ", ".join(choices) if choices else "a string")
        return v

    def boolean(self, k, default):
        if k not in self.data:
            return default
        v = self.data[k]
        if not isinstance(v, bool) and not (v == "auto" and default is None):
            self.fail(k, v, "true or false")
        return None if v == "auto" else v

    def vector(self, k, default, n=3, positive=False):
        if k not in self.data:
            return default
        v = self.data[k]
        if (not isinstance(v, list) or len(v) != n
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)
                or (positive and not all(x > 0 for x in v))):
            self.fail(k, v, f"a list of {n} {'positive ' if positive else ''}numbers")
        return tuple(float(x) for x in v)


_CONTENT_KEYS = {
    "monitor": ("type", "image", "diagonal_in", "resolution_px", "peak_luminance_cd_m2", "primaries", "white_point",
                "transfer", "framing"),
    "room": ("type", "light_luminance_cd_m2", "illuminant"),
    "hdr": ("type", "sun_luminance_cd_m2", "sky_luminance_cd_m2", "lamp_luminance_cd_m2", "room_light_luminance_cd_m2"),
    "mitsuba_xml": ("type", "file", "use_xml_camera"),
}


def _content(data, source: str):
    kind = data.get("type") if isinstance(data, dict) else None
    if kind not in CONTENT_TYPES:
        raise SceneError(f"{source}: content.type = {kind!r}: expected one of {', '.join(CONTENT_TYPES)}")
    t = _Table(source, "content", data, _CONTENT_KEYS[kind])
    if kind == "monitor":
        d = Monitor()
        res = t.vector("resolution_px", d.resolution_px, n=2, positive=True)
        if any(int(x) != x or x > 16384 for x in res):
            t.fail("resolution_px", list(res), "two whole numbers of pixels, each at most 16384")
        return Monitor(
            image=t.string("image", d.image),
            diagonal_in=t.number("diagonal_in", d.diagonal_in, 1, 400),
            resolution_px=(int(res[0]), int(res[1])),
            peak_luminance_cd_m2=t.number("peak_luminance_cd_m2", d.peak_luminance_cd_m2, 0, 1e7, lo_open=True),
            primaries=t.string("primaries", d.primaries),
            white_point=t.string("white_point", d.white_point),
            transfer=t.string("transfer", d.transfer, TRANSFERS),
            framing=t.string("framing", d.framing, FRAMINGS),
        )
    if kind == "room":
        d = Room()
        illuminant = t.string("illuminant", d.illuminant)
        if colour_tables.key("illuminants", illuminant) is None:
            t.fail("illuminant", illuminant, "a colour-science illuminant such as D65, A, D50, FL2")
        return Room(light_luminance_cd_m2=t.number("light_luminance_cd_m2", d.light_luminance_cd_m2, 0, 1e10,
                                                   lo_open=True), illuminant=illuminant)
    if kind == "hdr":
        d = HDRRoom()
        return HDRRoom(**{k: t.number(k, getattr(d, k), 0, 1e12) for k in _CONTENT_KEYS["hdr"][1:]})
    if "file" not in t.data:
        t.fail("file", None, "the path of a Mitsuba XML scene")
    return MitsubaXML(file=t.string("file", ""), use_xml_camera=t.boolean("use_xml_camera", True))


def _zernike(t: _Table, default: tuple) -> tuple:
    """[lens] zernike_waves = [[n, m, waves], …]: the lens's Zernike terms (psf.zernike), checked."""
    if "zernike_waves" not in t.data:
        return default
    from psf import Lens as PsfLens, LensError, zernike
    try:
        return PsfLens(zernike_waves=t.data["zernike_waves"]).zernike_waves
    except LensError:
        t.fail("zernike_waves", t.data["zernike_waves"], zernike.ALLOWED)


def parse_scene(data: dict, source: str) -> Scene:
    """Validate a parsed TOML document into a :class:`Scene`."""
    top = _Table(source, "", data, ("camera", "lens", "sensor", "bands", "render", "content"))
    if "content" not in data:
        top.fail("content", None, "a [content] table with a type (" + ", ".join(CONTENT_TYPES) + ")")
    content = _content(data["content"], source)

    t = _Table(source, "camera", data.get("camera", {}), ("origin_m", "target_m", "up"))
    d = Camera()
    camera = Camera(origin_m=t.vector("origin_m", d.origin_m), target_m=t.vector("target_m", d.target_m),
                    up=t.vector("up", d.up))
    if camera.origin_m is not None and camera.origin_m == camera.target_m:
        t.fail("target_m", list(camera.target_m), "a point different from camera.origin_m")

    t = _Table(source, "lens", data.get("lens", {}),
               ("focal_length_mm", "f_number", "focus_distance_m", "model", "zernike_waves"))
    d = Lens()
    lens = Lens(focal_length_mm=t.number("focal_length_mm", d.focal_length_mm, 0, 1e4, lo_open=True),
                f_number=t.number("f_number", d.f_number, 0.5, 128),
                focus_distance_m=t.number("focus_distance_m", d.focus_distance_m, 0, 1e9, lo_open=True, optional=True),
                model=t.string("model", d.model, LENS_MODELS), zernike_waves=_zernike(t, d.zernike_waves))
    if lens.focus_distance_m is not None and lens.focus_distance_m * 1e3 <= lens.focal_length_mm:
        t.fail("focus_distance_m", lens.focus_distance_m,
               f"a distance beyond the focal length ({lens.focal_length_mm} mm)")

    t = _Table(source, "sensor", data.get("sensor", {}), ("width_px", "height_px", "pitch_um"))
    d = Sensor()
    sensor = Sensor(width_px=t.number("width_px", d.width_px, 1, 16384, integer=True),
                    height_px=t.number("height_px", d.height_px, 1, 16384, integer=True),
                    pitch_um=t.number("pitch_um", d.pitch_um, 0, 1000, lo_open=True))

    t = _Table(source, "bands", data.get("bands", {}), ("range_nm", "step_nm"))
    d = Bands()
    rng = t.vector("range_nm", d.range_nm, n=2)
    lo, hi = MITSUBA_RANGE_NM
    if not (lo <= rng[0] < rng[1] <= hi):
        t.fail("range_nm", list(rng), f"[low, high] with {lo:g} <= low < high <= {hi:g} nm")
    bands = Bands(range_nm=rng, step_nm=t.number("step_nm", d.step_nm, 0.5, rng[1] - rng[0]))

    t = _Table(source, "render", data.get("render", {}), tuple(Render.__dataclass_fields__))
    d = Render()
    render = Render(
        spp=t.number("spp", d.spp, 1, 1 << 20, integer=True),
        noise=t.number("noise", d.noise, 0, 1, lo_open=True),
        seed=t.number("seed", d.seed, 0, 2**32 - 1, integer=True),
        sampler=t.string("sampler", d.sampler, SAMPLERS),
        path=t.string("path", d.path, RENDER_PATHS),
        max_depth=t.number("max_depth", d.max_depth, 1, 1024, integer=True, optional=True),
        margin_um=t.number("margin_um", d.margin_um, 0, 1e5),
        supersample=t.number("supersample", d.supersample, 1, 16, integer=True),
        bands_per_render=t.number("bands_per_render", d.bands_per_render, 1, 1000, integer=True),
        depth=t.boolean("depth", d.depth),
    )
    if "noise" in t.data and "spp" in t.data:
        t.fail("noise", render.noise, "either render.spp or render.noise, not both")
    if render.noise is not None:
        render = replace(render, spp=None)
    if render.path == "analytic" and not (isinstance(content, Monitor) and lens.model == "pinhole"):
        t.fail("path", render.path, "\"auto\", \"rgb_matrix\" or \"spectral\": \"analytic\" needs monitor content "
                                    "and lens.model = \"pinhole\"")
    if render.path == "rgb_matrix" and not isinstance(content, Monitor):
        t.fail("path", render.path,
               "\"spectral\" or \"auto\" for content other than the monitor (its transport depends on wavelength)")
    needs_pose = (isinstance(content, (Room, HDRRoom))
                  or (isinstance(content, MitsubaXML) and not content.use_xml_camera))
    if camera.origin_m is None and needs_pose:
        raise SceneError(f"{source}: camera.origin_m = None: expected the camera position in metres "
                         f"for content.type = {data['content']['type']}")
    return Scene(source=source, content=content, camera=camera, lens=lens, sensor=sensor, bands=bands, render=render)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file; a bare name (e.g. 'monitor') is looked up in `scenes/`."""
    p = Path(path)
    if not p.exists() and not p.suffix and (scenes_dir() / f"{p}.toml").exists():
        p = scenes_dir() / f"{p}.toml"
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as e:
        raise SceneError(f"{p}: cannot read the scene file ({e.strerror or e})") from None
    except UnicodeDecodeError as e:
        raise SceneError(f"{p}: not UTF-8 text (byte {e.start}): expected a TOML scene file") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{p}: not valid TOML ({e})") from None
    return parse_scene(data, str(p))


def parse_bands(text: str) -> Bands:
    """'400:700:10' (low:high:step, nm) as :class:`Bands`; raises SceneError naming --bands-nm."""
    parts = text.split(":")
    try:
        lo, hi, step = (float(x) for x in parts)
    except ValueError:
        raise SceneError(f"--bands-nm = {text!r}: expected LOW:HIGH:STEP in nm, e.g. 400:700:10") from None
    if not (MITSUBA_RANGE_NM[0] <= lo < hi <= MITSUBA_RANGE_NM[1]) or not (0.5 <= step <= hi - lo):
        raise SceneError(f"--bands-nm = {text!r}: expected {MITSUBA_RANGE_NM[0]:g} <= LOW < HIGH <= "
                         f"{MITSUBA_RANGE_NM[1]:g} and 0.5 <= STEP <= HIGH - LOW")
    return Bands(range_nm=(lo, hi), step_nm=step)


