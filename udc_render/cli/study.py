"""`udc-render study {psf,render,capture,far_field,realism,defocus,banding,gap,robustness,layout,layout-trained,
layout-dipole,design,held-out,channel-step,design-bands} --out DIR [--quick]`:
error-versus-run-time studies of the approximation knobs, the defocus and banding studies users run, and the
robustness of a restorer trained on one panel or on randomized panels (restore.studies.robustness)."""
from __future__ import annotations

import argparse
from functools import partial
from pathlib import Path

from udc_render.cli.args import UserError, add_display_argument, out_dir, positive
from udc_render.studies import design_bands, design_channels, design_held_out, gap

STUDIES = {
    "psf": "the PSF engine's knobs (pupil samples, precision, wavelength step, field phases, kernel size)",
    "render": "the renderer's knobs (samples per pixel, sampler, render path, bands per render)",
    "capture": "the capture synthesis's knobs (band width, per-channel form, field phases, precision)",
    "realism": "the paper's observables of its real displays beside ours, over the unfixed layout parameters",
    "defocus": "through-focus PSFs, MTFs and depth of field of glass, T-OLED and P-OLED",
    "banding": "the bands a display a distance d in front of the lens prints on a flat field",
    "gap": "the size of each effect beyond the paper's model (each on and off), and what it does to DeP",
    "far_field": "the far field's threshold and coarse factor (the light past the kernel window)",
    "layout": "a display's pixel layout scored for restorability: UPC's ring statistics in their sampling and on the "
              "exact kernels, the Wiener error under the sensor's noise, the open area (--display)",
    "layout-trained": "layouts compared by DeP and a small UNet trained online through a bank of each (--display: "
                      "comma-separated, each DISPLAY[@edge][@turned]; the first is the reference; about 20 min a "
                      "layout on 2 cores, minutes with --quick)",
    "layout-dipole": "a turned tiling's bands at d = 2 mm, UPC's statistic and the veil objective as the T-OLED's "
                     "slit moves across its cell: the cell's dipole (about 4 min; seconds with --quick)",
    "design": "the layout designer's knobs (the torch PSF's pupil samples, the optimiser's steps, … the pattern "
              "search's blur floor's rig): error against CPU time",
    "held-out": "committed designs (--designs) re-scored on 16 held-out tilings, paired with the T-OLED the simulator "
                "takes (exact; also on its own tiling) and the T-OLED on the design's squares (about 1 min a design "
                "at the veil objective, one thread)",
    "channel-step": "committed designs (--designs) scored by their objective at each channel step (one wavelength "
                    "per channel to the camera's band at 5 nm) against the simulator's T-OLED on its own tiling: "
                    "error against CPU time (about 3 min for 3 designs, one thread)",
    "design-bands": "committed designs (--designs) on 32 held-out D4 draws: their bands at d = 2 mm against the "
                    "turned T-OLED's at each design's open area, mean ± se per channel, the ratio's change on a "
                    "1 µm raster, and over the repeated T-OLED's; an arranged design over its registrations, with "
                    "their spread (about 3 min a design, one thread)",
    "robustness": "a UNet trained on the default P-OLED against one trained on randomized panels, scored on "
                  "held-out and out-of-family panels (trains both: minutes with --quick, hours without)",
}


IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr")
DESIGN_STUDIES = {"held-out": design_held_out, "channel-step": design_channels,
                  "design-bands": design_bands}  # the studies of --designs


def image_files(text: str) -> tuple[str, ...]:
    """An argument type: comma-separated image files, or one folder searched recursively for IMAGE_SUFFIXES
    (sorted); each must exist."""
    parts = [p for p in text.split(",") if p]
    if len(parts) == 1 and Path(parts[0]).is_dir():
        found = sorted(str(p) for p in Path(parts[0]).rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES)
        if not found:
            raise argparse.ArgumentTypeError(f"--images {text}: the folder holds no {'/'.join(IMAGE_SUFFIXES)} files")
        return tuple(found)
    missing = [p for p in parts if not Path(p).is_file()]
    if not parts or missing:
        raise argparse.ArgumentTypeError(f"--images {text}: no such file {missing[0] if missing else '(empty)'}; "
                                         "expected image files, comma-separated, or a folder of them")
    return tuple(parts)


def design_folders(text: str) -> tuple[Path, ...]:
    """An argument type: comma-separated folders (each checked for its design.json when the study starts)."""
    parts = [Path(p) for p in text.split(",") if p]
    if not parts:
        raise argparse.ArgumentTypeError(f"--designs {text!r}: expected `udc-render design` output folders, "
                                         "comma-separated")
    return tuple(parts)


