"""Deferred imports: an import inside a function must save a real cost on a path that does not need it
(`udc-render psf` imports neither torch nor mitsuba; the CLI reads every command's options at start).

Allowed inside a function: a module of HEAVY (its import time after numpy, written beside it: `python -c
"import numpy, time; t = time.perf_counter(); import X; print(time.perf_counter() - t)"`, best of 2 on the
2-core development machine), an OPTIONAL dependency or platform module, or a project module whose
module-level imports reach one of them. Everything else (the standard library, tqdm 25–48 ms, imageio
28 ms, tifffile 18–42 ms, OpenEXR 4 ms, pypng 1 ms, threadpoolctl 3 ms, a light project module) is
imported at the top of the module.
"""
from __future__ import annotations

from tests.udc_render.test_layers import imported_names, module_name, sources

HEAVY = {  # import time after numpy
    "torch": "977 ms",
    "mitsuba": "89 ms, then a variant's set-up on first use",
    "drjit": "67 ms (mitsuba's JIT)",
    "matplotlib": "96 ms; matplotlib.pyplot 340 ms",
    "dask": "99 ms",
    "colour": "948 ms (colour-science)",
    "scipy.signal": "653 ms",
    "scipy.optimize": "281 ms",
    "scipy.ndimage": "233 ms",
    "scipy.fft": "175 ms",
    "scipy.stats": "1.1-1.4 s",
    "skimage.restoration": "760 ms (scikit-image loads its subpackages lazily: the cost comes on first use)",
    "skimage.transform": "310 ms",
    "skimage.data": "279 ms with its first image",
    "skimage.metrics": "240 ms",
}
OPTIONAL = {
    "distributed": "extra 'dist' (253 ms)",
    "bm3d": "extra 'bm3d' (non-commercial licence)",
    "fcntl": "POSIX only",
}


def _among(module: str, names) -> bool:
    return any(module == n or module.startswith(n + ".") for n in names)


def _targets(base: str, names: list[str], modules: set[str]) -> set[str]:
    """The modules an import loads: pkg.name for each name that is a project module, else pkg; outside
    the project pkg.name for every name (`from scipy import signal`: scipy.signal)."""
    if base.split(".")[0] not in ("psf", "udc_render", "restore"):
        return {base, *(f"{base}.{n}" for n in names)}
    subs = {f"{base}.{n}" for n in names if f"{base}.{n}" in modules}
    return subs if subs and len(subs) == len(names) else subs | {base}


def _allowed(targets: set[str], heavy_project: set[str]) -> bool:
    return any(_among(t, HEAVY) or _among(t, OPTIONAL) or t in heavy_project for t in targets)


def heavy_project_modules() -> set[str]:
    """Project modules whose module-level imports reach a HEAVY or OPTIONAL module (fixed point)."""
    paths = {module_name(p): p for p in sources()}
    modules = set(paths)
    top = {m: set().union(*[_targets(b, n, modules) for b, n in imported_names(p, in_functions=False)] or [set()])
           for m, p in paths.items()}
    heavy = {m for m, t in top.items() if _allowed(t, set())}
    while new := {m for m in modules - heavy if top[m] & heavy}:
        heavy |= new
    return heavy


def test_function_level_imports_save_a_real_cost():
    modules = {module_name(p) for p in sources()}
    heavy = heavy_project_modules()
    light = set()
    for path in sources():
        for base, names in imported_names(path, in_functions=True):
            if not _allowed(_targets(base, names, modules), heavy):
                light.add((module_name(path), base))
    bad = sorted(f"{m}: {t}" for m, t in light)
    assert not bad, "imported inside a function, but light (move it to the top):\n" + "\n".join(bad)


def test_the_cli_reads_its_options_without_the_heavy_modules():
    """Every command's options are read at start: the parser loads no HEAVY module (torch alone costs ~1 s, and
    4.5 s CPU on a loaded machine; the design command's constants live in design.options for this). scipy.fft
    (175 ms) is the exception: the psf command's defaults come from psf.engine, which transforms at its top."""
    import subprocess
    import sys
    code = ("import sys; from udc_render.cli import build_parser; build_parser(); "
            f"print(sorted(m for m in {sorted(set(HEAVY) - {'scipy.fft'})!r} if m in sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert loaded == "[]", f"the CLI's parser imports {loaded}"
