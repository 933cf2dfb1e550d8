"""Choosing the Mitsuba variant: `llvm_ad_*` when a working libLLVM is found, else `scalar_*`.

A bad libLLVM (the base image's 15 or 16) makes Dr.Jit abort the whole process on its first kernel,
with no Python exception to catch, so each candidate library is tried in a subprocess that renders
a tiny scene. The verdict is cached per (library file, its size and mtime, mitsuba version).
`UDC_RENDER_VARIANT=scalar` forces the scalar variants; `DRJIT_LIBLLVM_PATH` names a library to
try first. The choice must be made before mitsuba is imported in this process.
"""
from __future__ import annotations

import glob
import json
import os
import subprocess
import sys
import warnings
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path

from psf.cache import cache_dir

LLVM_GLOBS = ("/usr/lib/x86_64-linux-gnu/libLLVM.so.*", "/usr/lib/x86_64-linux-gnu/libLLVM-*.so*",
              "/usr/lib/aarch64-linux-gnu/libLLVM.so.*", "/usr/lib/aarch64-linux-gnu/libLLVM-*.so*",
              "/usr/lib/llvm-*/lib/libLLVM*.so*", "/usr/local/lib/libLLVM*.so*", "/usr/lib64/libLLVM*.so*")
_PROBE = """
import mitsuba as mi
mi.set_variant('llvm_ad_rgb')
s = mi.load_dict({'type': 'scene', 'e': {'type': 'constant'}, 'i': {'type': 'path'}, 'sensor': {'type': 'perspective',
    'film': {'type': 'hdrfilm', 'width': 4, 'height': 4}}})
import numpy as np
assert abs(float(np.array(mi.render(s, spp=4)).mean()) - 1) < 1e-3
print('ok')
"""


class FallbackWarning(UserWarning):
    """No working LLVM: the slow scalar variants are used."""


@dataclass(frozen=True)
class Backend:
    """`kind` is 'llvm' or 'scalar'; `libllvm` the library used; `reason` why."""
    kind: str
    libllvm: str | None
    reason: str

    def variant(self, mode: str) -> str:
        """Mitsuba variant name for mode 'rgb' or 'spectral'."""
        return f"llvm_ad_{mode}" if self.kind == "llvm" else f"scalar_{mode}"


def candidates() -> list[str]:
    """libLLVM files on this machine, newest version first, DRJIT_LIBLLVM_PATH before all."""
    found = {os.path.realpath(p) for g in LLVM_GLOBS for p in glob.glob(g) if os.path.isfile(p)}

    def ver(p: str) -> tuple:
        digits = [int(t) for t in Path(p).name.replace("-", ".").split(".") if t.isdigit()]
        return tuple(digits) or (0,)
    ordered = sorted(found, key=ver, reverse=True)
    first = os.environ.get("DRJIT_LIBLLVM_PATH")
    if first:
        ordered = [first] + [p for p in ordered if p != os.path.realpath(first)]
    return ordered


def probe(libllvm: str, timeout_s: float = 120.0) -> bool:
    """True if the llvm variant renders correctly with `libllvm`, tried in a subprocess (cached)."""
    try:
        st = os.stat(libllvm)
    except OSError:
        return False
    key = (f"{os.path.realpath(libllvm)}|{st.st_size}|{int(st.st_mtime)}"
           f"|mitsuba {version('mitsuba')}|drjit {version('drjit')}")
    cache = cache_dir() / "llvm_probe.json"
    try:
        known = json.loads(cache.read_text())
    except (OSError, ValueError):
        known = {}
    if key in known:
        return bool(known[key])
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=libllvm)
    try:
        r = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, timeout=timeout_s)
        ok = r.returncode == 0 and r.stdout.strip().endswith("ok")
    except subprocess.TimeoutExpired:
        ok = False
    known[key] = ok
    try:
        cache.parent.mkdir(parents=True, exist_ok=True)
        tmp = cache.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps(known, indent=1))
        os.replace(tmp, cache)
    except OSError:
        pass
    return ok


_CHOSEN: Backend | None = None


def choose_backend() -> Backend:
    """Pick the backend once per process and set DRJIT_LIBLLVM_PATH for it (before mitsuba loads)."""
    global _CHOSEN
    if _CHOSEN is not None:
        return _CHOSEN
    if os.environ.get("UDC_RENDER_VARIANT", "").lower() == "scalar":
        _CHOSEN = Backend("scalar", None, "UDC_RENDER_VARIANT=scalar")
        return _CHOSEN
    tried = []
    for lib in candidates():
        if probe(lib):
            os.environ["DRJIT_LIBLLVM_PATH"] = lib
            _CHOSEN = Backend("llvm", lib, f"{lib} passed the subprocess probe")
            return _CHOSEN
        tried.append(Path(lib).name)
    why = (f"no libLLVM rendered correctly (tried {', '.join(tried)})" if tried else "no libLLVM found")
    warnings.warn(f"{why}: rendering with the scalar variants, 3-6x slower; install LLVM 19 "
                  "(apt-get install libllvm19) for the llvm variants", FallbackWarning, stacklevel=2)
    _CHOSEN = Backend("scalar", None, why)
    return _CHOSEN


_DRJIT_THREADS: int | None = None


def set_drjit_threads(threads: int) -> None:
    """Dr.Jit's thread pool size: set now when Mitsuba is loaded, else by set_variant when it loads it (a dataset
    worker of a monitor scene, whose render is analytic, never imports drjit: 0.15-0.2 s)."""
    global _DRJIT_THREADS
    _DRJIT_THREADS = int(threads)
    if "drjit" in sys.modules:
        sys.modules["drjit"].set_thread_count(_DRJIT_THREADS)


def set_variant(mode: str):
    """Import mitsuba with the chosen backend's variant for `mode` ('rgb' or 'spectral'), Dr.Jit's threads at
    set_drjit_threads' count if one was given."""
    backend = choose_backend()
    import mitsuba as mi
    if _DRJIT_THREADS is not None:
        import drjit
        drjit.set_thread_count(_DRJIT_THREADS)
    mi.set_variant(backend.variant(mode))
    return mi, backend
