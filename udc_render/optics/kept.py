"""What a process makes once and keeps: the summed kernels' spectra of a job's views (optics.primaries,
optics.field_planes), each a function of its key alone (the kernels' bytes, the weights, the monitor's matrix, the
FFT shape).

In memory, a store keeps its `limit` most recently used entries. Inside `on_disk(folder)` (a dataset job's kernel
cache: dataset.executors.make_item) an entry is also a derived cache entry (psf.cache.cached_arrays: uncompressed,
read memory-mapped), so the next worker and the next job load the bits the first one made instead of making them
again: a worker's first item made them in 2–4 CPU-s (issue 46).
"""
from __future__ import annotations

import contextlib
import contextvars
import hashlib
import weakref
from collections import OrderedDict
from pathlib import Path

import numpy as np

from psf.cache import cached_arrays

KIND = "kept-spectra-1"  # the cache entries' kind (psf.cache.derived_key): bump when what a key makes changes
_OFF = object()
_FOLDER: contextvars.ContextVar = contextvars.ContextVar("kept_spectra_folder", default=_OFF)
_DIGESTS: dict = {}  # ids of the arrays hashed → (weak references to them, their digest)


def digest(*arrays: np.ndarray) -> str:
    """SHA-1 of the arrays' bytes one after the other (C order), hashed once while the same array objects live: a
    worker's kernels are the same objects item after item (hashed again, 0.15 CPU-s an item). For arrays that are
    not written after (kernels, memory-mapped cache entries)."""
    ids = tuple(id(a) for a in arrays)
    hit = _DIGESTS.get(ids)
    if hit is not None and all(ref() is a for ref, a in zip(hit[0], arrays)):
        return hit[1]
    _DIGESTS[ids] = (tuple(weakref.ref(a, lambda _, ids=ids: _DIGESTS.pop(ids, None)) for a in arrays),
                     sha1_of(*arrays))
    return _DIGESTS[ids][1]


def sha1_of(*arrays) -> str:
    """SHA-1 of the arrays' bytes one after the other (C order: a.tobytes()), hashed each call (digest keeps it)."""
    h = hashlib.sha1()
    for a in arrays:
        h.update(np.ascontiguousarray(a).view(np.uint8).ravel())
    return h.hexdigest()


@contextlib.contextmanager
def on_disk(folder: Path | str | None):
    """Within the block, entries are also read from and written to the kernel cache `folder` (None: psf.cache's
    default folder)."""
    token = _FOLDER.set(folder)
    try:
        yield
    finally:
        _FOLDER.reset(token)


def _made(key: tuple, make) -> np.ndarray:
    """make() (an array), or inside on_disk the cache's entry for `key`, made and stored when missing."""
    folder = _FOLDER.get()
    if folder is _OFF:
        return make()
    digest = hashlib.sha256(repr(key).encode()).hexdigest()
    return cached_arrays(KIND, (digest,), lambda: {"spectra": make()}, folder)["spectra"]


def kept(store: OrderedDict, limit: int, key: tuple, make) -> np.ndarray:
    """store[key], else _made(key, make); the store keeps the `limit` most recently used entries."""
    value = store.pop(key, None)
    store[key] = _made(key, make) if value is None else value
    while len(store) > limit:
        store.popitem(last=False)
    return store[key]
