"""`udc-render calibrate --display D`: the paper's calibration protocols (γ, noise, PSF, MTF) on the
virtual rig, recovered against the truth; exit 1 when a check misses its tolerance."""
from __future__ import annotations

import argparse
from pathlib import Path

from udc_render.cli.args import (
    UserError,
    add_display_argument,
    add_far_field_arguments,
    add_sensor_arguments,
    out_dir,
    synth_config,
)
from udc_render.io.files import save_json


def register(sub) -> None:
    c = sub.add_parser("calibrate", help="run the paper's calibration protocols (γ, noise, PSF, MTF) on the "
                                         "virtual rig; exit 1 if a check misses its tolerance")
    add_display_argument(c, "the display to calibrate (not glass: the reference; d = 0 only)", required=True)
    c.add_argument("--out", type=Path, default=Path("out/calibrate"), help="output folder [out/calibrate]")
    c.add_argument("--quick", action="store_true", help="reduced rig (512×128 px, 161-px kernels, 15 bands): smoke run")
    add_sensor_arguments(c)
    add_far_field_arguments(c)
    c.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from udc_render.calibration.protocols import calibrate, format_table, plot_all
    from udc_render.optics.displays import load_display
    display = load_display(args.display)
    if display.is_glass:
        raise UserError(f"--display = {args.display!r}: expected toled, poled, a display file (.toml) or a "
                        "micrograph image; glass is the reference")
    if display.distance_mm > 0:
        raise UserError(f"--display = {args.display!r}: distance_mm = {display.distance_mm:g}: calibration "
                        "supports the principal-plane model (d = 0) only")
    out_dir(args.out)
    result = calibrate(display, args.out, args.quick, synth_config(args))
    save_json(args.out / "calibration.json", result)
    plots = plot_all(result, args.out)
    r = result["rig"]
    print(f"calibration of {display.name} ({result['mode']} rig: {r['sensor_px'][0]}x{r['sensor_px'][1]} px at "
          f"1.55 um, {r['kernel_px']}-px kernels, bands {r['bands_nm']} nm, noise {r['noise']}, gain {r['gain']:g}); "
          f"γ square {result['gamma']['square_px']:.0f} px, region {result['gamma']['region_px']} px")
    print(format_table(result["checks"]))
    failed = [c["quantity"] for c in result["checks"] if not c["pass"]]
    print(f"{result['seconds']['total']:.1f} s; wrote {args.out}/calibration.json, " + ", ".join(plots))
    if failed:
        print(f"FAILED: {len(failed)} check(s) missed their tolerance: {', '.join(failed)}")
        return 1
    print("all checks passed")
    return 0
