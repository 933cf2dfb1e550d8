"""One KernelSet ↔ .npz serialisation (the on-disk cache's entries), written atomically.

Layout: one key per KernelSet field that is not None; arrays as they are (dtype kept, so a round
trip is bit-identical), scalars as 0-d arrays, `params` and `notes` as JSON strings, `period_um`
as a 2-vector (read back as a tuple). A field missing from a file takes the dataclass default.

The archive is uncompressed (np.savez: every member ZIP_STORED), so a member's .npy data lies in the file as
it is in memory: read_members maps the large ones (np.memmap, read-only) instead of reading them. Loading a
cache entry then costs its small members and a few system calls, and the pages of the large ones are read
when touched (a dataset worker never touches its d > 0 phase kernels when their rank-r bases are cached) and
shared between the processes that map the same file (the page cache).
"""
from __future__ import annotations

import dataclasses
import json
import os
import struct
import uuid
import zipfile
from pathlib import Path

import numpy as np

from .engine import KernelSet

__all__ = ["JSON_FIELDS", "MAP_BYTES", "kernel_arrays", "kernels_from_arrays", "save_kernels", "load_kernels",
           "read_members", "atomic_write"]

JSON_FIELDS = ("params", "notes")
MAP_BYTES = 1 << 20  # members of at least 1 MiB are memory-mapped by read_members, smaller ones read


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


def _mapped(path: Path, fh, info: zipfile.ZipInfo) -> np.ndarray | None:
    """The .npy member `info` of the archive open as `fh`, memory-mapped read-only (a plain ndarray over the
    map), or None when it cannot be (compressed, small, an object or empty array: read it instead)."""
    if info.compress_type != zipfile.ZIP_STORED or info.file_size < MAP_BYTES:
        return None
    fh.seek(info.header_offset)
    local = fh.read(30)
    if len(local) != 30 or local[:4] != b"PK\x03\x04":
        raise ValueError(f"{path}: member {info.filename} has no local header")
    name_len, extra_len = struct.unpack("<HH", local[26:30])
    fh.seek(info.header_offset + 30 + name_len + extra_len)
    version = np.lib.format.read_magic(fh)
    header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
    shape, fortran, dtype = header(fh)
    if dtype.hasobject or not shape or 0 in shape:
        return None
    return np.memmap(path, dtype=dtype, mode="r", offset=fh.tell(), shape=shape,
                     order="F" if fortran else "C").view(np.ndarray)


def read_members(path: str | Path) -> dict[str, np.ndarray]:
    """{name: array} of an .npz file, members of MAP_BYTES or more memory-mapped (module doc), the others read.
    Raises OSError, ValueError or KeyError on a bad file (a truncated one: the map reaches past its end)."""
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as zf, open(path, "rb") as fh:
            out = {}
            for info in zf.infolist():
                name = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
                a = _mapped(path, fh, info)
                if a is None:
                    with zf.open(info) as member:
                        a = np.lib.format.read_array(member, allow_pickle=False)
                out[name] = a
            return out
    except (zipfile.BadZipFile, EOFError) as exc:
        raise ValueError(f"{path}: not a complete kernel file ({exc})") from None


def load_kernels(path: str | Path) -> KernelSet:
    """Read a KernelSet written by save_kernels (large arrays memory-mapped: read_members). Raises OSError,
    ValueError or KeyError on a bad file."""
    return kernels_from_arrays(read_members(path))
