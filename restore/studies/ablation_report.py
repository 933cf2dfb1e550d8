"""The conditioning ablation's report (restore.studies.ablation): ablation.json (the budget, every panel's row, the
summary), ablation.md (the budget, the means by panel family, each arm less the blind UNet, every panel) and
ablation.png (PSNR and level-matched PSNR by family and row, as bars).

A group's PSNR is the mean over its panels of each panel's mean paper PSNR (every panel scores the same images);
"level-matched" is restore.metrics.level_matched_psnr_db (each output channel's level solved with the truth, an
oracle): plain − level-matched is what the output's level and colour balance cost. The design chosen is the
conditioned arm (CONDITIONED) of the best plain PSNR over every held-out panel (the level is part of the task: the
description gives γ); the report says whether the level-matched PSNR picks the same.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from udc_render.io.files import save_json, save_text
from udc_render.io.plots import pyplot, save_plot
from udc_render.studies.report import duration, md_table

ARMS = {"unet": "UNet (randomized), blind", "wide": "unet-wide-fine, blind (the backbone's twin)",
        "level": "wiener-unet, neither part (x / γ)",
        "codes": "wiener-unet, kernel codes", "features": "wiener-unet, Wiener features",
        "both": "wiener-unet, both"}
ROWS = {"input": "input (packed RAW)", "dep": "DeP (the panel's kernels and γ)", **ARMS}
CONDITIONED = ("level", "codes", "features", "both")  # the wiener-unet arms: the choice is among them
GROUPS = {"all": "every held-out panel", "poled": "P-OLED draws", "toled": "T-OLED draws"}
TARGET_DB = 2.0  # issue 47: the conditioned model beats UNet (randomized) by ≥ 2 dB, plain and level-matched


def summary(rows: list[dict]) -> dict:
    """{group: {'panels': n, row: {'plain': dB, 'level': dB}}} over GROUPS' panels, and each arm less 'unet'."""
    out = {}
    for group in GROUPS:
        these = [r for r in rows if group == "all" or r["family"] == group]
        if not these:
            continue
        means = {k: {"plain": float(np.mean([r[f"psnr_{k}_db"] for r in these])),
                     "level": float(np.mean([r[f"psnr_{k}_level_db"] for r in these]))}
                 for k in ROWS if f"psnr_{k}_db" in these[0]}
        gains = {a: {s: means[a][s] - means["unet"][s] for s in ("plain", "level")} for a in ARMS if a != "unet"}
        out[group] = {"panels": len(these), "means": means, "minus_unet": gains,
                      "panels_above_unet": {a: {s: sum(_diff(r, a, "unet", s) > 0 for r in these)
                                                for s in ("plain", "level")} for a in gains}}
    return out


def _diff(row: dict, a: str, b: str, kind: str) -> float:
    """A panel's PSNR of row a less row b (kind 'plain' or 'level')."""
    suffix = "_level" if kind == "level" else ""
    return row[f"psnr_{a}{suffix}_db"] - row[f"psnr_{b}{suffix}_db"]


def paired(rows: list[dict], a: str, b: str) -> dict:
    """Arm a against arm b panel by panel: {kind: {'mean', 'sd' (n − 1), 'min', 'max', 'above' (panels a > b)}}."""
    out = {}
    for kind in ("plain", "level"):
        d = np.array([_diff(r, a, b, kind) for r in rows])
        out[kind] = {"mean": float(d.mean()), "sd": float(d.std(ddof=1)) if d.size > 1 else 0.0,
                     "min": float(d.min()), "max": float(d.max()), "above": int((d > 0).sum())}
    return out


def choice(s: dict, rows: list[dict]) -> dict:
    """The chosen conditioned arm (module doc), the level-matched PSNR's pick, the issue's 2 dB target at this
    budget for the chosen arm, and the chosen arm against the runner-up and against the blind UNet panel by panel
    (paired)."""
    gains = {a: g for a, g in s["all"]["minus_unet"].items() if a in CONDITIONED}
    ranked = sorted(gains, key=lambda a: -gains[a]["plain"])
    level = max(gains, key=lambda a: gains[a]["level"])
    return {"chosen": ranked[0], "level_pick": level, "gain_db": gains[ranked[0]],
            "target_met": all(gains[ranked[0]][k] >= TARGET_DB for k in ("plain", "level")),
            "runner_up": ranked[1], "against_runner_up": paired(rows, ranked[0], ranked[1]),
            "against_unet": paired(rows, ranked[0], "unet"), "against_wide": paired(rows, ranked[0], "wide")}


def _db(v) -> str:
    return "" if v is None else f"{v:.2f}"


def _signed(v) -> str:
    return "" if v is None else f"{v:+.2f}"


