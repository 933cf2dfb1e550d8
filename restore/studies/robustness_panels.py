"""How many randomized panels a restorer needs to generalise (the question behind `random_panels`): UNet
(randomized) trained with the robustness study's recipe on the first N panels of its randomized bank, scored on
the study's held-out draws, default P-OLED and T-OLED, beside the study's own models.

    python -m restore.studies.robustness_panels OUT [--counts 4,8] [--captures] [--seeds 1] [--quick]

OUT is a `udc-render study robustness` folder of the same budget (finished first, or resumed: its banks, clean
images, models and scores). Draws are independent per panel index (udc_render.dataset.randomize.draw_panel), so
the first N panels of the bank are a draw of N panels; the study's own randomized model is N = train_panels. Each
N trains in OUT/train/randomized_n<N> (the same seeds, steps and images; restore.train resumes it), its scores go
to OUT/panels_scores.jsonl (a row per (N, set, panel), kept on a re-run under the same fingerprint: run_fingerprint,
of the run's model file, the set's bank, the validation images and the score seed) and the report to
OUT/study_robustness_panels.{md,csv,png}. The validation pairs are the study's (panel_pairs, SCORE_SEED), so
N = train_panels reads the study's own scores. --captures also trains N = train_panels with a capture per crop
(restore.captures: each crop's own sensor and exposure from randomize `default`, the distributions the bank was
drawn from) in OUT/train/randomized_captures: what a bank's per-panel sensor and brightness cost. --seeds S,…
trains N = train_panels again with training seed S (its initial weights, crops and noise; the same panels) in
OUT/train/randomized_seed<S>: the spread between two trainings, against which the other differences are read.
"""
from __future__ import annotations

import json
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch
from tqdm import tqdm

from restore.captures import load_capture_draws
from restore.metrics import level_matched_psnr_db, paper_metrics
from restore.online import clean_images, images_fingerprint
from restore.studies.options import parse_options
from restore.studies.robustness import (
    BUDGETS,
    SCORE_SEED,
    SCORES_FILE,
    TRAIN_SEED,
    Budget,
    panel_pairs,
    read_scores,
    run_study,
    train_settings,
)
from restore.studies.robustness_report import DEP, MODELS, SETS, two
from restore.train import load_model, predict, train
from udc_render.dataset.bank import Bank, read_bank
from udc_render.errors import UdcError
from udc_render.io.files import save_figure, save_text
from udc_render.io.plots import pyplot
from udc_render.studies.fingerprint import FIELD, digest, file_digest, stale_note
from udc_render.studies.report import duration, md_table, write_tables

COUNTS = (4, 8)  # with the study's own 16: a factor of two apart
PANEL_SETS = ("heldout", "default", "toled")
ROWS_FILE, STEM = "panels_scores.jsonl", "study_robustness_panels"
CAPTURES_RUN = "randomized_captures"
CAPTURES = {False: "the panel's", True: "its own"}  # a crop's sensor and exposure
COLUMNS = ["panels", "captures", "seed", "steps", "train_s",
           *(f"psnr_{s}{t}_db" for s in PANEL_SETS for t in ("", "_level"))]


def first_panels(bank: Bank, n: int) -> Bank:
    """The bank cut to its first n panels (module doc: a draw of n panels)."""
    if not 1 <= n <= len(bank.panels):
        raise UdcError(f"--counts: {n} panels: expected 1 to {len(bank.panels)} (the bank's randomized panels)")
    return Bank(bank.folder, bank.settings, bank.panels[:n])


class Run(NamedTuple):
    """One training of the study: the first `panels` panels, a capture per crop or the panel's, a training seed."""
    panels: int
    captures: bool = False
    seed: int = TRAIN_SEED


def run_of(row: dict) -> Run:
    """The Run of a score row (rows of the panel's captures and the study's seed leave those keys out)."""
    return Run(row["panels"], row.get("captures", False), row.get("seed", TRAIN_SEED))


def run_name(run: Run) -> str:
    """The training folder of a run: CAPTURES_RUN, randomized_seed<S> or randomized_n<N>."""
    if run.captures:
        return CAPTURES_RUN
    return f"randomized_seed{run.seed}" if run.seed != TRAIN_SEED else f"randomized_n{run.panels}"


