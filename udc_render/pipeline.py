"""The pipeline: a scene ──► the ground truth and the captures a camera records through each display.

    plan_kernels(scene) ─┐
    render_scene(scene) ─┴─► synthesize: optics (blur, T(λ), field blend) ─► sensor     (capture_scene)

The lens, focal length and pixel pitch have one source, the scene: the kernels (psf_lens) and the
sensor's irradiance and cos⁴ fall-off (sensor_for_scene) both take them from it.

One render serves every display (the scene does not change); per display:

- form 'spectral' (default, physically based): the K band images are blurred with the K band
  kernels (psf at the band centres), multiplied by T(λ_k) · transmittance_k · (1 − energy
  outside_k), and integrated by the camera's sensitivities into an RGGB mosaic (udc_render.sensor).
- form 'per_channel' (the paper's y = γ x ⊗ k + n): x is the un-blurred camera RGB of the render,
  blurred with the three channel-effective kernels (psf.spectral.channel_kernels, weighted by the
  camera and D65) and scaled by the display's γ (the paper's values for the presets, the analytic
  γ of optics.gamma for a display file).

Ground truth ('gt'): what the clean capture would record without noise and without the mosaic: the
render through the glass panel (bare-lens kernels, gain 1), every camera channel at every pixel, in
units of the white level (1.0 = white at gain 1 = the full well), linear, not clipped, and without
the sensor's defect pixels (SynthConfig.defects, udc_render.sensor.defects: the same dead and hot
pixels in every capture, glass included, and never in the ground truth).

Exposure: 'auto' puts the monitor's full white at EXPOSURE_FILL of the full well in the brightest
channel through glass at gain 1 (a fixed setting for every image, like the paper's rig; behind the
displays the paper's gains 6 and 25 bring the levels back); for 3D scenes the EXPOSURE_PERCENTILE
of the glass image's brightest channel takes that place.

Object distance (defocus). The kernels carry the defocus of the object's distance (psf: the pupil phase
π r² (1/z − 1/z_f)/λ): for the monitor its plane's distance, known from the scene; for 3D scenes the
rendered depth, through depth layers (optics.layers: as few layers as the defocus tolerance
SynthConfig.defocus_tolerance_px allows, each blurred with its own kernels, summed with the layered
occlusion model). The render is a pinhole's (sharp); a thin-lens render already holds its defocus, so
its kernels stay in focus (counted once).

Very bright pixels (the sun) are convolved apart in float64 (bright_pixels, optics.BrightPixels), so
that the float32 FFTs' round-off stays below a tenth of the read noise at any dynamic range.

Kernels are planned from the scene alone (plan_kernels: the render grid and the lens are facts of the
scene), so they can be computed before or beside the render: at the render pitch with size
2·margin + 1 (the largest the margin allows), for the object at the scene's distance (the monitor's
plane; the focus distance for 3D scenes, whose other layers are planned after the render), and
cached on disk (psf.cache, in SynthConfig.kernel_cache or psf's default folder). They integrate over
the render pixel, and the render's pixels are area means too, so at render.supersample = 1 the
sensor pixel's box enters twice (an extra blur of one pixel); with supersample s the render and the
kernels use pitch / s and the sensor bins s × s, leaving an extra box of 1/s pixel
(`udc-render study capture` measures the error).
"""
from __future__ import annotations

import math
import time
import zlib
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from psf import KernelSet, compute_kernels
from psf.cache import cached
from psf.engine import DEFAULT_FIELD_PHASES
from psf.spectral import channel_kernels
from udc_render.errors import UdcError
from udc_render.optics import FieldBasis, field_basis, field_weights, live_phases
from udc_render.optics.layers import DefocusGeometry, DepthLayers, LayerError, choose_layers, one_layer
from udc_render.optics import gamma
from udc_render.optics.displays import PAPER_GAMMA, Display
from udc_render.render import BandImage, render_scene, resolve_xml_camera
from udc_render.scene import Monitor, Scene
from udc_render.scene.geometry import RenderGrid, camera_geometry, monitor_distance_m, psf_lens, render_grid
from udc_render.sensor import (Capture, DefectConfig, SensorConfig, band_electron_weights, capture, capture_electrons,
                               electrons_rgb, mosaic_of, rgb_to_rggb)
from udc_render.views import View, bin_pixels, bright_pixels, layered_electrons, per_channel_blur

