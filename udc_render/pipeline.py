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

Kernels are planned from the scene alone (plan_kernels: the render grid and the lens are facts of the
scene), so they can be computed before or beside the render: at the render pitch with size
2·margin + 1 (the largest the margin allows), for the object at the focus distance (in focus), and
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
from udc_render.optics import (FieldBasis, apply_kernels, band_spectra, convolve_bands, field_basis, field_weights,
                               live_phases)
from udc_render.optics import gamma
from udc_render.optics.displays import PAPER_GAMMA, Display
from udc_render.render import BandImage, render_scene
from udc_render.scene import Scene
from udc_render.scene.geometry import RenderGrid, camera_geometry, psf_lens, render_grid
from udc_render.sensor import (Capture, DefectConfig, SensorConfig, band_electron_weights, capture, capture_electrons,
                               cos4_map, electrons_rgb, mosaic_of, rgb_to_rggb)
from udc_render.sensor.radiometry import checked_nonnegative

FORMS = ("spectral", "per_channel")
EXPOSURE_FILL = 0.8
EXPOSURE_PERCENTILE = 99.5


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


def display_kernels(display: Display, scene: Scene, grid: RenderGrid, cfg: SynthConfig,
                    progress: bool = False) -> KernelSet:
    """The band kernels of `display` for `scene` (its lens and frame) on `grid`."""
    frame_um = (scene.sensor.width_px * scene.sensor.pitch_um, scene.sensor.height_px * scene.sensor.pitch_um)
    return band_kernel_set(display.layout, psf_lens(scene), grid, display.distance_mm, frame_um, cfg, display.name,
                           progress)


def display_channel_kernels(display: Display, scene: Scene, grid: RenderGrid, cfg: SynthConfig) -> KernelSet:
    """Channel-effective kernels [3] (camera-weighted under D65) for the per-channel form."""
    ks, _ = cached(channel_kernels, "channel", display.layout, psf_lens(scene), cfg.use_cache,
                   cache_dir=cfg.kernel_cache, camera=cfg.sensor.camera, illuminant="D65", step_nm=None,
                   pixel_um=grid.pitch_um, size_px=grid.kernel_size_px, distance_mm=0.0,
                   precision=cfg.kernel_precision)
    return ks


def plan_kernels(scene: Scene, displays: list[Display], cfg: SynthConfig, progress: bool = False) -> Kernels:
    """Every kernel set the synthesis of `scene` through `displays` needs, from the scene alone."""
    grid = render_grid(scene)
    glass = Display("glass", None)
    band = {"glass": display_kernels(glass, scene, grid, cfg, progress)}
    channel = {}
    for d in displays:
        if d.name not in band and (cfg.form == "spectral" or d.source != "preset"):  # per_channel: analytic γ
            band[d.name] = display_kernels(d, scene, grid, cfg, progress)
        if cfg.form == "per_channel":
            channel[d.name] = display_channel_kernels(d, scene, grid, cfg)
    return Kernels(grid, band, channel)


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


def ground_truth(band_image: BandImage, glass_kernels, sensor: SensorConfig, cfg: SynthConfig, spectra=None):
    """([3, H, W] linear camera RGB of the clean view in units of the full well (1 = white at gain 1),
    the glass view's electrons [3, H, W] and the optics record they came from)."""
    e_rgb, applied = channel_electrons(band_image, glass_kernels, None, sensor, cfg, spectra)
    return (e_rgb / sensor.full_well_e).astype(np.float32), e_rgb, applied


