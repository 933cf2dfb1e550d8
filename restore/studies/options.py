"""The options of the study modules run as `python -m restore.studies.<name>`: `--option value` pairs
without argparse, which the project keeps in udc_render.cli (tests/udc_render/test_layers.py)."""
from __future__ import annotations

import sys


def parse_options(argv: list[str], usage: str, repeated=()) -> tuple[list[str], dict]:
    """(positional arguments, {option: value, or a list for `repeated`}) of `--option value` pairs; a
    dangling option exits with `usage` (library modules take no argparse: the CLI lives in udc_render.cli)."""
    pos, opts, it = [], {k: [] for k in repeated}, iter(argv)
    for a in it:
        if a.startswith("--"):
            value = next(it, None)
            if value is None:
                sys.exit(f"error: {a} needs a value\nusage: {usage}")
            key = a[2:].replace("-", "_")
            if key in repeated:
                opts[key].append(value)
            else:
                opts[key] = value
        else:
            pos.append(a)
    return pos, opts