FORMS = ("spectral", "per_channel")
EXPOSURE_FILL = 0.8
EXPOSURE_PERCENTILE = 99.5
# Depth layers: the largest error in a pixel's blur-circle diameter, in render pixels (optics.layers).
# `study capture` (layers: a near ramp over a far plane, against the per-pixel reference): the error at the
# near object's edge falls linearly with the tolerance, 0.68 % at 1 px (8 layers; 0.36 % at 0.5 px with 13,
# 1.6 % at 4 px with 3). 1 px keeps the built-in room at 2048 × 1024 within 3× its one-layer optics
# (benchmarks/bench_layers.py: 0.5 px gives it 3 layers and 3.7×).
DEFAULT_DEFOCUS_TOLERANCE_PX = 1.0



class SynthError(UdcError):
    """Settings the synthesis cannot honour; one line."""


@dataclass(frozen=True)
class SynthConfig:
    """Knobs of the synthesis (defaults: the paper's rig; every one is recorded in the sidecars)."""
    form: str = "spectral"
    sensor: SensorConfig = field(default_factory=SensorConfig)  # gain is replaced by each display's
    exposure_s: float | None = None  # None: auto (module doc)
    precision: str = "float32"  # optics FFTs
    kernel_precision: str = "float32"
    field_phases: int | None = None  # d > 0: phases per axis (None: the engine's default, 4)
    blend: str = "source"
    # d > 0: rank of each band's phase-kernel basis (None: every phase, exact). 2, from `study capture`
    # (field_rank) and the full-frame check in README: 4.8× faster than every phase at 4e-4 relative RMS
    # (T-OLED, d = 2 mm; P-OLED 1e-4), a hundredth of the sensor noise, 3 % of the bands' amplitude.
    field_rank: int | None = 2
    seed: int = 0
    use_cache: bool = True
    kernel_cache: str | None = None  # kernel cache folder (None: psf.cache's default); how, not what: not recorded
    defects: DefectConfig | None = None  # dead and hot pixels of the sensor (None: none)
    # Depth layers (optics.layers): largest blur-diameter error, render px; None: no defocus at all
    # (every pixel in focus, the kernels of the focus distance)
    defocus_tolerance_px: float | None = DEFAULT_DEFOCUS_TOLERANCE_PX
    bright_split: bool = True  # very bright pixels convolved apart in float64 (bright_pixels)
    # The profile that chose form, distance and defects (udc_render.profiles.resolve_profile): a JSON
    # record {name, sets, options, applied}, kept in synth.json; None when no profile was used.
    profile: dict | None = field(default=None, hash=False)

    def __post_init__(self):
        if self.form not in FORMS:
            raise SynthError(f"form = {self.form!r}: expected one of {', '.join(FORMS)}")
        if self.defects is not None and not isinstance(self.defects, DefectConfig):
            raise SynthError(f"defects = {self.defects!r}: expected a sensor.defects.DefectConfig or None")
        if self.exposure_s is not None and not (self.exposure_s > 0 and math.isfinite(self.exposure_s)):
            raise SynthError(f"exposure_s = {self.exposure_s!r}: expected a positive number of seconds or auto")
        tol = self.defocus_tolerance_px
        if tol is not None and (isinstance(tol, bool) or not isinstance(tol, (int, float)) or not math.isfinite(tol)
                                or not tol >= 0.05):
            raise SynthError(f"defocus_tolerance_px = {tol!r}: expected a number of pixels ≥ 0.05, or None (no defocus)")


@dataclass(frozen=True)
class SynthResult:
    """What synthesize hands to the file writer (io.capture.write_synthesis): the arrays, and the
    records that become the JSON sidecars."""
    gt: np.ndarray  # [3, H, W] float32, linear camera RGB / white level (module doc)
    captures: dict[str, Capture]  # by display name
    meta: dict  # synth.json: scene, render, exposure, seeds
    display_meta: dict[str, dict]  # <display>/capture.json additions: display, optics, kernels, γ
    timing: dict = field(default_factory=dict)  # seconds; kept out of the files (identical runs, identical bytes)


@dataclass(frozen=True)
class Kernels:
    """The kernel sets a synthesis needs, by display name ('glass': the bare lens, always there):
    band kernels at the band centres (spectral form, and the analytic γ of display files) and
    camera-weighted channel kernels (per-channel form)."""
    grid: RenderGrid
    band: dict[str, KernelSet]
    channel: dict[str, KernelSet] = field(default_factory=dict)
    field_bases: dict[str, FieldBasis] = field(default_factory=dict)  # compact_kernels: rank-r phase bases
    object_distance_m: float = math.nan  # the distance the kernels are focused for (scene_object_distance_m)


