"""`udc-render dataset`: many capture pairs (udc_render.dataset has the layout and the guarantees).

    udc-render dataset --images DIR | --builtin --display glass,toled,poled --count N --out DIR
                       [--profile physical|paper] [--split 200,40,60] [--shard-size 1000]
                       [--workers N | --scheduler ADDRESS] [--previews] [--side-by-side]
    udc-render dataset --scene room|hdr|FILE.toml --display toled --count N --out DIR
                       [--pose-jitter-m 0.15,0.1,0.15] [--target-jitter-m 0.3,0.2,0] [...]
    udc-render dataset --builtin --randomize default|FILE.toml --panels N [--randomize-seed S] --count N ...

A monitor scene (the default) needs --images or --builtin (item i shows image i); a 3D scene (room, hdr,
a Mitsuba XML scene) takes neither: item i is a view of the scene from a jittered camera pose.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

from udc_render.cli.args import (
    UserError,
    add_capture_arguments,
    add_scene_arguments,
    capture_setup,
    out_dir,
    positive,
    scene_from_args,
)
from udc_render.dataset.plan import DEFAULT_ORIGIN_JITTER_M, DEFAULT_TARGET_JITTER_M
from udc_render.scene import Monitor


def _split(text: str) -> tuple[int, int, int]:
    try:
        counts = tuple(int(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--split must be TRAIN,VAL,TEST counts, got '{text}'") from None
    if len(counts) != 3 or min(counts) < 0 or sum(counts) < 1:
        raise argparse.ArgumentTypeError(f"--split must be three counts ≥ 0 (TRAIN,VAL,TEST) summing to ≥ 1, "
                                         f"got '{text}'")
    return counts


def _jitter(name: str):
    def parse(text: str) -> tuple[float, float, float]:
        try:
            v = tuple(float(t) for t in text.split(","))
        except ValueError:
            v = ()
        if len(v) != 3 or not all(math.isfinite(x) and x >= 0 for x in v):
            raise argparse.ArgumentTypeError(f"{name} must be three distances ≥ 0 in metres X,Y,Z, got '{text}'")
        return v
    return parse


def _xyz_text(v) -> str:
    return ",".join(f"{x:g}" for x in v)


def register(sub) -> None:
    p = sub.add_parser("dataset", help="many capture pairs: one monitor image or one view of a 3D scene per item "
                                       "through every display (sharded, resumable, parallel)")
    p.set_defaults(run=run, path=None, image=None)
    src = p.add_mutually_exclusive_group()
    src.add_argument("--images", type=Path, help="a monitor scene: a folder of images (searched recursively, sorted "
                                                 "by path); one of --images, --builtin is required for a monitor scene")
    src.add_argument("--builtin", action="store_true",
                     help="a monitor scene: scikit-image's samples and the procedural charts, then dead leaves in "
                          "the colours of those photographs (pattern:dead_leaves_colour), a new seed per item")
    p.add_argument("--pose-jitter-m", type=_jitter("--pose-jitter-m"),
                   help="a 3D scene: item i > 0 moves the camera origin by up to ± X,Y,Z metres (uniform, per world "
                        f"axis; item 0 is the scene's own pose) [{_xyz_text(DEFAULT_ORIGIN_JITTER_M)}]")
    p.add_argument("--target-jitter-m", type=_jitter("--target-jitter-m"),
                   help="a 3D scene: item i > 0 moves the camera target by up to ± X,Y,Z metres; the focus distance "
                        f"stays the scene's own pose's [{_xyz_text(DEFAULT_TARGET_JITTER_M)}]")
    p.add_argument("--count", type=positive("--count", int), help="number of items [the sum of --split]")
    p.add_argument("--split", type=_split, help="TRAIN,VAL,TEST item counts, assigned in id order [all train]")
    p.add_argument("--out", type=Path, default=Path("out/dataset"), help="output folder [out/dataset]")
    p.add_argument("--shard-size", type=positive("--shard-size", int), default=1000,
                   help="items per shard folder [1000]")
    run_on = p.add_mutually_exclusive_group()
    run_on.add_argument("--workers", type=positive("--workers", int), default=1,
                        help="1: in this process; N > 1: a local pool of N processes [1]")
    run_on.add_argument("--scheduler", help="address of a Dask distributed scheduler (tcp://HOST:PORT) to run items on")
    p.add_argument("--previews", action="store_true",
                   help="also write each item's sRGB previews (gt_preview.png, <display>/preview.png) [off]")
    p.add_argument("--side-by-side", action="store_true",
                   help="also write each item's side_by_side.png (implies --previews)")
    p.add_argument("--randomize", metavar="default|FILE.toml",
                   help="randomized panels, sensors and exposures (docs/guides/randomize.md): 'default', the "
                        "documented ranges, or a TOML file of distributions read over them; the items' display is "
                        "then the drawn panel, in <item>/random/ (leave --display out)")
    p.add_argument("--panels", type=positive("--panels", int),
                   help="with --randomize: the number of panels drawn once per job (their kernels planned once); "
                        "each item sees one of them [8]")
    p.add_argument("--randomize-seed", type=int, default=0, help="with --randomize: the seed of every draw [0]")
    add_scene_arguments(p, scene_option=True)
    add_capture_arguments(p)
    p.set_defaults(display=None)  # None: toled, or the drawn panel with --randomize


def split_counts(count: int | None, split: tuple[int, int, int] | None) -> tuple[int, int, int]:
    """(train, val, test) from --count and --split."""
    if split is None:
        if count is None:
            raise UserError("--count N is required (or --split TRAIN,VAL,TEST)")
        return count, 0, 0
    if count is not None and count != sum(split):
        raise UserError(f"--split {','.join(map(str, split))} sums to {sum(split)}, but --count is {count}")
    return split


DEFAULT_PANELS = 8


def randomization(args):
    """The job's Randomization (None without --randomize): the distributions and the panels drawn once."""
    from udc_render.dataset import Randomization
    from udc_render.dataset.randomize import draw_panels, load_distributions
    if args.randomize is None:
        if args.panels is not None or args.randomize_seed != 0:
            raise UserError(f"udc-render dataset: {'--panels' if args.panels is not None else '--randomize-seed'} "
                            "is for a randomized dataset: add --randomize default|FILE.toml")
        return None
    for option, given in (("--display", args.display), ("--distance-mm", args.distance_mm)):
        if given is not None:
            raise UserError(f"udc-render dataset: {option} {given} with --randomize: the drawn panel is the items' "
                            "display, its distance drawn (display.distance_mm in the TOML); leave it out")
    dists = load_distributions(args.randomize)
    panels = args.panels or DEFAULT_PANELS
    return Randomization(dists, args.randomize_seed, tuple(draw_panels(dists, panels, args.randomize_seed)))


