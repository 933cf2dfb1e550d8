"""The studies' shared report helpers: number formatting, markdown tables, timing, the machine line,
the CSV / markdown / PNG writers and the annotated log-log error-versus-time plot."""
from __future__ import annotations

import contextlib
import math
import os
import platform
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from udc_render.io.files import csv_text, save_text
from udc_render.io.plots import pyplot, save_plot  # noqa: F401 (re-exported: the studies import them from here)

# ----------------------------------------------------------------------------------------------
# Formatting


def fmt_cell(v, digits: int = 3) -> str:
    """A table cell: None and "" empty, True "**yes**", False empty, finite floats to `digits`
    significant figures, nan / ±inf and anything else as str(v)."""
    if v is None or v == "":
        return ""
    if isinstance(v, (bool, np.bool_)):
        return "**yes**" if v else ""
    if isinstance(v, (float, np.floating)):
        return f"{v:.{digits}g}" if math.isfinite(v) else str(v)
    return str(v)


def pct(v) -> str:
    """A fraction as a percentage to 3 significant figures (100 · v %); None and "" empty."""
    return "" if v is None or v == "" else f"{100 * v:.3g} %"


def duration(s) -> str:
    """Seconds in s below 90 s, min below 1.5 h, h above (2 significant figures); None as "?"."""
    if s is None:
        return "?"
    if s < 90:
        return f"{s:.2g} s"
    if s < 5400:
        return f"{s / 60:.2g} min"
    return f"{s / 3600:.2g} h"


def md_table(rows: list[dict], cols: list[tuple[str, str]], fmt: dict | None = None) -> list[str]:
    """Markdown table lines: one column per (key, header), each cell fmt[key](row.get(key)) (fmt_cell
    for keys not in fmt)."""
    fmt = fmt or {}
    out = ["| " + " | ".join(h for _, h in cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for r in rows:
        out.append("| " + " | ".join(fmt.get(k, fmt_cell)(r.get(k)) for k, _ in cols) + " |")
    return out


def load_average() -> tuple | None:
    """os.getloadavg() (1, 5, 15 min), None where the platform has none."""
    return os.getloadavg() if hasattr(os, "getloadavg") else None


def machine_text(elapsed_s: float) -> str:
    """'Total study time … s on N CPU cores (processor)'."""
    return (f"Total study time {elapsed_s:.0f} s on {os.cpu_count()} CPU cores "
            f"({platform.processor() or platform.machine()})")


# ----------------------------------------------------------------------------------------------
# Timing


@dataclass
class Timed:
    """The first run's result, wall and CPU seconds of every run, unique warning lines (if recorded)."""
    result: object
    seconds: list[float]
    cpu_seconds: list[float]
    warnings: list[str] = field(default_factory=list)


def timed(fn: Callable, repeats: int, *, seconds_of: Callable | None = None, repeat_below_s: float = math.inf,
          record_warnings: bool = False, tick: Callable | None = None) -> Timed:
    """Run fn() `repeats` times (runs after the first only while the first took < repeat_below_s).

    Wall seconds: seconds_of(result) when given (a run's own timer), else time.perf_counter around
    the call; CPU seconds: time.process_time (this process, all threads). record_warnings: warnings
    are caught ("category: message", each once) instead of shown. tick() after every run.
    """
    t = Timed(None, [], [])
    while len(t.seconds) < repeats and (not t.seconds or t.seconds[0] < repeat_below_s):
        with warnings.catch_warnings(record=True) if record_warnings else contextlib.nullcontext() as caught:
            if record_warnings:
                warnings.simplefilter("always")
            c0, t0 = time.process_time(), time.perf_counter()
            out = fn()
            wall = time.perf_counter() - t0
            t.cpu_seconds.append(time.process_time() - c0)
        t.seconds.append(seconds_of(out) if seconds_of else wall)
        for w in caught or ():
            line = f"{w.category.__name__}: {w.message}"
            if line not in t.warnings:
                t.warnings.append(line)
        if len(t.seconds) == 1:
            t.result = out
        del out
        if tick:
            tick()
    return t


# ----------------------------------------------------------------------------------------------
# Files and plots


def write_tables(out_dir: Path, stem: str, rows: list[dict], columns: list[str], markdown: str) -> None:
    """out_dir/stem.csv (the rows, `columns`) and out_dir/stem.md, each written atomically."""
    save_text(out_dir / f"{stem}.csv", csv_text(rows, columns))
    save_text(out_dir / f"{stem}.md", markdown)


def annotated_loglog(ax, seconds: list, errors: list, texts: list[str], label: str, lw: float):
    """One error-versus-time line on log-log axes, each point labelled with its text; returns the line."""
    line, = ax.loglog(seconds, errors, marker="o", ms=5, lw=lw, label=label)
    for t, e, text in zip(seconds, errors, texts):
        ax.annotate(text, (t, e), textcoords="offset points", xytext=(4, 3), fontsize=7, color=line.get_color())
    return line


def finish_axes(ax, title: str, xlabel: str, ylabel: str) -> None:
    """Title, axis labels, grid and legend of an error-versus-time panel (no minor tick labels on x)."""
    import matplotlib.ticker
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_title(title, fontsize=10)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=7, loc="best")
