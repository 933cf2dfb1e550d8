"""Making a kernel bank (udc_render.dataset.bank): one panel per display (preset_specs) or per drawn panel
(random_specs), its kernels through the kernel cache.

Per panel, on the scene's sensor (pitch, frame, lens focused on the monitor's plane, as pipeline.plan_kernels;
a drawn panel's own lens, randomize.panel_scene):
- d = 0 (or glass): the per-channel form's 3 kernels, the very call of the numpy synthesis
  (synth_kernels.display_channel_kernels on a grid at the sensor pitch with margin kernel_px // 2);
- d > 0: the camera's channel kernels at d with their field phases (psf.spectral.channel_kernels through
  psf.cache, as display_channel_kernels' 'camera' with distance_mm = d), sampled at the scene's band step (the
  spectral synthesis's sampling of λ; d = 0's λ/S would take 16 phases × ~400 wavelengths at 513 px, 16 times
  the kernels of the d = 0 set), each channel's phase kernels reduced to the rank-r basis of
  optics.field.field_basis on the live phases of the frame with its margins (the exact blend, field_rank None,
  keeps every live phase kernel with coefficients I). The paper's recipe has no d > 0 form: refused;
- γ as pipeline.display_gamma: the paper's for a preset, else optics.gamma's from the band kernels of the
  scene's render grid (at the display's d) and the monitor's white;
- the sensor: the synthesis's (sensor_for_scene) with the display's gain, γ / gain per site, the exposure (the
  scene's auto exposure, pipeline.auto_exposure_s, without a render; a drawn panel's × exposure.scale), the
  defect pixels and FPN (a drawn panel's: capture draw i's, with their own seeds), the brightness (a drawn
  panel's exposure.brightness: the trainer scales the clean image by it, as a randomized dataset scales the
  render);
- what the spectral synthesis adds (the physical profile; the per-channel form, the paper's, has neither):
  the far field (panel_far: synth_kernels.far_field of the display's band kernels on the scene's render grid,
  the very call, weighted per channel as γ weights the bands) and the display's haze (panel_haze: the
  profile's stray light's for a preset, the drawn one for a drawn panel). A haze the bank cannot honour (drawn
  under the per-channel form, or with the profile's haze off) and stray light beyond the haze are refused.

make_bank writes each panel's file and then bank.json (both atomic), so an interrupted run resumes: a re-run
with the same settings makes only the panels not yet recorded; other settings on the same folder are refused.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from psf.cache import ENGINE_VERSION, cached
from psf.spectral import channel_kernels
from udc_render.content import spectra
from udc_render.dataset.bank import (
    BANK_FILE,
    FORMAT_1,
    BankError,
    Panel,
    PanelFar,
    PanelField,
    PanelHaze,
    file_sha256,
    panel_effects,
    save_panel,
    write_bank_json,
)
from udc_render.dataset.randomize import (
    PANEL_NAME,
    as_record,
    capture_config,
    capture_display,
    draw_capture,
    draw_panels,
    panel_scene,
    scaled_exposure_s,
)
from udc_render.dataset.store import unrecorded_engine
from udc_render.optics import field_basis, field_weights, gamma, live_phases
from udc_render.optics.displays import PAPER_GAMMA, Display
from udc_render.pipeline import SynthConfig, auto_exposure_s, sensor_for_scene
from udc_render.render import BandImage
from udc_render.scene import Monitor, Scene
from udc_render.scene.geometry import RenderGrid, psf_lens, render_grid, sensor_kernel_px
from udc_render.sensor import rgb_to_rggb
from udc_render.synth_kernels import display_channel_kernels, display_kernels, far_field, scene_object_distance_m

NOT_APPLIED = {"room light, ghost, lens glare, display emission": "off in the profile's stray light (optics.stray; "
                                                                   "the bank refuses them on)",
               "spectral integration": "per channel: one kernel and one γ per camera channel, for the monitor's white "
                                       "(the spectral synthesis integrates every band)"}


def monitor_white_bands(scene: Scene) -> np.ndarray:
    """[K] band-mean radiance of the scene's monitor at full white (what the render's primaries matrix sums to)."""
    m = scene.content
    primaries, _ = spectra.monitor_primaries(m.primaries, m.peak_luminance_cd_m2, Path(scene.source).resolve().parent,
                                             m.white_point)
    return spectra.band_means(primaries, np.asarray(scene.bands.edges_nm)).sum(axis=0)


def scene_exposure_s(scene: Scene, cfg: SynthConfig) -> tuple[float, str]:
    """The synthesis's auto exposure of a monitor scene (pipeline.auto_exposure_s: its white at EXPOSURE_FILL of the
    full well through glass), without a render; cfg.exposure_s when set."""
    if cfg.exposure_s is not None:
        return float(cfg.exposure_s), "set"
    if not isinstance(scene.content, Monitor):
        raise BankError(f"--scene {scene.source}: a {scene.content_type} scene has no monitor white to expose for: "
                        "give --exposure-s")
    edges = np.asarray(scene.bands.edges_nm, float)
    white = monitor_white_bands(scene)
    probe = BandImage(np.zeros((edges.size - 1, 2, 2), np.float32), edges, scene.sensor.pitch_um, 0, None,
                      primaries_matrix=np.stack([white, 0 * white, 0 * white]))
    return auto_exposure_s(probe, sensor_for_scene(cfg.sensor, scene))


def sensor_grid(scene: Scene, kernel_px: int) -> RenderGrid:
    """The grid of the bank's kernels: the sensor pitch, margin kernel_px // 2, the scene's bands."""
    if kernel_px < 3 or kernel_px % 2 == 0:
        raise BankError(f"--kernel-px = {kernel_px}: expected an odd number ≥ 3")
    return RenderGrid(float(scene.sensor.pitch_um), kernel_px // 2, tuple(float(e) for e in scene.bands.edges_nm))


def scene_white(scene: Scene, edges_nm) -> np.ndarray:
    """[K] the band radiance of the white γ is defined for: the scene's monitor's, else flat."""
    return monitor_white_bands(scene) if isinstance(scene.content, Monitor) else np.ones(len(edges_nm) - 1)


def panel_gamma(display: Display, scene: Scene, cfg: SynthConfig) -> tuple[tuple, str]:
    """γ (R, G, B) and its source, as pipeline.display_gamma for the scene's monitor white."""
    if display.source == "preset":
        return PAPER_GAMMA[display.name], "the paper's γ for this preset"
    grid, z = render_grid(scene), scene_object_distance_m(scene)
    g = gamma.display_gamma(display, display_kernels(display, scene, grid, cfg, object_distance_m=z),
                            display_kernels(Display("glass", None), scene, grid, cfg, object_distance_m=z),
                            np.asarray(grid.edges_nm, float), cfg.sensor.camera, scene_white(scene, grid.edges_nm))
    return tuple(float(x) for x in g), "γ of the display file (optics.gamma)"


