"""`udc-render design-pattern --cell CELL.png --out DIR`: arrange a fixed cell's D4 elements in a K × K period that
bands least at d = 2 mm with UPC's ratio held (udc_render.design.pattern); writes a display file every command
takes; the same command resumes an interrupted run."""
from __future__ import annotations

from pathlib import Path

from udc_render.cli.args import out_dir, positive
from udc_render.design.options import CHANNELS

# UPC's published gain is 1.26 × (their L2 cell over their turned T-OLED, G); one random tiling's ratio varies by
# about 1 % (sd, design.json's upc.turned.draws), so the default floor asks for one sd above it
PATTERN_FLOOR = 1.27
PATTERN_TILES = 16  # random 16 × 16 patterns of veil130's cell reach its turned UPC ratio (1.26 of 1.28, G)


def register(sub) -> None:
    p = sub.add_parser("design-pattern", help="arrange a designed cell's turned tiles in a long period that bands "
                                              "least with UPC's ratio held; writes a display file")
    p.set_defaults(run=run)
    p.add_argument("--cell", required=True, help="a design's cell.png: 21 × 21 of 0 and 255 (8 µm squares)")
    p.add_argument("--arrangement", type=positive("--arrangement", int), default=PATTERN_TILES,
                   help=f"K, the period's tiles a side, 2 … 16 [{PATTERN_TILES}]")
    p.add_argument("--upc-floor", type=positive("--upc-floor"), default=PATTERN_FLOOR,
                   help=f"hold UPC's mean ring minima (their mode) at this ratio to the turned T-OLED's in "
                        f"--floor-channels [{PATTERN_FLOOR}]")
    p.add_argument("--floor-channels", default="G", help=f"some of {CHANNELS} [G: UPC's headline ratio]")
    p.add_argument("--sweeps", type=positive("--sweeps", int), default=8,
                   help="at most this many sweeps over the tiles; the search stops earlier when one keeps nothing [8]")
    p.add_argument("--blur-floor", action="store_true",
                   help="also hold the blur error of the exact kernel (the paper's rig, G) at the cell turned's, or "
                        "below it let it not fall [off]")
    p.add_argument("--blur-floor-draws", type=positive("--blur-floor-draws", int), default=1,
                   help="with --blur-floor: the floor is the mean over this many D4 draws of the cell turned [1]")
    p.add_argument("--start", type=Path, default=None,
                   help="start from the arrangement another design-pattern run of this cell and K ended at (its "
                        "folder), e.g. to search it on under other floors [the best of 12 random arrangements]")
    p.add_argument("--seed", type=int, default=0, help="seed of the start and of the sweeps' orders [0]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--out", type=Path, default=Path("out/design_pattern"),
                   help="output folder: design.toml, supercell.png, pattern.json, pattern_bands.png "
                        "[out/design_pattern]")


def run(args) -> int:
    from udc_render.design.pattern import check_settings
    from udc_render.design.pattern_job import read_pattern_cell, read_start, run_pattern
    from udc_render.design.torch_psf import DesignError
    cell = read_pattern_cell(args.cell)
    check_settings(args.arrangement, args.floor_channels)
    if args.blur_floor_draws > 1 and not args.blur_floor:
        raise DesignError(f"--blur-floor-draws {args.blur_floor_draws}: a floor's draws need --blur-floor")
    start = None if args.start is None else (str(args.start), read_start(args.start, cell, args.arrangement))
    out = out_dir(args.out)
    doc = run_pattern(args.cell, cell, args.arrangement, args.upc_floor, args.floor_channels, args.sweeps, args.seed,
                      out, args.quiet, args.blur_floor, args.blur_floor_draws, start)
    b, u = doc["banding"], doc["upc"]["arranged"]
    n = len(doc["history"])
    print(f"after {n} sweep{'s' if n != 1 else ''}: bands {' / '.join(f'{v:.3f}' for v in b['mean'])} × the repeated "
          f"T-OLED's (R / G / B, 2 µm raster), UPC's ratio {' / '.join(f'{v:.3f}' for v in u['ratio'])} × the "
          f"turned T-OLED's; wrote {out}/design.toml, supercell.png, pattern.json, pattern_bands.png")
    return 0
