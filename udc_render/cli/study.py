"""`udc-render study {psf,render,capture,realism,defocus,banding} --out DIR [--quick]`: error-versus-run-time
studies of the approximation knobs, and the defocus and banding studies users run."""
from __future__ import annotations

from pathlib import Path

from udc_render.cli.args import out_dir

STUDIES = {
    "psf": "the PSF engine's knobs (pupil samples, precision, wavelength step, field phases, kernel size)",
    "render": "the renderer's knobs (samples per pixel, sampler, render path, bands per render)",
    "capture": "the capture synthesis's knobs (band width, per-channel form, field phases, precision)",
    "realism": "the paper's observables of its real displays beside ours, over the unfixed layout parameters",
    "defocus": "through-focus PSFs, MTFs and depth of field of glass, T-OLED and P-OLED",
    "banding": "the bands a display a distance d in front of the lens prints on a flat field",
}


def register(sub) -> None:
    s = sub.add_parser("study", help="error-versus-run-time studies of the approximation knobs; defocus and banding studies")
    s.set_defaults(run=run)
    s.add_argument("what", choices=tuple(STUDIES),
                   help="the study: " + "; ".join(f"{name}: {what}" for name, what in STUDIES.items()))
    s.add_argument("--out", type=Path, default=Path("out/study"),
                   help="output folder: study_<what>.csv, .md, .png [out/study]")
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