def register(sub) -> None:
    s = sub.add_parser("study",
                       help="error-versus-run-time studies of the approximation knobs; defocus and banding studies")
    s.set_defaults(run=run)
    s.add_argument("what", choices=tuple(STUDIES),
                   help="the study: " + "; ".join(f"{name}: {what}" for name, what in STUDIES.items()))
    s.add_argument("--out", type=Path, default=Path("out/study"),
                   help="output folder: study_<what>.csv, .md, .png [out/study]")
    s.add_argument("--quick", action="store_true", help="a reduced grid (smoke run)")
    s.add_argument("--conditioned", action="store_true",
                   help="robustness only: also train the restorer conditioned on the panel's description "
                        "(wiener-unet) on the randomized panels and score it with each test panel's own")
    s.add_argument("--images", type=image_files, default=(),
                   help="gap only: image files (comma-separated, or a folder searched for .png/.jpg/.tif) scored "
                        "beside the dead leaves, e.g. DIV2K's validation photographs [none]")
    add_display_argument(s, "layout: the display whose layout is scored; layout-trained: the layouts compared, "
                         "comma-separated, each a display with @edge (its cell framed at the tile's edge) and @turned "
                         "(a random quarter-turn per tile) appended as wanted", default="toled",
                         micrograph="pixels of --micrograph-pixel-um, amplitude values")
    s.add_argument("--micrograph-pixel-um", type=positive("--micrograph-pixel-um"), default=1.0,
                   help="layout only: a micrograph's pixel size in µm [1]")
    s.add_argument("--tile-seed", type=int, default=0, help="layout only: seed of the turned tiling's D4 draws [0]")
    s.add_argument("--distance-mm", type=positive("--distance-mm"), default=2.0,
                   help="layout only: the display-to-lens distance d of the banding figures, mm [2]")
    s.add_argument("--frame", choices=("as_given", "edge"), default="as_given",
                   help="layout only: the cell as the layout frames it, or with its first open column moved to the "
                        "tile's edge, where a turn about the tile's centre moves the opening [as_given]")
    s.add_argument("--restore", choices=("dep",), default=None,
                   help="layout only: dep: also restore crops of a natural image through the layout's kernels with "
                        "DeP and report the PSNR (off by default: DeP's Wiener sampler takes about a second per "
                        "plane, 12 planes: 12-14 s more per layout) [off]")
    s.add_argument("--train-seed", type=int, default=0,
                   help="layout-trained only: the UNets' training seed (crops, order, initial weights); the scores' "
                        "images and noise draws stay the same, so two seeds measure the training's spread [0]")
    s.add_argument("--train-epochs", type=int, default=None,
                   help="layout-trained only: the UNets' epochs (the full budget's 80, the robustness recipe's 240 "
                        "take about 3x as long) [the budget's]")
    s.add_argument("--score-images", type=int, default=None,
                   help="layout-trained only: score on this many validation images, the budget's first, then more "
                        "dead leaves of the same generator (the paired differences' standard error falls as 1/√n; "
                        "training unchanged; about 1.6 s an image a layout) [the budget's: 8]")
    s.add_argument("--pitch-um", type=positive("--pitch-um"), default=None,
                   help="layout-trained only: the rig's sensor pitch in µm; the frame stays 512 × 256 px, so a finer "
                        "pitch sees a smaller field and takes larger kernels (the render margin), and DeP restores "
                        "packed planes of twice the pitch [the budget's: 6.2, --quick 12.4; the paper's sensor: 1.55]")
    s.add_argument("--pixel-um", type=positive("--pixel-um"), default=None,
                   help="held-out only: score the designs' objective at this sensor pitch in µm, its kernel window "
                        "kept in µm (12.4: the packed planes DeP restores in study layout-trained) [the first "
                        "design's: 3.1]")
    s.add_argument("--packed", action="store_true",
                   help="held-out only: score the objective on the packed planes of --pixel-um's pixels, the kernel "
                        "DeP deconvolves with (--pixel-um 6.2 --packed: study layout-trained's DeP) [as saved]")
    s.add_argument("--designs", type=design_folders, default=(),
                   help="held-out, channel-step and design-bands only: `udc-render design` output folders, "
                        "comma-separated [none]")
    s.add_argument("--restore-crops", choices=("astronaut", "photos"), default="astronaut",
                   help="layout only, with --restore: the natural crops restored: astronaut, its face and suit (2 "
                        "crops); photos, 8 crops of astronaut, chelsea, coffee and rocket (4x the time) [astronaut]")


