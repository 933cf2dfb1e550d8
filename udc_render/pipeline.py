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
  blurred with three channel kernels (SynthConfig.channel_kernels: 'paper', the paper's recipe at 640 /
  520 / 450 nm, psf.paper; 'camera', psf.spectral.channel_kernels weighted by the camera and D65) and
  scaled by the display's γ (the paper's values for the presets, the analytic
  γ of optics.gamma for a display file).

Ground truth ('gt'): what the clean capture would record without noise and without the mosaic: the
render through the glass panel (bare-lens kernels, gain 1), every camera channel at every pixel, in
units of the white level (1.0 = white at gain 1 = the full well), linear, not clipped, and without
the sensor's defect pixels (SynthConfig.defects, udc_render.sensor.defects: the same dead and hot
pixels in every capture, glass included, and never in the ground truth), nor its fixed-pattern noise
(SynthConfig.fpn, udc_render.sensor.fpn: PRNU, DSNU, row/column offsets and dark current, the same maps
in every capture).

Averaged ground truth (SynthConfig.gt_frames = N; the profiles set 16): the paper's ground truth is the
mean of 16 glass captures at gain 1 (l.235), so its temporal noise is the single frame's σ/√16 = σ/4.
With N, 'gt' is the mean of N captures of the glass electrons (sensor.frames.mean_of_frames: the glass
capture's noise model at gain 1, quantised to the bit depth, saturating at the white level, hence
clipped), each camera channel at every pixel with its own noise, from its own noise stream
(gt_noise_seed). Averaging removes temporal noise, not what is the same in every frame: the defect
pixels and the fixed-pattern noise stay out of the ground truth as above (they are sites of a mosaic the
ground truth does not have; the paper's RGB went through an in-camera pipeline, l.236, whose defect
correction is unknown), and so does the in-camera demosaic (docs/concepts/physics.md).

