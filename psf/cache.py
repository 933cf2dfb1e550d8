"""On-disk cache of kernel sets, keyed by every parameter that makes them.

The key is the SHA-256 of the canonical JSON of (engine version, call name, all arguments,
the display's full description including a micrograph's pixel hash). Entries are .npz files
written atomically. Location: $UDC_RENDER_CACHE, else ~/.cache/udc-render/psf.
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
from dataclasses import fields
from pathlib import Path

import numpy as np

from .engine import KernelSet

ENGINE_VERSION = "psf-2"  # psf-2: KernelSet.period_um, distance_mm, image_distance_um


def cache_dir() -> Path:
    return Path(os.environ.get("UDC_RENDER_CACHE", Path.home() / ".cache" / "udc-render" / "psf"))


def cache_key(name: str, display, lens, **kwargs) -> str:
    desc = {"engine": ENGINE_VERSION, "call": name,
            "display": display.describe() if display is not None else None,
            "lens": lens.describe(), "args": kwargs}
    blob = json.dumps(desc, sort_keys=True, default=lambda o: o.tolist() if isinstance(o, np.ndarray) else str(o))
    return hashlib.sha256(blob.encode()).hexdigest()


def load(key: str, folder: Path | None = None) -> KernelSet | None:
    path = Path(folder or cache_dir()) / f"{key}.npz"
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            values = {}
            for f in fields(KernelSet):
                if f.name in ("params", "notes"):
                    values[f.name] = json.loads(str(z[f.name]))
                elif f.name == "period_um" and f.name in z.files:
                    values[f.name] = tuple(float(v) for v in z[f.name])
                elif f.name in z.files:
                    values[f.name] = z[f.name] if z[f.name].ndim else z[f.name].item()
                else:
                    values[f.name] = None
        return KernelSet(**values)
    except (OSError, ValueError, KeyError):
        return None  # a damaged entry is recomputed


def store(key: str, ks: KernelSet, folder: Path | None = None) -> None:
    folder = Path(folder or cache_dir())
    folder.mkdir(parents=True, exist_ok=True)
    arrays = {f.name: getattr(ks, f.name) for f in fields(KernelSet) if getattr(ks, f.name) is not None}
    arrays["params"] = np.array(json.dumps(ks.params))
    arrays["notes"] = np.array(json.dumps(ks.notes))
    fd, tmp = tempfile.mkstemp(prefix=f".{key}.", suffix=".npz", dir=folder)
    os.close(fd)
    try:
        np.savez(tmp, **arrays)
        os.replace(tmp, folder / f"{key}.npz")
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def cached(fn, name: str, display, lens, use_cache: bool = True, *, cache_dir: Path | str | None = None,
           **kwargs) -> tuple[KernelSet, bool]:
    """fn(display, lens, **kwargs) through the cache in `cache_dir` (None: cache_dir()'s default);
    returns (kernels, came_from_cache)."""
    if not use_cache:
        return fn(display, lens, **kwargs), False
    # Callables (progress bars, weight functions) are named by other arguments (weight_name).
    key = cache_key(name, display, lens, **{k: v for k, v in kwargs.items() if not callable(v)})
    hit = load(key, cache_dir)
    if hit is not None:
        return hit, True
    ks = fn(display, lens, **kwargs)
    store(key, ks, cache_dir)
    return ks, False
