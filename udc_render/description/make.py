"""The producers of a panel's description (udc_render.description): a bank's panel, a preset or display file, and
`udc-render fit`'s folder. describe_display is THE function `udc-render evaluate --display FILE` uses, and the one a
conditioned restorer's description of a display file or preset is made by.

- describe_panel (a kernel bank's panel, udc_render.dataset.bank.Panel): its kernels at the sensor pitch packed
  (udc_render.description.packed_window; the field's bases alike, not normalised), its γ, its sensor; the share
  outside the window counts its far field's light (a format-1 bank has none: only its window's light is seen).
  Its kernels are those of describe_display's at another sampling (the engine's exact pixel integration at the
  sensor pitch, then 2 × 2 sensor pixels summed), so a bank's panel and describe_display of the same display
  agree to the engine's window and λ step (tests/udc_render/test_description.py).
- describe_display (a preset, a display file or a micrograph, a sensor, a frame and the rig's optics): the
  kernels of DeP (exact kernel) (restore.known 'exact': the camera's sensitivities × D65, psf.spectral.
  channel_kernels through the kernel cache, synth_kernels.camera_channel_kernels at d = 0), computed at the sensor
  pitch over 2K + 1 pixels and packed as a bank's panel is (packed_window): a bank's panel of that display and
  its description then agree to the kernels' window and λ step (the packed pitch's own kernels, DeP's, sum a
  box of 2 sensor pixels where the packing sums ½, 1, ½ of three: 10–13 % of the peak apart at 24.8 µm pixels);
  d > 0: those channel kernels with their field phases (bank_make's call), reduced to the rank-r basis on the
  phases the frame uses (optics.field.field_basis), packed;
  γ as the synthesis defines it (pipeline.display_gamma, bank_make.panel_gamma): the paper's γ for a preset (the
  presets' transmissions are fitted so that optics.gamma gives it), optics.gamma's display_gamma for a file, from
  the display's and the bare lens's band kernels on the rig's render grid and the rig's white; the sensor with the
  display's gain.
- describe_fit (`udc-render fit --out DIR`): describe_display of DIR/display.toml with the sensor's keys of
  DIR/sensor.toml (its noise λ, bits and levels) over the given sensor.

The rig (Rig): the lens (focused, with the object at its distance), the render grid of γ's band kernels and the
white γ is defined for: a scene's (scene_rig; the monitor scene at the frame and pitch by default), or a
dataset's, read from an item's synth.json (dataset_rig).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from psf import Lens
from psf.cache import cached
from psf.spectral import channel_kernels
from udc_render.description import (
    DESCRIPTION_KERNEL_PX,
    DescriptionError,
    FieldDescription,
    PanelDescription,
    packed_window,
)
from udc_render.io.files import read_toml
from udc_render.optics import field_basis, field_weights, gamma, live_phases
from udc_render.optics.displays import PAPER_GAMMA, Display, load_display
from udc_render.scene import load_scene
from udc_render.scene.geometry import RenderGrid, psf_lens, render_grid
from udc_render.scene.overrides import with_overrides
from udc_render.sensor import SensorConfig, SensorError, rgb_to_rggb
from udc_render.sensor.noise import sensor_lambdas
from udc_render.synth_config import SynthConfig
from udc_render.synth_kernels import band_kernel_set, camera_channel_kernels, scene_object_distance_m

__all__ = ["Rig", "dataset_rig", "describe_display", "describe_fit", "describe_panel", "display_kernels", "scene_rig",
           "with_sensor"]


@dataclass(frozen=True)
class Rig:
    """The optics a display's description is made for (module doc): the lens, the render grid of γ's band kernels,
    the white's band radiance [K] (None: flat), the kernels' precision, field phases and rank (d > 0)."""
    lens: Lens
    grid: RenderGrid
    white_bands: tuple | None = None
    precision: str = "float32"
    field_phases: int | None = None
    field_rank: int | None = 4

    @property
    def step_nm(self) -> float:
        """The grid's band step: the d > 0 kernels' λ step (bank_make's)."""
        return float(np.diff(np.asarray(self.grid.edges_nm, float)).min())


def scene_rig(scene=None, frame_px: tuple[int, int] | None = None, pitch_um: float | None = None) -> Rig:
    """The rig of a scene (None: the monitor scene) at frame_px (width, height) and pitch_um (None: its own)."""
    from udc_render.dataset.bank_make import scene_white
    scene = with_overrides(scene or load_scene("monitor"), sensor_px=frame_px, pitch_um=pitch_um)
    grid = render_grid(scene)
    return Rig(psf_lens(scene, scene_object_distance_m(scene)), grid,
               tuple(float(v) for v in scene_white(scene, grid.edges_nm)))


def dataset_rig(item_folder: Path) -> Rig:
    """The rig an item of `udc-render dataset` was synthesised with, from its synth.json (as restore.known reads
    it): its lens, its kernel grid and band edges, its monitor's white (the render's band matrix)."""
    path = Path(item_folder) / "synth.json"
    if not path.is_file():
        raise DescriptionError(f"{path}: missing: a panel description needs the rig its captures were made with "
                               "(items of `udc-render dataset` have a synth.json)")
    synth = json.loads(path.read_text())
    render = synth["render"]
    edges = tuple(float(e) for e in render["band_edges_nm"])
    matrix = render.get("band_matrix")
    white = None if matrix is None else tuple(float(v) for v in np.asarray(matrix, float).sum(axis=0))
    grid = RenderGrid(float(synth["kernel_pixel_um"]), (int(synth["kernel_size_px"]) - 1) // 2, edges)
    return Rig(Lens(**synth["lens"]), grid, white, synth.get("kernel_precision", "float32"))


def _sensor(sensor) -> SensorConfig:
    if isinstance(sensor, SensorConfig):
        return sensor
    if isinstance(sensor, dict):
        names = {f.name for f in fields(SensorConfig)}
        return SensorConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in sensor.items() if k in names})
    return SensorConfig.from_toml(sensor)