Stray light (SynthConfig.stray_light, optics.stray, spectral form): room light on the monitor's screen,
the display's haze, a driven display's own light, the ghost between display and lens and the lens's veiling
glare, added to each view's electrons before the mosaic; the ground truth gets what glass and the same
lens would give it (the room light, the glass's ghost, the glare).

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

import time
import zlib
from dataclasses import asdict, dataclass, field, replace
from functools import partial

import numpy as np
from tqdm import tqdm

from udc_render.optics import gamma
from udc_render.optics.displays import PAPER_GAMMA, Display
from udc_render.optics.layers import DefocusGeometry, DepthLayers, LayerError, choose_layers, one_layer
from udc_render.optics.stray import synthesis_stray_light
from udc_render.render import BandImage, render_scene, resolve_xml_camera
from udc_render.scene import Monitor, Scene
from udc_render.scene.geometry import RenderGrid, camera_geometry, monitor_distance_m, psf_lens
from udc_render.sensor import (
    Capture,
    SensorConfig,
    band_electron_weights,
    capture,
    capture_electrons,
    electrons_rgb,
    mosaic_of,
    rgb_to_rggb,
)
from udc_render.sensor.frames import burst_sensor, mean_of_frames
from udc_render.synth_config import (
    CHANNEL_KERNELS,
    DEFAULT_DEFOCUS_TOLERANCE_PX,
    EXPOSURE_FILL,
    EXPOSURE_PERCENTILE,
    FORMS,
    SynthConfig,
    SynthError,
)
from udc_render.synth_kernels import (
    Kernels,
    band_kernel_set,
    compact_kernels,
    display_channel_kernels,
    display_kernels,
    kernel_spectra,
    plan_kernels,
    prepare_kernels,
    scene_object_distance_m,
    store_field_planes,
    store_power_maps,
)
from udc_render.views import View, bin_pixels, bright_pixels, field_print, layered_electrons, per_channel_blur

# The settings (synth_config) and the kernels (synth_kernels) are part of the pipeline's public names.
__all__ = ["CHANNEL_KERNELS", "DEFAULT_DEFOCUS_TOLERANCE_PX", "EXPOSURE_FILL", "EXPOSURE_PERCENTILE", "FORMS",
           "Kernels", "SynthConfig", "SynthError", "SynthResult", "auto_exposure_s", "band_kernel_set", "capture_scene",
           "capture_views", "check_grid", "compact_kernels", "depth_layers", "display_channel_kernels", "display_gamma",
           "display_kernels", "gt_noise_seed", "layer_kernels", "noise_seed", "plan_kernels", "prepare_kernels",
           "scene_object_distance_m", "sensor_for_scene", "store_field_planes", "store_power_maps",
           "synthesize"]


GT_RECORD = {False: "linear camera RGB through glass (bare-lens kernels), no noise, no mosaic, no defect pixels, "
                    "no FPN, / full well (1.0 = white level at gain 1), not clipped",
             True: "linear camera RGB through glass (bare-lens kernels), the mean of gt_frames captures at gain 1 "
                   "(temporal noise σ/√N, quantised, clipped at the white level), no mosaic, no defect pixels, "
                   "no FPN, (DN − black) / (g · full well) (1.0 = white level at gain 1)"}


@dataclass(frozen=True)
class SynthResult:
    """What synthesize hands to the file writer (io.capture.write_synthesis): the arrays, and the
    records that become the JSON sidecars."""
    gt: np.ndarray  # [3, H, W] float32, linear camera RGB / white level (module doc)
    captures: dict[str, Capture]  # by display name
    meta: dict  # synth.json: scene, render, exposure, seeds
    display_meta: dict[str, dict]  # <display>/capture.json additions: display, optics, kernels, γ
    timing: dict = field(default_factory=dict)  # seconds; kept out of the files (identical runs, identical bytes)


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
    to a job does not change the others' noise). Kept, not a streams.stream: numpy pads the entropy with
    zeros, but the last word is a CRC-32, zero for one name in 2³² and for none in use (glass, toled,
    poled, random, 'gt frames': tests/udc_render/test_dataset_streams.py), so no capture's stream is
    SeedSequence([seed, item]); changing it would change every dataset's noise."""
    return np.random.SeedSequence([int(seed), int(item), zlib.crc32(display_name.encode())])


GT_NOISE_STREAM = "gt frames"  # the averaged ground truth's stream name: no display's (their names have no spaces)


def gt_noise_seed(seed: int, item: int) -> np.random.SeedSequence:
    """Noise stream of the averaged ground truth's frames: noise_seed(seed, item, 'gt frames'), apart from
    every display's."""
    return noise_seed(seed, item, GT_NOISE_STREAM)


def averaged_gt(glass_e: np.ndarray, sensor: SensorConfig, frames: int, seed: int,
                item: int) -> tuple[np.ndarray, dict]:
    """The ground truth as the paper took it (module doc): the mean DN of `frames` glass captures at gain 1 of
    the electrons [3, H, W], each channel with the noise of its RGGB site (G: Gr's), as (DN − black) / (g · FW)
    (the noise-free ground truth's units), and its record."""
    s = replace(sensor, gain=1.0)
    rng = np.random.default_rng(gt_noise_seed(seed, item))
    s = burst_sensor(s, rng)
    planes, drawn = zip(*(mean_of_frames(glass_e[c], s, frames, rng, site) for c, site in enumerate((0, 1, 3))))
    gt = ((np.stack(planes) - s.black_level_dn) / (s.dn_per_electron * s.full_well_e)).astype(np.float32)
    record = {"frames": frames, "noise": s.noise, "gain": 1.0, "noise_seed": f"SeedSequence([{seed}, {item}, "
              f"crc32('{GT_NOISE_STREAM}')])", "pixels_drawn_frame_by_frame": int(sum(drawn))}
    if s.noise == "gaussian":
        record.update(lambda_read=list(s.lambda_read), lambda_shot=list(s.lambda_shot))
    return gt, record


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
    tol, focus_m = cfg.defocus_tolerance_px, geom.focus_distance_m
    if tol is None:
        return one_layer(focus_m, g, "defocus off (defocus_tolerance_px = None): every pixel in focus")
    if scene.lens.model == "thinlens":
        return one_layer(focus_m, g, "thin-lens render: its defocus is in the render, not added again", tol)
    if isinstance(scene.content, Monitor):
        return one_layer(monitor_distance_m(scene), g, "the monitor's plane", tol)
    if band_image.depth_m is None:
        return one_layer(focus_m, g, "no depth rendered (render.depth = false): every pixel in focus", tol)
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
        k = plan_kernels(scene, displays, cfg, progress, object_distance_m=z, far=False)  # the focus's far fields
        out.append(compact_kernels(k, scene, cfg) if kernels.field_bases else k)
    return out


def capture_views(kernels: Kernels, displays: list[Display], edges_nm, far: dict | None = None,
                  prints: dict | None = None) -> list[View]:
    """The ground truth ('gt': glass, T = 1) and every display but a glass with T = 1 (that one is the ground
    truth's optics exactly), each with its far field from `far` (None: kernels.far; a depth layer's views
    share the focus kernels' far fields) and its field blend's verdict from `prints` (field_prints)."""
    far, prints = kernels.far if far is None else far, prints or {}
    out = [View("gt", kernels.band["glass"], None, far_field=far.get("glass"),
                spectra=partial(kernel_spectra, kernels, "glass"))]
    for d in displays:
        t = d.transmission.band_means(edges_nm)
        if not (d.is_glass and np.all(t == 1)):
            out.append(View(d.name, kernels.band[d.name], t, kernels.field_bases.get(d.name), far.get(d.name),
                            kernels.power_maps.get(d.name), prints.get(d.name),
                            partial(kernel_spectra, kernels, d.name), kernels.field_planes.get(d.name)))
    return out


def field_prints(band_image: BandImage, kernels: Kernels, displays: list[Display], sensor: SensorConfig,
                 cfg: SynthConfig) -> dict:
    """{view name: views.field_print's verdict} of every d > 0 view of the focus kernels (every depth layer's view
    follows it)."""
    out = {}
    for v in capture_views(kernels, displays, band_image.edges_nm):
        verdict = field_print(band_image, v, sensor, kernels.field_spread.get(v.name), cfg.field_print_sigma)
        if verdict is not None:
            out[v.name] = verdict
    return out


def synthesize(band_image: BandImage, scene: Scene, displays: list[Display], cfg: SynthConfig = SynthConfig(),
               item: int = 0, progress: bool = False, kernels: Kernels | None = None) -> SynthResult:
    """The ground truth and one capture per display from one render, with the kernels planned for its
    scene (plan_kernels; planned here when not given) and for each of its depth layers (module doc)."""
    names = [d.name for d in displays]
    if len(set(names)) != len(names):
        raise SynthError(f"displays {names}: names must be distinct (they name the output folders)")
    kernels = kernels or plan_kernels(scene, displays, cfg, progress)
    check_grid(band_image, kernels.grid)
    layers = depth_layers(band_image, scene, kernels.grid, cfg)
    per_layer = layer_kernels(layers, kernels, scene, displays, cfg, progress)
    t0 = time.perf_counter()
    optics_sensor = sensor_for_scene(cfg.sensor, scene)
    exposure, how = ((cfg.exposure_s, "set") if cfg.exposure_s is not None
                     else auto_exposure_s(band_image, optics_sensor))
    base_sensor = replace(optics_sensor, exposure_s=float(exposure))
    bright = bright_pixels(band_image, base_sensor) if cfg.bright_split else None
    bar = tqdm(total=len(displays) + 1, desc="captures", unit="view", disable=not progress, leave=False)
    spectral_views = displays if cfg.form == "spectral" else []
    prints = field_prints(band_image, kernels, spectral_views, base_sensor, cfg)
    electrons = layered_electrons(band_image, layers, lambda i: capture_views(
        per_layer[i], spectral_views, band_image.edges_nm, kernels.far, prints), base_sensor, cfg, bright)
    electrons, stray = synthesis_stray_light(cfg.stray_light, electrons, band_image, base_sensor, cfg.form,
                                             {d.name for d in displays if d.is_glass})
    glass_e, gt_optics = electrons["gt"]
    gt, gt_noise = (glass_e / base_sensor.full_well_e).astype(np.float32), None
    if cfg.gt_frames is not None:
        gt, gt_noise = averaged_gt(glass_e, base_sensor, cfg.gt_frames, cfg.seed, item)
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
    meta = {"form": cfg.form, "channel_kernels": cfg.channel_kernels if cfg.form == "per_channel" else None,
            "exposure_s": exposure, "exposure_rule": how, "seed": cfg.seed, "item": item,
            "gt": GT_RECORD[cfg.gt_frames is not None], "gt_frames": cfg.gt_frames, "gt_noise": gt_noise,
            "gt_optics": gt_optics,
            "depth_layers": layers.describe(), "bright_pixels": 0 if bright is None else int(bright.mask.sum()),
            "defects": None if cfg.defects is None else asdict(cfg.defects), "profile": cfg.profile,
            "fpn": None if cfg.fpn is None else asdict(cfg.fpn),
            "stray_light": stray,
            "kernel_size_px": kernels.grid.kernel_size_px, "kernel_pixel_um": float(band_image.pitch_um),
            "kernel_precision": cfg.kernel_precision, "lens": psf_lens(scene).describe(),
            "far_field": _far_field_record(kernels, cfg),
            "render": {k: v for k, v in band_image.meta.items() if k != "seconds"}}
    timing = {"render_s": band_image.meta.get("seconds"), "synth_s": round(time.perf_counter() - t0, 3)}
    return SynthResult(gt, captures, meta, display_meta, timing)


def _far_field_record(kernels: Kernels, cfg: SynthConfig) -> dict:
    """synth.json's far field: the settings and, per view, the share of the transmitted power added per band."""
    return {"threshold": cfg.far_field_threshold, "coarse_factor": cfg.far_field_coarse,
            "form": "spectral only (the per-channel form is the paper's y = γ x ⊗ k)",
            "far_share": {name: f.added.tolist() for name, f in kernels.far.items()},
            "lost_share": {name: ks.energy_outside.tolist() for name, ks in kernels.band.items()}}


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
        "input": "camera-channel electrons of the blurred bands (views.layered_electrons)"}, cfg.fpn)
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
    blurred = bin_pixels(per_channel_blur(rgb, layers, lambda i: per_layer[i].channel[d.name].kernels,
                                          band_image.margin_px, cfg.precision, bright),
                         band_image.pitch_um, base_sensor.pitch_um)
    # DN = gain · (γ/gain) · x · R: the paper's γ includes the display's gain; electrons are γ/gain · x · FW
    sensor = replace(base_sensor, gain=d.gain, form="per_channel",
                     gamma_rggb=tuple(g / d.gain for g in rgb_to_rggb(gamma)))
    cap = capture(blurred, None, sensor, rng, defects=cfg.defects, fpn=cfg.fpn)
    return cap, {"gamma_rgb": list(gamma), "gamma_source": why,
                 "channel_kernels": CHANNEL_KERNELS[cfg.channel_kernels]}