def band_kernel_set(layout, lens, grid: RenderGrid, distance_mm: float, frame_um: tuple[float, float],
                    cfg: SynthConfig, label: str = "", progress: bool = False) -> KernelSet:
    """psf.KernelSet at the band centres of `grid` (field phases when d > 0), through the kernel cache."""
    from tqdm import tqdm
    size = grid.kernel_size_px
    if size < 3:
        raise SynthError(f"render margin {grid.margin_px} px leaves no room for a kernel: raise render.margin_um")
    d_mm = distance_mm if layout is not None else 0.0
    phases = (cfg.field_phases or DEFAULT_FIELD_PHASES) ** 2 if d_mm > 0 else 1
    with tqdm(total=phases * grid.centres_nm.size, desc=f"kernels {label}", unit="kernel",
              disable=not progress, leave=False) as bar:  # ticks only when the kernels are not cached
        ks, _ = cached(compute_kernels, "mono", layout, lens, cfg.use_cache, cache_dir=cfg.kernel_cache,
                       wavelengths_nm=grid.centres_nm, pixel_um=grid.pitch_um, size_px=size, distance_mm=d_mm,
                       field_phases=cfg.field_phases, precision=cfg.kernel_precision, sensor_um=frame_um,
                       progress=bar.update)
    return ks


def scene_object_distance_m(scene: Scene) -> float:
    """The object distance the scene itself fixes: the monitor's plane (the camera sits on its centre
    line); for 3D scenes, and for any thin-lens render (its defocus is in the render), the focus distance."""
    if isinstance(scene.content, Monitor) and scene.lens.model == "pinhole":
        return monitor_distance_m(scene)
    return camera_geometry(scene).focus_distance_m


def display_kernels(display: Display, scene: Scene, grid: RenderGrid, cfg: SynthConfig,
                    progress: bool = False, object_distance_m: float | None = None) -> KernelSet:
    """The band kernels of `display` for `scene` (its lens and frame) on `grid`, for objects at
    `object_distance_m` (None: the focus distance)."""
    frame_um = (scene.sensor.width_px * scene.sensor.pitch_um, scene.sensor.height_px * scene.sensor.pitch_um)
    return band_kernel_set(display.layout, psf_lens(scene, object_distance_m), grid, display.distance_mm, frame_um,
                           cfg, display.name, progress)


def display_channel_kernels(display: Display, scene: Scene, grid: RenderGrid, cfg: SynthConfig,
                            object_distance_m: float | None = None) -> KernelSet:
    """Channel-effective kernels [3] (camera-weighted under D65) for the per-channel form."""
    ks, _ = cached(channel_kernels, "channel", display.layout, psf_lens(scene, object_distance_m), cfg.use_cache,
                   cache_dir=cfg.kernel_cache, camera=cfg.sensor.camera, illuminant="D65", step_nm=None,
                   pixel_um=grid.pitch_um, size_px=grid.kernel_size_px, distance_mm=0.0,
                   precision=cfg.kernel_precision)
    return ks


def plan_kernels(scene: Scene, displays: list[Display], cfg: SynthConfig, progress: bool = False,
                 object_distance_m: float | None = None) -> Kernels:
    """Every kernel set the synthesis of `scene` through `displays` needs, from the scene alone, for
    objects at `object_distance_m` (None: scene_object_distance_m; the focus distance when
    cfg.defocus_tolerance_px is None)."""
    grid = render_grid(scene)
    z = object_distance_m
    if z is None:
        z = camera_geometry(scene).focus_distance_m if cfg.defocus_tolerance_px is None else scene_object_distance_m(scene)
    glass = Display("glass", None)
    band = {"glass": display_kernels(glass, scene, grid, cfg, progress, z)}
    channel = {}
    for d in displays:
        if d.name not in band and (cfg.form == "spectral" or d.source != "preset"):  # per_channel: analytic γ
            band[d.name] = display_kernels(d, scene, grid, cfg, progress, z)
        if cfg.form == "per_channel":
            channel[d.name] = display_channel_kernels(d, scene, grid, cfg, z)
    return Kernels(grid, band, channel, object_distance_m=float(z))


