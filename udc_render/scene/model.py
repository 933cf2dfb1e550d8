"""The scene model: frozen dataclasses for the rig and the content (parse.py fills them from TOML).

A scene describes the rig (camera pose, lens, sensor), the wavelength bands, the render settings
and the content (the virtual monitor, a built-in 3D room, the HDR room, or a user's Mitsuba XML),
in physical units. Every bad value is rejected with one line naming the file, the key, the value
and what is allowed (:class:`SceneError`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

from udc_render.errors import UdcError

CONTENT_TYPES = ("monitor", "room", "hdr", "mitsuba_xml")
RENDER_PATHS = ("auto", "analytic", "rgb_matrix", "spectral")
# Mitsuba samplers (plugin names); each pass is one independent randomisation (render.job)
SAMPLERS = ("independent", "stratified", "multijitter", "orthogonal", "ldsampler")
LENS_MODELS = ("pinhole", "thinlens")
FRAMINGS = ("fit", "fill")
TRANSFERS = ("srgb", "gamma2.2", "linear")
MITSUBA_RANGE_NM = (360.0, 830.0)  # the spectral variants' wavelength range

# Default margin: half the physical width of the PSF engine's default kernel (255 px of 3.1 µm),
# so that a linear convolution with the largest default kernel never reaches past the render.
DEFAULT_KERNEL_WIDTH_UM = 255 * 3.1
DEFAULT_MARGIN_UM = math.ceil(DEFAULT_KERNEL_WIDTH_UM / 2)


class SceneError(UdcError):
    """A bad scene file: one line naming file, key, value and what is allowed."""


@dataclass(frozen=True)
class Lens:
    focal_length_mm: float = 6.0
    f_number: float = 1.8
    focus_distance_m: float | None = None  # None: the monitor's distance (monitor) or the target's
    model: str = "pinhole"  # pinhole: all in focus, defocus left to the wave optics (depth output)
    # Wavefront aberrations of the lens for the wave optics: (n, m, waves RMS at 550 nm) per Zernike term
    # (psf.zernike, psf.lens.Lens.zernike_waves); () the diffraction-limited lens (default: no magnitude published)
    zernike_waves: tuple = ()

    def __post_init__(self):
        if self.zernike_waves:  # checked and sorted by the psf lens (a [lens] table is checked in parse)
            from psf import Lens as PsfLens, LensError, zernike
            try:
                object.__setattr__(self, "zernike_waves", PsfLens(zernike_waves=self.zernike_waves).zernike_waves)
            except LensError:
                raise SceneError(f"lens.zernike_waves = {self.zernike_waves!r}: expected {zernike.ALLOWED}") from None

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
    sampler: str = "multijitter"  # a Mitsuba sampler (SAMPLERS); study render: the fastest to a target error in 3D
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
class XMLCamera:
    """The pose taken from a Mitsuba XML file's first sensor (udc_render.render.resolve_xml_camera): only
    the pose and the focus distance; the scene's [lens] and [sensor] keep the focal length, f-number,
    sensor size and pitch, hence the field of view. The XML's own field of view and a thin lens's
    aperture are recorded here and not used."""
    file: str
    sensor: str  # the plugin: perspective or thinlens
    sensor_id: str
    origin_m: tuple[float, float, float]
    target_m: tuple[float, float, float]  # the lookat's target, or at 1 m along the axis when not readable
    up: tuple[float, float, float]
    focus_distance_m: float  # as rendered (inf: at infinity)
    focus_from: str  # "lens.focus_distance_m", "thinlens focus_distance", "lookat target" or "infinity"
    xml_fov_x_deg: float | None = None  # not used: the field of view is the scene's sensor and lens
    xml_aperture_radius_m: float | None = None  # thinlens: not used (defocus: the wave optics, from depth)


@dataclass(frozen=True)
class MitsubaXML:
    file: str = ""
    use_xml_camera: bool = True  # take the pose from the file's first sensor
    xml_camera: XMLCamera | None = None  # the pose taken (set by render.resolve_xml_camera; None: not yet)


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
