"""`udc-render synth` (one scene through one or more displays) and `udc-render demo` (the main job).

    udc-render synth SCENE --display toled[,poled,PATH] [--distance-mm D] --out DIR
    udc-render demo [--out DIR]
"""
from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

from udc_render.cli import UserError, _float_pair, _non_negative, _positive, add_scene_arguments, scene_from_args

DEMO_DISPLAYS = "glass,toled,poled"


def add_capture_arguments(p: argparse.ArgumentParser) -> None:
    """Knobs shared by synth, demo and dataset."""
    p.add_argument("--display", default="toled",
                   help="comma-separated: glass, toled, poled or display files (.toml); the glass "
                        "capture is always made too [toled]")
    p.add_argument("--distance-mm", type=_non_negative("--distance-mm"),
                   help="display-to-lens distance d for every display [each display's own: 0 for the presets]")
    p.add_argument("--form", choices=("spectral", "per_channel"), default="spectral",
                   help="spectral: K band kernels and camera sensitivities (physical); per_channel: the "
                        "paper's y = γ x ⊗ k + n with 3 channel kernels [spectral]")
    p.add_argument("--sensor-config", type=Path,
                   help="TOML file of sensor-model keys (gain is per display; see udc_render/sensor.py)")
    p.add_argument("--noise-model", choices=("poisson", "gaussian", "none"), help="[poisson]")
    p.add_argument("--exposure-s", type=_positive("--exposure-s"),
                   help="exposure time [auto: the monitor's white at 0.8 of the full well through glass]")
    p.add_argument("--field-phases", type=_positive("--field-phases", int), help="d > 0: phases per axis [4]")
    p.add_argument("--precision", choices=("float32", "float64"), default="float32", help="optics FFTs [float32]")
    p.add_argument("--noise-seed", type=int, default=0, help="seed of the sensor noise [0]")
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the kernel cache")


def register(sub) -> dict:
    s = sub.add_parser("synth", help="render a scene and synthesise its captures through displays")
    s.add_argument("scene", help="a scene file (TOML) or the name of one in scenes/ (monitor, room, hdr)")
    s.add_argument("--out", type=Path, default=Path("out/synth"), help="output folder [out/synth]")
    s.add_argument("--keep-render", action="store_true", help="also write the band render (render.exr, large)")
    add_scene_arguments(s)
    add_capture_arguments(s)

    d = sub.add_parser("demo", help="the main job: the default rig through glass, T-OLED and P-OLED")
    d.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder [out/demo]")
    d.add_argument("--image", default=None, help="what the monitor shows [the scene's: builtin:astronaut]")
    d.add_argument("--sensor-px", type=_float_pair("--sensor-px"), help="sensor width,height in pixels [2048,1024]")
    d.add_argument("--quiet", action="store_true", help="no progress bar")
    return {"synth": run_synth, "demo": run_demo}


def synth_config(args):
    from udc_render.sensor import SensorConfig, SensorError
    from udc_render.synth import SynthConfig
    sensor = SensorConfig()
    if getattr(args, "sensor_config", None) is not None:
        from udc_render.fileio import read_toml
        path = args.sensor_config
        data = read_toml(path, UserError, "--sensor-config")
        try:
            sensor = SensorConfig.from_dict(data)
        except SensorError as e:
            raise UserError(f"{path}: {e}") from None
    if getattr(args, "noise_model", None):
        sensor = replace(sensor, noise=args.noise_model)
    return SynthConfig(form=getattr(args, "form", "spectral"), sensor=sensor,
                       exposure_s=getattr(args, "exposure_s", None), precision=getattr(args, "precision", "float32"),
                       field_phases=getattr(args, "field_phases", None), seed=getattr(args, "noise_seed", 0),
                       use_cache=not getattr(args, "no_cache", False))


def parse_displays(text: str, distance_mm: float | None) -> list:
    """glass first, then the listed displays (each once), with the distance override applied."""
    from udc_render.displays import load_display
    names = [t.strip() for t in text.split(",") if t.strip()]
    if not names:
        raise UserError(f"--display = {text!r}: expected glass, toled, poled or display files, comma-separated")
    out = [load_display("glass")]
    for n in names:
        d = load_display(n)
        if d.is_glass:
            continue
        out.append(d if distance_mm is None else d.with_distance(distance_mm))
    return out


def synth_and_write(scene, displays, cfg, out: Path, quiet: bool, keep_render: bool = False) -> dict:
    from udc_render.band_io import save_band_image
    from udc_render.capture_io import write_synthesis
    from udc_render.render import render_scene
    from udc_render.synth import synthesize
    t0 = time.perf_counter()
    band_image = render_scene(scene, progress=not quiet)
    t_render = time.perf_counter() - t0
    if keep_render:
        save_band_image(band_image, out / "render")
    result = synthesize(band_image, scene, displays, cfg, progress=not quiet)
    t_synth = time.perf_counter() - t0 - t_render
    summary = write_synthesis(out, result, cfg.sensor.camera)
    t_all = time.perf_counter() - t0
    print(f"{scene.source}: {band_image.bands.shape[0]} bands, frame {scene.sensor.width_px}x{scene.sensor.height_px}, "
          f"form {cfg.form}, exposure {result.meta['exposure_s'] * 1e3:.2f} ms ({result.meta['exposure_rule']})")
    print(f"{'view':>10} {'gain':>5} {'mean R':>8} {'mean Gr':>8} {'mean Gb':>8} {'mean B':>8} {'PSNR dB':>8}")
    for d in displays:
        v = summary["views"][d.name]
        m = v["mean_level"]
        print(f"{d.name:>10} {d.gain:>5g} {m['R']:>8.4f} {m['Gr']:>8.4f} {m['Gb']:>8.4f} {m['B']:>8.4f} "
              f"{v['psnr_db_vs_gt']:>8.2f}")
    print(f"render {t_render:.1f} s, captures {t_synth:.1f} s, total {t_all:.1f} s; wrote {out}/ "
          f"(gt.exr, <view>/raw.png, packed.tiff, preview.png, capture.json, side_by_side.png, summary.md)")
    return summary


def run_synth(args) -> int:
    scene = scene_from_args(args)
    displays = parse_displays(args.display, args.distance_mm)
    synth_and_write(scene, displays, synth_config(args), args.out, args.quiet, args.keep_render)
    return 0


def run_demo(args) -> int:
    ns = argparse.Namespace(scene="monitor", spp=None, noise=None, seed=None, path=None, bands_nm=None,
                            image=args.image, sensor_px=args.sensor_px, pitch_um=None)
    scene = scene_from_args(ns)
    displays = parse_displays(DEMO_DISPLAYS, None)
    synth_and_write(scene, displays, synth_config(argparse.Namespace()), args.out, args.quiet)
    return 0

