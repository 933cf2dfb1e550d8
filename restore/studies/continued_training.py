"""Is a model's plateau the model's or the budget's? Continue a finished run past its stop.

The run's last checkpoint (weights, Adam state, epochs done, log) is copied into a new folder and
restore.train.train resumes it with the run's own settings except two: the epoch cap `--epochs`
(the learning rate is halved from ⌊epochs / 2⌋ on, so a cap at most twice the epochs done keeps the
run's final rate) and no plateau stop. Same data, crops, seed sequence and loop, so the continued
curve is the one the run would have drawn with a later cap. The run folder itself is not touched, and
the evaluation rows (restore.studies.results) still score the run's own model.pt.

    python -m restore.studies.continued_training out/results/train/unet_toled out/results/dataset_physical \\
        --epochs 112 --out out/continued/unet_toled

Resumable: run it again to go on. The new folder holds continued_from.json (the source run and its
settings), train.json, checkpoint.pt, loss.csv and loss.png (the whole curve, the run's part included).
Prints the validations after the run's stop.
"""
from __future__ import annotations

import dataclasses
import json
import shutil
import sys
from pathlib import Path

from restore.studies.options import parse_options
from udc_render.errors import UdcError
from udc_render.io.files import save_json


def continued_settings(run: Path, epochs: int):
    """(the run's TrainSettings with the cap `epochs` and no plateau stop, the run's epochs done)."""
    import torch

    from restore.train import TrainError, TrainSettings, checkpoint_errors
    path = run / "train.json"
    if not path.is_file() or not (run / "checkpoint.pt").is_file():
        raise TrainError(f"RUN = {str(run)!r}: expected a training run folder (train.json and checkpoint.pt)")
    old = TrainSettings(**json.loads(path.read_text()))
    with checkpoint_errors(run / "checkpoint.pt", "expected a checkpoint of `udc-render train`"):
        done = int(torch.load(run / "checkpoint.pt", map_location="cpu", weights_only=False)["epoch"])
    if epochs <= done:
        raise TrainError(f"--epochs = {epochs}: expected more than the run's {done} epochs done")
    return dataclasses.replace(old, epochs=epochs, plateau_db=None), done


def continue_run(run: Path, data: Path, out: Path, epochs: int, val_every: int = 4, progress: bool = True) -> list:
    """Continue `run` to `epochs` in `out` (resumes there); the log rows after the run's stop."""
    from restore.train import TrainError, data_fingerprint, read_log, train
    run, out = Path(run), Path(out)
    settings, done = continued_settings(run, epochs)
    if settings.data_fingerprint and data_fingerprint(data) != settings.data_fingerprint:
        raise TrainError(f"DATA = {str(data)!r}: not the dataset the run trained on (manifest sha256 "
                         f"{data_fingerprint(data)} ≠ {settings.data_fingerprint})")
    if out.resolve() == run.resolve():
        raise TrainError(f"--out = {str(out)!r}: must not be the run folder itself")
    source = out / "continued_from.json"
    record = {"run": str(run), "epochs_done": done, "settings": json.loads((run / "train.json").read_text())}
    same = ("epochs_done", "settings")  # not the run's path: run folders may move
    if source.is_file() and {k: json.loads(source.read_text()).get(k) for k in same} != {k: record[k] for k in same}:
        raise TrainError(f"{source}: this folder continues another run; use another --out")
    out.mkdir(parents=True, exist_ok=True)
    if not (out / "checkpoint.pt").is_file():
        shutil.copyfile(run / "checkpoint.pt", out / "checkpoint.pt.part")
        (out / "checkpoint.pt.part").replace(out / "checkpoint.pt")
        save_json(source, record)
    train(data, out, settings, val_every=val_every, progress=progress)
    return [r for r in read_log(out / "loss.csv") if r["epoch"] > done and r["val_psnr_db"] is not None]


def main(argv: list[str]) -> None:
    usage = ("python -m restore.studies.continued_training RUN DATA --epochs N --out FOLDER "
             "[--val-every 4]")
    pos, o = parse_options(argv, usage)
    if len(pos) != 2 or "epochs" not in o or "out" not in o:
        sys.exit(f"usage: {usage}")
    try:
        rows = continue_run(Path(pos[0]), Path(pos[1]), Path(o["out"]), int(o["epochs"]), int(o.get("val_every", 4)))
    except (UdcError, OSError, ValueError) as exc:
        sys.exit(f"error: {exc}")
    print("| epoch | step | lr | loss | val PSNR (dB) |\n|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['epoch']:.0f} | {r['step']:.0f} | {r['lr']:.0e} | {r['loss']:.4f} | {r['val_psnr_db']:.2f} |")


if __name__ == "__main__":
    main(sys.argv[1:])
