"""`udc-render design --out DIR`: search a binary display cell for restorability (udc_render.design.optimise) and
write it as a display file every command takes; the same command resumes an interrupted run."""
from __future__ import annotations

from pathlib import Path

from udc_render.cli.args import number, out_dir, positive
from udc_render.design.options import (
    ARRANGEMENT_TILES,
    CHANNEL_STEP_NM,
    CHANNELS,
    CROP_PX,
    DEFAULT_FEATURE_UM,
    INITS,
    LITHOGRAPHY_UM,
    OBJECTIVES,
    OPTICS,
    RIG_PIXEL_UM,
    SYMMETRIES,
    TILINGS,
)


def register(sub) -> None:
    p = sub.add_parser("design", help="optimise a display pixel cell for restorability; writes a display file")
    p.set_defaults(run=run)
    p.add_argument("--cell-um", type=positive("--cell-um"), default=168.0,
                   help="the cell's side in µm, a multiple of --feature-um [168: UPC's cell]")
    p.add_argument("--feature-um", type=positive("--feature-um"), default=DEFAULT_FEATURE_UM,
                   help=f"the minimum feature size in µm: the design's squares; ≥ {LITHOGRAPHY_UM} (LTPS "
                        f"lithography) [{DEFAULT_FEATURE_UM:g}: UPC's pupil sampling]")
    p.add_argument("--open-area", type=float, default=0.20, help="the open area, a fraction in (0, 1) [0.20]")
    p.add_argument("--tiling", choices=TILINGS, default="turned",
                   help="repeated: the cell tiled as it is; turned: each tile turned and mirrored at random "
                        "(one fixed D4 draw for the search, another held out for the scores); arranged: a K × K "
                        "pattern of the tile's D4 elements (--arrangement), repeated, searched with the cell: a "
                        "periodic display (supercell.png) [turned]")
    p.add_argument("--arrangement", type=positive("--arrangement", int), default=ARRANGEMENT_TILES,
                   help=f"--tiling arranged: K, the arrangement's tiles a side (period K × --cell-um) "
                        f"[{ARRANGEMENT_TILES}]")
    p.add_argument("--objective", choices=OBJECTIVES, default="wiener",
                   help="wiener: the Wiener estimate's expected error under the sensor's noise; upc: UPC's "
                        "Wiener-response term (lowest 30 %% of |H|²/(|H|² + 0.015)); crop: wiener on a --crop-px crop, "
                        "the kernel's light reaching past it interference; rings: UPC's mean ring minima of the MTF, "
                        "their figure of merit (−mean log over the channels) [wiener]")
    p.add_argument("--optics", choices=OPTICS, default="rig",
                   help="rig: the paper's rig, the engine's exact kernels; upc: UPC's sampling (610 / 530 / 470 nm, "
                        "f = 10 mm, their 168 µm cell of 8 µm), with --objective upc or rings [rig]")
    p.add_argument("--far-veil", action="store_true",
                   help="wiener and crop: add the squared bias ((1 − f) / f)² μ² of the light past the kernel's window "
                        "(share f inside), the veil a restorer with the window's kernel leaves (plain DeP)")
    p.add_argument("--upc-floor", type=positive("--upc-floor"), default=None,
                   help="wiener and crop: hold UPC's mean ring minima (their sampling) at this ratio to the T-OLED's "
                        "in --floor-channels, by a hinge on the objective (udc_render.design.floor) [off]")
    p.add_argument("--floor-channels", default="G",
                   help=f"the channels --upc-floor holds, some of {CHANNELS} [G: UPC's headline ratio, 1.26 ×]")
    p.add_argument("--floor-uncropped", action="store_true",
                   help="--upc-floor holds the statistic times the share of the light inside UPC's crop, which their "
                        "normalisation after the crop cannot inflate")
    p.add_argument("--banding-ceiling", type=positive("--banding-ceiling"), default=None,
                   help="wiener and crop: hold the bands at d = 2 mm (the relative sd of the power over the paper "
                        "sensor's mask shifts) at most this ratio to the T-OLED's in R, G and B, by a hinge on the "
                        "objective (udc_render.design.bands) [off]")
    p.add_argument("--channels", default=CHANNELS,
                   help=f"the channels the objective averages, some of {CHANNELS} (e.g. B) [{CHANNELS}]")
    p.add_argument("--crop-px", type=positive("--crop-px", int), default=CROP_PX,
                   help=f"--objective crop: the restorer's crop in px [{CROP_PX}: study layout --restore dep's]")
    p.add_argument("--contrast", type=positive("--contrast"), default=None,
                   help="the scene's RMS contrast in the wiener and crop objectives [0.3 with wiener; 1.0 with crop: "
                        "its designs restore best by DeP at 1.0 of 0.3, 0.5, 1.0 (docs/guides/design.md)]")
    p.add_argument("--mean-level", type=positive("--mean-level"), default=None,
                   help="the scene's mean in the wiener and crop objectives, a fraction of the glass capture's full "
                        "well [0.5; study layout-trained's scenes: 0.41 with --contrast 0.51 (docs/guides/design.md)]")
    p.add_argument("--init", default="scatter",
                   help=f"the search's start, one of {', '.join(INITS)} or a cell PNG: scatter: a random scatter; "
                        "toled: the preset T-OLED on the squares, its slit at the tile's edge; PATH: a former design's "
                        "cell.png (0 / 255, the same squares and open area) [scatter]")
    p.add_argument("--symmetry", choices=SYMMETRIES, default="none",
                   help="none: a free cell; c2: a point-symmetric cell (equal to itself turned by 180°), whose "
                        "centroid sits at the tile's centre, so a turned tiling has no dipole bands "
                        "(udc_render.design.symmetry); the swaps and kicks move its square pairs [none]")
    p.add_argument("--steps", type=positive("--steps", int), default=150,
                   help="at most this many swaps of an open and an opaque square; the search stops earlier at a "
                        "local optimum [150]")
    p.add_argument("--candidates", type=positive("--candidates", int), default=40,
                   help="swaps scored exactly per step, the most promising by the gradient first [40]")
    p.add_argument("--kicks", type=number("--kicks", int, 0, lo_open=False), default=0,
                   help="iterated local search: at each local optimum, kick the best cell by --kick-swaps random "
                        "swaps and descend again, this many times (each descent counts toward --steps) [0]")
    p.add_argument("--kick-swaps", type=positive("--kick-swaps", int), default=4,
                   help="random swaps of one kick [4]")
    p.add_argument("--search-tilings", type=positive("--search-tilings", int), default=1,
                   help="--tiling turned: the search's objective is the mean over this many fixed D4 draws (one "
                        "draw's objective is fitted to that draw; study design part g) [1]")
    p.add_argument("--channel-step", type=number("--channel-step", float, 0, lo_open=False), default=None,
                   help="--optics rig: ≥ 1 sums each channel over the camera's band sampled at this step in nm, "
                        "weighted by its sensitivity × D65 (the kernels `study layout-trained`'s bank takes); 0: one "
                        "wavelength per channel, 640 / 520 / 450 nm (the paper's recipe; the designs committed before "
                        f"this option) [{CHANNEL_STEP_NM:g} with --optics rig: study channel-step; 0 with upc]")
    p.add_argument("--scatters", type=positive("--scatters", int), default=20,
                   help="random scatters at the same open area scored beside the design, the baseline [20]")
    p.add_argument("--held-out-tilings", type=number("--held-out-tilings", int, 0, lo_open=False), default=16,
                   help="wiener and crop, turned: the design and the T-OLEDs scored on this many more held-out "
                        "tilings, paired (design.json's held_out; 0: none) [16]")
    p.add_argument("--seed", type=int, default=0, help="seed of the initial cell, the scatters and the tilings [0]")
    p.add_argument("--pupil-samples", type=positive("--pupil-samples", int), default=512,
                   help="pupil samples across the aperture of the objective's kernels [512]")
    p.add_argument("--kernel-px", type=positive("--kernel-px", int), default=127,
                   help="the objective's kernel size in --pixel-um pixels, odd [127]")
    p.add_argument("--pixel-um", type=positive("--pixel-um"), default=RIG_PIXEL_UM,
                   help="--optics rig: the objective's sensor pitch in µm, the pitch the restorer works at (a Bayer "
                        "camera's packed planes: twice its pixel) [3.1: the paper's rig, its 1.55 µm sensor's packed "
                        "planes; study layout-trained's DeP: 12.4]")
    p.add_argument("--packed", action="store_true",
                   help="--objective wiener or crop: score the kernels on the packed planes DeP restores (2 × 2 "
                        "pixels of --pixel-um weighted ½, 1, ½: restore.known.packed_from_sensor; --crop-px in "
                        "packed pixels) [off: the kernels at --pixel-um]")
    p.add_argument("--device", default="cpu", help="torch device, e.g. cuda [cpu]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--out", type=Path, default=Path("out/design"),
                   help="output folder: design.toml, cell.png, design.json, design_loss.png [out/design]")


