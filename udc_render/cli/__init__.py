"""The `udc-render` command line: one thin module per command, each parsing its options and calling
one library or experiment function.

    udc-render psf --display toled --wavelengths-nm 450,520,640 --out DIR
    udc-render render SCENE --out DIR [--spp N | --noise 0.01] [--bands-nm 400:700:10]
    udc-render synth SCENE --display toled[,poled,FILE] --out DIR;   udc-render demo [--out DIR]
    udc-render dataset --builtin | --images DIR --count N --out DIR [--workers N | --scheduler ADDR]
    udc-render bank --display toled,poled --out DIR   (a kernel bank for train --degrade online)
    udc-render calibrate --display toled --out DIR
    udc-render fit --psf IMAGE [IMAGE ...] [--flat IMAGE] [--white GLASS DISPLAY] [--noise-frames DIR] --out DIR
    udc-render study {psf,render,capture,realism,defocus,banding} --out DIR [--quick]
    udc-render train / evaluate / results   (restore/)
    udc-render cache [--unused-days N] [--max-gb G] [--dry-run]   (the kernel cache's size; pruning)
    udc-render --version

Every --display takes the same things (udc_render.optics.displays.load_display): glass (or none),
toled, poled, a display file (.toml) or a micrograph image (.png/.tif/.tiff/.exr); comma-separated
where a command takes several.

A user error (UdcError, and the psf package's errors) prints one line naming the option, file or key,
the value and what is allowed, and exits 2; no traceback. Output folders are made and checked
before any computation.
"""
from __future__ import annotations

import sys
from importlib.metadata import PackageNotFoundError, version

from psf.engine import PSFError
from psf.layouts import LayoutError
from psf.lens import LensError
from udc_render import __version__
from udc_render.cli import (
    bank,
    cache,
    calibrate,
    dataset,
    design,
    design_pattern,
    evaluate,
    fit,
    psf,
    render,
    results,
    study,
    synth,
    train,
)
from udc_render.cli.args import Parser
from udc_render.errors import UdcError

COMMANDS = (psf, render, synth, dataset, bank, calibrate, fit, study, design, design_pattern, train, evaluate, results,
            cache)
USER_ERRORS = (UdcError, PSFError, LayoutError, LensError)


def package_version() -> str:
    """The installed distribution's version, else the package's own (a source tree not installed)."""
    try:
        return version("udc-render")
    except PackageNotFoundError:
        return __version__


def build_parser() -> Parser:
    parser = Parser(prog="udc-render", description="Physically based under-display camera simulation.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}",
                        help="print the version and exit")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser,
                                help="the command; udc-render COMMAND --help for its options")
    for command in COMMANDS:
        command.register(sub)
    return parser


def main(argv=None) -> int:
    try:
        args = build_parser().parse_args(argv)
        return args.run(args)
    except USER_ERRORS as exc:
        print(f"udc-render: error: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("udc-render: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