def _noise(sensor: SensorConfig) -> tuple[tuple, tuple]:
    """(λ_read [4], λ_shot [4]) in the normalised input's units (udc_render.description module doc)."""
    if sensor.noise == "none":
        return (0.0,) * 4, (0.0,) * 4
    if sensor.noise == "poisson" or sensor.lambda_source == "sensor":
        r, s = sensor_lambdas(sensor)
        return (float(r),) * 4, (float(s),) * 4
    if sensor.lambda_source == "brooks":
        raise DescriptionError("sensor.lambda_source = 'brooks': λ is drawn per capture, so a panel description "
                               "has none; describe the capture with its drawn λ (lambda_source 'fixed')")
    return tuple(sensor.lambda_read), tuple(sensor.lambda_shot)


def _description(name: str, source: str, kernels, outside, gamma_rgb, sensor: SensorConfig, frame_px,
                 field=None) -> PanelDescription:
    read, shot = _noise(sensor)
    return PanelDescription(
        name, source, np.asarray(kernels, np.float32), tuple(float(v) for v in outside),
        tuple(float(v) for v in rgb_to_rggb(gamma_rgb)), float(sensor.gain), sensor.noise, read, shot,
        float(sensor.dn_per_electron * sensor.full_well_e / sensor.range_dn), int(sensor.black_level_dn),
        int(sensor.white_level_dn), int(sensor.bit_depth), sensor.camera, float(sensor.pitch_um),
        (int(frame_px[0]), int(frame_px[1])), field)


def with_sensor(description: PanelDescription, sensor: SensorConfig) -> PanelDescription:
    """The description with its sensor's fields (gain, noise, saturation, levels, camera, pitch) from `sensor`: a
    panel seen through a sensor drawn per crop (restore.captures), its kernels and γ unchanged."""
    new = _description(description.name, description.source, description.kernels, description.outside_rgb, (0,) * 3,
                       sensor, description.frame_px, description.field)
    return replace(new, gamma_rggb=description.gamma_rggb)


