"""The PSF kernels of a synthesis (udc_render.pipeline): per display, the band kernel sets of the scene's
render grid (psf.compute_kernels, cached), the 3 channel kernels of the per-channel form, and the
compact rank-r bases a dataset worker keeps. Re-exported by udc_render.pipeline.

What is made from the kernels and the render grid alone (a display's far field, its rank-r field bases and
exact-power maps on the grid) goes into the kernel cache beside them (psf.cache.cached_arrays, keyed by the
kernel entries' keys, Kernels.keys, and the grid), uncompressed: made once by the first process that needs
it (a dataset's parent, before its workers start), memory-mapped by every other.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from tqdm import tqdm

from psf import KernelSet, compute_kernels
from psf.cache import cached, cached_arrays, cached_keyed
from psf.engine import DEFAULT_FIELD_PHASES
from psf.far import CACHE_NAME as FAR_CACHE_NAME, ORDER_PIXEL_FACTOR, order_kernels
from psf.spectral import channel_kernels
from udc_render.optics import FieldBasis, PowerMap, field_basis, field_power_map, field_weights, live_phases
from udc_render.optics.convolution import kernel_spectra as spectra_of
from udc_render.optics.displays import Display
from udc_render.optics.far_field import FarField, acceptance_um, far_window_px, make_far_field
from udc_render.optics.field import phase_spread_l1
from udc_render.optics.field_planes import MAX_RANK as PLANES_MAX_RANK, PlaneBasis, plane_basis
from udc_render.scene import Monitor, Scene
from udc_render.scene.geometry import RenderGrid, camera_geometry, monitor_distance_m, psf_lens, render_grid
from udc_render.synth_config import SynthConfig, SynthError

PAPER_CHANNEL_NM = (640.0, 520.0, 450.0)  # R, G, B: "the approximated center peaks" of the filters (l.263)


@dataclass(frozen=True)
class Kernels:
    """The kernel sets a synthesis needs, by display name ('glass': the bare lens, always there):
    band kernels at the band centres (spectral form, and the analytic γ of display files) and
    the per-channel form's 3 kernels (SynthConfig.channel_kernels)."""
    grid: RenderGrid
    band: dict[str, KernelSet]
    channel: dict[str, KernelSet] = field(default_factory=dict)
    field_bases: dict[str, FieldBasis] = field(default_factory=dict)  # compact_kernels: rank-r phase bases
    power_maps: dict[str, PowerMap] = field(default_factory=dict)  # store_power_maps: exact power, made once
    field_planes: dict[str, PlaneBasis] = field(default_factory=dict)  # store_field_planes: a monitor's blend
    object_distance_m: float = math.nan  # the distance the kernels are focused for (scene_object_distance_m)
    far: dict[str, FarField] = field(default_factory=dict)  # spectral form: the light past the window (far_field)
    keys: dict[str, str] = field(default_factory=dict)  # the band kernel sets' cache keys (none without the cache)
    field_spread: dict = field(default_factory=dict)  # d > 0 sets: [K] max_q ‖k_q − k̄‖₁ (optics.phase_spread_l1)
    cache_dir: str | None = None  # the kernel cache folder they came from (None: psf.cache's default)
    cache_spectra: bool = False  # the kernels' spectra on the render grid go into the cache too (kernel_spectra)


def band_kernel_set(layout, lens, grid: RenderGrid, distance_mm: float, frame_um: tuple[float, float],
                    cfg: SynthConfig, label: str = "", progress: bool = False) -> KernelSet:
    """psf.KernelSet at the band centres of `grid` (field phases when d > 0), through the kernel cache."""
    return band_kernel_entry(layout, lens, grid, distance_mm, frame_um, cfg, label, progress)[0]


def band_kernel_entry(layout, lens, grid: RenderGrid, distance_mm: float, frame_um: tuple[float, float],
                      cfg: SynthConfig, label: str = "", progress: bool = False) -> tuple[KernelSet, str | None]:
    """band_kernel_set and its cache key (None without the cache)."""
    size = grid.kernel_size_px
    if size < 3:
        raise SynthError(f"render margin {grid.margin_px} px leaves no room for a kernel: raise render.margin_um")
    d_mm = distance_mm if layout is not None else 0.0
    phases = (cfg.field_phases or DEFAULT_FIELD_PHASES) ** 2 if d_mm > 0 else 1
    with tqdm(total=phases * grid.centres_nm.size, desc=f"kernels {label}", unit="kernel",
              disable=not progress, leave=False) as bar:  # ticks only when the kernels are not cached
        ks, _, key = cached_keyed(compute_kernels, "mono", layout, lens, cfg.use_cache, cache_dir=cfg.kernel_cache,
                                  wavelengths_nm=grid.centres_nm, pixel_um=grid.pitch_um, size_px=size,
                                  distance_mm=d_mm, field_phases=cfg.field_phases, precision=cfg.kernel_precision,
                                  sensor_um=frame_um, progress=bar.update)
    return ks, key


