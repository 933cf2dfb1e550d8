"""`udc-render fit`: the simulator fitted to a user's own panel from its measurements (udc_render/fit).

    udc-render fit --psf IMAGE [IMAGE ...] --wavelength-nm 650 --pixel-um 1.55 \
        [--black-level DN] [--saturation DN] [--focal-length-mm 6 --f-number 1.8] \
        [--family auto|toled|poled|micrograph [--micrograph FILE --micrograph-pixel-um P]] \
        [--flat IMAGE] [--white GLASS DISPLAY] [--noise-frames DIR] --out DIR

Writes display.toml (for --display of psf, synth, dataset), sensor.toml (with --noise-frames; for
--sensor-config), fit.json, fit.md and fit.png. What cannot be fitted is refused in one line (exit 2).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from tqdm import tqdm

from udc_render.cli.args import UserError, non_negative, odd_size, out_dir, positive

FAMILIES = ("auto", "toled", "poled", "micrograph")


def _bands(text):
    try:
        lo, hi, step = (float(v) for v in text.split(":"))
    except ValueError:
        lo = hi = step = float("nan")
    if not (300 <= lo < hi <= 1100 and 0 < step <= hi - lo):
        raise argparse.ArgumentTypeError(f"--white-bands-nm must look like LOW:HIGH:STEP (e.g. 400:700:10), got "
                                         f"'{text}'")
    return lo, hi, step


def register(sub) -> None:
    p = sub.add_parser("fit", help="fit a display file (and a sensor file) to a user's measurements: a laser PSF, "
                                   "a flat field, a white-square pair, repeated frames")
    p.set_defaults(run=run)
    p.add_argument("--psf", nargs="+", required=True, type=Path, metavar="IMAGE",
                   help="one or more exposures of a collimated laser through the display (PNG/TIFF of 8 or 16 bits, "
                        "grey or colour, or a raw DNG of any compression LibRaw reads); several are merged into one "
                        "HDR PSF, saturated pixels masked")
    p.add_argument("--wavelength-nm", type=positive("--wavelength-nm"), default=650.0,
                   help="the laser's wavelength [650, the paper's]")
    p.add_argument("--pixel-um", type=positive("--pixel-um"), default=1.55, help="the sensor's pixel pitch [1.55]")
    p.add_argument("--black-level", type=non_negative("--black-level"),
                   help="one black level in DN for every pixel [a DNG's, per CFA site, row and column (BlackLevel, "
                        "BlackLevelDeltaH/V), else 0]")
    p.add_argument("--saturation", type=positive("--saturation"),
                   help="pixels at or above this DN are clipped and masked [a DNG's WhiteLevel (after its "
                        "LinearizationTable), else the integer type's largest value]")
    p.add_argument("--focal-length-mm", type=positive("--focal-length-mm"), default=6.0,
                   help="the lens's focal length: the orders sit m λ f / p apart on the sensor [6, the paper's rig]")
    p.add_argument("--f-number", type=positive("--f-number"), default=1.8, help="the lens's f-number [1.8]")
    p.add_argument("--family", choices=FAMILIES, default="auto",
                   help="the layout to fit: toled: a stripe cell (pitch, open fraction, slit height); poled: a "
                        "pentile cell (pitch, open fraction, small-to-large ratio); micrograph: the tile of "
                        "--micrograph (its scale and orientation only); auto: every family whose lattice matches the "
                        "orders, the lowest residual wins [auto]")
    p.add_argument("--micrograph", type=Path, help="a transmission image of one display tile (PNG/TIFF/EXR, amplitude "
                                                   "values) for --family micrograph (and auto)")
    p.add_argument("--micrograph-pixel-um", type=positive("--micrograph-pixel-um"), default=1.0,
                   help="the micrograph's nominal pixel size; the fit reports its scale against it [1.0]")
    p.add_argument("--flat", type=Path, metavar="IMAGE",
                   help="a flat field through the display at its real distance: its bands' period gives d")
    p.add_argument("--white", nargs=2, type=Path, metavar=("GLASS", "DISPLAY"),
                   help="the white square through glass and through the display (RAW or linear images): γ per "
                        "RGGB channel, the display's transmission fitted to it")
    p.add_argument("--white-gain", type=positive("--white-gain"), default=1.0,
                   help="the display capture's sensor gain over the glass capture's; written as the display's gain [1]")
    p.add_argument("--white-bands-nm", type=_bands, default=(400.0, 700.0, 10.0), metavar="LOW:HIGH:STEP",
                   help="the bands of the transmission fit's kernels [400:700:10, the presets']")
    p.add_argument("--noise-frames", type=Path, metavar="DIR",
                   help="a folder of repeated RAW frames of a static scene (sub-folders: more series): λ_read and "
                        "λ_shot per channel, written as sensor.toml")
    p.add_argument("--camera", default="Nikon 5100 (NPL)",
                   help="the camera's spectral sensitivities ('Nikon 5100 (NPL)', 'Sigma SDMerill (NPL)' or a CSV): "
                        "a CFA's sites at the laser line, the white's channels [Nikon 5100 (NPL)]")
    p.add_argument("--window-px", type=odd_size("--window-px"), default=511,
                   help="the side of the square fitted around the spot, odd [511]")
    p.add_argument("--name", default="fitted", help="the display's name in display.toml [fitted]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--out", type=Path, required=True, help="output folder")


def run(args) -> int:
    from udc_render.fit import FitSpec, run_fit
    if args.family == "micrograph" and args.micrograph is None:
        raise UserError("--family micrograph: expected --micrograph FILE (the tile's transmission image)")
    if any(c in args.name for c in "/\\ ") or not args.name:
        raise UserError(f"--name {args.name!r}: expected a non-empty name without spaces or slashes")
    out = out_dir(args.out)
    spec = FitSpec(psf=tuple(str(p) for p in args.psf), wavelength_nm=args.wavelength_nm, pixel_um=args.pixel_um,
                   black_dn=args.black_level, saturation_dn=args.saturation, focal_length_mm=args.focal_length_mm,
                   f_number=args.f_number, family=args.family,
                   micrograph=None if args.micrograph is None else str(args.micrograph),
                   micrograph_pixel_um=args.micrograph_pixel_um, flat=None if args.flat is None else str(args.flat),
                   white=None if args.white is None else tuple(str(p) for p in args.white), white_gain=args.white_gain,
                   white_bands_nm=args.white_bands_nm,
                   noise_frames=None if args.noise_frames is None else str(args.noise_frames), camera=args.camera,
                   window_px=args.window_px, name=args.name)
    with tqdm(desc="fit", unit="stage", disable=True if args.quiet else None) as bar:
        def say(text):
            bar.set_postfix_str(text)
            bar.update(1)
        result = run_fit(spec, out, say)
    p = result["psf"]
    lat = p["lattice"]
    print(f"{p['family']}: " + ", ".join(f"{k} {v['value']:.5g} ± {v['sigma']:.2g}" for k, v in p["parameters"].items())
          + f"; pitch {lat['pitch_x_um']['value']:.5g} ± {lat['pitch_x_um']['sigma']:.2g} × "
          f"{lat['pitch_y_um']['value']:.5g} ± {lat['pitch_y_um']['sigma']:.2g} um, rotation "
          f"{lat['rotation_deg']['value']:.3f} ± {lat['rotation_deg']['sigma']:.2g} deg; χ²/dof {p['chi2_red']:.3g}")
    if "flat" in result:
        d = result["flat"]["distance_mm"]
        print(f"distance {d['value']:.4g} ± {d['sigma']:.2g} mm")
    if "white" in result:
        print("γ R/Gr/Gb/B " + "/".join(f"{g['value']:.4f}" for g in result["white"]["gamma"])
              + f"; T(λ) {result['white']['transmission']['type']}")
    s = result["synthesis_check"]
    print(f"synthesis with display.toml: orders' powers relative L2 {s['orders_relative_l2']:.4f} (noise "
          f"{s['orders_noise_l2']:.4f}), image {s['image_relative_l2']:.4f} (noise {s['image_noise_l2']:.4f})")
    print(f"wrote {out}/" + f", {out}/".join(result["written"]))
    return 0