def panel_field(ks, scene: Scene, grid: RenderGrid, rank: int | None) -> PanelField:
    """The d > 0 field of channel kernels `ks` on the frame with its margins (module doc)."""
    shape = (scene.sensor.height_px + 2 * grid.margin_px, scene.sensor.width_px + 2 * grid.margin_px)
    wy, wx, geometry = field_weights(ks, shape, grid.pitch_um, ks.distance_mm)
    live = live_phases(wy, wx)
    if rank is None:
        bases = np.stack([[ks.field_kernels[c, j, i] for j, i in live] for c in range(3)])
        coeffs = np.broadcast_to(np.eye(len(live)), (3, len(live), len(live))).copy()
    else:
        fb = field_basis(ks.field_kernels, live, rank)
        r = max(b.shape[0] for b in fb.bases)  # a channel with fewer independent phases: zero bases
        bases = np.zeros((3, r) + ks.field_kernels.shape[-2:], ks.field_kernels.dtype)
        coeffs = np.zeros((3, len(live), r))
        for c in range(3):
            bases[c, :fb.bases[c].shape[0]], coeffs[c, :, :fb.coeffs[c].shape[1]] = fb.bases[c], fb.coeffs[c]
    shifts = np.asarray(ks.field_shifts_um, float)
    return PanelField(bases, coeffs, live, shifts[0, :, 0], shifts[:, 0, 1], tuple(geometry["periodic"]),
                      tuple(geometry["period_um"]), float(ks.distance_mm), float(geometry["image_distance_um"]),
                      np.asarray(ks.field_power, float),
                      None if ks.field_series is None else np.asarray(ks.field_series))