def far_field(layout, lens, grid: RenderGrid, core: KernelSet, frame_um: tuple[float, float],
              cfg: SynthConfig, core_key: str | None = None) -> FarField | None:
    """The far field of the band kernels `core` (optics.far_field): the same PSF computed at cfg.far_field_coarse
    × the render pitch over the acceptance (through the kernel cache), less the core window's part: a periodic
    display's and the bare lens's from the diffraction orders (psf.far.order_kernels), an aperiodic tile's (or
    at a coarse pitch too fine for orders as points) by the engine at d = 0. None when it is off
    (far_field_threshold None), when no band loses more than the threshold, or when the core window already
    reaches every frame pixel from every render pixel. core_key: the core's cache key, which puts the far field
    into the kernel cache (module doc)."""
    threshold = cfg.far_field_threshold
    if threshold is None or not (core.energy_outside > threshold).any():
        return None
    coarse = cfg.far_field_coarse
    size, half_um = far_window_px(frame_um, grid.margin_px * grid.pitch_um, coarse * grid.pitch_um)
    if half_um <= (core.size_px // 2 + coarse) * grid.pitch_um:
        return None
    common = dict(cache_dir=cfg.kernel_cache, wavelengths_nm=grid.centres_nm, pixel_um=coarse * grid.pitch_um,
                  size_px=size, precision=cfg.kernel_precision)
    orders = layout is None or (getattr(layout, "periodic", True) and hasattr(layout, "fourier_coefficients"))
    airy_um = grid.edges_nm[-1] * 1e-3 * lens.image_distance_um / lens.aperture_um  # λ z / D at the longest λ
    if orders and coarse * grid.pitch_um >= ORDER_PIXEL_FACTOR * airy_um:
        far, _, far_key = cached_keyed(order_kernels, FAR_CACHE_NAME, layout, lens, cfg.use_cache, **common)
    else:
        far, _, far_key = cached_keyed(compute_kernels, "mono", layout, lens, cfg.use_cache, distance_mm=0.0, **common)
    acceptance = acceptance_um(frame_um)
    arrays = cached_arrays("far-field-1", (core_key, far_key),
                           lambda: make_far_field(core, far, coarse, acceptance, threshold).arrays(), cfg.kernel_cache,
                           coarse=coarse, acceptance_um=acceptance, threshold=threshold)
    return FarField.from_arrays(arrays)


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
    return display_kernel_entry(display, scene, grid, cfg, progress, object_distance_m)[0]


def display_kernel_entry(display: Display, scene: Scene, grid: RenderGrid, cfg: SynthConfig, progress: bool = False,
                         object_distance_m: float | None = None) -> tuple[KernelSet, str | None]:
    """display_kernels and its cache key (None without the cache)."""
    frame_um = (scene.sensor.width_px * scene.sensor.pitch_um, scene.sensor.height_px * scene.sensor.pitch_um)
    return band_kernel_entry(display.layout, psf_lens(scene, object_distance_m), grid, display.distance_mm, frame_um,
                             cfg, display.name, progress)


def display_channel_kernels(display: Display, scene: Scene, grid: RenderGrid, cfg: SynthConfig,
                            object_distance_m: float | None = None) -> KernelSet:
    """The per-channel form's kernels [3] (R, G, B) by cfg.channel_kernels: 'paper': the paper's recipe as
    printed at PAPER_CHANNEL_NM (the very call `udc-render psf --method paper` makes); 'camera': the
    camera's sensitivities × D65 (psf.spectral.channel_kernels)."""
    lens = psf_lens(scene, object_distance_m)
    common = dict(use_cache=cfg.use_cache, cache_dir=cfg.kernel_cache, precision=cfg.kernel_precision)
    if cfg.channel_kernels == "paper":
        return paper_channel_kernels(display.layout, lens, grid.pitch_um, grid.kernel_size_px, **common)
    return camera_channel_kernels(display.layout, lens, cfg.sensor.camera, grid.pitch_um, grid.kernel_size_px,
                                  **common)


def paper_channel_kernels(layout, lens, pixel_um: float, size_px: int, use_cache: bool = True,
                          cache_dir: str | None = None, precision: str = "float32") -> KernelSet:
    """The paper's computed PSF [3] (R, G, B): its recipe as printed at PAPER_CHANNEL_NM, d = 0 (the call
    `udc-render psf --method paper` makes), through the kernel cache."""
    ks, _ = cached(compute_kernels, "mono", layout, lens, use_cache, cache_dir=cache_dir,
                   wavelengths_nm=PAPER_CHANNEL_NM, method="paper", pixel_um=pixel_um, size_px=size_px,
                   distance_mm=0.0, precision=precision)
    return ks


def camera_channel_kernels(layout, lens, camera: str, pixel_um: float, size_px: int, use_cache: bool = True,
                           cache_dir: str | None = None, precision: str = "float32") -> KernelSet:
    """The channel-effective kernels [3] (R, G, B) of the camera's sensitivities under D65, d = 0
    (psf.spectral.channel_kernels), through the kernel cache."""
    ks, _ = cached(channel_kernels, "channel", layout, lens, use_cache, cache_dir=cache_dir, camera=camera,
                   illuminant="D65", step_nm=None, pixel_um=pixel_um, size_px=size_px, distance_mm=0.0,
                   precision=precision)
    return ks


def plan_kernels(scene: Scene, displays: list[Display], cfg: SynthConfig, progress: bool = False,
                 object_distance_m: float | None = None, far: bool = True) -> Kernels:
    """Every kernel set the synthesis of `scene` through `displays` needs, from the scene alone, for
    objects at `object_distance_m` (None: scene_object_distance_m; the focus distance when
    cfg.defocus_tolerance_px is None); with `far` (spectral form), the far fields of the band kernels
    (far_field; every depth layer shares those of the focus)."""
    grid = render_grid(scene)
    z = object_distance_m
    if z is None:
        z = (camera_geometry(scene).focus_distance_m if cfg.defocus_tolerance_px is None
             else scene_object_distance_m(scene))
    glass = Display("glass", None)
    band, keys = {}, {}
    band["glass"], keys["glass"] = display_kernel_entry(glass, scene, grid, cfg, progress, z)
    channel = {}
    for d in displays:
        if d.name not in band and (cfg.form == "spectral" or d.source != "preset"):  # per_channel: analytic γ
            band[d.name], keys[d.name] = display_kernel_entry(d, scene, grid, cfg, progress, z)
        if cfg.form == "per_channel":
            channel[d.name] = display_channel_kernels(d, scene, grid, cfg, z)
    far_fields = {}
    if far and cfg.form == "spectral":
        frame_um = (scene.sensor.width_px * scene.sensor.pitch_um, scene.sensor.height_px * scene.sensor.pitch_um)
        layouts = {"glass": None, **{d.name: d.layout for d in displays}}
        for name, ks in band.items():
            f = far_field(layouts[name], psf_lens(scene, z), grid, ks, frame_um, cfg, keys[name])
            if f is not None:
                far_fields[name] = f
    spread = {}
    if cfg.field_print_sigma is not None:  # what the field blend can change (views.field_print)
        for name, ks in band.items():
            if ks.field_kernels is not None and ks.distance_mm > 0:
                spread[name] = cached_arrays("phase-spread-1", (keys[name],), lambda ks=ks: {
                    "l1": phase_spread_l1(ks.field_kernels, ks.kernels)}, cfg.kernel_cache)["l1"]
    return Kernels(grid, band, channel, object_distance_m=float(z), far=far_fields, field_spread=spread,
                   keys={n: k for n, k in keys.items() if k is not None}, cache_dir=cfg.kernel_cache)


def compact_kernels(kernels: Kernels, scene: Scene, cfg: SynthConfig) -> Kernels:
    """The kernels with each d > 0 set's phase kernels [K, P, P, S, S] replaced by their rank-r bases on
    the scene's render grid (optics.field_basis; the same numbers convolve_field would make per call):
    a dataset worker keeps 2/16 of the memory and makes the SVDs once, or loads them from the kernel cache
    (module doc). Unchanged when the field rank is None (exact: every phase kernel is used)."""
    if cfg.field_rank is None:
        return kernels
    cam = camera_geometry(scene)
    band, bases = dict(kernels.band), {}
    for name, ks in kernels.band.items():
        if ks.field_kernels is not None and ks.distance_mm > 0:
            wy, wx, _ = field_weights(ks, (cam.height_px, cam.width_px), kernels.grid.pitch_um, ks.distance_mm)
            live = live_phases(wy, wx)
            arrays = cached_arrays("field-basis-1", (kernels.keys.get(name),),
                                   lambda: field_basis(ks.field_kernels, live, cfg.field_rank).arrays(),
                                   cfg.kernel_cache, live=live, rank=cfg.field_rank)
            bases[name] = FieldBasis.from_arrays(arrays)
            band[name] = replace(ks, field_kernels=None)
    return replace(kernels, band=band, field_bases=bases)


def store_power_maps(kernels: Kernels, scene: Scene, cache_dir: str | None = None) -> Kernels:
    """The kernels with each d > 0 set's exact-power map on the scene's render grid made now and kept
    (optics.field_power: the numbers apply_kernels would make per capture, two chirp z-transforms per band,
    5–7 s for 30 bands at 2558 × 1534 px; kept in float32, K · H · W · 4 bytes per display: 0.47 GB there):
    a dataset worker makes them once, not once per item (benchmarks/bench_banding_rank.py --full-frame), or
    loads them from the kernel cache in `cache_dir` (module doc; cached when kernels.keys names the set)."""
    cam = camera_geometry(scene)
    shape, pitch = (cam.height_px, cam.width_px), kernels.grid.pitch_um
    maps = {}
    for name, ks in kernels.band.items():
        if ks.field_series is not None and ks.distance_mm > 0:
            _, _, g = field_weights(ks, shape, pitch, ks.distance_mm)
            fresh = field_power_map(ks, shape, pitch, ks.distance_mm, g["image_distance_um"], g["period_um"])
            arrays = cached_arrays("power-map-1", (kernels.keys.get(name),), lambda: {"maps": fresh.stored().maps},
                                   cache_dir, shape=list(shape), pitch_um=pitch, distance_mm=ks.distance_mm,
                                   image_distance_um=g["image_distance_um"], period_um=list(g["period_um"]))
            maps[name] = replace(fresh, maps=arrays["maps"])
    return replace(kernels, power_maps=maps)


def store_field_planes(kernels: Kernels, scene: Scene, cfg: SynthConfig) -> Kernels:
    """The kernels with each d > 0 set's weight maps in one shared basis on the scene's render grid
    (optics.field_planes.plane_basis: 45-55 CPU-s for 120 maps of 2558 × 1534 px), from the kernel cache when
    kernels.keys names the set. Only where a capture can use them: a monitor (its three planes), the spectral
    form, blend 'source', compacted bases (compact_kernels), cfg.field_planes_rank set, and a cache key (without
    the cache every worker would make them again, at more than they save over a few items); else unchanged."""
    if (cfg.field_planes_rank is None or not isinstance(scene.content, Monitor) or cfg.form != "spectral"
            or cfg.blend != "source"):
        return kernels
    cam = camera_geometry(scene)
    shape, pitch, out = (cam.height_px, cam.width_px), kernels.grid.pitch_um, {}
    for name, basis in kernels.field_bases.items():
        if kernels.keys.get(name) is None:
            continue
        ks = kernels.band[name]
        wy, wx, _ = field_weights(ks, shape, pitch, ks.distance_mm)
        pm = kernels.power_maps.get(name)
        arrays = cached_arrays("field-planes-1", (kernels.keys.get(name),), lambda: plane_basis(
            basis, ks.field_power, pm, wy, wx).arrays(), cfg.kernel_cache, shape=list(shape), pitch_um=pitch,
            rank=basis.rank, live=basis.live, exact_power=pm is not None, max_rank=PLANES_MAX_RANK)
        out[name] = PlaneBasis.from_arrays(arrays)
    return replace(kernels, field_planes=out)


def prepare_kernels(scene: Scene, displays: list[Display], cfg: SynthConfig) -> Kernels:
    """Every kernel product a dataset worker keeps: plan_kernels, compact_kernels, store_power_maps and
    store_field_planes, through the kernel cache (a dataset's parent makes them there once; its workers load
    them); the kernels' spectra go there too when first used (cache_spectra)."""
    kernels = compact_kernels(plan_kernels(scene, displays, cfg), scene, cfg)
    kernels = store_field_planes(store_power_maps(kernels, scene, cfg.kernel_cache), scene, cfg)
    return replace(kernels, cache_spectra=True)


def kernel_spectra(kernels: Kernels, name: str, blends: bool, shape, precision: str):
    """The spectra at FFT shape `shape` of view `name`'s kernels through the kernel cache (module doc): the band
    kernels [K, Fy, Fx//2 + 1] (blends False), or per band its rank-r field basis's [r, Fy, Fx//2 + 1] (blends);
    None when not cached (kernels.cache_spectra off, no cache key, or a blend without a basis): made per call.
    Float32 spectra of a 2048 × 1024 frame's grid are 15.7 MB a kernel: 0.47 GB for 30 band kernels, 1.9 GB for
    their rank-4 bases, shared by every process that maps them."""
    key = kernels.keys.get(name)
    basis = kernels.field_bases.get(name) if blends else None
    if not kernels.cache_spectra or key is None or (blends and basis is None):
        return None
    params = dict(shape=[int(n) for n in shape], precision=precision)
    if not blends:
        return cached_arrays("kernel-spectra-1", (key,), lambda: {
            "spectra": spectra_of(kernels.band[name].kernels, shape, precision)},
            kernels.cache_dir, **params)["spectra"]
    arrays = cached_arrays("basis-spectra-1", (key,), lambda: {
        f"spectra_{k}": spectra_of(b, shape, precision) for k, b in enumerate(basis.bases)}, kernels.cache_dir,
        rank=basis.rank, live=basis.live, **params)
    return [arrays[f"spectra_{k}"] for k in range(len(basis.bases))]
