"""Scene files: TOML in `scenes/`, validated into frozen dataclasses.

A scene describes the rig (camera pose, lens, sensor), the wavelength bands, the render settings
and the content (the virtual monitor, a built-in 3D room, the HDR room, or a user's Mitsuba XML),
in physical units. Every bad value is rejected with one line naming the file, the key, the value
and what is allowed (:class:`SceneError`).

    scene = load_scene("scenes/monitor.toml")
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path


SCENES_DIR = Path(__file__).resolve().parent.parent / "scenes"
CONTENT_TYPES = ("monitor", "room", "hdr", "mitsuba_xml")
RENDER_PATHS = ("auto", "rgb_matrix", "spectral")
LENS_MODELS = ("pinhole", "thinlens")
FRAMINGS = ("fit", "fill")
TRANSFERS = ("srgb", "gamma2.2", "linear")
MITSUBA_RANGE_NM = (360.0, 830.0)  # the spectral variants' wavelength range

# Default margin: half the physical width of the PSF engine's default kernel (255 px of 3.1 µm),
# so that a linear convolution with the largest default kernel never reaches past the render.
DEFAULT_KERNEL_WIDTH_UM = 255 * 3.1
DEFAULT_MARGIN_UM = math.ceil(DEFAULT_KERNEL_WIDTH_UM / 2)


class SceneError(ValueError):
    """A bad scene file: one line naming file, key, value and what is allowed."""


@dataclass(frozen=True)
class Lens:
    focal_length_mm: float = 6.0
    f_number: float = 1.8
    focus_distance_m: float | None = None  # None: the monitor's distance (monitor) or the target's
    model: str = "pinhole"  # pinhole: all in focus, defocus left to the wave optics (depth output)

    @property
    def aperture_mm(self) -> float:
        return self.focal_length_mm / self.f_number


@dataclass(frozen=True)
class Sensor:
    width_px: int = 2048
    height_px: int = 1024
    pitch_um: float = 1.55


@dataclass(frozen=True)
class Camera:
    origin_m: tuple[float, float, float] | None = None  # None: placed by the content (monitor framing)
    target_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)


@dataclass(frozen=True)
class Bands:
    range_nm: tuple[float, float] = (400.0, 700.0)
    step_nm: float = 10.0

    @property
    def edges_nm(self) -> tuple[float, ...]:
        lo, hi = self.range_nm
        k = max(1, round((hi - lo) / self.step_nm))
        return tuple(lo + (hi - lo) * i / k for i in range(k + 1))

    @property
    def count(self) -> int:
        return len(self.edges_nm) - 1


@dataclass(frozen=True)
class Render:
    spp: int | None = 16
    noise: float | None = None  # target relative RMS noise; spp is then chosen from pilot renders
    seed: int = 0
    path: str = "auto"
    max_depth: int | None = None  # None: 2 for direct emission (monitor), 8 for 3D scenes
    margin_um: float = DEFAULT_MARGIN_UM
    supersample: int = 1  # render pixels per sensor pixel, per axis
    bands_per_render: int = 30  # study render: all bands in one render halves the samples for equal camera (XYZ) error
    depth: bool | None = None  # None: for 3D content only (a flat monitor has one known distance)


@dataclass(frozen=True)
class Monitor:
    image: str = "builtin:astronaut"
    diagonal_in: float = 27.0
    resolution_px: tuple[int, int] = (3840, 2160)
    peak_luminance_cd_m2: float = 300.0
    primaries: str = "Apple Studio Display"
    white_point: str = "D65"  # the panel's calibrated white; "native": the measured primaries' ratios
    transfer: str = "srgb"
    framing: str = "fit"  # fit: whole monitor in frame (the paper); fill: monitor fills the frame

    @property
    def size_m(self) -> tuple[float, float]:
        w, h = self.resolution_px
        d = self.diagonal_in * 0.0254
        return d * w / math.hypot(w, h), d * h / math.hypot(w, h)


@dataclass(frozen=True)
class Room:
    """A closed room with coloured diffuse objects (ColorChecker reflectances)."""
    light_luminance_cd_m2: float = 2000.0
    illuminant: str = "D65"


@dataclass(frozen=True)
class HDRRoom:
    """A dim room with a window showing sky and sun, and small bright lamps."""
    sun_luminance_cd_m2: float = 1.6e9
    sky_luminance_cd_m2: float = 8000.0
    lamp_luminance_cd_m2: float = 2.0e5
    room_light_luminance_cd_m2: float = 50.0


@dataclass(frozen=True)
class MitsubaXML:
    file: str = ""
    use_xml_camera: bool = True  # take the pose from the file's first sensor


@dataclass(frozen=True)
class Scene:
    source: str
    content: Monitor | Room | HDRRoom | MitsubaXML
    camera: Camera = field(default_factory=Camera)
    lens: Lens = field(default_factory=Lens)
    sensor: Sensor = field(default_factory=Sensor)
    bands: Bands = field(default_factory=Bands)
    render: Render = field(default_factory=Render)

    @property
    def content_type(self) -> str:
        return {Monitor: "monitor", Room: "room", HDRRoom: "hdr", MitsubaXML: "mitsuba_xml"}[type(self.content)]

    def resolve(self, path_text: str) -> Path:
        """A path in the scene file, relative to the file's folder."""
        p = Path(path_text).expanduser()
        return p if p.is_absolute() else Path(self.source).resolve().parent / p

    def with_render(self, **changes) -> "Scene":
        return replace(self, render=replace(self.render, **changes))

    def with_bands(self, bands: "Bands") -> "Scene":
        return replace(self, bands=bands)