def channel_electrons(band_image: BandImage, kernel_set, transmission, sensor: SensorConfig, cfg: SynthConfig,
                      spectra=None, field_basis: FieldBasis | None = None) -> tuple[np.ndarray, dict]:
    """Mean electrons [3, H, W] (float64, sensor pitch, cos⁴ included) that an R, G and B pixel would
    collect through one display: e_c = cos⁴ · bin(Σ_k w_ck g_k (x_k ⊗ k_k)), w = band_electron_weights.
    The band sum is taken in Fourier space (apply_kernels' channel_weights: three inverse FFTs, not K);
    blend 'output' sums the K blurred bands instead. Round-off negatives are set to 0 (counted), larger ones
    refused, as the sensor does for band radiance (sensor.radiometry.checked_nonnegative)."""
    w = band_electron_weights(band_image.edges_nm, sensor)
    kw = dict(blend=cfg.blend, field_rank=cfg.field_rank, field_basis=field_basis)
    if cfg.blend == "source":
        optics = apply_kernels(band_image, kernel_set, transmission, cfg.precision, channel_weights=w, spectra=spectra, **kw)
        e = optics.images.astype(np.float64)
    else:
        optics = apply_kernels(band_image, kernel_set, transmission, cfg.precision, **kw)
        e = np.einsum("ck,khw->chw", w, optics.images, dtype=np.float64, optimize=True)
    e, clamped = checked_nonnegative(bin_pixels(e, band_image.pitch_um, sensor.pitch_um), "channel electrons")
    if sensor.cos4_falloff:
        e *= cos4_map(*e.shape[1:], sensor.pitch_um, sensor.focal_length_um)
    applied = {**optics.applied, "gains": optics.gains.tolist(), "transmission": optics.transmission.tolist(),
               "negative_electrons_clamped": clamped}
    return e, applied


