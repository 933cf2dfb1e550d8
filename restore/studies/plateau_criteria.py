"""Where each plateau criterion would have stopped the training runs of a folder (restore.train.plateau_step).

A criterion is (fit_window, min_validations): the line through the validations of the last fit_window of the
steps, at least min_validations of them, must change by less than 0.1 dB over a fifth of the steps. The
criteria compared are the one restore.train used until 2026-11-25 (the last fifth, ≥ 4) and today's (the last
two fifths, ≥ 6). For every run folder (a loss.csv) the table gives the epoch and validation PSNR at which each
criterion stops it (— if never), the last validation, and today's trend at the end in dB per fifth of the
steps. On the carried cpu models the old criterion stopped three UNets that then gained 0.6–1.5 dB
(the third run's slot; docs/results_history.md, docs/figures/restore_studies/plateau_criteria.md).

    python -m restore.studies.plateau_criteria [FOLDER] [--threshold-db 0.1]

FOLDER holds run folders (out/results/train, a slot of restore/trained; the shipped slot when not given,
restore.studies.budgets.shipped_folder); prints a Markdown table.
"""
from __future__ import annotations

import sys
from pathlib import Path

from restore.studies.budgets import shipped_folder
from restore.studies.options import parse_options

CRITERIA = {"last fifth, ≥ 4 (until 2026-11-25)": (0.2, 4), "last two fifths, ≥ 6 (today)": (0.4, 6)}


def stops(loss_csv: Path, threshold_db: float = 0.1) -> dict:
    """{criterion: (epoch, val dB) or None, "end": (epoch, val dB), "trend_db": today's trend at the end}."""
    from restore.train import plateau_step, read_log, trend_db_per_fifth
    log = read_log(loss_csv)
    validated = {r["step"]: (int(r["epoch"]), r["val_psnr_db"]) for r in log if r["val_psnr_db"] is not None}
    if not validated:
        raise ValueError(f"{loss_csv}: no validation PSNR logged")
    row = {name: validated.get(plateau_step(log, threshold_db, *criterion)) for name, criterion in CRITERIA.items()}
    vals = [(step, psnr) for step, (_, psnr) in sorted(validated.items())]
    return {**row, "end": validated[vals[-1][0]], "trend_db": trend_db_per_fifth(vals)}


def _cell(stop: tuple | None) -> str:
    return "—" if stop is None else f"epoch {stop[0]}, {stop[1]:.2f} dB"


def markdown(folder: Path, threshold_db: float = 0.1) -> str:
    """One row per run folder under `folder` (module doc)."""
    runs = sorted(p.parent for p in Path(folder).glob("*/loss.csv"))
    if not runs:
        raise ValueError(f"{folder}: no run folder with a loss.csv")
    lines = [f"| run | {' | '.join(CRITERIA)} | last validation | trend at the end (dB per fifth) |",
             "|---|" + "---|" * (len(CRITERIA) + 2)]
    for run in runs:
        r = stops(run / "loss.csv", threshold_db)
        trend = "—" if r["trend_db"] is None else f"{r['trend_db']:+.2f}"
        lines.append(f"| {run.name} | {' | '.join(_cell(r[n]) for n in CRITERIA)} | {_cell(r['end'])} | {trend} |")
    return "\n".join(lines)


def main(argv: list[str]) -> None:
    usage = "python -m restore.studies.plateau_criteria [FOLDER] [--threshold-db 0.1]"
    pos, o = parse_options(argv, usage)
    if len(pos) > 1:
        sys.exit(f"usage: {usage}")
    try:
        print(markdown(Path(pos[0]) if pos else shipped_folder(), float(o.get("threshold_db", 0.1))))
    except (OSError, ValueError) as exc:
        sys.exit(f"error: {exc}")


if __name__ == "__main__":
    main(sys.argv[1:])
