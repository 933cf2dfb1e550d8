"""The robustness study's outputs (restore.studies.robustness): study_robustness.csv (one row per test set),
study_robustness.md (the budget and wall time, the drops side by side, every panel's scores) and
study_robustness.png (PSNR per set and row, and the drops, as bars). The rows: the input, DeP given the panel's
own kernel and γ (a reference that knows the panel), the same DeP on the captures without the sensor's noise (what
the noise costs it; no drop is taken for either) and the two UNets.

A set's PSNR is the mean of its panels' mean paper PSNR (every panel scores the same images); a model's drop on a
set is its PSNR there less its PSNR on the default panel (negative: worse than on the default panel). The same
for the level-matched PSNR (restore.metrics.level_matched_psnr_db: each channel's level solved per image with the
truth), which separates the error in the image's structure from a wrong level or colour balance.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from udc_render.errors import UdcError
from udc_render.io.files import save_figure
from udc_render.io.plots import pyplot
from udc_render.studies.report import duration, load_average, md_table, write_tables

MODELS = {"fixed": "UNet (default P-OLED)", "randomized": "UNet (randomized)",
          "conditioned": "conditioned (randomized, given the panel)"}
UNETS = ("fixed", "randomized")  # every budget's; 'conditioned' where the budget trains one (its rows then hold it)
SETS = {"default": "default P-OLED (d = 2 mm)", "heldout": "held-out draws within the ranges",
        "toled": "T-OLED (d = 2 mm)", "disordered": "disordered P-OLED",
        "micrograph": "micrograph-type layout (diamond tile)", "far": "P-OLED at d = 8 mm",
        "toled_far": "T-OLED at d = 8 mm"}
SHORT = {"default": "default\nP-OLED", "heldout": "held-out\ndraws", "toled": "T-OLED\n2 mm",
         "disordered": "disordered\nP-OLED", "micrograph": "micrograph\ntile", "far": "P-OLED\n8 mm",
         "toled_far": "T-OLED\n8 mm"}  # the figure's tick labels
DEP = "DeP (the panel's kernel)"  # restore.studies.robustness.dep_outputs: it knows the panel's kernels and γ
QUIET = "DeP, no noise"  # the same, on the captures without the sensor's noise, FPN and defects
ROWS = {"input": "input (packed RAW)", "dep": DEP, "dep_noiseless": QUIET, **MODELS}
COLUMNS = ["set", "panels", "images", "psnr_input_db", "psnr_dep_db", "psnr_dep_noiseless_db", "psnr_fixed_db",
           "drop_fixed_db", "psnr_randomized_db", "drop_randomized_db", "randomized_minus_fixed_db",
           "psnr_input_level_db", "psnr_dep_level_db", "psnr_dep_noiseless_level_db", "psnr_fixed_level_db",
           "drop_fixed_level_db", "psnr_randomized_level_db", "drop_randomized_level_db",
           "randomized_minus_fixed_level_db"]
CONDITIONED_COLUMNS = [f"{k}{t}_db" for t in ("", "_level")
                       for k in ("psnr_conditioned", "drop_conditioned", "conditioned_minus_randomized")]
COLOURS = {"input": "0.7", "dep": "0.35", "dep_noiseless": "0.55", "fixed": "tab:blue", "randomized": "tab:orange",
           "conditioned": "tab:green"}


def present(rows: list[dict]) -> list[str]:
    """The keys of ROWS that the score rows hold (the conditioned model's only where the budget trained it)."""
    return [k for k in ROWS if k not in MODELS or k in UNETS or (rows and f"psnr_{k}_db" in rows[0])]


def columns(rows: list[dict]) -> list[str]:
    """The CSV's columns: COLUMNS, and the conditioned model's where the rows hold it."""
    return COLUMNS + (CONDITIONED_COLUMNS if "conditioned" in present(rows) else [])


def summary_rows(rows: list[dict]) -> list[dict]:
    """One row per set present (in SETS' order): panels, images, each row's mean PSNR, both models' drops
    against their own default-panel PSNR (None without a default row) and randomized − fixed."""
    out, keys = [], present(rows)
    models = [k for k in keys if k in MODELS]
    for s in SETS:
        mine = [r for r in rows if r["set"] == s]
        if not mine:
            continue
        row = {"set": s, "panels": len(mine), "images": mine[0]["images"]}
        for k in keys:
            for tail in ("", "_level"):
                row[f"psnr_{k}{tail}_db"] = float(np.mean([r[f"psnr_{k}{tail}_db"] for r in mine]))
        out.append(row)
    base = next((r for r in out if r["set"] == "default"), None)
    for row in out:
        for tail in ("", "_level"):
            for k in models:
                key = f"psnr_{k}{tail}_db"
                row[f"drop_{k}{tail}_db"] = None if base is None else row[key] - base[key]
            row[f"randomized_minus_fixed{tail}_db"] = row[f"psnr_randomized{tail}_db"] - row[f"psnr_fixed{tail}_db"]
            if "conditioned" in models:
                row[f"conditioned_minus_randomized{tail}_db"] = (row[f"psnr_conditioned{tail}_db"]
                                                                 - row[f"psnr_randomized{tail}_db"])
    return out


def two(v) -> str:
    """A PSNR in dB to 0.01."""
    return f"{v:.2f}"


def db(v) -> str:
    """A signed difference in dB to 0.01 ('0.00' for one that rounds to zero; empty for None)."""
    if v is None:
        return ""
    return "0.00" if round(v, 2) == 0 else f"{v:+.2f}"


def budget_text(budget: dict, times: dict, train: dict, rows: list[dict]) -> list[str]:
    """The CPU budget: the recipe and the measured seconds per stage (summed over re-runs)."""
    w, h = budget["sensor_px"]
    scoring = sum(r["seconds"] for r in rows)
    total = sum(times.values()) + sum(t["seconds"] for t in train.values()) + scoring
    banks = sum(v for k, v in times.items() if k.startswith("bank "))
    load = load_average()
    lines = [
        f"- **Budget `{budget['name']}`**: UNet `{budget['model']}`, {budget['steps']} Adam steps each "
        f"({budget['epochs']} epochs × {budget['train_images']} images × {budget['crops_per_image']} crops / batch "
        f"{budget['batch']}), crops of {budget['crop_px']} px, lr {budget['lr']:g}, gradient clip "
        f"{budget['clip_grad_norm']}; {budget['train_images']} training and {budget['val_images']} validation "
        f"images of {w} × {h} px at {budget['pitch_um']:g} µm (bands {budget['bands_nm'] or 'the scene’s'}, "
        f"{budget['field_phases']} × {budget['field_phases']} field phases); {budget['train_panels']} randomized "
        f"training panels, {budget['heldout_panels']} held-out.",
        f"- **Wall time (measured, this machine, summed over re-runs)**: clean images "
        f"{duration(times.get('clean images', 0.0))}, banks {duration(banks)}, training "
        + ", ".join(f"{MODELS[k]} {duration(t['seconds'])}" for k, t in train.items())
        + f", scoring {duration(scoring)}; total {duration(total)} on {os.cpu_count()} CPU cores"
        + (f" (load average {load[1]:.1f} at the end)" if load else "") + ".",
        "- **Seeds**: " + ", ".join(f"{k} {v}" for k, v in budget["seeds"].items()) + ".",
    ]
    return lines


def markdown(result: dict) -> str:
    rows, summary = result["rows"], summary_rows(result["rows"])
    train = result["train"]
    lines = ["# Study: robustness of a restorer to the panel it meets", "",
             "Two UNets with the same recipe, steps, seeds and clean crops, degraded on the fly "
             "(`udc-render train --degrade online`): one on the `physical` profile's default P-OLED (d = 2 mm), "
             "one on randomized panels drawn from the documented ranges. Both scored with the paper protocol's "
             "PSNR (linear, clipped to [0, 1], border cropped; the input on its packed RAW) on the validation "
             "images degraded once through every panel of each set, with fixed seeds. Drop: the set's PSNR less "
             "the same model's on the default panel. DeP is given each panel's own kernels (the bank's, at the "
             "packed pitch) and γ: a reference that knows the panel, blind only to its field dependence; 'DeP, no "
             "noise' is the same on the captures without the sensor's noise, fixed-pattern noise and defects.", "",
             *budget_text(result["budget"], result["times"], train, rows),
             "", "## PSNR (dB) and drops", ""]
    if "conditioned" in present(rows):
        lines[2] += (" A third model, conditioned on the panel's description (restore.models_conditioned), trained "
                     "like the randomized UNet, restores each test panel with that panel's own description.")
    lines += psnr_table(summary, "")
    lines += ["", "## Level-matched PSNR (dB) and drops", "",
              "Each channel of each output (and of the input) scaled by its least-squares gain onto the truth "
              "before the paper protocol's PSNR (`restore.metrics.level_matched_psnr_db`): the level and colour "
              "balance solved per image with the truth, an oracle no restorer has. What is left is the error in "
              "the image's structure (blur, noise, artefacts); the table above less this one is what a wrong "
              "level or balance costs.", ""]
    lines += psnr_table(summary, "_level")
    lines += ["", "Validation PSNR at the end of training (each on its own training panels' validation): "
              + ", ".join(f"{MODELS[k]} {t['val_psnr_db']:.2f} dB after {t['steps']} steps"
                          for k, t in train.items() if t.get("val_psnr_db") is not None) + ".",
              "", "## Every panel", ""]
    pcols = [("set", "set"), ("panel", "panel"), ("family", "family"), ("distance_mm", "d (mm)"),
             *((f"psnr_{k}_db", "input" if k == "input" else ROWS[k]) for k in present(rows))]
    lines += md_table(rows, pcols, {**{f"psnr_{k}_db": two for k in present(rows)},
                                    "distance_mm": lambda v: f"{v:.2f}"})
    return "\n".join(lines) + "\n"


def psnr_table(summary: list[dict], tail: str) -> list[str]:
    """The sets' PSNR and drops (tail '': paper PSNR; '_level': level-matched) as a Markdown table."""
    cols = [("set", "test set"), ("panels", "panels"), (f"psnr_input{tail}_db", "input"), (f"psnr_dep{tail}_db", DEP),
            (f"psnr_dep_noiseless{tail}_db", QUIET),
            (f"psnr_fixed{tail}_db", MODELS["fixed"]), (f"drop_fixed{tail}_db", "drop"),
            (f"psnr_randomized{tail}_db", MODELS["randomized"]), (f"drop_randomized{tail}_db", "drop"),
            (f"randomized_minus_fixed{tail}_db", "randomized − default")]
    if summary and f"psnr_conditioned{tail}_db" in summary[0]:
        cols += [(f"psnr_conditioned{tail}_db", MODELS["conditioned"]), (f"drop_conditioned{tail}_db", "drop"),
                 (f"conditioned_minus_randomized{tail}_db", "conditioned − randomized")]
    return md_table(summary, cols, {"set": lambda s: SETS[s], f"psnr_input{tail}_db": two, f"psnr_dep{tail}_db": two,
                                    f"psnr_dep_noiseless{tail}_db": two, f"psnr_fixed{tail}_db": two,
                                    f"psnr_randomized{tail}_db": two, f"psnr_conditioned{tail}_db": two,
                                    f"drop_fixed{tail}_db": db, f"drop_randomized{tail}_db": db,
                                    f"drop_conditioned{tail}_db": db, f"randomized_minus_fixed{tail}_db": db,
                                    f"conditioned_minus_randomized{tail}_db": db})


def plot(summary: list[dict], path: Path) -> None:
    """Three panels: the paper and the level-matched PSNR per set (every row) and both models' drops, as grouped
    bars."""
    plt = pyplot()
    fig, (ax, cx, bx) = plt.subplots(1, 3, figsize=(19, 4))
    x = np.arange(len(summary))
    labels = [SHORT[r["set"]] for r in summary]
    keys = [k for k in ROWS if f"psnr_{k}_db" in summary[0]]
    models = [k for k in keys if k in MODELS]
    w, wd = 0.8 / len(keys), 0.76 / len(models)
    for i, k in enumerate(keys):
        at = x + (i - (len(keys) - 1) / 2) * w
        ax.bar(at, [r[f"psnr_{k}_db"] for r in summary], w, label=ROWS[k], color=COLOURS[k])
        cx.bar(at, [r[f"psnr_{k}_level_db"] for r in summary], w, label=ROWS[k], color=COLOURS[k])
    for i, k in enumerate(models):
        bx.bar(x + (i - (len(models) - 1) / 2) * wd, [r[f"drop_{k}_db"] or 0.0 for r in summary], wd,
               label=MODELS[k], color=COLOURS[k])
    top = 1.3 * max(r[f"psnr_{k}{t}_db"] for r in summary for k in keys for t in ("", "_level"))
    ax.set_ylim(0, top)  # room for the legend
    cx.set_ylim(0, top)
    bx.axhline(0, color="k", lw=0.8)
    for a, title, ylabel, where in ((ax, "paper PSNR per test set", "PSNR (dB)", "upper left"),
                                    (cx, "level-matched PSNR (level and balance solved with the truth)", "PSNR (dB)",
                                     "upper left"),
                                    (bx, "drop against the default panel", "ΔPSNR (dB)", "upper right")):
        a.set_xticks(x, labels, fontsize=8)
        a.set_title(title, fontsize=10)
        a.set_ylabel(ylabel)
        a.grid(axis="y", alpha=0.3)
        a.legend(fontsize=7, loc=where)
    save_figure(fig, path)
    plt.close(fig)


def write_report(out: Path, result: dict) -> None:
    """study_robustness.csv, .md and .png in `out`; every score must be finite."""
    bad = [(r["set"], r["panel"], k) for r in result["rows"] for k in present(result["rows"]) for t in ("", "_level")
           if not math.isfinite(r[f"psnr_{k}{t}_db"])]
    if bad:
        raise UdcError(f"study robustness: non-finite PSNR for {bad[0]} (and {len(bad) - 1} more)")
    summary = summary_rows(result["rows"])
    write_tables(Path(out), "study_robustness", summary, columns(result["rows"]), markdown(result))
    plot(summary, Path(out) / "study_robustness.png")
