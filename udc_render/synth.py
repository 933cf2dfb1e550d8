"""Capture synthesis: a rendered scene ──► the captures a camera records through each display.

    band image (render) ─► kernels (psf, per display) ─► optics (blur, T(λ), field blend) ─► sensor

One render serves every display (the scene does not change); per display:

- form 'spectral' (default, physically based): the K band images are blurred with the K band
  kernels (psf at the band centres), multiplied by T(λ_k) · transmittance_k · (1 − energy
  outside_k), and integrated by the camera's sensitivities into an RGGB mosaic (sensor.py).
- form 'per_channel' (the paper's y = γ x ⊗ k + n): x is the un-blurred camera RGB of the render,
  blurred with the three channel-effective kernels (psf.spectral.channel_kernels, weighted by the
  camera and D65) and scaled by the display's γ (the paper's values for the presets, the analytic
  γ of displays.channel_gamma for a display file).

Ground truth ('gt'): what the clean capture would record without noise and without the mosaic: the
render through the glass panel (bare-lens kernels, gain 1), every camera channel at every pixel, in
units of the white level (1.0 = white at gain 1 = the full well), linear, not clipped.

Exposure: 'auto' puts the monitor's full white at EXPOSURE_FILL of the full well in the brightest
channel through glass at gain 1 (a fixed setting for every image, like the paper's rig; behind the
displays the paper's gains 6 and 25 bring the levels back); for 3D scenes the EXPOSURE_PERCENTILE
of the glass image's brightest channel takes that place.

Kernels are computed at the render pitch with size 2·margin + 1 (the largest the margin allows), for
the object at the focus distance (in focus), and cached on disk (psf.cache). They integrate over
the render pixel, and the render's pixels are area means too, so at render.supersample = 1 the
sensor pixel's box enters twice (an extra blur of one pixel); with supersample s the render and the
kernels use pitch / s and the sensor bins s × s, leaving an extra box of 1/s pixel
(`udc-render study capture` measures the error).
"""
from __future__ import annotations

import math
import time
import zlib
from dataclasses import dataclass, field, replace

import numpy as np

from psf import Lens, compute_kernels
from psf.cache import cached
from psf.spectral import channel_kernels

from udc_render.displays import PAPER_GAMMA, Display, channel_gamma
from udc_render.optics import apply_kernels, convolve_bands
from udc_render.render import BandImage
from udc_render.rig import camera_geometry
from udc_render.scene import Scene
from udc_render.sensor import SensorConfig, band_electron_weights, capture, electrons_rgb

FORMS = ("spectral", "per_channel")
EXPOSURE_FILL = 0.8
EXPOSURE_PERCENTILE = 99.5


class SynthError(ValueError):
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
    seed: int = 0
    use_cache: bool = True

    def __post_init__(self):
        if self.form not in FORMS:
            raise SynthError(f"form = {self.form!r}: expected one of {', '.join(FORMS)}")
        if self.exposure_s is not None and not (self.exposure_s > 0 and math.isfinite(self.exposure_s)):
            raise SynthError(f"exposure_s = {self.exposure_s!r}: expected a positive number of seconds or auto")


@dataclass
class SynthResult:
    gt: np.ndarray  # [3, H, W] float32, linear camera RGB / white level (module doc)
    captures: dict  # display name -> Capture
    meta: dict  # shared: scene, render, exposure, seeds
    display_meta: dict  # display name -> dict (display, optics, kernels, γ)
    timing: dict = field(default_factory=dict)  # seconds; kept out of the files (identical runs, identical bytes)


def rig_lens(scene: Scene) -> Lens:
    """The psf Lens of the scene's camera, focused (and the object placed) at the focus distance."""
    geom = camera_geometry(scene)
    focus_mm = geom.focus_distance_m * 1000.0
    f_um = scene.lens.focal_length_mm * 1000.0
    return Lens(focal_length_um=f_um, aperture_um=f_um / scene.lens.f_number, focus_distance_mm=focus_mm,
                object_distance_mm=focus_mm)


def kernel_size_px(band_image: BandImage) -> int:
    """Largest odd kernel the render margin allows without wrap-around: 2·margin + 1."""
    return 2 * int(band_image.margin_px) + 1


