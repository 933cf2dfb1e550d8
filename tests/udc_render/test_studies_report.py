"""The studies' shared report helpers (udc_render/studies/report.py): exact cell formats, table text,
and the timing loop's repeat rule."""
import math
import warnings

import numpy as np

from udc_render.studies.report import duration, fmt_cell, md_table, pct, timed


def test_fmt_cell_numbers_bools_and_blanks():
    assert fmt_cell(0.000123) == "0.000123"
    assert fmt_cell(123456.0) == "1.23e+05"
    assert fmt_cell(np.float32(2.5)) == "2.5"
    assert fmt_cell(1 / 3, digits=5) == "0.33333"
    assert fmt_cell(math.inf) == "inf" and fmt_cell(-math.inf) == "-inf" and fmt_cell(math.nan) == "nan"
    assert fmt_cell(True) == "**yes**" and fmt_cell(np.bool_(True)) == "**yes**"
    assert fmt_cell(False) == "" and fmt_cell(None) == "" and fmt_cell("") == ""
    assert fmt_cell(64) == "64" and fmt_cell("128x64") == "128x64"


def test_pct_and_duration():
    assert pct(0.0123) == "1.23 %" and pct(None) == "" and pct("") == ""
    assert duration(None) == "?"
    assert duration(12.34) == "12 s"
    assert duration(600) == "10 min"
    assert duration(7200) == "2 h"


def test_md_table_exact_text():
    rows = [{"spp": 4, "err": 0.000123, "ok": True}, {"spp": 16, "err": None, "ok": False}]
    lines = md_table(rows, [("spp", "spp"), ("err", "error"), ("ok", "default")], {"err": pct})
    assert "\n".join(lines) == ("| spp | error | default |\n"
                                "|---|---|---|\n"
                                "| 4 | 0.0123 % | **yes** |\n"
                                "| 16 |  |  |")


def test_timed_repeats_records_warnings_and_ticks():
    calls, ticks = [], []

    def fn():
        calls.append(1)
        warnings.warn("coarse", RuntimeWarning)
        return len(calls)

    t = timed(fn, 3, record_warnings=True, tick=lambda: ticks.append(1))
    assert t.result == 1 and len(t.seconds) == len(t.cpu_seconds) == 3 and len(ticks) == 3
    assert t.warnings == ["RuntimeWarning: coarse"]  # each line once
    # a run's own timer; no repeat once the first run reaches repeat_below_s
    t = timed(lambda: {"seconds": 5.0}, 3, seconds_of=lambda r: r["seconds"], repeat_below_s=4.0)
    assert t.seconds == [5.0]
    t = timed(lambda: {"seconds": 1.0}, 3, seconds_of=lambda r: r["seconds"], repeat_below_s=4.0)
    assert t.seconds == [1.0, 1.0, 1.0] and t.warnings == []
