"""study gap (udc_render.studies.gap): the light-moved measure, the summary against the base and the verdict."""
import json
from dataclasses import replace

import numpy as np
import pytest

from udc_render.studies.gap import Shot, versus
from udc_render.studies.gap_report import summarise, verdict


def _shot(clean, packed=None, gt=None):
    clean = np.asarray(clean, np.float32)
    return Shot(packed if packed is not None else clean, clean, gt if gt is not None else clean, np.ones(4), 0.0)


def test_light_moved_is_the_l1_share_of_the_base():
    rng = np.random.default_rng(0)
    off = rng.uniform(0.1, 0.5, (4, 32, 32)).astype(np.float32)
    veil = np.full_like(off, 0.05 * off.mean())  # 5 % of the light added uniformly
    m = versus(_shot(off + veil), _shot(off))
    assert m["light_moved"] == pytest.approx(0.05, rel=1e-5)
    assert np.isfinite(m["capture_vs_base_db"])
    g = versus(_shot(off, gt=off * 0 + 1.0), _shot(off, gt=off * 0 + 0.5), "gt")
    assert g["light_moved"] == pytest.approx(1.0)


def _row(row, kind, dep, display="poled", content="dead leaves"):
    return {"row": row, "kind": kind, "display": display, "content": content, "image": "x", "level": 0.1,
            "input_db": 15.0, "dep_db": dep, "synth_s": 1.0, "dep_s": 1.0}


def test_verdict_names_an_effect_that_costs_dep_six_db():
    rows = [_row("physical, every effect off", "base", 23.0), _row("haze on", "effect", 16.5),
            _row("dead and hot pixels on", "effect", 22.6), _row("physical (every default)", "profile", 16.0)]
    s = summarise(rows)
    assert {r["row"]: round(r["dep_change_db"], 6) for r in s}["haze on"] == -6.5
    text = verdict(s)
    assert "haze on (-6.50 dB)" in text and "dead and hot" not in text


def test_verdict_says_none_when_no_effect_reaches_the_shortfall():
    rows = [_row("physical, every effect off", "base", 23.0), _row("haze on", "effect", 22.0),
            _row("physical (every default)", "profile", 21.5)]
    text = verdict(summarise(rows))
    assert "No effect measured here makes DeP 6–10 dB worse" in text
    assert "haze on: -1.00 dB" in text and "-1.50 dB" in text


@pytest.mark.slow
def test_quick_study_writes_its_tables(tmp_path):
    """`udc-render study gap --quick` (minutes): every file, a row per effect and display, finite scores."""
    from udc_render.studies.gap import run_study
    from udc_render.studies.gap_effects import EFFECTS
    rows = run_study(tmp_path, quick=True, progress=False)
    assert {p.name for p in tmp_path.iterdir()} >= {"study_gap.csv", "study_gap.md", "study_gap.png"}
    assert sum(r["kind"] == "effect" for r in rows) == 2 * 2 * len(EFFECTS)  # 2 images × 2 displays
    assert all(np.isfinite(r["dep_db"]) and np.isfinite(r["input_db"]) for r in rows)


def test_rows_log_resumes_and_ignores_a_torn_line(tmp_path):
    from udc_render.studies.gap import read_rows
    log = tmp_path / "rows_full.jsonl"
    log.write_text('{"image": "a", "rows": [{"row": "x"}]}\n{"image": "b", "rows": [{"ro')
    assert read_rows(log) == {"a": [{"row": "x"}]}
    assert read_rows(tmp_path / "none.jsonl") == {}


def test_dep_candidates_are_compared_with_the_captures_they_restore_and_off_effects_are_marked():
    """A DeP candidate runs on the shipped profile's captures: its change is against that row, not the bare
    base; a hit by an effect the physical profile leaves off says so, with its evidence."""
    from udc_render.studies.gap_effects import EFFECTS
    off = next(e for e in EFFECTS if not e.default_on)
    rows = [_row("physical, every effect off", "base", 23.0), _row("physical (every default)", "profile", 22.0),
            _row("DeP: exact kernel", "dep", 22.5), _row(f"{off.name} on", "effect", 15.0)]
    s = {r["row"]: r["dep_change_db"] for r in summarise(rows)}
    assert s["DeP: exact kernel"] == pytest.approx(0.5) and s["physical (every default)"] == pytest.approx(-1.0)
    assert f"{off.name} on (-8.00 dB; off in physical: {off.evidence})" in verdict(summarise(rows))