def describe_panel(panel, frame_px: tuple[int, int], kernel_px: int = DESCRIPTION_KERNEL_PX) -> PanelDescription:
    """The description of a bank's panel (udc_render.dataset.bank.Panel; its sensor as drawn) on a frame of
    frame_px (width, height): module doc."""
    kernels, outside = packed_window(panel.kernels, kernel_px)
    if panel.far is not None:  # the light past the bank's window, a share of the window's (bank.PanelFar)
        outside = 1.0 - (1.0 - outside) / (1.0 + np.asarray(panel.far.share_rgb, float))
    field = None
    f = panel.field
    if f is not None:
        bases, _ = packed_window(f.bases, kernel_px, normalise=False)
        field = FieldDescription(bases, np.asarray(f.coeffs, float), tuple(f.live), np.asarray(f.shifts_x_um, float),
                                 np.asarray(f.shifts_y_um, float), tuple(f.period_um), float(f.distance_mm),
                                 float(f.image_distance_um))
    return _description(panel.name, f"bank panel {panel.name}", kernels, outside, panel.gamma_rgb, panel.sensor,
                        frame_px, field)


def _display(display) -> Display:
    return display if isinstance(display, Display) else load_display(str(display))


def _field(ks, frame_px, kernel_px: int, rank: int | None) -> FieldDescription:
    """The rank-r basis of channel kernels `ks` with field phases at the sensor pitch on the frame with its margins
    (bank_make.panel_field's), packed (packed_window, not normalised)."""
    shape = (frame_px[1] + ks.size_px - 1, frame_px[0] + ks.size_px - 1)
    wy, wx, geometry = field_weights(ks, shape, ks.pixel_um, ks.distance_mm)
    live = live_phases(wy, wx)
    if rank is None:
        bases = np.stack([[ks.field_kernels[c, j, i] for j, i in live] for c in range(3)])
        coeffs = np.broadcast_to(np.eye(len(live)), (3, len(live), len(live))).copy()
    else:
        fb = field_basis(ks.field_kernels, live, rank)
        r = max(b.shape[0] for b in fb.bases)
        bases, coeffs = np.zeros((3, r) + ks.field_kernels.shape[-2:]), np.zeros((3, len(live), r))
        for c in range(3):
            bases[c, :fb.bases[c].shape[0]], coeffs[c, :, :fb.coeffs[c].shape[1]] = fb.bases[c], fb.coeffs[c]
    shifts = np.asarray(ks.field_shifts_um, float)
    return FieldDescription(packed_window(bases, kernel_px, normalise=False)[0], coeffs, live, shifts[0, :, 0],
                            shifts[:, 0, 1],
                            tuple(geometry["period_um"]), float(ks.distance_mm), float(geometry["image_distance_um"]))


def display_kernels(display: Display, rig: Rig, camera: str, sensor_pitch_um: float, frame_px,
                    kernel_px: int = DESCRIPTION_KERNEL_PX, use_cache: bool = True):
    """(kernels [3, K, K] at the packed pitch, the share outside the window [3], the field or None) of a display
    (module doc: DeP (exact kernel)'s kernels; d > 0 with the field's basis)."""
    d = 0.0 if display.is_glass else float(display.distance_mm)
    size = 2 * kernel_px + 1  # at the sensor pitch: K packed pixels and the half pixels around them
    if d == 0:
        ks = camera_channel_kernels(display.layout, rig.lens, camera, float(sensor_pitch_um), size, use_cache,
                                    precision=rig.precision)
        field = None
    else:
        frame_um = (frame_px[0] * sensor_pitch_um, frame_px[1] * sensor_pitch_um)
        ks, _ = cached(channel_kernels, "channel", display.layout, rig.lens, use_cache, camera=camera,
                       illuminant="D65", step_nm=rig.step_nm, pixel_um=float(sensor_pitch_um), size_px=size,
                       distance_mm=d, field_phases=rig.field_phases, precision=rig.precision, sensor_um=frame_um)
        field = _field(ks, frame_px, kernel_px, rig.field_rank)
    kernels, cut = packed_window(ks.kernels, kernel_px)
    return kernels, 1.0 - (1.0 - np.asarray(ks.energy_outside, float)) * (1.0 - cut), field