def train_runs(out: Path, b: Budget, runs: list[Run], data: Path, progress: bool) -> dict:
    """{run: train summary} of the randomized UNet on each run's first N panels, with its seed and, where it says
    so, a capture per crop (restore.train resumes each)."""
    bank = read_bank(out / "banks" / "random")
    summaries = {}
    for run in runs:
        s = replace(train_settings(b, first_panels(bank, run.panels), data), seed=run.seed)
        if run.captures:
            s = replace(s, degrade={**s.degrade, "captures": load_capture_draws("default").describe()})
        summaries[run] = train(data, out / "train" / run_name(run), s, device="cpu", checkpoint_s=60.0,
                               val_every=max(1, b.epochs // 5), progress=progress, bank=bank.folder)
    return summaries


def run_fingerprint(out: Path, run: Run, bank: Bank, images: str) -> str:
    """The fingerprint of a run's rows on one set: the sha256 of its model.pt (retrained, it is another model),
    the set's bank (bank.json's fingerprint), the validation images and the score seed."""
    return digest({"model": file_digest(out / "train" / run_name(run) / "model.pt"), "bank": bank.fingerprint,
                   "images": images, "score_seed": SCORE_SEED})


def score_runs(out: Path, runs: list[Run], data: Path, progress: bool) -> list[dict]:
    """Every (run, set, panel) row of panels_scores.jsonl (logged rows are kept under their run_fingerprint only,
    the others recomputed)."""
    path = out / ROWS_FILE
    banks = {s: read_bank(out / "banks" / s) for s in PANEL_SETS}
    images, seen = clean_images(data, "val"), images_fingerprint(data)
    fingerprints = {(run, s): run_fingerprint(out, run, banks[s], seen) for run in runs for s in PANEL_SETS}
    logged = read_scores(path)
    rows = [r for r in logged if run_of(r) not in runs  # another invocation's run: not this one's to judge
            or r.get(FIELD) == fingerprints.get((run_of(r), r["set"]))]
    if note := stale_note("robustness panels", len(logged) - len(rows), path):
        print(note)
    done = {(run_of(r), r["set"], r["panel"]) for r in rows}
    todo = [(run, s, i) for run in runs for s in PANEL_SETS for i, p in enumerate(banks[s].panels)
            if (run, s, p.name) not in done]
    models = {run: load_model(out / "train" / run_name(run) / "model.pt", "cpu")[0] for run in {t[0] for t in todo}}
    for run, s, i in tqdm(todo, desc="score", unit="panel", disable=not progress):
        t0 = time.perf_counter()
        panel = banks[s].panels[i]
        scored = [(predict(models[run], x, torch.device("cpu")), gt) for x, gt in panel_pairs(banks[s], panel, images)]
        rows.append({"panels": run.panels, **({"captures": True} if run.captures else {}),
                     **({"seed": run.seed} if run.seed != TRAIN_SEED else {}), "set": s, "panel": panel.name,
                     "psnr_db": float(np.mean([paper_metrics(y, gt)["psnr_db_paper"] for y, gt in scored])),
                     "psnr_level_db": float(np.mean([level_matched_psnr_db(y, gt) for y, gt in scored])),
                     "seconds": round(time.perf_counter() - t0, 2), FIELD: fingerprints[(run, s)]})
        save_text(path, "".join(json.dumps(r) + "\n" for r in rows))
    return rows


def set_means(rows: list[dict], key: str) -> dict:
    """{set: the mean over its panels of rows[key]} for the sets of PANEL_SETS present."""
    return {s: float(np.mean([r[key] for r in rows if r["set"] == s])) for s in PANEL_SETS
            if any(r["set"] == s for r in rows)}


def summary(rows: list[dict], study: list[dict], b: Budget, trained: dict, study_train: dict) -> list[dict]:
    """One row per run (N ascending, then captures and seed): its steps and training seconds, and each set's paper
    and level-matched PSNR; the study's own randomized model is Run(b.train_panels)."""
    runs = {run: ([r for r in rows if run_of(r) == run], "psnr_db", "psnr_level_db", trained[run]) for run in trained}
    runs[Run(b.train_panels)] = (study, "psnr_randomized_db", "psnr_randomized_level_db", study_train)
    out = []
    for run in sorted(runs):
        mine, key, level, t = runs[run]
        row = {"panels": run.panels, "captures": CAPTURES[run.captures], "seed": run.seed, "steps": t.get("steps"),
               "train_s": t.get("seconds")}
        for tail, k in (("", key), ("_level", level)):
            row.update({f"psnr_{s}{tail}_db": v for s, v in set_means(mine, k).items()})
        out.append(row)
    return out


def references(study: list[dict]) -> dict:
    """{name: {set: PSNR}} of the study's specialist (UNet on the default P-OLED) and DeP with each panel's kernel."""
    return {MODELS["fixed"]: set_means(study, "psnr_fixed_db"), DEP: set_means(study, "psnr_dep_db")}


def markdown(table: list[dict], refs: dict, b: Budget) -> str:
    cols = [("panels", "panels N"), ("captures", "a crop's sensor and exposure"), ("seed", "training seed"),
            ("steps", "steps"), ("train_s", "training")]
    cols += [(f"psnr_{s}{t}_db", f"{SETS[s]}{' (level-matched)' if t else ''}") for t in ("", "_level")
             for s in PANEL_SETS]
    fmt = {c: two for c, _ in cols[5:]}
    fmt["train_s"] = duration
    ref_rows = [{"name": name, **{f"psnr_{s}_db": v for s, v in r.items()}} for name, r in refs.items()]
    return "\n".join([
        "# Study: how many randomized panels a restorer needs", "",
        f"UNet (randomized) of the robustness study's `{b.name}` budget trained on the first N of its "
        f"{b.train_panels} randomized panels, with the same seeds, steps and images, and scored (paper protocol's "
        "PSNR, dB) on the study's test sets: the held-out draws within the ranges, the default P-OLED and the "
        f"T-OLED. N = {b.train_panels} with the panel's sensor and exposure is the study's own model; 'its own': "
        "every crop draws its sensor and exposure (brightness included) from the ranges (`udc-render train "
        "--capture-draws`). Another training seed: the same panels, other initial weights, crops and noise. "
        "`python -m restore.studies.robustness_panels OUT [--captures] [--seeds S]`.", "",
        *md_table(table, cols, fmt), "",
        "The study's references on the same images (not trained on randomized panels):", "",
        *md_table(ref_rows, [("name", "row"), *((f"psnr_{s}_db", SETS[s]) for s in PANEL_SETS)],
                  {f"psnr_{s}_db": two for s in PANEL_SETS}), ""])


def plot(table: list[dict], refs: dict, path: Path) -> None:
    """PSNR per set against N (log axis), paper and level-matched, with DeP's held-out PSNR as a line."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    panel = [r for r in table if r["captures"] == CAPTURES[False] and r["seed"] == TRAIN_SEED]
    own = [r for r in table if r["captures"] == CAPTURES[True]]
    reseeded = [r for r in table if r["seed"] != TRAIN_SEED]
    n = [r["panels"] for r in panel]
    for ax, tail, title in ((axes[0], "", "paper PSNR"), (axes[1], "_level", "level-matched PSNR")):
        for s in PANEL_SETS:
            line, = ax.plot(n, [r.get(f"psnr_{s}{tail}_db") for r in panel], "o-", label=SETS[s])
            if own:
                ax.plot([r["panels"] for r in own], [r.get(f"psnr_{s}{tail}_db") for r in own], "*",
                        color=line.get_color(), ms=11, label=f"{SETS[s]}, a capture per crop")
            if reseeded:
                ax.plot([r["panels"] for r in reseeded], [r.get(f"psnr_{s}{tail}_db") for r in reseeded], "x",
                        color=line.get_color(), ms=9, label=f"{SETS[s]}, another training seed")
        ax.axhline(refs[DEP]["heldout"], color="0.4", ls="--", lw=0.8, label=f"{DEP}, held-out draws")
        ax.set_xscale("log", base=2)
        ax.set_xticks(n, [str(v) for v in n])
        ax.set_xlabel("randomized training panels N")
        ax.set_ylabel("PSNR (dB)")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8)
    fig.subplots_adjust(bottom=0.24, wspace=0.25)
    save_figure(fig, path)
    plt.close(fig)


def run_panels(out: Path, counts: list[int], quick: bool = False, progress: bool = True,
               captures: bool = False, seeds: tuple[int, ...] = ()) -> list[dict]:
    """The robustness study in `out` (finished or resumed), then each N of `counts` (with captures N =
    train_panels with a capture per crop; each seed of `seeds`, N = train_panels trained with it): trained, scored,
    reported."""
    b = BUDGETS["quick" if quick else "full"]
    counts = sorted(set(counts) - {b.train_panels})
    for n in counts:
        if not 1 <= n < b.train_panels:
            raise UdcError(f"--counts: {n} panels: expected 1 to {b.train_panels} (the study's randomized panels)")
    if TRAIN_SEED in seeds:
        raise UdcError(f"--seeds: {TRAIN_SEED}: the study's own training seed: expected others")
    result = run_study(out, quick, progress=progress)
    out = Path(out).resolve()
    data = out / "clean"
    runs = [Run(n) for n in counts] + ([Run(b.train_panels, True)] if captures else [])
    runs += [Run(b.train_panels, seed=int(v)) for v in seeds]
    trained = train_runs(out, b, runs, data, progress)
    rows = score_runs(out, runs, data, progress)
    study = [r for r in read_scores(out / SCORES_FILE) if r["set"] in PANEL_SETS]
    table = summary(rows, study, b, trained, result["train"]["randomized"])
    refs = references(study)
    write_tables(out, STEM, table, COLUMNS, markdown(table, refs, b))
    plot(table, refs, out / f"{STEM}.png")
    return table


def main(argv: list[str]) -> None:
    usage = "python -m restore.studies.robustness_panels OUT [--counts 4,8] [--captures] [--seeds 1] [--quick]"
    quick, captures = "--quick" in argv, "--captures" in argv
    pos, o = parse_options([a for a in argv if a not in ("--quick", "--captures")], usage)
    if len(pos) != 1:
        sys.exit(f"usage: {usage}")
    try:
        counts = [int(v) for v in o["counts"].split(",")] if "counts" in o else list(COUNTS)
        seeds = tuple(int(v) for v in o["seeds"].split(",")) if "seeds" in o else ()
    except ValueError:
        sys.exit(f"error: --counts = {o.get('counts')!r}, --seeds = {o.get('seeds')!r}: expected whole numbers "
                 "separated by commas, e.g. 4,8")
    try:
        table = run_panels(Path(pos[0]), counts, quick, captures=captures, seeds=seeds)
    except (UdcError, OSError) as exc:
        sys.exit(f"error: {exc}")
    print((Path(pos[0]) / f"{STEM}.md").read_text(), end="")
    print(f"N = {', '.join(str(r['panels']) for r in table)}")


if __name__ == "__main__":
    main(sys.argv[1:])
