"""study gap (udc_render.studies.gap): the light-moved measure, the summary against the base and the verdict."""
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