@pytest.fixture(scope="module")
def quick_setups():
    from udc_render.studies.gap import base_setups
    return base_setups((64, 32))


@pytest.fixture
def fake_gap(monkeypatch, quick_setups, tmp_path):
    """study gap on two --images files with its costly parts replaced: the quick setups (a test may change them),
    one row per image made from the image and the item that seeds its noise, and no report; returns (the study
    module, the setups in use, the rows_for_image calls, the two images)."""
    from udc_render.studies import gap
    setups, calls = dict(quick_setups), []

    def rows_for_image(image, content, item, setups_, bar, rank):
        calls.append((image, item))
        return [{"image": image, "row": "physical, every effect off", "kind": "base", "display": "poled",
                 "content": content, "dep_db": float(item % 997)}]
    monkeypatch.setattr(gap, "base_setups", lambda sensor_px: setups)
    monkeypatch.setattr(gap, "rows_for_image", rows_for_image)
    monkeypatch.setattr(gap, "write_report", lambda *a: None)
    monkeypatch.setitem(gap.QUICK, "content", ())
    monkeypatch.setitem(gap.QUICK, "photographs", ())
    images = []
    for name, value in (("a.png", 10), ("b.png", 200)):
        (tmp_path / "img").mkdir(exist_ok=True)
        path = tmp_path / "img" / name
        path.write_bytes(bytes([value]) * 64)  # the study reads the file's bytes only to know it
        images.append(str(path))
    return gap, setups, calls, images


def by_image(rows):
    return {r["image"]: r for r in rows}


def test_reordered_images_keep_their_noise_and_their_logged_rows(fake_gap, tmp_path):
    """An image's noise follows the image, not its place in --images; a reordered resume reuses every row."""
    gap, _, calls, (a, b) = fake_gap
    first = gap.run_study(tmp_path / "one", quick=True, images=(a, b), progress=False)
    items = dict(calls)
    assert len(calls) == 2 and items[a] != items[b]
    again = gap.run_study(tmp_path / "one", quick=True, images=(b, a), progress=False)
    assert len(calls) == 2 and by_image(again) == by_image(first)  # nothing recomputed
    fresh = gap.run_study(tmp_path / "two", quick=True, images=(b, a), progress=False)
    assert dict(calls[2:]) == items and by_image(fresh) == by_image(first)


def test_same_bytes_elsewhere_are_the_same_image(fake_gap, tmp_path):
    gap, *_ = fake_gap
    (tmp_path / "x.png").write_bytes(b"\x01" * 64)
    (tmp_path / "y.png").write_bytes(b"\x01" * 64)
    (tmp_path / "z.png").write_bytes(b"\x02" * 64)
    ids = [gap.image_identity(str(tmp_path / n)) for n in ("x.png", "y.png", "z.png")]
    assert ids[0] == ids[1] != ids[2] and gap.image_item(ids[0]) != gap.image_item(ids[2])
    assert gap.image_identity("pattern:dead_leaves_colour:101") == "pattern:dead_leaves_colour:101"


def test_a_changed_setting_recomputes_the_logged_rows_and_says_so(fake_gap, tmp_path, capsys):
    gap, setups, calls, images = fake_gap
    gap.run_study(tmp_path, quick=True, images=tuple(images), progress=False)
    gap.run_study(tmp_path, quick=True, images=tuple(images), progress=False)
    assert len(calls) == 2 and "recomputed" not in capsys.readouterr().out
    bare = setups["bare"]
    setups["bare"] = replace(bare, cfg=replace(bare.cfg, exposure_s=0.01))
    gap.run_study(tmp_path, quick=True, images=tuple(images), progress=False)
    assert len(calls) == 4
    assert "study gap: 2 logged rows in" in capsys.readouterr().out
    assert len(gap.read_log(tmp_path / "rows_quick.jsonl")) == 2  # the stale entries left the log


def test_a_log_without_fingerprints_is_recomputed(fake_gap, tmp_path, capsys):
    gap, _, calls, (a, b) = fake_gap
    old = {"image": a, "rows": [{"image": a, "row": "x", "dep_db": 1.0}], "seconds": 1.0}  # the format before
    (tmp_path / "rows_quick.jsonl").write_text(json.dumps(old) + "\n")
    rows = gap.run_study(tmp_path, quick=True, images=(a, b), progress=False)
    assert [c[0] for c in calls] == [a, b] and by_image(rows)[a]["row"] != "x"
    assert "study gap: 1 logged row in" in capsys.readouterr().out
