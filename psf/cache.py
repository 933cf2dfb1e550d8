"""On-disk cache of kernel sets, keyed by every parameter that makes them.

The key is the SHA-256 of the canonical JSON of (engine version, call name, all arguments,
the display's full description including a micrograph's pixel hash). Entries are .npz files
written atomically by psf.kernel_io. Location: the `cache_dir` argument of cached(), else
$UDC_RENDER_CACHE, else ~/.cache/udc-render/psf (read, never written: psf sets no environment).
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from .engine import KernelSet
from .kernel_io import load_kernels, save_kernels

__all__ = ["ENGINE_VERSION", "cache_dir", "cache_key", "entry_path", "load", "store", "cached"]

ENGINE_VERSION = "psf-4"  # psf-2: KernelSet.period_um, distance_mm, image_distance_um; psf-3: field_series;
# psf-4: method 'paper' is the recipe as printed (psf.paper)


def cache_dir() -> Path:
    return Path(os.environ.get("UDC_RENDER_CACHE", Path.home() / ".cache" / "udc-render" / "psf"))


def cache_key(name: str, display, lens, **kwargs) -> str:
    desc = {"engine": ENGINE_VERSION, "call": name,
            "display": display.describe() if display is not None else None,
            "lens": lens.describe(), "args": kwargs}
    blob = json.dumps(desc, sort_keys=True, default=lambda o: o.tolist() if isinstance(o, np.ndarray) else str(o))
    return hashlib.sha256(blob.encode()).hexdigest()


def entry_path(key: str, folder: Path | str | None = None) -> Path:
    """The .npz file of a cache key in `folder` (None: cache_dir())."""
    return Path(folder or cache_dir()) / f"{key}.npz"


def load(key: str, folder: Path | str | None = None) -> KernelSet | None:
    """The cached KernelSet of `key`, or None when absent or damaged (then it is recomputed)."""
    path = entry_path(key, folder)
    if not path.is_file():
        return None
    try:
        return load_kernels(path)
    except (OSError, ValueError, KeyError):
        return None


def store(key: str, ks: KernelSet, folder: Path | str | None = None) -> None:
    """Write `ks` as the entry of `key` (atomic: psf.kernel_io.save_kernels)."""
    save_kernels(entry_path(key, folder), ks)


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