def markdown(result: dict, s: dict, c: dict) -> str:
    b, t = result["budget"], result["times"]
    lines = [f"# The conditioning ablation (CPU budget, training seed {b['seeds']['train']})", "",
             f"Budget `{b['name']}`: {b['sensor_px'][0]} × {b['sensor_px'][1]} px of {b['pitch_um']} µm, bands "
             f"{b['bands_nm']} nm, {b['field_phases']} × {b['field_phases']} field phases; {b['train_images']} "
             f"training and {b['val_images']} validation images (colour dead leaves); {len(b['panels']['random'])} "
             f"randomized training panels (seed {b['seeds']['randomize']}), {len(b['panels']['heldout'])} held-out "
             f"(seed {b['seeds']['heldout']}); every arm {b['steps']} steps of {b['batch']} crops of "
             f"{b['crop_px']} px, "
             f"lr {b['lr']} halved at half, gradient clip {b['clip_grad_norm']}, training seed {b['seeds']['train']}.",
             "", "Wall time: " + ", ".join(f"{k} {duration(v)}" for k, v in t.items()) + ".", ""]
    arms = [{"arm": f"`{a}`", "what": ARMS[a], "params": f"{result['parameters'][a]:,}",
             "loss": result["train"][a].get("final_loss"), "seconds": duration(result["train"][a].get("seconds"))}
            for a in ARMS]
    lines += md_table(arms, [("arm", "arm"), ("what", "model"), ("params", "parameters"),
                             ("loss", "final training loss"), ("seconds", "training")]) + [""]
    for group, title in GROUPS.items():
        if group not in s:
            continue
        g = s[group]
        table = [{"row": ROWS[k], "plain": _db(m["plain"]), "level": _db(m["level"]),
                  "dp": _signed(g["minus_unet"].get(k, {}).get("plain")),
                  "dl": _signed(g["minus_unet"].get(k, {}).get("level")),
                  "above": "/".join(str(v) for v in g["panels_above_unet"].get(k, {}).values())}
                 for k, m in g["means"].items()]
        lines += [f"## {title} ({g['panels']} panels)", ""] + md_table(
            table, [("row", "row"), ("plain", "PSNR (dB)"), ("level", "level-matched"), ("dp", "− blind UNet"),
                    ("dl", "− blind UNet, level-matched"), ("above", "panels above it (plain/level)")]) + [""]
    gain = c["gain_db"]
    lines += ["## Choice", "",
              f"Best conditioned arm by plain PSNR on every held-out panel: `{c['chosen']}` ({gain['plain']:+.2f} dB "
              f"over the blind UNet, {gain['level']:+.2f} dB level-matched); by level-matched PSNR: "
              f"`{c['level_pick']}`. The issue's target (≥ {TARGET_DB:g} dB, plain and level-matched) at this "
              f"budget: {'met' if c['target_met'] else 'not met'}.", ""]
    for other, p in ((c["runner_up"], c["against_runner_up"]), ("unet", c["against_unet"]),
                     ("wide", c["against_wide"])):
        lines.append(f"- `{c['chosen']}` − `{other}` panel by panel: " + "; ".join(
            f"{kind} {v['mean']:+.2f} ± {v['sd']:.2f} dB (sd over panels; {v['min']:+.2f} to {v['max']:+.2f}), "
            f"above on {v['above']} of {len(result['rows'])}" for kind, v in p.items()))
    lines += ["", "## Every panel", ""]
    keys = [k for k in ROWS if f"psnr_{k}_db" in result["rows"][0]]
    panel_rows = [{"panel": r["panel"], "family": r["family"], "d": f"{r['distance_mm']:.2f}",
                   **{k: f"{r[f'psnr_{k}_db']:.2f} / {r[f'psnr_{k}_level_db']:.2f}" for k in keys}}
                  for r in result["rows"]]
    lines += md_table(panel_rows, [("panel", "panel"), ("family", "family"), ("d", "d (mm)")]
                      + [(k, f"{k} (plain / level)") for k in keys])
    return "\n".join(lines) + "\n"


def figure(s: dict, path: Path) -> None:
    """PSNR and level-matched PSNR per group (GROUPS) and row (ROWS), as bars."""
    plt = pyplot()
    groups = [g for g in GROUPS if g in s]
    keys = list(s[groups[0]]["means"])
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=True)
    width = 0.8 / len(keys)
    for ax, kind, title in zip(axes, ("plain", "level"), ("PSNR (paper protocol)", "level-matched PSNR")):
        for j, k in enumerate(keys):
            values = [s[g]["means"][k][kind] for g in groups]
            ax.bar(np.arange(len(groups)) + (j - (len(keys) - 1) / 2) * width, values, width, label=ROWS[k])
        ax.set_xticks(range(len(groups)), [f"{GROUPS[g]}\n({s[g]['panels']})" for g in groups], fontsize=8)
        ax.set_title(title, fontsize=9)
        ax.grid(axis="y", alpha=0.3)
    lo = min(s[g]["means"][k][kind] for g in groups for k in keys for kind in ("plain", "level"))
    axes[0].set_ylim(max(0.0, np.floor(lo) - 1), None)
    axes[0].set_ylabel("dB")
    axes[1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    save_plot(fig, path)


def write_report(out: Path, result: dict) -> dict:
    """ablation.json, ablation.md and ablation.png in `out` (module doc); returns the summary and the choice."""
    s = summary(result["rows"])
    c = choice(s, result["rows"])
    save_json(out / "ablation.json", {**result, "summary": s, "choice": c})
    save_text(out / "ablation.md", markdown(result, s, c))
    figure(s, out / "ablation.png")
    return {"summary": s, "choice": c}
