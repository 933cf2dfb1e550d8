"""A training run's files: its checkpoint (model, optimiser, epochs, steps, loss log; atomic, byte-stable), the
loss log's loss.csv and loss.png, and model.pt loaded back for evaluation (restore.train's run folder)."""
from __future__ import annotations

import csv
import io
from contextlib import contextmanager
from dataclasses import asdict
from pathlib import Path

import torch

from restore.models import build_model, model_config
from udc_render.errors import UdcError
from udc_render.io.files import atomic_path, csv_text, save_figure, save_text
from udc_render.io.plots import pyplot

LOG_COLUMNS = ["epoch", "step", "lr", "loss", "val_psnr_db", "seconds"]


class TrainError(UdcError):
    """Training settings or a run folder that cannot be used; one line."""


def pick_device(name: str = "auto") -> torch.device:
    """'auto': the GPU when one is present, else the CPU."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise TrainError(f"--device = {name!r}: no CUDA GPU here (use auto or cpu)")
    return torch.device(name)


def read_log(path: Path) -> list[dict]:
    """The loss log of a loss.csv (LOG_COLUMNS; an empty cell is None)."""
    with open(path, newline="") as f:
        return [{k: (float(v) if v != "" else None) for k, v in row.items()} for row in csv.DictReader(f)]


@contextmanager
def checkpoint_errors(path: Path, advice: str):
    """Any failure while reading `path` or loading it into a model (a truncated or damaged file,
    another program's file) as one TrainError line ending in `advice`."""
    try:
        yield
    except Exception as exc:
        reason = str(exc).partition("\n")[0].split(". ")[0]
        raise TrainError(f"{path}: damaged, truncated or not a udc-render checkpoint "
                         f"({type(exc).__name__}: {reason}); {advice}") from None


def resume(path: Path, model, opt, dev) -> tuple[int, int, list]:
    """(epochs done, steps, log) of the checkpoint at `path`, its state loaded into model and opt;
    (0, 0, []) when there is none."""
    if not path.is_file():
        return 0, 0, []
    with checkpoint_errors(path, "delete it to train from the start, or use another --out"):
        state = torch.load(path, map_location=dev, weights_only=False)
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["optimizer"])
        return state["epoch"], state["step"], state["log"]


def save_checkpoint(out: Path, model, opt, epoch: int, step: int, log: list, settings) -> None:
    """checkpoint.pt (atomic), loss.csv and loss.png of a run after `epoch` epochs (settings: its TrainSettings)."""
    state = {"model": model.state_dict(), "optimizer": opt.state_dict(), "epoch": epoch, "step": step, "log": log,
             "model_config": model_config(model), "settings": asdict(settings)}
    save_torch(out / "checkpoint.pt", state)
    save_text(out / "loss.csv", csv_text(log, LOG_COLUMNS))
    plot_loss(log, out / "loss.png")


def save_torch(path: Path, obj) -> None:
    """torch.save, atomically, through memory: the zip's records are named 'archive/…' rather than after the
    temporary file, so the same object always gives the same bytes."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    with atomic_path(path, ".pt") as tmp:
        Path(tmp).write_bytes(buf.getvalue())


def plot_loss(log: list, path: Path) -> None:
    plt = pyplot()
    if not log:
        return
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.semilogy([r["epoch"] for r in log], [r["loss"] for r in log], label="training loss")
    ax.set_xlabel("epoch")
    ax.set_ylabel("loss")
    val = [(r["epoch"], r["val_psnr_db"]) for r in log if r.get("val_psnr_db") is not None]
    if val:
        ax2 = ax.twinx()
        ax2.plot(*zip(*val), "o-", color="C1", label="validation PSNR")
        ax2.set_ylabel("validation PSNR (dB)")
    ax.set_title("training log")
    save_figure(fig, path)
    plt.close(fig)


def load_model(path: Path, device: str = "auto") -> tuple[torch.nn.Module, dict]:
    """(model in eval mode, its record) from model.pt or checkpoint.pt."""
    path = Path(path)
    if not path.is_file():
        raise TrainError(f"--model = {str(path)!r}: no such checkpoint file (expected model.pt or checkpoint.pt "
                         "from `udc-render train`, or dep)")
    with checkpoint_errors(path, "expected model.pt or checkpoint.pt from `udc-render train`"):
        state = torch.load(path, map_location="cpu", weights_only=False)
        cfg = state["model_config"]
        weights = state["state_dict"] if "state_dict" in state else state["model"]
    model = build_model(cfg, source=str(path))
    model.load_state_dict(weights)
    dev = pick_device(device)
    record = {"model_config": cfg, "display": state.get("display") or state["settings"]["display"],
              "settings": state["settings"], "device": str(dev)}
    return model.to(dev, memory_format=torch.channels_last).eval(), record
