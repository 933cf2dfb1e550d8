"""Re-score the test split on today's captures with the shipped weights, without retraining (issue 29:
DeP as the paper ran it, beside DeP with the exact kernel).

    python -m restore.studies.rescore OUT [--write RESULTS.md] [--no-networks]

Makes (or resumes) only the test items of `udc-render results --budget cpu`'s physical dataset (the same
job: ids, images and seeds; restore.studies.datasets) under today's physical profile in OUT/dataset_physical,
scores input, DeP (the paper's computed PSF), DeP (exact kernel) and the carried models of
the shipped slot of restore/trained (trained on the captures of their RESULTS.md run, not on these) into OUT/eval
(restore.studies.scoring.evaluate_rows, which resumes), and writes OUT/rescore.md: the paper-protocol
table with a header that says what changed (--no-networks: input and the two DeP rows only; the networks
are retrained when RESULTS.md is regenerated). With --write, that section replaces the one between
RESCORE_BEGIN and RESCORE_END in the document (appended before the held-out section the first time); the
rest of the document stays as its run wrote it, until `udc-render results` regenerates it.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

from restore.studies.budgets import BUDGETS, DISPLAYS, ROWS, shipped_folder
from udc_render.io.files import save_text

RESCORE_BEGIN, RESCORE_END = "<!-- rescore: begin -->", "<!-- rescore: end -->"


def shipped_models(carry: Path | None = None) -> dict:
    """{(row, display): model.pt} of every carried model that exists in `carry` (the shipped slot unless given)."""
    carry = carry or shipped_folder()
    return {(row, d): carry / f"{row}_{d}" / "model.pt" for row, _, _ in ROWS for d in DISPLAYS
            if (carry / f"{row}_{d}" / "model.pt").is_file()}


def make_test_split(out: Path, progress: bool = True) -> Path:
    """The cpu budget's physical dataset, test items only, made or resumed in out/dataset_physical."""
    from restore.studies.datasets import dataset_job
    from udc_render.dataset import run_dataset
    b = BUDGETS["cpu"]
    folder = out / "dataset_physical"
    run_dataset(dataset_job("physical", b["sensor_px"], folder, tuple(b["items"])), progress=progress, splits=("test",))
    return folder


def spent_seconds(data: Path, ev: Path) -> float:
    """The items' seconds (timing.jsonl) plus the rows' scoring seconds (row_seconds.json), over every resume."""
    items = [json.loads(line)["seconds"] for line in (data / "timing.jsonl").read_text().splitlines() if line.strip()]
    return sum(items) + sum(json.loads((ev / "row_seconds.json").read_text()).values())


def section(results: dict, seconds: float, data: Path, networks: bool = True) -> str:
    """The re-scored table as a RESULTS.md section."""
    from restore.evaluate import protocol_table
    synth = json.loads(next(data.rglob("synth.json")).read_text())
    profile = synth.get("profile") or {}
    return "\n".join([
        RESCORE_BEGIN, "## Re-scored on today's captures (test split)", "",
        f"The test split's {BUDGETS['cpu']['items'][2]} items made again under today's physical profile "
        f"({json.dumps(profile.get('applied', {}), sort_keys=True)}) and scored by "
        "`python -m restore.studies.rescore OUT --write RESULTS.md` "
        f"({seconds / 3600:.2f} h of items and scoring on this machine, summed over resumes). "
        "'dep' deconvolves with the paper's computed PSF (its recipe "
        "at 640 / 520 / 450 nm, as the paper's DeP did, l.277); 'dep_exact' (DeP (exact kernel)) with the "
        "camera-weighted channel kernels, the upper bound a good PSF gives; the table above this section calls "
        "the latter 'dep'. " + ("The networks are the shipped weights, trained on the captures of the run above, "
                                 "not on these: they are retrained when RESULTS.md is regenerated." if networks else
                                 "The networks are not re-scored here (`--no-networks`): they are retrained on "
                                 "the final profile when RESULTS.md is regenerated."), "",
        protocol_table(results, "paper"), "", RESCORE_END])


def write_into(document: Path, text: str) -> None:
    """Replace the re-score section of `document`, or insert it before its held-out section (else at the end)."""
    doc = document.read_text()
    if RESCORE_BEGIN in doc:
        head, rest = doc.split(RESCORE_BEGIN, 1)
        doc = head + text + rest.split(RESCORE_END, 1)[1]
    elif "\n## Held-out photographs" in doc:
        head, rest = doc.split("\n## Held-out photographs", 1)
        doc = head + "\n" + text + "\n\n## Held-out photographs" + rest
    else:
        doc = doc.rstrip("\n") + "\n\n" + text + "\n"
    save_text(document, doc)


def rescore(out: Path, write: Path | None = None, progress: bool = True, networks: bool = True) -> str:
    """Make the test split, score every row (networks: also the shipped models), write out/rescore.md (and
    into `write`); returns the section."""
    from restore.studies.scoring import evaluate_rows
    data = make_test_split(out, progress)
    results = evaluate_rows(data, shipped_models() if networks else {}, out / "eval", progress)
    text = section(results, spent_seconds(data, out / "eval"), data, networks)
    save_text(out / "rescore.md", text + "\n")
    if write is not None:
        write_into(write, text)
    return text


def main(argv: list[str]) -> None:
    if not argv or argv[0].startswith("-"):
        sys.exit("usage: python -m restore.studies.rescore OUT [--write RESULTS.md] [--no-networks]")
    write = Path(argv[argv.index("--write") + 1]) if "--write" in argv else None
    print(rescore(Path(argv[0]), write, networks="--no-networks" not in argv))


if __name__ == "__main__":
    main(sys.argv[1:])
