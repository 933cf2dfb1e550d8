"""The kernel cache's pruning (psf.cache_usage, `udc-render cache`): the least recently used go first, by the
later of the access and modification times; interrupted writes' temporaries go once stale."""
import os
import time

import pytest

from psf.cache_usage import STALE_TMP_S, Entry, entries, remove, stale_temporaries, to_remove
from udc_render.cli import main

DAY = 86400.0
NOW = 1.8e9


def _file(folder, name, size, atime, mtime):
    path = folder / name
    path.write_bytes(b"x" * size)
    os.utime(path, (atime, mtime))
    return path


def test_entries_are_ordered_by_their_last_use_the_later_of_access_and_modification(tmp_path):
    _file(tmp_path, "a.npz", 10, NOW - 5 * DAY, NOW - 9 * DAY)  # read 5 days ago
    _file(tmp_path, "b.npz", 20, NOW - 9 * DAY, NOW - 2 * DAY)  # written 2 days ago (a noatime mount)
    _file(tmp_path, "c.npz", 30, NOW - 7 * DAY, NOW - 8 * DAY)
    _file(tmp_path, "notes.txt", 40, NOW, NOW)  # not an entry
    found = entries(tmp_path)
    assert [e.path.name for e in found] == ["c.npz", "a.npz", "b.npz"]
    assert [e.last_used_s for e in found] == [NOW - 7 * DAY, NOW - 5 * DAY, NOW - 2 * DAY]
    assert [e.size_bytes for e in found] == [30, 10, 20]


def test_the_unused_go_then_the_least_recently_used_beyond_the_budget(tmp_path):
    found = [Entry(tmp_path / n, size, NOW - days * DAY) for n, size, days in
             (("old", 100, 40), ("mid", 300, 10), ("new", 200, 1), ("newest", 50, 0.5))]
    names = lambda chosen: [e.path.name for e in chosen]  # noqa: E731
    assert to_remove(found, now_s=NOW) == []
    assert names(to_remove(found, unused_days=30, now_s=NOW)) == ["old"]
    assert names(to_remove(found, max_bytes=300, now_s=NOW)) == ["old", "mid"]  # 650 → 550 → 250 bytes
    assert names(to_remove(found, max_bytes=250, now_s=NOW)) == ["old", "mid"]  # exactly the budget stays
    assert names(to_remove(found, unused_days=5, max_bytes=0, now_s=NOW)) == ["old", "mid", "new", "newest"]
    assert names(to_remove(found, unused_days=5, max_bytes=10_000, now_s=NOW)) == ["old", "mid"]


def test_only_stale_temporaries_are_removed(tmp_path):
    now = time.time()
    _file(tmp_path, ".k.npz.abc.tmp", 5, now, now - STALE_TMP_S - 60)
    _file(tmp_path, ".k.npz.def.tmp", 5, now, now - 10)  # a write going on
    assert [e.path.name for e in stale_temporaries(tmp_path, now)] == [".k.npz.abc.tmp"]


def test_remove_skips_what_is_gone_and_counts_the_bytes_freed(tmp_path):
    kept = _file(tmp_path, "kept.npz", 7, NOW, NOW)
    gone = entries(tmp_path)
    kept.unlink()
    assert remove(gone) == 0
    chosen = [Entry(_file(tmp_path, "x.npz", 11, NOW, NOW), 11, NOW)]
    assert remove(chosen) == 11 and not (tmp_path / "x.npz").exists()


def test_the_command_reports_lists_and_removes(tmp_path, capsys):
    now = time.time()
    _file(tmp_path, "old.npz", 2_000_000, now - 40 * DAY, now - 40 * DAY)
    _file(tmp_path, "new.npz", 1_000_000, now - DAY, now - DAY)
    assert main(["cache", "--dir", str(tmp_path)]) == 0
    assert "2 entries, 0.00 GB, last used 1.0 to 40.0 days ago" in capsys.readouterr().out
    assert main(["cache", "--dir", str(tmp_path), "--unused-days", "30", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "would remove old.npz" in out and "would remove new.npz" not in out and "would remove 1 files" in out
    assert (tmp_path / "old.npz").exists()
    assert main(["cache", "--dir", str(tmp_path), "--max-gb", "0.0015"]) == 0
    assert "removed 1 files" in capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new.npz"]


@pytest.mark.parametrize("argv, says", [(["--dir", "MISSING"], "--dir"), (["--max-gb", "-1"], "--max-gb must be ≥ 0"),
                                        (["--unused-days", "nan"], "--unused-days must be ≥ 0")])
def test_bad_input_is_one_line(argv, says, tmp_path, capsys):
    argv = [str(tmp_path / a) if a == "MISSING" else a for a in argv]
    assert main(["cache", "--dir", str(tmp_path), *argv] if "--dir" not in argv else ["cache", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err
