"""Training a restorer (UNet or ResNet) on one display's pairs: the paper's recipe (§5).

    L1 loss (or L1 + (1 − SSIM)), Adam β = (0.9, 0.999), ε = 1e-8, learning rate 1e-4 halved at
    half the schedule (the paper: 400 epochs, halved after 200), random 256-px crops with
    Bayer-preserving augmentation, the transforms the panel allows (restore.data, restore.augment).

An epoch is `crops_per_pair` random crops of every training pair. The run folder holds:
    train.json       the settings (a different run on the same folder is refused)
    checkpoint.pt    model, optimiser, epochs done, loss log (atomic; written every checkpoint_s
                     seconds at an epoch's end and at the end): a re-run resumes from it
    model.pt         the final weights and how to rebuild the model (what `evaluate` loads)
    train_summary.json   epochs, steps, plateau, seconds: a finished run (the cap or the plateau reached) is
                     not loaded again, with or without its checkpoint (restore.studies.carry keeps none)
    loss.csv, loss.png   the loss log (mean training loss per epoch, validation PSNR)
With plateau_db set, training stops at the first validation where the validation PSNR's trend (a line fitted through the
last two fifths of the steps) changes by less than plateau_db over a fifth of the steps (plateau_step); the summary says
whether and where, and a finished run's plateau is re-checked from its loss.csv, so a run stopped under an older
criterion resumes. With autocast 'bf16' the forward pass runs in bfloat16 (train_step). Resumed training gives the same
weights as an uninterrupted run on the same machine and threads: sample order and crops are seeded by (seed, epoch).
A model that needs the panel's description (restore.conditioning) trains only online: each crop's batch carries its
bank panel's description, validation image j that of panel j mod N, and the model records the bank's DescriptionSpec.
The run folder's files are written and read by restore.checkpoints.
"""
from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from restore.augment import pair_dataset
from restore.checkpoints import (
    LOG_COLUMNS as LOG_COLUMNS,  # the run's files (re-exported: their old home)
    TrainError,
    checkpoint_errors as checkpoint_errors,
    load_model as load_model,
    pick_device,
    read_log,
    resume,
    save_checkpoint,
    save_torch,
)
from restore.conditioning import check_description_source, described_training, predict_described
from restore.data import PairBatches, largest_crop_px, list_pairs, load_pair, read_manifest
from restore.losses import loss_fn
from restore.models import build_model, model_config
from restore.online import DrawLog, online_data
from restore.precision import check_autocast
from udc_render.io.files import save_json
from udc_render.metrics import psnr_db

PLATEAU_WINDOW = 0.2  # the change is measured over a fifth of the steps
PLATEAU_FIT_WINDOW = 0.4  # from a line fitted through the validations of the last two fifths
PLATEAU_MIN_VALIDATIONS = 6  # validations inside the fitted window before a plateau can be declared


@dataclass(frozen=True)
class TrainSettings:
    """Everything that decides the trained weights (recorded in train.json)."""
    model: dict
    display: str
    epochs: int = 400
    batch: int = 4
    crop_px: int = 256
    crops_per_pair: int = 1
    lr: float = 1e-4
    loss: str = "l1"
    seed: int = 0
    data_fingerprint: str = ""
    # Stop once validation PSNR has plateaued: its trend changes by less than this (dB) over a
    # fifth of the steps (plateau_step); None: every epoch. Issue 15's criterion is 0.1 dB.
    plateau_db: float | None = None
    # Validate on the central val_crop_px square of each val frame (None: the whole frame). A stopping signal
    # only: the test split is always scored whole (restore.evaluate). Keeps the ResNet's validations cheap.
    val_crop_px: int | None = None
    # Clip the gradient's global L2 norm to this (None: no clipping). Without it the full UNet at lr 2e-4
    # spiked at epoch 24 (loss 0.058 → 0.068, validation −1.6 dB); its norms ran 0.09–0.33, one batch 0.74.
    clip_grad_norm: float | None = None
    # The forward pass in bfloat16 under torch.autocast ("bf16"; weights, loss, gradients' accumulation and
    # Adam stay float32), or all float32 (None). On this AVX512-BF16 CPU a UNet step takes half the time
    # (benchmarks/README.md, bench_train); validation and evaluation always run in float32.
    autocast: str | None = None
    # The online degradation (restore.online; None: the dataset's captures): {"mode": "online", "bank_fingerprint",
    # "panels": the bank's panels drawn from}.
    degrade: dict | None = None


AUTOCASTS = (None, "bf16")