def display_gamma_rgb(display: Display, rig: Rig, camera: str, frame_um, use_cache: bool = True) -> tuple:
    """γ (R, G, B) as the synthesis defines it (module doc)."""
    if display.source == "preset":
        return PAPER_GAMMA[display.name]
    cfg = SynthConfig(kernel_precision=rig.precision, use_cache=use_cache, field_phases=rig.field_phases)
    ks = band_kernel_set(display.layout, rig.lens, rig.grid, display.distance_mm, frame_um, cfg)
    glass = band_kernel_set(None, rig.lens, rig.grid, 0.0, frame_um, cfg)
    white = None if rig.white_bands is None else np.asarray(rig.white_bands, float)
    white = np.ones(len(rig.grid.edges_nm) - 1) if white is None else white
    return tuple(float(v) for v in gamma.display_gamma(display, ks, glass, np.asarray(rig.grid.edges_nm, float),
                                                       camera, white))


def describe_display(display, sensor, frame_px: tuple[int, int], rig: Rig | None = None,
                     kernel_px: int = DESCRIPTION_KERNEL_PX, use_cache: bool = True) -> PanelDescription:
    """The description of `display` (a Display, or a --display spec: a preset, a display file, a micrograph) in
    front of `sensor` (a SensorConfig, its dict (capture.json's "sensor") or a sensor TOML file; its gain replaced
    by the display's) on a frame of frame_px (width, height) sensor pixels, for `rig` (None: the monitor scene's
    at that frame and the sensor's pitch): module doc."""
    display = _display(display)
    sensor = replace(_sensor(sensor), gain=float(display.gain))
    frame_px = (int(frame_px[0]), int(frame_px[1]))
    rig = rig or scene_rig(frame_px=frame_px, pitch_um=sensor.pitch_um)
    kernels, outside, field = display_kernels(display, rig, sensor.camera, sensor.pitch_um, frame_px, kernel_px,
                                              use_cache)
    frame_um = (frame_px[0] * sensor.pitch_um, frame_px[1] * sensor.pitch_um)
    g = display_gamma_rgb(display, rig, sensor.camera, frame_um, use_cache)
    source = f"preset {display.name}" if display.source == "preset" else f"display file {display.source}"
    return _description(display.name, source, kernels, outside, g, sensor, frame_px, field)


def fit_sensor(folder: Path, sensor) -> SensorConfig:
    """`sensor` with the keys of `udc-render fit`'s folder/sensor.toml (when there is one) in place."""
    base = _sensor(sensor)
    path = Path(folder) / "sensor.toml"
    if not path.is_file():
        return base
    data = read_toml(path, SensorError, "sensor config")
    SensorConfig.from_dict(data)  # its keys and values checked, the file named
    return replace(base, **{k: tuple(v) if isinstance(v, list) else v for k, v in data.items()})


def describe_fit(folder: Path, sensor, frame_px: tuple[int, int], rig: Rig | None = None,
                 kernel_px: int = DESCRIPTION_KERNEL_PX, use_cache: bool = True) -> PanelDescription:
    """The description of the panel `udc-render fit --out folder` fitted: describe_display of folder/display.toml
    with folder/sensor.toml's keys over `sensor` (module doc)."""
    folder = Path(folder)
    if not (folder / "display.toml").is_file():
        raise DescriptionError(f"{folder}: no display.toml: expected the folder of `udc-render fit --out`")
    d = describe_display(folder / "display.toml", fit_sensor(folder, sensor), frame_px, rig, kernel_px, use_cache)
    return replace(d, source=f"fit {folder}")