def channel_kernel_set(display: Display, scene: Scene, grid: RenderGrid, cfg: SynthConfig):
    """The display's 3 channel kernels on `grid` (module doc), for the object at the scene's distance."""
    z = scene_object_distance_m(scene)
    d = 0.0 if display.is_glass else float(display.distance_mm)
    if d == 0:
        return display_channel_kernels(display, scene, grid, cfg, z)
    if cfg.channel_kernels != "camera":
        raise BankError(f"--display {display.name} at d = {d:g} mm with --channel-kernels {cfg.channel_kernels}: the "
                        "paper's recipe has no field phases; use --channel-kernels camera or --distance-mm 0")
    frame_um = (scene.sensor.width_px * scene.sensor.pitch_um, scene.sensor.height_px * scene.sensor.pitch_um)
    ks, _ = cached(channel_kernels, "channel", display.layout, psf_lens(scene, z), cfg.use_cache,
                   cache_dir=cfg.kernel_cache, camera=cfg.sensor.camera, illuminant="D65",
                   step_nm=float(scene.bands.step_nm),
                   pixel_um=grid.pitch_um, size_px=grid.kernel_size_px, distance_mm=d, field_phases=cfg.field_phases,
                   precision=cfg.kernel_precision, sensor_um=frame_um)
    return ks


def panel_far(display: Display, scene: Scene, cfg: SynthConfig, kernel_px: int) -> tuple[PanelFar | None, str]:
    """(the panel's far field (bank.PanelFar) or None, what it is or why none): the spectral synthesis's far field
    of the display's band kernels on the scene's render grid (synth_kernels.far_field, the same calls through the
    kernel cache), F_c = Σ_k W_ck T_k τ_k f_k / Σ_k W_ck T_k τ_k (1 − o_k) with W the camera's electrons of the white
    γ is defined for (optics.gamma.white_weights)."""
    if cfg.form != "spectral":
        return None, "not applied: the per-channel form (the paper's y = γ x ⊗ k + n) has none"
    if cfg.far_field_threshold is None:
        return None, "not applied: far_field_threshold None (off)"
    grid, z = render_grid(scene), scene_object_distance_m(scene)
    band = display_kernels(display, scene, grid, cfg, object_distance_m=z)
    frame_um = (scene.sensor.width_px * scene.sensor.pitch_um, scene.sensor.height_px * scene.sensor.pitch_um)
    far = far_field(display.layout, psf_lens(scene, z), grid, band, frame_um, cfg)
    if far is None:
        return None, (f"not applied: no band loses more than far_field_threshold = {cfg.far_field_threshold:g} "
                      "past the kernel window, or the window reaches the whole frame")
    coarse = far.coarse * grid.pitch_um / scene.sensor.pitch_um
    if abs(coarse - round(coarse)) > 1e-9 or kernel_px > sensor_kernel_px(scene):
        raise BankError(f"--kernel-px {kernel_px} with render.supersample {scene.render.supersample}: the far field is "
                        f"split at the render window ({sensor_kernel_px(scene)} px) in whole sensor pixels of "
                        f"{far.coarse} render pixels; use a smaller --kernel-px or render.supersample 1")
    edges = np.asarray(grid.edges_nm, float)
    w = gamma.white_weights(edges, cfg.sensor.camera, scene_white(scene, edges))
    t = display.transmission.band_means(edges) * np.asarray(band.transmittance, float)
    core = w @ (t * (1.0 - np.asarray(band.energy_outside, float)))
    kernels = np.einsum("ck,kij->cij", w * t[None, :], far.kernels) / core[:, None, None]
    return PanelFar(kernels, int(round(coarse))), "applied (optics.far_field per channel)"


def panel_haze(name: str, haze: float, cfg: SynthConfig) -> tuple[PanelHaze | None, str]:
    """(the panel's haze (bank.PanelHaze) or None, what it is or why none); a haze the bank cannot honour is
    refused in one line."""
    if haze == 0:
        return None, ("not applied: the display's haze is 0" if cfg.form == "spectral" else
                      "not applied: the per-channel form (the paper's y = γ x ⊗ k + n) has none")
    if cfg.form != "spectral" or not cfg.stray_light.haze:
        raise BankError(f"--display {name}: a haze of {haze:g} under the {cfg.form} form with the profile's haze "
                        f"{dict(cfg.stray_light.haze) or 'off'}: the bank cannot apply it; set its haze to 0 (a "
                        "distributions file's display.<family>.haze) or use --profile physical")
    return PanelHaze(float(haze), cfg.stray_light.haze_inner_deg), "applied (optics.stray, effect d)"