def dataset_job(args):
    """The DatasetJob that the parsed `udc-render dataset` arguments describe (also benchmarks/bench_dataset.py)."""
    from udc_render.dataset import DatasetJob
    split = split_counts(args.count, args.split)
    rand = randomization(args)
    cfg, displays = capture_setup(args, "glass" if rand is not None else args.display or "toled")
    scene = scene_from_args(args)
    jitters = [o for o, v in (("--pose-jitter-m", args.pose_jitter_m), ("--target-jitter-m", args.target_jitter_m))
               if v is not None]
    if isinstance(scene.content, Monitor):
        if args.images is None and not args.builtin:
            raise UserError(f"udc-render dataset: one of the arguments --images --builtin is required: item i of the "
                            f"monitor scene {scene.source} shows image i (a 3D scene, --scene room|hdr|FILE, "
                            "needs neither)")
        if jitters:
            raise UserError(f"udc-render dataset: {jitters[0]} is for a 3D scene; the monitor scene {scene.source} "
                            f"changes its image per item (--images, --builtin)")
    elif args.images is not None or args.builtin:
        which = '--images' if args.images is not None else '--builtin'
        raise UserError(f"udc-render dataset: {which} is for a monitor "
                        f"scene; the {scene.content_type} scene {scene.source} makes item i a view of it from a "
                        f"jittered camera pose (--pose-jitter-m, --target-jitter-m)")
    return DatasetJob(scene, displays, cfg, out=out_dir(args.out), split=split, images_dir=args.images,
                      shard_size=args.shard_size, side_by_side=args.side_by_side,
                      previews=args.previews or args.side_by_side,
                      origin_jitter_m=args.pose_jitter_m or DEFAULT_ORIGIN_JITTER_M,
                      target_jitter_m=args.target_jitter_m or DEFAULT_TARGET_JITTER_M, randomize=rand)


def run(args) -> int:
    from udc_render.dataset import run_dataset
    from udc_render.profiles import describe
    job = dataset_job(args)
    cfg = job.cfg
    s = run_dataset(job, args.workers, args.scheduler, progress=not args.quiet)
    rate = f", {s['wall_s'] / s['made']:.2f} s/item wall" if s["made"] else ""
    if s["panels_plan_s"]:
        p = s["panels_plan_s"]
        rate += f"; {len(p)} panels' kernels planned in {sum(p):.1f} s, {sum(p) / len(p):.2f} s per panel"
    stale = f", {s['stale_removed']} stale temporary folders removed" if s["stale_removed"] else ""
    print(describe(cfg.profile))
    if job.randomize is not None:
        r = job.randomize
        print(f"randomized ({r.dists.source}, seed {r.seed}): {len(r.panels)} "
              f"panel{'s' if len(r.panels) > 1 else ''} drawn once (job.json); each item's "
              "panel, read noise, defect pixels, fixed-pattern noise and exposure drawn in its capture.json")
    print(f"{s['complete']}/{s['count']} items in {s['out']} ({s['made']} made now{rate}, "
          f"{s['count'] - s['made']} already there{stale}); manifest.jsonl, job.json, timing.jsonl")
    return 0