def compact_kernels(kernels: Kernels, scene: Scene, cfg: SynthConfig) -> Kernels:
    """The kernels with each d > 0 set's phase kernels [K, P, P, S, S] replaced by their rank-r bases on
    the scene's render grid (optics.field_basis; the same numbers convolve_field would make per call):
    a dataset worker keeps 2/16 of the memory and makes the SVDs once. Unchanged when the field rank is
    None (exact: every phase kernel is used)."""
    if cfg.field_rank is None:
        return kernels
    cam = camera_geometry(scene)
    band, bases = dict(kernels.band), {}
    for name, ks in kernels.band.items():
        if ks.field_kernels is not None and ks.distance_mm > 0:
            wy, wx, _ = field_weights(ks, (cam.height_px, cam.width_px), kernels.grid.pitch_um, ks.distance_mm)
            bases[name] = field_basis(ks.field_kernels, live_phases(wy, wx), cfg.field_rank)
            band[name] = replace(ks, field_kernels=None)
    return replace(kernels, band=band, field_bases=bases)


def sensor_for_scene(sensor: SensorConfig, scene: Scene) -> SensorConfig:
    """The sensor with the scene's optics: pitch, f-number (irradiance πL/4N²) and focal length
    (cos⁴ fall-off) come from the scene file, never from the sensor settings."""
    return replace(sensor, pitch_um=float(scene.sensor.pitch_um), f_number=float(scene.lens.f_number),
                   focal_length_um=float(scene.lens.focal_length_mm) * 1000.0)


def auto_exposure_s(band_image: BandImage, sensor: SensorConfig) -> tuple[float, str]:
    """Exposure (s) and how it was chosen (module doc)."""
    unit = replace(sensor, exposure_s=1.0)
    w = band_electron_weights(band_image.edges_nm, unit)  # [3, K] e⁻ per second per unit radiance
    white = band_image.white_bands()
    if white is not None:
        per_s = float((w @ white).max())
        how = f"monitor white at {EXPOSURE_FILL:g} of the full well (brightest channel, glass, gain 1)"
    else:
        frame = band_image.frame(band_image.bands)
        rgb = electrons_rgb(frame[:, ::4, ::4], band_image.edges_nm, unit)
        per_s = float(np.percentile(rgb.max(axis=0), EXPOSURE_PERCENTILE))
        how = f"{EXPOSURE_PERCENTILE:g}th percentile of the glass image at {EXPOSURE_FILL:g} of the full well"
    if not per_s > 0:
        return sensor.exposure_s, "scene is black: the sensor's exposure_s kept"
    return EXPOSURE_FILL * sensor.full_well_e / per_s, how


def noise_seed(seed: int, item: int, display_name: str) -> np.random.SeedSequence:
    """Noise stream of one capture: SeedSequence([seed, item, crc32(display name)]) (adding a display
    to a job does not change the others' noise)."""
    return np.random.SeedSequence([int(seed), int(item), zlib.crc32(display_name.encode())])


def check_grid(band_image: BandImage, grid: RenderGrid) -> None:
    """The kernels were planned for the grid the render used (pitch, margin, bands)."""
    same = (abs(band_image.pitch_um - grid.pitch_um) <= 1e-9 * grid.pitch_um and band_image.margin_px == grid.margin_px
            and np.array_equal(np.asarray(band_image.edges_nm, float), np.asarray(grid.edges_nm, float)))
    if not same:
        raise SynthError(f"kernels planned for pitch {grid.pitch_um} µm, margin {grid.margin_px} px, "
                         f"{len(grid.edges_nm) - 1} bands; the render has pitch {band_image.pitch_um} µm, margin "
                         f"{band_image.margin_px} px, {band_image.edges_nm.size - 1} bands: plan them from this scene")


def depth_layers(band_image: BandImage, scene: Scene, grid: RenderGrid, cfg: SynthConfig) -> DepthLayers:
    """The render's depth layers (optics.layers): one for the monitor's plane, a thin-lens render, a scene
    without depth or with defocus off; else those the defocus tolerance needs for the rendered depth."""
    geom = camera_geometry(scene)
    lens = psf_lens(scene)
    g = DefocusGeometry(lens.aperture_um, lens.image_distance_um, geom.focus_distance_m, grid.pitch_um)
    tol = cfg.defocus_tolerance_px
    if tol is None:
        return one_layer(geom.focus_distance_m, g, "defocus off (defocus_tolerance_px = None): every pixel in focus")
    if scene.lens.model == "thinlens":
        return one_layer(geom.focus_distance_m, g, "thin-lens render: its defocus is in the render, not added again", tol)
    if isinstance(scene.content, Monitor):
        return one_layer(monitor_distance_m(scene), g, "the monitor's plane", tol)
    if band_image.depth_m is None:
        return one_layer(geom.focus_distance_m, g, "no depth rendered (render.depth = false): every pixel in focus", tol)
    try:
        return choose_layers(band_image.depth_m, g, tol, grid.kernel_size_px)
    except LayerError as e:
        raise SynthError(f"{scene.source}: {e}") from None