def data_fingerprint(data_dir: Path) -> str:
    """sha256 of the dataset's manifest: which items, splits and displays (not where the folder is)."""
    read_manifest(data_dir)  # a clear error when it is not a dataset folder
    return hashlib.sha256((Path(data_dir) / "manifest.jsonl").read_bytes()).hexdigest()[:16]


def learning_rate(settings: TrainSettings, epoch: int) -> float:
    """lr, halved from epoch ⌊epochs / 2⌋ on."""
    return settings.lr * (0.5 if epoch >= settings.epochs // 2 else 1.0)


def plateau_step(log: list, threshold_db: float, fit_window: float = PLATEAU_FIT_WINDOW,
                 min_validations: int = PLATEAU_MIN_VALIDATIONS) -> int | None:
    """The first validated step S at which validation PSNR changes by less than threshold_db over a fifth of
    the steps: the least-squares line through the validations logged at steps ≥ (1 − PLATEAU_FIT_WINDOW) · S,
    at least PLATEAU_MIN_VALIDATIONS of them, has |slope| · PLATEAU_WINDOW · S < threshold_db. None before.
    (fit_window and min_validations: other criteria, for restore.studies.plateau_criteria.)

    The line spans two fifths, not one: validation PSNR jitters by 0.1–0.4 dB between validations, and a line
    through the last fifth's four or five points stopped four of five cpu-budget UNets (epochs 32–50) whose
    two-fifths trend still rose 0.13–0.31 dB per fifth (the float32 T-OLED UNet: 0.06 dB per fifth from its
    last 6 validations, 0.24 dB from its last 11). Before that, the span of three points stopped the grey run's
    T-OLED UNet at 21.87 dB while it was rising to 22.27 dB (restore.studies.continued_training)."""
    vals = validations(log)
    for i, (step, _) in enumerate(vals):
        change = trend_db_per_fifth(vals[:i + 1], fit_window, min_validations)
        if change is not None and abs(change) < threshold_db:
            return step
    return None


def validations(log: list) -> list[tuple[float, float]]:
    """The (step, validation PSNR) pairs of a loss log, in its order."""
    return [(r["step"], r["val_psnr_db"]) for r in log if r.get("val_psnr_db") is not None]


def trend_db_per_fifth(vals: list[tuple[float, float]], fit_window: float = PLATEAU_FIT_WINDOW,
                       min_validations: int = PLATEAU_MIN_VALIDATIONS) -> float | None:
    """The change in dB over a fifth of the steps of the line fitted through the (step, PSNR) validations of
    the last fit_window of the steps (two fifths), slope · PLATEAU_WINDOW · S at the last step S; None with
    fewer than min_validations of them."""
    step = vals[-1][0]
    window = np.array([(t, v) for t, v in vals if t >= (1 - fit_window) * step], dtype=np.float64)
    if len(window) < min_validations:
        return None
    return float(np.polyfit(window[:, 0], window[:, 1], 1)[0] * PLATEAU_WINDOW * step)


def predict(model: torch.nn.Module, packed: np.ndarray, device: torch.device, description=None) -> np.ndarray:
    """[3, H, W] float32 restored image of one packed RAW [4, H/2, W/2] (channels_last: 1.4–1.5× faster
    inference on the CPU, benchmarks/README.md); a model that needs it is given the panel's `description`."""
    if description is not None:
        return predict_described(model, packed, description, device)
    with torch.inference_mode():
        x = torch.from_numpy(np.ascontiguousarray(packed, np.float32))[None].to(device)
        x = x.to(memory_format=torch.channels_last)
        return model(x)[0].float().cpu().numpy()


def train_step(model, opt, x: torch.Tensor, y: torch.Tensor, loss_of, settings: TrainSettings, *description) -> float:
    """One Adam step on the batch (x, y), already on the model's device in channels_last (and the crops'
    description tensors, for a model that needs them): the forward in bfloat16 when settings.autocast is 'bf16'
    (the loss on its output widened to float32), the gradient's norm clipped to settings.clip_grad_norm; returns
    the loss."""
    with torch.autocast(x.device.type, dtype=torch.bfloat16, enabled=settings.autocast == "bf16"):
        out = model(x, *description)
    loss = loss_of(out.float(), y)
    opt.zero_grad(set_to_none=True)
    loss.backward()
    if settings.clip_grad_norm is not None:
        torch.nn.utils.clip_grad_norm_(model.parameters(), settings.clip_grad_norm)
    opt.step()
    return loss.item()


def validation_psnr(model, pairs, device, descriptions: list | None = None) -> float | None:
    """Mean PSNR (dB, linear units clipped to [0, 1], whole frame) over the validation pairs
    [(packed, gt), ...] (load_pair), each restored with its description where `descriptions` are given."""
    if not pairs:
        return None
    model.eval()
    vals = [psnr_db(np.clip(predict(model, packed, device, d), 0, 1), np.clip(gt, 0, 1), peak=1.0)
            for (packed, gt), d in zip(pairs, descriptions or [None] * len(pairs))]
    model.train()
    return float(np.mean(vals))


def settings_differ(path: Path, settings: TrainSettings) -> str | None:
    """'KEY = NEW differs from this folder's run (OLD)' for the first setting that the train.json at `path`
    records otherwise, else None."""
    old, new = json.loads(path.read_text()), json.loads(json.dumps(asdict(settings)))
    diff = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
    return f"{diff[0]} = {new.get(diff[0])!r} differs from this folder's run ({old.get(diff[0])!r})" if diff else None


def _check_run_folder(out: Path, settings: TrainSettings) -> None:
    """Refuse a run folder whose train.json records other settings."""
    path = out / "train.json"
    if path.is_file() and (diff := settings_differ(path, settings)):
        raise TrainError(f"{path}: {diff}: use another --out or the same settings to resume")


def finished_summary(out: Path, settings: TrainSettings) -> dict | None:
    """The saved summary of the finished run in `out` (train.json already checked against `settings`; model.pt,
    train_summary.json and loss.csv written; the epoch cap reached, or the plateau by today's plateau_step on
    loss.csv), else None."""
    paths = [out / f for f in ("train.json", "model.pt", "train_summary.json", "loss.csv")]
    if not all(p.is_file() for p in paths):
        return None
    summary = json.loads(paths[2].read_text())
    if summary.get("epochs") == settings.epochs:
        return summary
    plateaued = settings.plateau_db is not None and plateau_step(read_log(paths[3]), settings.plateau_db) is not None
    return summary if plateaued else None


def _training_data(data_dir: Path, settings: TrainSettings, dev, bank: Path | None = None,
                   workers: int | None = None) -> tuple[object, list]:
    """(the training batches, the validation pairs as arrays): every pair read and checked (load_pair), and
    --crop-px checked against the smallest frame; with settings.degrade, the clean images and the bank's
    panels of the online degradation (restore.online)."""
    if settings.degrade is not None:
        data, val = online_data(data_dir, bank, settings, dev, workers)
        h, w = min((im.pixels.shape[1:] for im in data.images), key=min)
    else:
        pairs = pair_dataset(data_dir, settings)  # the transforms the panel allows (restore.augment)
        h, w = min((gt.shape[1:] for _, gt in pairs.arrays), key=min)
        if settings.crop_px > largest_crop_px(h, w):
            raise TrainError(f"--crop-px = {settings.crop_px}: too large for the {w} × {h} px frames of {data_dir} "
                             f"({settings.display}): at most {largest_crop_px(h, w)} (the smaller side less 2 px)")
        data = PairBatches(pairs, settings.batch, settings.seed)
        val = [load_pair(p) for p in list_pairs(data_dir, "val", [settings.display])]
    if settings.val_crop_px is not None:
        c = settings.val_crop_px
        if c < 32 or c % 32 or c > min(h, w):
            raise TrainError(f"val_crop_px = {c}: expected a multiple of 32 px from 32 to {min(h, w)} "
                             f"(the smaller side of {data_dir}'s frames)")
        val = [centre_crop(packed, gt, c) for packed, gt in val]
    return data, val


def centre_crop(packed: np.ndarray, gt: np.ndarray, crop_px: int) -> tuple[np.ndarray, np.ndarray]:
    """(packed [4, c/2, c/2], gt [3, c, c]): the central crop_px square of a pair, in whole RGGB cells."""
    half = crop_px // 2
    y, x = (packed.shape[1] - half) // 2, (packed.shape[2] - half) // 2
    return packed[:, y:y + half, x:x + half], gt[:, 2 * y:2 * y + crop_px, 2 * x:2 * x + crop_px]


def train(data_dir: Path, out: Path, settings: TrainSettings, device: str = "auto", checkpoint_s: float = 60.0,
          val_every: int = 10, progress: bool = True, bank: Path | None = None,
          degrade_workers: int | None = None) -> dict:
    """Train (or resume) in `out`; returns a summary (epochs, final loss, validation PSNR, seconds).
    Nothing is written in `out` before the settings, the run folder and every pair have been checked.
    settings.degrade: the online degradation through the kernel bank in `bank` (restore.online), in degrade_workers
    processes on the CPU (0: in this one) or a thread on a GPU (1); None: 1; the same numbers either way."""
    data_dir, out = Path(data_dir), Path(out)
    if settings.epochs < 1 or settings.batch < 1:
        raise TrainError(f"epochs = {settings.epochs}, batch = {settings.batch}: expected integers ≥ 1")
    if settings.autocast not in AUTOCASTS:
        raise TrainError(f"autocast = {settings.autocast!r}: expected one of {', '.join(map(str, AUTOCASTS))}")
    loss_of = loss_fn(settings.loss)
    check_description_source(settings.model, settings.degrade)
    _check_run_folder(out, settings)
    if (done := finished_summary(out, settings)) is not None:
        return done
    dev = pick_device(device)
    check_autocast(settings.autocast, dev)
    data, val_pairs = _training_data(data_dir, settings, dev, bank, degrade_workers)
    torch.manual_seed(settings.seed)
    model = build_model(settings.model).to(dev, memory_format=torch.channels_last)  # 1.07× (bench_train)
    data, val_descriptions = described_training(model, data, len(val_pairs))  # restore.conditioning
    opt = torch.optim.Adam(model.parameters(), lr=settings.lr, betas=(0.9, 0.999), eps=1e-8)
    save_json(out / "train.json", asdict(settings))  # everything above checked: the run folder is used now
    start_epoch, step, log = resume(out / "checkpoint.pt", model, opt, dev)
    draw_log = DrawLog(out, start_epoch) if settings.degrade is not None else None
    t_start, t_ckpt = time.perf_counter() - (log[-1]["seconds"] if log else 0.0), time.perf_counter()  # cumulative
    model.train()
    bar = tqdm(range(start_epoch, settings.epochs), initial=start_epoch, total=settings.epochs, unit="epoch",
               desc=f"train {settings.model['type']} {settings.display}", disable=not progress)
    plateau = plateau_step(log, settings.plateau_db) if settings.plateau_db is not None else None
    for epoch in bar:
        if plateau is not None:  # a resumed run that had already plateaued
            break
        for group in opt.param_groups:
            group["lr"] = learning_rate(settings, epoch)
        draws, batches = data.epoch(epoch)
        losses = []
        for x, y, *description in batches:  # the crops' descriptions, for a model that needs them
            x = x.to(dev, memory_format=torch.channels_last)
            y = y.to(dev, memory_format=torch.channels_last)
            losses.append(train_step(model, opt, x, y, loss_of, settings, *description))
            step += 1
        if not all(math.isfinite(v) for v in losses):
            raise TrainError(f"epoch {epoch + 1}: the loss is not finite ({losses[-1]}); lower the learning rate")
        if draw_log is not None:
            draw_log.add(epoch, draws)
        last = epoch + 1 == settings.epochs
        validate = last or (epoch + 1) % val_every == 0
        val = validation_psnr(model, val_pairs, dev, val_descriptions) if validate else None
        log.append({"epoch": epoch + 1, "step": step, "lr": learning_rate(settings, epoch),
                    "loss": float(np.mean(losses)), "val_psnr_db": val,
                    "seconds": round(time.perf_counter() - t_start, 2)})
        bar.set_postfix(loss=f"{log[-1]['loss']:.4g}")
        if val is not None and settings.plateau_db is not None:
            plateau = plateau_step(log, settings.plateau_db)
        if last or plateau is not None or time.perf_counter() - t_ckpt >= checkpoint_s:
            save_checkpoint(out, model, opt, epoch + 1, step, log, settings)
            if draw_log is not None:
                draw_log.save()
            t_ckpt = time.perf_counter()
    bar.close()
    epochs_done = log[-1]["epoch"] if log else 0
    weights = {k: v.detach().cpu() for k, v in model.state_dict().items()}  # loadable where no GPU is
    final = {"model_config": model_config(model), "state_dict": weights, "display": settings.display,
             "settings": asdict(settings), "epochs_done": epochs_done, "plateau_step": plateau}
    save_torch(out / "model.pt", final)
    summary = {"epochs": epochs_done, "epochs_planned": settings.epochs, "steps": step, "plateau_step": plateau,
               "plateaued": plateau is not None, "final_loss": log[-1]["loss"] if log else None,
               "val_psnr_db": next((r["val_psnr_db"] for r in reversed(log) if r["val_psnr_db"] is not None), None),
               "train_pairs": data.count, "val_pairs": len(val_pairs), "device": str(dev), **data.record,
               "seconds": round(time.perf_counter() - t_start, 1)}
    save_json(out / "train_summary.json", summary)
    return summary


