"""`udc-render study {psf,render,capture,realism,defocus,banding} --out DIR [--quick]`: error-versus-run-time
studies of the approximation knobs, and the defocus and banding studies users run."""
from __future__ import annotations

from pathlib import Path

from udc_render.cli.args import out_dir

STUDIES = ("psf", "render", "capture", "realism", "defocus", "banding")


def register(sub) -> None:
    s = sub.add_parser("study", help="error-versus-run-time studies of the approximation knobs; defocus and banding studies")
    s.set_defaults(run=run)
    s.add_argument("what", choices=STUDIES)
    s.add_argument("--out", type=Path, default=Path("out/study"))
    s.add_argument("--quick", action="store_true", help="a reduced grid (smoke run)")


def run(args) -> int:
    out = out_dir(args.out)
    if args.what == "realism":
        from udc_render.studies.realism import run_study
    elif args.what == "defocus":
        from udc_render.studies.defocus import run_study
    elif args.what == "banding":
        from udc_render.studies.banding import run_study
    elif args.what == "capture":
        from udc_render.studies.capture_knobs import run_study
    elif args.what == "render":
        from udc_render.studies.render_knobs import run_study
    else:
        from udc_render.studies.psf_knobs import run_study
    run_study(out, quick=args.quick)
    name = f"study_{args.what}"
    print(f"wrote {out}/{name}.csv, {name}.md, {name}.png")
    return 0