def layer_kernels(layers: DepthLayers, kernels: Kernels, scene: Scene, displays: list[Display], cfg: SynthConfig,
                  progress: bool = False) -> list[Kernels]:
    """The kernels of each layer's distance: `kernels` where it is theirs, else planned (through the kernel
    cache) and, like `kernels`, compacted to rank-r field bases when those are used."""
    out = []
    for z in layers.depths_m:
        if z == kernels.object_distance_m:
            out.append(kernels)
            continue
        k = plan_kernels(scene, displays, cfg, progress, object_distance_m=z)
        out.append(compact_kernels(k, scene, cfg) if kernels.field_bases else k)
    return out


def capture_views(kernels: Kernels, displays: list[Display], edges_nm) -> list[View]:
    """The ground truth ('gt': glass, T = 1) and every display but a glass with T = 1 (that one is the ground
    truth's optics exactly)."""
    out = [View("gt", kernels.band["glass"], None)]
    for d in displays:
        t = d.transmission.band_means(edges_nm)
        if not (d.is_glass and np.all(t == 1)):
            out.append(View(d.name, kernels.band[d.name], t, kernels.field_bases.get(d.name)))
    return out


def synthesize(band_image: BandImage, scene: Scene, displays: list[Display], cfg: SynthConfig = SynthConfig(),
               item: int = 0, progress: bool = False, kernels: Kernels | None = None) -> SynthResult:
    """The ground truth and one capture per display from one render, with the kernels planned for its
    scene (plan_kernels; planned here when not given) and for each of its depth layers (module doc)."""
    from tqdm import tqdm
    names = [d.name for d in displays]
    if len(set(names)) != len(names):
        raise SynthError(f"displays {names}: names must be distinct (they name the output folders)")
    kernels = kernels or plan_kernels(scene, displays, cfg, progress)
    check_grid(band_image, kernels.grid)
    layers = depth_layers(band_image, scene, kernels.grid, cfg)
    per_layer = layer_kernels(layers, kernels, scene, displays, cfg, progress)
    t0 = time.perf_counter()
    optics_sensor = sensor_for_scene(cfg.sensor, scene)
    exposure, how = (cfg.exposure_s, "set") if cfg.exposure_s is not None else auto_exposure_s(band_image, optics_sensor)
    base_sensor = replace(optics_sensor, exposure_s=float(exposure))
    bright = bright_pixels(band_image, base_sensor) if cfg.bright_split else None
    bar = tqdm(total=len(displays) + 1, desc="captures", unit="view", disable=not progress, leave=False)
    spectral_views = displays if cfg.form == "spectral" else []
    electrons = layered_electrons(band_image, layers,
                                  lambda l: capture_views(per_layer[l], spectral_views, band_image.edges_nm),
                                  base_sensor, cfg, bright)
    glass_e, gt_optics = electrons["gt"]
    gt = (glass_e / base_sensor.full_well_e).astype(np.float32)
    bar.update()
    captures, display_meta, rgb = {}, {}, None
    for d in displays:
        rng = np.random.default_rng(noise_seed(cfg.seed, item, d.name))
        if cfg.form == "spectral":
            cap, extra = _spectral_capture(band_image, d, electrons.get(d.name, electrons["gt"]), cfg, base_sensor, rng)
        else:
            if rgb is None:  # the un-blurred camera RGB of the render grid, shared by every display
                rgb = (electrons_rgb(band_image.bands, band_image.edges_nm, base_sensor)
                       / base_sensor.full_well_e).astype(np.float32)
            cap, extra = _per_channel_capture(band_image, rgb, d, per_layer, layers, cfg, base_sensor, rng, bright)
        captures[d.name] = cap
        display_meta[d.name] = {"display": d.describe(), "form": cfg.form, "noise_seed":
                                f"SeedSequence([{cfg.seed}, {item}, crc32('{d.name}')])", **extra}
        bar.update()
    bar.close()
    meta = {"form": cfg.form, "exposure_s": exposure, "exposure_rule": how, "seed": cfg.seed, "item": item,
            "gt": "linear camera RGB through glass (bare-lens kernels), no noise, no mosaic, no defect pixels, "
                  "/ full well (1.0 = white level at gain 1), not clipped", "gt_optics": gt_optics,
            "depth_layers": layers.describe(), "bright_pixels": 0 if bright is None else int(bright.mask.sum()),
            "defects": None if cfg.defects is None else asdict(cfg.defects), "profile": cfg.profile,
            "kernel_size_px": kernels.grid.kernel_size_px, "kernel_pixel_um": float(band_image.pitch_um),
            "kernel_precision": cfg.kernel_precision, "lens": psf_lens(scene).describe(),
            "render": {k: v for k, v in band_image.meta.items() if k != "seconds"}}
    timing = {"render_s": band_image.meta.get("seconds"), "synth_s": round(time.perf_counter() - t0, 3)}
    return SynthResult(gt, captures, meta, display_meta, timing)


