"""On-disk cache of kernel sets, keyed by every parameter that makes them, and of what is derived from them.

The key is the SHA-256 of the canonical JSON of (engine version, call name, all arguments,
the display's full description including a micrograph's pixel hash). Entries are .npz files
written atomically by psf.kernel_io and read with their large arrays memory-mapped (kernel_io.read_members).
Location: the `cache_dir` argument of cached(), else $UDC_RENDER_CACHE, else ~/.cache/udc-render/psf
(read, never written: psf sets no environment).

Derived entries (cached_arrays): arrays made from cached kernel sets by a fixed function (a far field, the
rank-r field bases of a render grid, its exact-power maps), keyed by the kind of product, the keys of the
entries it is made from and its own parameters (derived_key), so that a product is computed once and loaded,
memory-mapped, by every process that needs it.
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from .engine import KernelSet
from .kernel_io import atomic_write, load_kernels, read_members, save_kernels

__all__ = ["ENGINE_VERSION", "cache_dir", "cache_key", "entry_path", "load", "store", "cached", "cached_keyed",
           "derived_key", "cached_arrays"]

ENGINE_VERSION = "psf-5"  # psf-2: KernelSet.period_um, distance_mm, image_distance_um; psf-3: field_series;
# psf-4: method 'paper' is the recipe as printed (psf.paper); psf-5: an aperiodic display's field phases span the
# sensor's shifts (psf.plan.field_shifts), not one tile period


def cache_dir() -> Path:
    return Path(os.environ.get("UDC_RENDER_CACHE", Path.home() / ".cache" / "udc-render" / "psf"))


def _digest(desc: dict) -> str:
    blob = json.dumps(desc, sort_keys=True, default=lambda o: o.tolist() if isinstance(o, np.ndarray) else str(o))
    return hashlib.sha256(blob.encode()).hexdigest()


def cache_key(name: str, display, lens, **kwargs) -> str:
    return _digest({"engine": ENGINE_VERSION, "call": name,
                    "display": display.describe() if display is not None else None,
                    "lens": lens.describe(), "args": kwargs})


def derived_key(kind: str, sources, **params) -> str:
    """The key of a product of kind `kind` (name and version of the function that makes it) made from the
    entries `sources` (their keys) with `params` (every other input)."""
    return _digest({"engine": ENGINE_VERSION, "derived": kind, "from": list(sources), "params": params})


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


def cached_keyed(fn, name: str, display, lens, use_cache: bool = True, *, cache_dir: Path | str | None = None,
                 **kwargs) -> tuple[KernelSet, bool, str | None]:
    """cached(), and the entry's key (None without the cache)."""
    if not use_cache:
        return fn(display, lens, **kwargs), False, None
    # Callables (progress bars, weight functions) are named by other arguments (weight_name).
    key = cache_key(name, display, lens, **{k: v for k, v in kwargs.items() if not callable(v)})
    hit = load(key, cache_dir)
    if hit is not None:
        return hit, True, key
    ks = fn(display, lens, **kwargs)
    store(key, ks, cache_dir)
    return ks, False, key


def cached(fn, name: str, display, lens, use_cache: bool = True, *, cache_dir: Path | str | None = None,
           **kwargs) -> tuple[KernelSet, bool]:
    """fn(display, lens, **kwargs) through the cache in `cache_dir` (None: cache_dir()'s default);
    returns (kernels, came_from_cache)."""
    ks, hit, _ = cached_keyed(fn, name, display, lens, use_cache, cache_dir=cache_dir, **kwargs)
    return ks, hit


def cached_arrays(kind: str, sources, make, cache_dir: Path | str | None = None, **params) -> dict[str, np.ndarray]:
    """make() → {name: array} through the cache as the derived entry derived_key(kind, sources, **params)
    (module doc); sources None (an input not from the cache): make() every time. Loaded memory-mapped."""
    if sources is None or any(k is None for k in sources):
        return make()
    path = entry_path(derived_key(kind, sources, **params), cache_dir)
    if path.is_file():
        try:
            return read_members(path)
        except (OSError, ValueError, KeyError):
            pass  # damaged: made again
    arrays = {k: np.asarray(v) for k, v in make().items()}
    atomic_write(path, lambda fh: np.savez(fh, **arrays))
    return arrays
