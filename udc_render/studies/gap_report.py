"""The gap study's tables, verdict and figure (udc_render.studies.gap): means over each content group, the
change of DeP against the bare base, and the answer to the study's question.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from udc_render.studies.gap_effects import DEP_VARIANTS, EFFECTS
from udc_render.studies.report import duration, machine_text, md_table, pct, pyplot, save_plot, write_tables

COLUMNS = ["row", "display", "content", "images", "level", "input_db", "dep_db", "dep_change_db", "capture_vs_base_db",
           "light_moved", "paper_dep_db"]
HEADERS = {"row": "row", "display": "display", "content": "content", "images": "images",
           "level": "level (GT mean / white)", "input_db": "input PSNR (dB)", "dep_db": "DeP PSNR (dB)",
           "dep_change_db": "DeP − base (dB)", "capture_vs_base_db": "capture vs base (dB)",
           "light_moved": "light moved", "paper_dep_db": "paper's DeP, real panel (dB)"}
PAPER_DEP_DB = {"toled": 28.50, "poled": 16.97}  # the paper's DeP on its real panels, PSNR (l.380)
SHORTFALL_DB = (6.0, 10.0)  # how much worse the paper's real P-OLED is for DeP than ours (issue 29)


SHIPPED_ROW = "physical (every default)"  # the captures the DeP candidates restore


def summarise(rows: list[dict]) -> list[dict]:
    """Means over the images of each (row, display, content group), with DeP's change against the base row
    of the same display and image; a DeP candidate's against the shipped profile's row, whose captures it
    restores (one run on fewer images is compared on those)."""
    base = {(r["display"], r["image"]): r["dep_db"] for r in rows if r["kind"] == "base"}
    shipped = {(r["display"], r["image"]): r["dep_db"] for r in rows if r["row"] == SHIPPED_ROW}
    keys = list(dict.fromkeys((r["row"], r["display"], r["content"]) for r in rows))
    out = []
    for row, display, content in keys:
        rs = [r for r in rows if (r["row"], r["display"], r["content"]) == (row, display, content)]
        m = {k: float(np.mean([r[k] for r in rs])) for k in ("level", "input_db", "dep_db", "synth_s", "dep_s")}
        for k in ("capture_vs_base_db", "light_moved"):
            if k in rs[0]:
                m[k] = float(np.mean([r[k] for r in rs]))
        ref = shipped if rs[0]["kind"] == "dep" else base
        m["dep_change_db"] = float(np.mean([r["dep_db"] - ref[(r["display"], r["image"])] for r in rs]))
        out.append({"row": row, "display": display, "content": content, "images": len(rs), "kind": rs[0]["kind"],
                    "paper_dep_db": PAPER_DEP_DB[display], **m})
    return out


def verdict(summary: list[dict]) -> str:
    """Which effect or DeP candidate, if any, lowers DeP on the P-OLED's dead leaves by the real panel's
    6–10 dB; else the largest, and how far it falls short."""
    cands = [s for s in summary if s["display"] == "poled" and s["content"] == "dead leaves"
             and s["kind"] in ("effect", "dep", "profile") and s["row"] != "paper profile"]
    if not cands:
        return "No P-OLED dead-leaves rows were measured."
    singles = [s for s in cands if s["kind"] != "profile"] or cands
    worst = min(singles, key=lambda s: s["dep_change_db"])
    base = next(s for s in summary if s["display"] == "poled" and s["content"] == "dead leaves" and s["kind"] == "base")
    lo, _ = SHORTFALL_DB
    hits = [s for s in cands if -s["dep_change_db"] >= lo]
    head = (f"On the P-OLED's dead leaves, DeP (paper PSF) scores {base['dep_db']:.2f} dB on the bare physical model "
            f"(level {base['level']:.3f} of white); the paper's DeP scored {base['paper_dep_db']:.2f} dB on its real "
            f"panel.")
    if hits:
        names = ", ".join(f"{s['row']} ({s['dep_change_db']:+.2f} dB{_off_note(s['row'])})" for s in hits)
        return f"{head} Lowering DeP by 6 dB or more: {names}."
    return (f"{head} **No effect measured here makes DeP 6–10 dB worse.** The largest change is {worst['row']}: "
            f"{worst['dep_change_db']:+.2f} dB; the shipped profile with every default: "
            + next(f"{s['dep_change_db']:+.2f} dB." for s in cands if s["row"] == "physical (every default)"))


def _off_note(row: str) -> str:
    """'; off in physical: <its evidence>' for an effect the physical profile leaves off, else ''."""
    effect = next((e for e in EFFECTS if f"{e.name} on" == row), None)
    return "" if effect is None or effect.default_on else f"; off in physical: {effect.evidence}"


def plot(summary: list[dict], path: Path) -> None:
    """DeP's change against the base per effect and DeP candidate, per display and content group."""
    plt = pyplot()
    groups = list(dict.fromkeys((s["display"], s["content"]) for s in summary))
    names = list(dict.fromkeys(s["row"] for s in summary if s["kind"] != "base"))
    fig, ax = plt.subplots(figsize=(10, 0.35 * len(names) * len(groups) ** 0.5 + 2.5))
    h = 0.8 / len(groups)
    for gi, (display, content) in enumerate(groups):
        vals = [next((s["dep_change_db"] for s in summary if s["row"] == n and s["display"] == display
                      and s["content"] == content), np.nan) for n in names]
        ax.barh(np.arange(len(names)) + gi * h, vals, height=h, label=f"{display}, {content}")
    ax.axvspan(-SHORTFALL_DB[1], -SHORTFALL_DB[0], color="r", alpha=0.1, label="the real P-OLED's shortfall (6–10 dB)")
    ax.axvline(0, color="k", lw=0.8)
    ax.set_yticks(np.arange(len(names)) + 0.4 - h / 2, names, fontsize=8)
    ax.invert_yaxis()
    ax.set(xlabel="DeP PSNR − the bare base's (DeP candidates: − the shipped profile's) (dB, paper protocol)",
           title="What each effect does to DeP (paper PSF)")
    ax.grid(True, axis="x", alpha=0.3)
    ax.legend(fontsize=7, loc="lower left")
    save_plot(fig, path)