def capture_scene(scene: Scene, displays: list[Display], cfg: SynthConfig = SynthConfig(), item: int = 0,
                  kernels: Kernels | None = None, progress: bool = False) -> tuple[BandImage, SynthResult]:
    """The one render → synthesis composition: plan the kernels (unless given), render, synthesise (a
    Mitsuba XML scene with its own camera pose first: render.resolve_xml_camera)."""
    scene = resolve_xml_camera(scene)
    kernels = kernels or plan_kernels(scene, displays, cfg, progress)
    band_image = render_scene(scene, progress=progress)
    return band_image, synthesize(band_image, scene, displays, cfg, item, progress, kernels)


def _spectral_capture(band_image: BandImage, d: Display, view_electrons: tuple, cfg: SynthConfig, base_sensor, rng):
    """The capture of display d from its view's electrons (views.layered_electrons; a glass with T = 1 has
    the ground truth's)."""
    e_rgb, applied = view_electrons
    t = d.transmission.band_means(band_image.edges_nm)
    sensor = replace(base_sensor, gain=d.gain, form="spectral")
    cap = capture_electrons(mosaic_of(e_rgb), sensor, rng, cfg.defects, {
        "input_shape": list(band_image.bands.shape), "input_pitch_um": float(band_image.pitch_um),
        "edges_nm": np.asarray(band_image.edges_nm, float).tolist(),
        "input": "camera-channel electrons of the blurred bands (views.layered_electrons)"})
    applied = dict(applied)
    gains = applied.pop("gains")
    return cap, {"optics": applied, "optics_gains": gains, "transmission_band_means": t.tolist()}


def display_gamma(d: Display, band_image: BandImage, kernels: Kernels, sensor: SensorConfig) -> tuple:
    """γ (R, G, B) of a display relative to glass: the paper's value for a preset, else optics.gamma's
    for the scene's white (a flat spectrum when the scene has no monitor)."""
    if d.source == "preset":
        return PAPER_GAMMA[d.name], "the paper's γ for this preset"
    white = band_image.white_bands()
    white = white if white is not None else np.ones(band_image.edges_nm.size - 1)
    g = gamma.display_gamma(d, kernels.band[d.name], kernels.band["glass"], band_image.edges_nm, sensor.camera, white)
    return tuple(float(x) for x in g), "γ of the display file (optics.gamma)"


def _per_channel_capture(band_image, rgb, d: Display, per_layer: list[Kernels], layers: DepthLayers,
                         cfg: SynthConfig, base_sensor, rng, bright=None):
    gamma, why = display_gamma(d, band_image, per_layer[0], base_sensor)
    blurred = bin_pixels(per_channel_blur(rgb, layers, lambda l: per_layer[l].channel[d.name].kernels,
                                          band_image.margin_px, cfg.precision, bright),
                         band_image.pitch_um, base_sensor.pitch_um)
    # DN = gain · (γ/gain) · x · R: the paper's γ includes the display's gain; electrons are γ/gain · x · FW
    sensor = replace(base_sensor, gain=d.gain, form="per_channel",
                     gamma_rggb=tuple(g / d.gain for g in rgb_to_rggb(gamma)))
    cap = capture(blurred, None, sensor, rng, defects=cfg.defects)
    return cap, {"gamma_rgb": list(gamma), "gamma_source": why, "channel_kernels": "camera × D65 weighted"}