def display_kernels(display: Display, scene: Scene, band_image: BandImage, cfg: SynthConfig, progress: bool = False):
    """psf.KernelSet at the band centres (spectral form) for `display` on the render grid."""
    from tqdm import tqdm
    from psf.engine import DEFAULT_FIELD_PHASES
    frame_um = (scene.sensor.width_px * scene.sensor.pitch_um, scene.sensor.height_px * scene.sensor.pitch_um)
    size = kernel_size_px(band_image)
    if size < 3:
        raise SynthError(f"render margin {band_image.margin_px} px leaves no room for a kernel: raise render.margin_um")
    d_mm = display.distance_mm if display.layout is not None else 0.0
    phases = (cfg.field_phases or DEFAULT_FIELD_PHASES) ** 2 if d_mm > 0 else 1
    with tqdm(total=phases * band_image.centres_nm.size, desc=f"kernels {display.name}", unit="kernel",
              disable=not progress, leave=False) as bar:  # ticks only when the kernels are not cached
        ks, _ = cached(compute_kernels, "mono", display.layout, rig_lens(scene), cfg.use_cache,
                       wavelengths_nm=band_image.centres_nm, pixel_um=float(band_image.pitch_um), size_px=size,
                       distance_mm=d_mm, field_phases=cfg.field_phases, precision=cfg.kernel_precision,
                       sensor_um=frame_um, progress=bar.update)
    return ks


def display_channel_kernels(display: Display, scene: Scene, band_image: BandImage, cfg: SynthConfig):
    """Channel-effective kernels [3] (camera-weighted under D65) for the per-channel form."""
    ks, _ = cached(channel_kernels, "channel", display.layout, rig_lens(scene), cfg.use_cache,
                   camera=cfg.sensor.camera, illuminant="D65", step_nm=None, pixel_um=float(band_image.pitch_um),
                   size_px=kernel_size_px(band_image), distance_mm=0.0, precision=cfg.kernel_precision)
    return ks


def white_radiance_bands(band_image: BandImage) -> np.ndarray | None:
    """[K] band radiance of the monitor's full white (rgb_matrix and spectral monitor renders record the
    band-mean primaries matrix), or None for other content."""
    m = band_image.meta.get("band_matrix")
    return None if m is None else np.asarray(m, float).sum(axis=0)


def auto_exposure_s(band_image: BandImage, sensor: SensorConfig) -> tuple[float, str]:
    """Exposure (s) and how it was chosen (module doc)."""
    unit = replace(sensor, exposure_s=1.0)
    w = band_electron_weights(band_image.edges_nm, unit)  # [3, K] e⁻ per second per unit radiance
    white = white_radiance_bands(band_image)
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


def ground_truth(band_image: BandImage, glass_kernels, sensor: SensorConfig, cfg: SynthConfig):
    """([3, H, W] linear camera RGB of the clean view in units of the full well (1 = white at gain 1),
    the glass optics result it came from)."""
    optics = apply_kernels(band_image, glass_kernels, None, cfg.precision)
    gt = bin_pixels(electrons_rgb(optics.images, band_image.edges_nm, sensor), band_image.pitch_um, sensor.pitch_um)
    return (gt / sensor.full_well_e).astype(np.float32), optics