def effects_table() -> list[str]:
    rows = ([{"name": e.name, "on": "yes" if e.default_on else "no", "evidence": e.evidence} for e in EFFECTS]
            + [{"name": f"DeP: {v.name}", "on": "",
                "evidence": v.evidence + ("" if v.available() else " (not installed: not run)")} for v in DEP_VARIANTS])
    return md_table(rows, [("name", "effect"), ("on", "on in physical"), ("evidence", "evidence for its size")])


def write_report(out: Path, rows: list[dict], setups: dict, c: dict, seconds: float, quick: bool) -> None:
    """study_gap.csv (every image), study_gap.md (means, verdict, set-up) and study_gap.png."""
    summary = summarise(rows)
    fmt = {"level": lambda v: f"{v:.3f}", "input_db": lambda v: f"{v:.2f}", "dep_db": lambda v: f"{v:.2f}",
           "dep_change_db": lambda v: f"{v:+.2f}", "capture_vs_base_db": lambda v: "" if v is None else f"{v:.2f}",
           "light_moved": pct, "paper_dep_db": lambda v: f"{v:.2f}"}
    w, h = c["sensor_px"]
    md = ["# Gap: the effects beyond the paper's model, and DeP", "",
          f"{'Quick run. ' if quick else ''}The default monitor scene at {w} × {h} px, both displays, the paper "
          "protocol (linear, [0, 1] of the white level). Every row's DeP uses the paper's computed PSF "
          "(its recipe at 640 / 520 / 450 nm) and the γ of the bare model; 'DeP − base' is against the row "
          "'physical, every effect off' of the same display and content (a DeP candidate's: against "
          "'physical (every default)', whose captures it restores); 'capture vs base' and 'light moved' "
          "compare the effect's capture with that row's (same noise seed). Module doc: udc_render/studies/gap.py.", "",
          "## The answer", "", verdict(summary), "",
          "## Means per content group", "", *md_table(summary, [(k, HEADERS[k]) for k in COLUMNS], fmt), "",
          "## The effects", "", *effects_table(), "",
          f"{machine_text(seconds)} ({duration(seconds)}).", ""]
    write_tables(out, "study_gap", rows, sorted({k for r in rows for k in r}), "\n".join(md))
    plot(summary, out / "study_gap.png")
