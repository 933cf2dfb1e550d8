"""`udc-render cache [--dir DIR] [--unused-days N] [--max-gb G] [--dry-run]`: what the kernel cache holds, and
removing the entries not used for N days or the least recently used beyond G gigabytes (psf.cache_usage)."""
from __future__ import annotations

import time
from pathlib import Path

from psf.cache_usage import entries, remove, stale_temporaries, to_remove
from udc_render.cli.args import non_negative
from udc_render.errors import UdcError


def register(sub) -> None:
    c = sub.add_parser("cache", help="the kernel cache's size; remove entries unused for N days or beyond G GB")
    c.set_defaults(run=run)
    c.add_argument("--dir", type=Path, default=None,
                   help="the cache folder [$UDC_RENDER_CACHE, else ~/.cache/udc-render/psf]")
    c.add_argument("--unused-days", type=non_negative("--unused-days"), default=None,
                   help="remove the entries not used for more than this many days")
    c.add_argument("--max-gb", type=non_negative("--max-gb"), default=None,
                   help="then remove the least recently used entries until the rest hold at most this many GB")
    c.add_argument("--dry-run", action="store_true", help="list what would be removed; remove nothing")


def _gb(n_bytes: int) -> str:
    return f"{n_bytes / 1e9:.2f} GB"


def run(args) -> int:
    from psf.cache import cache_dir
    folder = args.dir or cache_dir()
    if not folder.is_dir():
        raise UdcError(f"--dir {folder}: no such folder (the kernel cache is made by the first run that plans "
                       "kernels)")
    now = time.time()
    found = entries(folder)
    total = sum(e.size_bytes for e in found)
    age = (f", last used {(now - found[-1].last_used_s) / 86400:.1f} to {(now - found[0].last_used_s) / 86400:.1f} "
           "days ago" if found else "")
    print(f"{folder}: {len(found)} entries, {_gb(total)}{age}")
    if args.unused_days is None and args.max_gb is None:
        return 0
    max_bytes = None if args.max_gb is None else int(args.max_gb * 1e9)
    chosen = to_remove(found, args.unused_days, max_bytes, now) + stale_temporaries(folder, now)
    size = sum(e.size_bytes for e in chosen)
    if args.dry_run:
        for e in chosen:
            print(f"would remove {e.path.name} ({_gb(e.size_bytes)}, last used {(now - e.last_used_s) / 86400:.1f} "
                  "days ago)")
        print(f"would remove {len(chosen)} files, {_gb(size)}; {_gb(total - size)} would remain")
        return 0
    freed = remove(chosen)
    print(f"removed {len(chosen)} files, {_gb(freed)}; {_gb(total - freed)} remain")
    return 0