def bin_pixels(a: np.ndarray, pitch_um: float, sensor_pitch_um: float) -> np.ndarray:
    """Block mean [..., H·s, W·s] -> [..., H, W] where s = sensor pitch / render pitch (render.supersample)."""
    s = int(round(sensor_pitch_um / pitch_um))
    if s == 1:
        return a
    *lead, h, w = a.shape
    return a.reshape(*lead, h // s, s, w // s, s).mean(axis=(-3, -1))


def synthesize(band_image: BandImage, scene: Scene, displays: list[Display], cfg: SynthConfig = SynthConfig(),
               item: int = 0, progress: bool = False) -> SynthResult:
    """The ground truth and one capture per display from one render (module doc)."""
    from tqdm import tqdm
    names = [d.name for d in displays]
    if len(set(names)) != len(names):
        raise SynthError(f"displays {names}: names must be distinct (they name the output folders)")
    t0 = time.perf_counter()
    at_pitch = replace(cfg.sensor, pitch_um=float(scene.sensor.pitch_um))
    exposure, how = (cfg.exposure_s, "set") if cfg.exposure_s is not None else auto_exposure_s(band_image, at_pitch)
    base_sensor = replace(at_pitch, exposure_s=float(exposure))
    glass = next((d for d in displays if d.is_glass), None) or Display("glass", None)
    bar = tqdm(total=len(displays) + 1, desc="captures", unit="view", disable=not progress, leave=False)
    glass_ks = display_kernels(glass, scene, band_image, cfg, progress)
    gt, glass_optics = ground_truth(band_image, glass_ks, base_sensor, cfg)
    bar.update()
    captures, display_meta, rgb = {}, {}, None
    for d in displays:
        rng = np.random.default_rng(noise_seed(cfg.seed, item, d.name))
        if cfg.form == "spectral":
            t = d.transmission.band_means(band_image.edges_nm)
            if d.is_glass and d.distance_mm == 0 and np.all(t == 1):  # the ground truth's optics exactly
                optics = glass_optics
            else:
                ks = display_kernels(d, scene, band_image, cfg, progress)
                optics = apply_kernels(band_image, ks, t, cfg.precision, blend=cfg.blend)
            sensor = replace(base_sensor, gain=d.gain, form="spectral")
            cap = capture(optics.images, band_image.edges_nm, sensor, rng, input_pitch_um=float(band_image.pitch_um))
            extra = {"optics": optics.applied, "optics_gains": optics.gains.tolist(),
                     "transmission_band_means": t.tolist()}
        else:
            if rgb is None:  # the un-blurred camera RGB of the render grid, shared by every display
                rgb = (electrons_rgb(band_image.bands, band_image.edges_nm, base_sensor)
                       / base_sensor.full_well_e).astype(np.float32)
            cap, extra = _per_channel_capture(band_image, rgb, scene, d, cfg, base_sensor, rng, glass_ks)
        captures[d.name] = cap
        display_meta[d.name] = {"display": d.describe(), "form": cfg.form, "noise_seed":
                                f"SeedSequence([{cfg.seed}, {item}, crc32('{d.name}')])", **extra}
        bar.update()
    bar.close()
    meta = {"form": cfg.form, "exposure_s": exposure, "exposure_rule": how, "seed": cfg.seed, "item": item,
            "gt": "linear camera RGB through glass (bare-lens kernels), no noise, no mosaic, / full well "
                  "(1.0 = white level at gain 1), not clipped", "gt_optics": glass_optics.applied,
            "kernel_size_px": kernel_size_px(band_image), "kernel_pixel_um": float(band_image.pitch_um),
            "kernel_precision": cfg.kernel_precision, "lens": rig_lens(scene).describe(),
            "render": {k: v for k, v in band_image.meta.items() if k != "seconds"}}
    timing = {"render_s": band_image.meta.get("seconds"), "synth_s": round(time.perf_counter() - t0, 3)}
    return SynthResult(gt, captures, meta, display_meta, timing)


def display_gamma(d: Display, scene: Scene, band_image: BandImage, cfg: SynthConfig, glass_ks) -> tuple:
    """γ (R, G, B) of a display relative to glass: the paper's value for a preset, else analytic."""
    if d.source == "preset":
        return PAPER_GAMMA[d.name], "the paper's γ for this preset"
    ks = display_kernels(d, scene, band_image, cfg)
    sensor = replace(cfg.sensor, exposure_s=1.0)
    white = white_radiance_bands(band_image)
    spectrum = white if white is not None else np.ones(band_image.edges_nm.size - 1)
    w = band_electron_weights(band_image.edges_nm, sensor) * spectrum[None, :]
    g = channel_gamma(w, d, ks.transmittance * (1 - ks.energy_outside),
                      glass_ks.transmittance * (1 - glass_ks.energy_outside), band_image.edges_nm)
    return tuple(float(x) for x in g), "analytic γ of the display file (displays.channel_gamma)"


def _per_channel_capture(band_image, rgb, scene, d: Display, cfg: SynthConfig, base_sensor, rng, glass_ks):
    gamma, why = display_gamma(d, scene, band_image, cfg, glass_ks)
    ks = display_channel_kernels(d, scene, band_image, cfg)
    blurred = bin_pixels(convolve_bands(rgb, ks.kernels, band_image.margin_px, None, cfg.precision),
                         band_image.pitch_um, base_sensor.pitch_um)
    g_rggb = (gamma[0], gamma[1], gamma[1], gamma[2])
    # DN = gain · (γ/gain) · x · R: the paper's γ includes the display's gain; electrons are γ/gain · x · FW
    sensor = replace(base_sensor, gain=d.gain, form="per_channel", gamma_rggb=tuple(g / d.gain for g in g_rggb))
    cap = capture(blurred, None, sensor, rng)
    return cap, {"gamma_rgb": list(gamma), "gamma_source": why, "channel_kernels": "camera × D65 weighted"}