def _channel_step(args) -> float:
    """--channel-step as given, else CHANNEL_STEP_NM in the rig's optics and 0 in UPC's (their one wavelength per
    channel)."""
    if args.channel_step is not None:
        return args.channel_step
    return CHANNEL_STEP_NM if args.optics == "rig" else 0.0


def run(args) -> int:
    from udc_render.design.config import DesignConfig
    from udc_render.design.job import run_design
    config = DesignConfig(args.cell_um, args.feature_um, args.open_area, args.tiling, args.objective, args.steps,
                          args.candidates, args.seed, args.pupil_samples, args.kernel_px, args.scatters, args.crop_px,
                          args.contrast, args.init, args.optics, args.channels, args.far_veil,
                          args.upc_floor, args.floor_channels, args.floor_uncropped, args.banding_ceiling,
                          args.kicks, args.kick_swaps, args.search_tilings, _channel_step(args),
                          mean_level=args.mean_level, symmetry=args.symmetry, pixel_um=args.pixel_um,
                          packed=args.packed, arrangement=args.arrangement)
    out = out_dir(args.out)
    doc = run_design(config, out, args.device, args.quiet, held_out_tilings=args.held_out_tilings)
    f, b = doc["final"], doc["scatters"]
    unit = " dB" if b["key"] == "psnr_db" else ""
    print(f"open area {f['open_area']:.4f} ({doc['open_squares']} of {doc['cell_px']}² squares), {b['key']} "
          f"{f[b['key']]:.4g}{unit} after {doc['steps_done']} steps{' (converged)' if doc['converged'] else ''}; "
          f"{b['n']} random scatters {b['mean']:.4g} ± {b['std']:.2g}{unit}, the best {b['best']:.4g}{unit}, margin "
          f"{b['margin']:.3g}{unit}; wrote {out}/design.toml, cell.png, design.json, design_loss.png")
    if doc["held_out"]:
        v = doc["held_out"]["d4"]["vs"]["design"]["toled_preset"]
        print(f"on {doc['held_out']['n']} held-out tilings, the design − the preset T-OLED: {v['mean']:+.3f} ± "
              f"{v['se']:.3f} dB (se; leads on {v['leads']})")
    return 0