def run(args) -> int:
    if args.images and args.what != "gap":
        raise UserError(f"--images {','.join(map(str, args.images))}: only `study gap` takes images")
    if args.what not in ("layout", "layout-trained") and args.display != "toled":
        raise UserError(f"--display {args.display}: only `study layout` and `study layout-trained` take a display")
    if args.what != "layout" and args.frame != "as_given":
        raise UserError(f"--frame {args.frame}: only `study layout` takes a framing")
    if args.what != "layout" and args.distance_mm != 2.0:
        raise UserError(f"--distance-mm {args.distance_mm}: only `study layout` takes a distance")
    if args.train_seed != 0 and args.what != "layout-trained":
        raise UserError(f"--train-seed {args.train_seed}: only `study layout-trained` trains")
    if args.train_epochs is not None and (args.what != "layout-trained" or args.train_epochs < 1):
        raise UserError(f"--train-epochs {args.train_epochs}: expected a count ≥ 1, and only `study layout-trained` "
                        "trains")
    if args.score_images is not None and args.what != "layout-trained":
        raise UserError(f"--score-images {args.score_images}: only `study layout-trained` scores validation images")
    if args.pitch_um is not None and args.what != "layout-trained":
        raise UserError(f"--pitch-um {args.pitch_um:g}: only `study layout-trained` takes a sensor pitch")
    if args.pixel_um is not None and args.what != "held-out":
        raise UserError(f"--pixel-um {args.pixel_um:g}: only `study held-out` takes the objective's pitch")
    if args.packed and args.what != "held-out":
        raise UserError("--packed: only `study held-out` scores the objective on packed planes")
    if args.restore and args.what != "layout":
        raise UserError(f"--restore {args.restore}: only `study layout` restores")
    if args.restore_crops != "astronaut" and not args.restore:
        raise UserError(f"--restore-crops {args.restore_crops}: only with --restore dep")
    if args.conditioned and args.what != "robustness":
        raise UserError("--conditioned: only `study robustness` trains a conditioned restorer")
    if bool(args.designs) != (args.what in DESIGN_STUDIES):
        raise UserError("--designs: `study held-out`, `study channel-step` and `study design-bands` take it, and "
                        "only they (design folders, comma-separated)")
    if args.what in DESIGN_STUDIES:
        return _designs(args, DESIGN_STUDIES[args.what])
    if args.what == "layout":
        return _layout(args)
    if args.what == "layout-trained":
        return _layout_trained(args)
    out = out_dir(args.out)
    if args.what == "gap":
        gap.run_study(out, quick=args.quick, images=args.images)
        print(f"wrote {out}/study_gap.csv, study_gap.md, study_gap.png")
        return 0
    if args.what == "realism":
        from udc_render.studies.realism import run_study
    elif args.what == "defocus":
        from udc_render.studies.defocus import run_study
    elif args.what == "banding":
        from udc_render.studies.banding import run_study
    elif args.what == "capture":
        from udc_render.studies.capture_knobs import run_study
    elif args.what == "far_field":
        from udc_render.studies.capture_far import run_study
    elif args.what == "design":
        from udc_render.studies.design_knobs import run_study
    elif args.what == "layout-dipole":
        from udc_render.studies.layout_dipole import run_study
    elif args.what == "robustness":
        from restore.studies.robustness import run_study
        run_study = partial(run_study, conditioned=args.conditioned)
    elif args.what == "render":
        from udc_render.studies.render_knobs import run_study
    else:
        from udc_render.studies.psf_knobs import run_study
    run_study(out, quick=args.quick)
    name = f"study_{args.what.replace('-', '_')}"
    print(f"wrote {out}/{name}.csv, {name}.md, {name}.png")
    return 0


def _designs(args, study) -> int:
    """`study held-out`, `channel-step` and `design-bands`: every folder read before the output folder is made."""
    study.check(list(args.designs))
    out = out_dir(args.out)
    extra = {} if args.pixel_um is None else {"pixel_um": args.pixel_um}
    if args.packed:
        extra["packed"] = True
    study.run_study(out, list(args.designs), quick=args.quick, **extra)
    name = study.NAME
    print(f"wrote {out}/{name}.json, {name}.csv, {name}.md, {name}.png")
    return 0


def _layout(args) -> int:
    """`study layout`: the display loaded and the output folder checked first, then the scores written."""
    from udc_render.optics.displays import load_display
    from udc_render.studies.layout import layout_cell, score_layout
    from udc_render.studies.layout_report import write
    display = load_display(args.display, pixel_um=args.micrograph_pixel_um)
    if display.layout is None:
        raise UserError(f"--display {args.display}: glass has no pixel layout to score")
    layout_cell(display.layout)  # a tile the study cannot take is refused before the folder is made
    out = out_dir(args.out)
    scores = score_layout(display.name, display.layout, args.tile_seed, args.frame, args.quick,
                          distance_mm=args.distance_mm, restore=args.restore,
                          crops=args.restore_crops)
    names = write(scores, out)
    print(f"wrote {out}/" + f", {out}/".join(names))
    return 0


def _layout_trained(args) -> int:
    """`study layout-trained`: the folder checked, then the study (which loads every layout before any work: a bad
    entry is refused in one line)."""
    from restore.studies.layout_trained import NAME, check_score_images, run_study
    check_score_images(args.score_images)
    out = out_dir(args.out)
    run_study(out, [p for p in args.display.split(",") if p], quick=args.quick, train_seed=args.train_seed,
              epochs=args.train_epochs, pitch_um=args.pitch_um, score_images=args.score_images)
    print(f"wrote {out}/{NAME}.md, {NAME}.json, {NAME}.png, {NAME}_restored.png")
    return 0