@dataclass(frozen=True)
class PanelSpec:
    """What makes one panel: the display (its name the panel's), the scene (the lens: a drawn panel's own), the
    synthesis settings (sensor, defects, FPN, kernels), the exposure (s), extra record values (a drawn panel's
    draws, its brightness: the factor on the clean image's radiance, 1 for a preset) and its haze."""
    display: Display
    scene: Scene
    cfg: SynthConfig
    exposure_s: float
    record: dict = field(default_factory=dict)
    haze: float = 0.0


def preset_specs(displays: list[Display], scene: Scene, cfg: SynthConfig) -> list[PanelSpec]:
    """One panel per display, every one with the synthesis's sensor and the scene's exposure (scene_exposure_s)."""
    exposure, rule = scene_exposure_s(scene, cfg)
    return [PanelSpec(d, scene, cfg, exposure, {"brightness": 1.0, "exposure_rule": rule},
                      cfg.stray_light.haze_of(d.name)) for d in displays]


def random_specs(dists, n: int, seed: int, scene: Scene, cfg: SynthConfig) -> list[PanelSpec]:
    """N drawn panels (udc_render.dataset.randomize.draw_panels), panel i named random_<i> with the sensor and
    exposure of capture draw i (draw_capture(…, item = i): gain scale, read noise, defect pixels and FPN with
    their seeds, exposure scale and brightness), its lens (panel_scene)."""
    out = []
    for draw in draw_panels(dists, n, seed):
        cap = draw_capture(dists, n, seed, draw.index)
        display = replace(capture_display(draw, cap), name=f"{PANEL_NAME}_{draw.index:03d}")
        own = panel_scene(scene, draw.lens)
        exposure, rule = scene_exposure_s(own, cfg)  # the panel's f-number's (randomized.py's rule)
        out.append(PanelSpec(display, own, capture_config(cfg, cap), scaled_exposure_s(exposure, cap),
                             {"brightness": float(cap.brightness), "exposure_rule": f"{rule} × exposure.scale",
                              "panel_draw": as_record(draw), "capture_draw": as_record(cap)}, float(draw.haze)))
    return out


def make_panel(spec: PanelSpec, kernel_px: int) -> Panel:
    """One panel (module doc)."""
    display, scene, cfg = spec.display, spec.scene, spec.cfg
    grid = sensor_grid(scene, kernel_px)
    ks = channel_kernel_set(display, scene, grid, cfg)
    g, why = panel_gamma(display, scene, cfg)
    sensor = replace(sensor_for_scene(cfg.sensor, scene), exposure_s=float(spec.exposure_s), gain=float(display.gain),
                     form="per_channel", gamma_rggb=tuple(v / display.gain for v in rgb_to_rggb(g)))
    blend = None
    if ks.field_kernels is not None and ks.distance_mm > 0:
        blend = panel_field(ks, scene, grid, cfg.field_rank)
    far, far_note = panel_far(display, scene, cfg, kernel_px)
    haze, haze_note = panel_haze(display.name, spec.haze, cfg)
    record = {"display": display.describe(), "lens": psf_lens(scene).describe(), "gamma_source": why,
              "transmission_rgb": [v / display.gain for v in g], "kernel_notes": list(ks.notes),
              "kernel_params": ks.params, **spec.record}
    panel = Panel(display.name, np.asarray(ks.kernels, np.float32), grid.pitch_um, g, sensor, cfg.defects, cfg.fpn,
                  blend, record, far=far, haze=haze)
    missing = {k: v for k, v in (("far field", far_note), ("haze", haze_note)) if v.startswith("not applied")}
    return replace(panel, record=json.loads(json.dumps({**record, "effects": panel_effects(
        panel, {**missing, **NOT_APPLIED})}, default=str)))


