"""What the kernel cache folder holds and which entries to remove (`udc-render cache`).

Every entry is one .npz file (psf.cache: kernel sets, their derived products, the kept spectra of
udc_render.optics.kept, colour-science's tables of psf.colour_tables); a write interrupted before its rename
leaves a hidden temporary (.NAME.HEX.tmp, psf.kernel_io.atomic_write). An entry's last use is the later of its
access and modification times: the kernel updates the access time when a file is read or memory-mapped, at most
once a day under Linux's default `relatime` and never under `noatime` (then the last use is the entry's
creation). Any removed entry is made again by the next run that needs it (kernel sets: minutes each).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Entry", "STALE_TMP_S", "entries", "stale_temporaries", "to_remove", "remove"]

STALE_TMP_S = 3600.0  # a temporary older than this is a killed write's, not one being written


@dataclass(frozen=True)
class Entry:
    path: Path
    size_bytes: int
    last_used_s: float  # seconds since the epoch: max(access, modification)


def _entry(path: Path) -> Entry:
    st = path.stat()
    return Entry(path, st.st_size, max(st.st_atime, st.st_mtime))


def entries(folder: Path) -> list[Entry]:
    """The folder's entries (*.npz), least recently used first."""
    return sorted((_entry(p) for p in Path(folder).glob("*.npz") if p.is_file()), key=lambda e: e.last_used_s)


def stale_temporaries(folder: Path, now_s: float | None = None) -> list[Entry]:
    """Temporaries of interrupted writes: hidden .tmp files last written more than STALE_TMP_S ago."""
    now_s = time.time() if now_s is None else now_s
    found = [(p, p.stat()) for p in Path(folder).glob(".*.tmp") if p.is_file()]
    return [Entry(p, st.st_size, max(st.st_atime, st.st_mtime)) for p, st in found if now_s - st.st_mtime > STALE_TMP_S]


def to_remove(found: list[Entry], unused_days: float | None = None, max_bytes: int | None = None,
              now_s: float | None = None) -> list[Entry]:
    """The entries to remove: those unused for more than `unused_days`, then the least recently used until the
    rest hold at most `max_bytes` (None: no such rule)."""
    now_s = time.time() if now_s is None else now_s
    ordered = sorted(found, key=lambda e: e.last_used_s)
    unused = [unused_days is not None and now_s - e.last_used_s > unused_days * 86400.0 for e in ordered]
    gone = [e for e, u in zip(ordered, unused) if u]
    kept = [e for e, u in zip(ordered, unused) if not u]
    total = sum(e.size_bytes for e in kept)
    for e in kept:
        if max_bytes is None or total <= max_bytes:
            break
        gone.append(e)
        total -= e.size_bytes
    return gone


def remove(chosen: list[Entry]) -> int:
    """Delete the chosen files (one already gone is skipped); the bytes freed. A process that has an entry
    memory-mapped keeps reading it until it closes it."""
    freed = 0
    for e in chosen:
        try:
            e.path.unlink()
        except FileNotFoundError:
            continue
        freed += e.size_bytes
    return freed
