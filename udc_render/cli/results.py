"""`udc-render results --budget {cpu,quick,paper} --write RESULTS.md`: dataset ─► training ─►
evaluation ─► faces ─► the document (restore.studies.results), resumable."""
from __future__ import annotations

from pathlib import Path

from restore.studies.budgets import default_carry
from restore.studies.results import BUDGETS, ordering_checks, run_results
from udc_render.cli.args import out_dir


def register(sub) -> None:
    p = sub.add_parser("results", help="dataset → train → evaluate (test split, held-out photographs) → face detection "
                                       "→ RESULTS.md (resumable)")
    p.add_argument("--out", type=Path, default=Path("out/results"), help="work folder [out/results]")
    p.add_argument("--budget", choices=tuple(BUDGETS), default="cpu",
                   help="cpu (2048 × 1024, 150/20/30 items per profile: hours on 2 cores; resumable), "
                        "quick (a smoke run), paper (400 epochs; a GPU) [cpu]")
    p.add_argument("--write", type=Path, help="also write the document here (e.g. RESULTS.md)")
    p.add_argument("--carry", type=Path,
                   help="keep each finished model here (float16 weights, a folder git can track) and bring it back "
                        "into a fresh --out (restore.studies.carry) "
                        "[cpu: the shipped slot, restore/trained/shipped.json; other budgets: none]")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(run=run)


def run(args) -> int:
    out_dir(args.out)
    carry = args.carry or default_carry(args.budget)
    if carry:
        out_dir(Path(carry), "--carry")
    r = run_results(args.out, args.budget, args.write, progress=not args.quiet, carry=carry and Path(carry))
    for claim, ok, v in ordering_checks(r["results"]):
        print(f"{'ok  ' if ok else 'FAIL'} {claim}: {v}")
    print(f"written: {args.out / 'RESULTS.md'}" + (f" and {args.write}" if args.write else ""))
    if r.get("stale_slot"):
        print(f"{carry} now ships (restore/trained/shipped.json); the models of the previous results are stale: "
              f"git rm -r restore/trained/{r['stale_slot']}")
    return 0