# ---------------------------------------------------------------- validation


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
    "monitor": ("type", "image", "diagonal_in", "resolution_px", "peak_luminance_cd_m2", "primaries", "white_point", "transfer",
                "framing"),
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
        import colour
        if illuminant not in colour.SDS_ILLUMINANTS:
            t.fail("illuminant", illuminant, "a colour-science illuminant such as D65, A, D50, FL2")
        return Room(light_luminance_cd_m2=t.number("light_luminance_cd_m2", d.light_luminance_cd_m2, 0, 1e10, lo_open=True),
                    illuminant=illuminant)
    if kind == "hdr":
        d = HDRRoom()
        return HDRRoom(**{k: t.number(k, getattr(d, k), 0, 1e12) for k in _CONTENT_KEYS["hdr"][1:]})
    if "file" not in t.data:
        t.fail("file", None, "the path of a Mitsuba XML scene")
    return MitsubaXML(file=t.string("file", ""), use_xml_camera=t.boolean("use_xml_camera", True))


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

    t = _Table(source, "lens", data.get("lens", {}), ("focal_length_mm", "f_number", "focus_distance_m", "model"))
    d = Lens()
    lens = Lens(focal_length_mm=t.number("focal_length_mm", d.focal_length_mm, 0, 1e4, lo_open=True),
                f_number=t.number("f_number", d.f_number, 0.5, 128),
                focus_distance_m=t.number("focus_distance_m", d.focus_distance_m, 0, 1e9, lo_open=True, optional=True),
                model=t.string("model", d.model, LENS_MODELS))
    if lens.focus_distance_m is not None and lens.focus_distance_m * 1e3 <= lens.focal_length_mm:
        t.fail("focus_distance_m", lens.focus_distance_m, f"a distance beyond the focal length ({lens.focal_length_mm} mm)")

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
    if render.path == "rgb_matrix" and not isinstance(content, Monitor):
        t.fail("path", render.path, "\"spectral\" or \"auto\" for content other than the monitor (its transport depends on wavelength)")
    needs_pose = isinstance(content, (Room, HDRRoom)) or (isinstance(content, MitsubaXML) and not content.use_xml_camera)
    if camera.origin_m is None and needs_pose:
        raise SceneError(f"{source}: camera.origin_m = None: expected the camera position in metres "
                         f"for content.type = {data['content']['type']}")
    return Scene(source=source, content=content, camera=camera, lens=lens, sensor=sensor, bands=bands, render=render)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file; a bare name (e.g. 'monitor') is looked up in `scenes/`."""
    p = Path(path)
    if not p.exists() and not p.suffix and (SCENES_DIR / f"{p}.toml").exists():
        p = SCENES_DIR / f"{p}.toml"
    try:
        text = p.read_text()
    except OSError as e:
        raise SceneError(f"{p}: cannot read the scene file ({e.strerror or e})") from None
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


__all__ = ["Scene", "SceneError", "load_scene", "parse_scene", "parse_bands", "Monitor", "Room", "HDRRoom",
           "MitsubaXML", "Camera", "Lens", "Sensor", "Bands", "Render"]