def bin_pixels(a: np.ndarray, pitch_um: float, sensor_pitch_um: float) -> np.ndarray:
    """Block mean [..., H·s, W·s] -> [..., H, W] where s = sensor pitch / render pitch (render.supersample)."""
    s = int(round(sensor_pitch_um / pitch_um))
    if s == 1:
        return a
    *lead, h, w = a.shape
    return a.reshape(*lead, h // s, s, w // s, s).mean(axis=(-3, -1))


def check_grid(band_image: BandImage, grid: RenderGrid) -> None:
    """The kernels were planned for the grid the render used (pitch, margin, bands)."""
    same = (abs(band_image.pitch_um - grid.pitch_um) <= 1e-9 * grid.pitch_um and band_image.margin_px == grid.margin_px
            and np.array_equal(np.asarray(band_image.edges_nm, float), np.asarray(grid.edges_nm, float)))
    if not same:
        raise SynthError(f"kernels planned for pitch {grid.pitch_um} µm, margin {grid.margin_px} px, "
                         f"{len(grid.edges_nm) - 1} bands; the render has pitch {band_image.pitch_um} µm, margin "
                         f"{band_image.margin_px} px, {band_image.edges_nm.size - 1} bands: plan them from this scene")


def shared_spectra(band_image: BandImage, displays: list[Display], kernels: Kernels, cfg: SynthConfig):
    """The band images' spectra (optics.band_spectra), computed once when a display besides the ground
    truth convolves the plain bands too (d = 0, spectral form); else None (each view transforms its own)."""
    plain = [d for d in displays if cfg.form == "spectral" and d.name not in kernels.field_bases
             and kernels.band[d.name].field_kernels is None and not d.is_glass]
    if not plain:
        return None
    return band_spectra(band_image.bands, kernels.grid.kernel_size_px, band_image.margin_px, cfg.precision)


def synthesize(band_image: BandImage, scene: Scene, displays: list[Display], cfg: SynthConfig = SynthConfig(),
               item: int = 0, progress: bool = False, kernels: Kernels | None = None) -> SynthResult:
    """The ground truth and one capture per display from one render, with the kernels planned for its
    scene (plan_kernels; planned here when not given) (module doc)."""
    from tqdm import tqdm
    names = [d.name for d in displays]
    if len(set(names)) != len(names):
        raise SynthError(f"displays {names}: names must be distinct (they name the output folders)")
    kernels = kernels or plan_kernels(scene, displays, cfg, progress)
    check_grid(band_image, kernels.grid)
    t0 = time.perf_counter()
    optics_sensor = sensor_for_scene(cfg.sensor, scene)
    exposure, how = (cfg.exposure_s, "set") if cfg.exposure_s is not None else auto_exposure_s(band_image, optics_sensor)
    base_sensor = replace(optics_sensor, exposure_s=float(exposure))
    bar = tqdm(total=len(displays) + 1, desc="captures", unit="view", disable=not progress, leave=False)
    spectra = shared_spectra(band_image, displays, kernels, cfg)
    gt, glass_e, gt_optics = ground_truth(band_image, kernels.band["glass"], base_sensor, cfg, spectra)
    bar.update()
    captures, display_meta, rgb = {}, {}, None
    for d in displays:
        rng = np.random.default_rng(noise_seed(cfg.seed, item, d.name))
        if cfg.form == "spectral":
            cap, extra = _spectral_capture(band_image, d, kernels, cfg, base_sensor, rng, (glass_e, gt_optics), spectra)
        else:
            if rgb is None:  # the un-blurred camera RGB of the render grid, shared by every display
                rgb = (electrons_rgb(band_image.bands, band_image.edges_nm, base_sensor)
                       / base_sensor.full_well_e).astype(np.float32)
            cap, extra = _per_channel_capture(band_image, rgb, d, kernels, cfg, base_sensor, rng)
        captures[d.name] = cap
        display_meta[d.name] = {"display": d.describe(), "form": cfg.form, "noise_seed":
                                f"SeedSequence([{cfg.seed}, {item}, crc32('{d.name}')])", **extra}
        bar.update()
    bar.close()
    meta = {"form": cfg.form, "exposure_s": exposure, "exposure_rule": how, "seed": cfg.seed, "item": item,
            "gt": "linear camera RGB through glass (bare-lens kernels), no noise, no mosaic, no defect pixels, "
                  "/ full well (1.0 = white level at gain 1), not clipped", "gt_optics": gt_optics,
            "defects": None if cfg.defects is None else asdict(cfg.defects), "profile": cfg.profile,
            "kernel_size_px": kernels.grid.kernel_size_px, "kernel_pixel_um": float(band_image.pitch_um),
            "kernel_precision": cfg.kernel_precision, "lens": psf_lens(scene).describe(),
            "render": {k: v for k, v in band_image.meta.items() if k != "seconds"}}
    timing = {"render_s": band_image.meta.get("seconds"), "synth_s": round(time.perf_counter() - t0, 3)}
    return SynthResult(gt, captures, meta, display_meta, timing)


def capture_scene(scene: Scene, displays: list[Display], cfg: SynthConfig = SynthConfig(), item: int = 0,
                  kernels: Kernels | None = None, progress: bool = False) -> tuple[BandImage, SynthResult]:
    """The one render → synthesis composition: plan the kernels (unless given), render, synthesise."""
    kernels = kernels or plan_kernels(scene, displays, cfg, progress)
    band_image = render_scene(scene, progress=progress)
    return band_image, synthesize(band_image, scene, displays, cfg, item, progress, kernels)


def _spectral_capture(band_image: BandImage, d: Display, kernels: Kernels, cfg: SynthConfig, base_sensor, rng,
                      glass_electrons, spectra):
    t = d.transmission.band_means(band_image.edges_nm)
    if d.is_glass and np.all(t == 1):  # the ground truth's optics exactly (a bare lens has no field kernels)
        e_rgb, applied = glass_electrons
    else:
        e_rgb, applied = channel_electrons(band_image, kernels.band[d.name], t, base_sensor, cfg, spectra,
                                           kernels.field_bases.get(d.name))
    sensor = replace(base_sensor, gain=d.gain, form="spectral")
    cap = capture_electrons(mosaic_of(e_rgb), sensor, rng, cfg.defects, {
        "input_shape": list(band_image.bands.shape), "input_pitch_um": float(band_image.pitch_um),
        "edges_nm": np.asarray(band_image.edges_nm, float).tolist(),
        "input": "camera-channel electrons of the blurred bands (pipeline.channel_electrons)"})
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


def _per_channel_capture(band_image, rgb, d: Display, kernels: Kernels, cfg: SynthConfig, base_sensor, rng):
    gamma, why = display_gamma(d, band_image, kernels, base_sensor)
    ks = kernels.channel[d.name]
    blurred = bin_pixels(convolve_bands(rgb, ks.kernels, band_image.margin_px, None, cfg.precision),
                         band_image.pitch_um, base_sensor.pitch_um)
    # DN = gain · (γ/gain) · x · R: the paper's γ includes the display's gain; electrons are γ/gain · x · FW
    sensor = replace(base_sensor, gain=d.gain, form="per_channel",
                     gamma_rggb=tuple(g / d.gain for g in rgb_to_rggb(gamma)))
    cap = capture(blurred, None, sensor, rng, defects=cfg.defects)
    return cap, {"gamma_rgb": list(gamma), "gamma_source": why, "channel_kernels": "camera × D65 weighted"}
