"""`udc-render synth` (one scene through one or more displays) and `udc-render demo` (the main job).

    udc-render synth SCENE --display toled[,poled,PATH] [--profile physical|paper] [--distance-mm D] --out DIR
    udc-render demo [--out DIR] [--profile physical|paper] [--channel-kernels paper|camera]

The default profile is physical.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from udc_render.cli.args import (
    add_capture_arguments,
    add_channel_kernels_argument,
    add_scene_arguments,
    capture_setup,
    float_pair,
    out_dir,
    scene_from_args,
)
from udc_render.io.band_image import save_band_image
from udc_render.io.capture import write_synthesis
from udc_render.scene import load_scene
from udc_render.scene.overrides import with_overrides

DEMO_DISPLAYS = "glass,toled,poled"


def register(sub) -> None:
    s = sub.add_parser("synth", help="render a scene and synthesise its captures through displays")
    s.set_defaults(run=run_synth)
    s.add_argument("--out", type=Path, default=Path("out/synth"), help="output folder [out/synth]")
    s.add_argument("--keep-render", action="store_true", help="also write the band render (render.exr, large)")
    add_scene_arguments(s)
    add_capture_arguments(s)

    d = sub.add_parser("demo", help="the main job: the default rig through glass, T-OLED and P-OLED")
    d.set_defaults(run=run_demo)
    d.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder [out/demo]")
    d.add_argument("--image", default=None, help="what the monitor shows [the scene's: builtin:astronaut]")
    d.add_argument("--sensor-px", type=float_pair("--sensor-px"), help="sensor width,height in pixels [2048,1024]")
    d.add_argument("--quiet", action="store_true", help="no progress bar")
    from udc_render.profiles import DEFAULT_PROFILE, PROFILES
    d.add_argument("--profile", choices=tuple(PROFILES), default=DEFAULT_PROFILE,
                   help=f"synthesis profile (udc_render/profiles.py; paper: d = 0, minutes faster on a cold "
                        f"kernel cache) [{DEFAULT_PROFILE}]")
    add_channel_kernels_argument(d)


def synth_and_write(scene, displays, cfg, out: Path, quiet: bool, keep_render: bool = False) -> dict:
    """Plan the kernels, render, synthesise, write; print the summary table."""
    from udc_render.pipeline import plan_kernels, synthesize
    from udc_render.profiles import describe
    from udc_render.render import render_scene
    t0 = time.perf_counter()
    kernels = plan_kernels(scene, displays, cfg, progress=not quiet)
    t_kernels = time.perf_counter() - t0
    band_image = render_scene(scene, progress=not quiet)
    t_render = time.perf_counter() - t0 - t_kernels
    if keep_render:
        save_band_image(band_image, out / "render")
    result = synthesize(band_image, scene, displays, cfg, progress=not quiet, kernels=kernels)
    t_synth = time.perf_counter() - t0 - t_kernels - t_render
    summary = write_synthesis(out, result, cfg.sensor.camera)
    print(f"{scene.source}: {band_image.bands.shape[0]} bands, frame {scene.sensor.width_px}x{scene.sensor.height_px}, "
          f"form {cfg.form}, exposure {result.meta['exposure_s'] * 1e3:.2f} ms ({result.meta['exposure_rule']})")
    print(describe(cfg.profile))
    layers = result.meta["depth_layers"]
    blur = ", ".join(f"{b:.2g}" for b in layers["blur_diameter_px"])
    print(f"depth: {layers['count']} layer{'s' if layers['count'] > 1 else ''} (blur diameter {blur} px; "
          f"{layers['reason']})" + (f"; {result.meta['bright_pixels']} very bright pixels convolved apart in float64"
                                    if result.meta["bright_pixels"] else ""))
    print(f"{'view':>10} {'gain':>5} {'mean R':>8} {'mean Gr':>8} {'mean Gb':>8} {'mean B':>8} {'PSNR paper':>10} "
          f"{'PSNR srgb':>10}")
    for d in displays:
        v = summary["views"][d.name]
        m = v["mean_level"]
        print(f"{d.name:>10} {d.gain:>5g} {m['R']:>8.4f} {m['Gr']:>8.4f} {m['Gb']:>8.4f} {m['B']:>8.4f} "
              f"{v['psnr_db_vs_gt']:>10.2f} {v['psnr_db_vs_gt_srgb']:>10.2f}")
    print("PSNR (dB) against the ground truth: paper = udc_render.metrics protocol 'paper' (packed RAW, linear, "
          "no white balance); srgb = protocol 'srgb' (daylight balance, sRGB, border cropped)")
    print(f"kernels {t_kernels:.1f} s, render {t_render:.1f} s, captures {t_synth:.1f} s, total "
          f"{time.perf_counter() - t0:.1f} s; wrote {out}/ (gt.exr, gt_preview.png, <view>/raw.dng, preview.png, "
          "capture.json, side_by_side.png, summary.md)")
    return summary


def run_synth(args) -> int:
    scene = scene_from_args(args)
    cfg, displays = capture_setup(args)
    synth_and_write(scene, displays, cfg, out_dir(args.out), args.quiet, args.keep_render)
    return 0


def run_demo(args) -> int:
    scene = with_overrides(load_scene("monitor"), image=args.image, sensor_px=args.sensor_px)
    cfg, displays = capture_setup(argparse.Namespace(profile=args.profile, channel_kernels=args.channel_kernels),
                                  DEMO_DISPLAYS)
    synth_and_write(scene, displays, cfg, out_dir(args.out), args.quiet)
    return 0
