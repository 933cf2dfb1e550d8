"""One KernelSet ↔ .npz serialisation (the on-disk cache's entries), written atomically.

Layout: one key per KernelSet field that is not None; arrays as they are (dtype kept, so a round
trip is bit-identical), scalars as 0-d arrays, `params` and `notes` as JSON strings, `period_um`
as a 2-vector (read back as a tuple). A field missing from a file takes the dataclass default.
"""
from __future__ import annotations

import dataclasses
import json
import os
import uuid
import zipfile
from pathlib import Path

import numpy as np

from .engine import KernelSet

__all__ = ["JSON_FIELDS", "kernel_arrays", "kernels_from_arrays", "save_kernels", "load_kernels", "atomic_write"]

JSON_FIELDS = ("params", "notes")


def kernel_arrays(ks: KernelSet) -> dict[str, np.ndarray]:
    """The .npz members of a KernelSet: {field: array} for every field that is not None."""
    arrays = {}
    for f in dataclasses.fields(KernelSet):
        value = getattr(ks, f.name)
        if f.name in JSON_FIELDS:
            arrays[f.name] = np.array(json.dumps(value))
        elif value is not None:
            arrays[f.name] = np.asarray(value)
    return arrays


def _field_value(f: dataclasses.Field, members):
    """One field from the .npz members: JSON decoded, period as a tuple, 0-d arrays as Python scalars."""
    if f.name not in members:
        if f.default is not dataclasses.MISSING:
            return f.default
        if f.default_factory is not dataclasses.MISSING:
            return f.default_factory()
        raise KeyError(f"kernel file has no '{f.name}'")
    a = members[f.name]
    if f.name in JSON_FIELDS:
        return json.loads(str(a))
    if f.name == "period_um":
        return tuple(float(v) for v in a)
    return a if a.ndim else a.item()


def kernels_from_arrays(members) -> KernelSet:
    """A KernelSet from a mapping of .npz members (an open np.load, or kernel_arrays' dict)."""
    return KernelSet(**{f.name: _field_value(f, members) for f in dataclasses.fields(KernelSet)})


def atomic_write(path: str | Path, write) -> Path:
    """write(binary file) into a temporary file beside `path`, then os.replace it onto `path`:
    readers see the old file or the whole new one, never a part. The temporary is removed on error."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        with open(tmp, "xb") as fh:
            write(fh)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def save_kernels(path: str | Path, ks: KernelSet) -> Path:
    """Write `ks` to the .npz file `path` (uncompressed), atomically."""
    arrays = kernel_arrays(ks)
    return atomic_write(path, lambda fh: np.savez(fh, **arrays))


def load_kernels(path: str | Path) -> KernelSet:
    """Read a KernelSet written by save_kernels. Raises OSError, ValueError or KeyError on a bad file."""
    try:
        with np.load(Path(path), allow_pickle=False) as z:
            return kernels_from_arrays({name: z[name] for name in z.files})
    except (zipfile.BadZipFile, EOFError) as exc:
        raise ValueError(f"{path}: not a complete kernel file ({exc})") from None