def bank_settings(scene: Scene, cfg: SynthConfig, kernel_px: int, specs: list[PanelSpec], extra: dict) -> dict:
    """What decides the bank's panels, as plain JSON values (a re-run with other settings is refused)."""
    # field_print_sigma leaves a dataset item's faint field blend out, field_planes_rank takes a monitor item's blend
    # through its planes; a bank's panels keep every blend on their own crops: not theirs
    synth = {k: v for k, v in asdict(cfg).items()
             if k not in ("use_cache", "kernel_cache", "stray_light", "field_print_sigma", "field_planes_rank")}
    stray = cfg.stray_light
    if stray.room_on or stray.lens_reflectance or stray.lens_glare or stray.emission_on:
        raise BankError(f"stray light {stray.describe()}: a bank applies the display's haze only; switch the room "
                        "light, ghost, lens glare and display emission off")
    for spec in specs:  # a haze the bank cannot apply: refused before any kernel is made
        panel_haze(spec.display.name, spec.haze, spec.cfg)
    spectral = cfg.form == "spectral"
    effects = {"far_field": "the spectral synthesis's, per channel (bank.PanelFar)" if spectral else "none",
               "haze": "the display's (bank.PanelHaze)" if spectral else "none", "stray_light": stray.describe()}
    doc = {"scene": scene.source, "frame_px": [scene.sensor.width_px, scene.sensor.height_px],
           "pitch_um": scene.sensor.pitch_um, "kernel_px": kernel_px, "lens": psf_lens(scene).describe(),
           "edges_nm": list(scene.bands.edges_nm),
           "form": "per_channel (the numpy synthesis's y = γ x ⊗ k + n; d > 0: the field blend of each channel)",
           "synth": synth, "displays": [s.display.describe() for s in specs], "effects": effects,
           "psf_engine": ENGINE_VERSION, **extra}  # kernels of another engine version: a new bank, not a resume
    return json.loads(json.dumps(doc, default=str))


def make_bank(out: Path, specs: list[PanelSpec], settings: dict, kernel_px: int, progress: bool = True) -> dict:
    """Write (or finish) the bank of `specs` in `out` (module doc); returns its summary."""
    out = Path(out)
    names = [s.display.name for s in specs]
    if not specs or len(set(names)) != len(names):
        raise BankError(f"--display {','.join(names)}: expected distinct display names (they name the panels)")
    records = _resumable_records(out, settings)
    made = 0
    for i, spec in enumerate(tqdm(specs, desc="bank", unit="panel", disable=not progress)):
        if i < len(records):
            continue
        records.append(save_panel(out, i, make_panel(spec, kernel_px)))
        write_bank_json(out, settings, records, len(specs))
        made += 1
    return {"out": str(out), "panels": len(records), "made": made, "names": names,
            "field_panels": [r["name"] for r in records if r["field"] is not None]}


def differing_settings(doc: dict, settings: dict) -> list[str]:
    """The keys in which bank.json's `doc` and `settings` (bank_settings) differ, less its own bookkeeping (format,
    count, complete, panels): none when the bank was made, or begun, with these settings. A format-1 doc is
    compared on the keys that format has (not "effects": its panels carry no far field and no haze, bank.
    FORMAT_1_EFFECTS), so that the carried bank.json of a shipped model still names its bank
    (restore.studies.random_row.carried_bank); make_bank never resumes one. A doc without "psf_engine" (made before
    engine version psf-5 recorded it) names today's kernels unless it holds an aperiodic display, the only kernels
    psf-5 changed (store.unrecorded_engine)."""
    skip = ({"format", "count", "complete", "panels"} | ({"effects"} if doc.get("format") == FORMAT_1 else set())
            | unrecorded_engine(doc))
    return sorted(k for k in settings.keys() | doc.keys() if k not in skip and doc.get(k) != settings.get(k))


def _resumable_records(out: Path, settings: dict) -> list[dict]:
    """The panels already made in `out` for these settings (none in a new folder); other settings: refused."""
    path = out / BANK_FILE
    if not path.is_file():
        return []
    try:
        old = json.loads(path.read_text())
    except (OSError, ValueError):
        raise BankError(f"{path}: unreadable; use another --out or delete the folder") from None
    if keys := differing_settings(old, settings) or (["format"] if old.get("format") == FORMAT_1 else []):
        raise BankError(f"--out {out} holds a different bank (differs in {', '.join(keys)}); use another --out or "
                        "delete the folder")
    done = []
    for r in old.get("panels", []):  # the whole ones, up to the first missing or damaged file
        if not ((out / r["file"]).is_file() and file_sha256(out / r["file"]) == r["sha256"]):
            break
        done.append(r)
    return done
