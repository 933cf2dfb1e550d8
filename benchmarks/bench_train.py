#!/usr/bin/env python
"""Training throughput of the restorers on this CPU: what raises steps per second (issue 15, step 1).

One training step is what restore.train does per batch: forward, L1 loss, backward, Adam. Cases, each
against the baseline (restore.train as it is: contiguous tensors, torch's default threads, no compile,
batch 4 of 256-px crops, the data loaded in the training process):

- threads: torch.set_num_threads 1 and 2;
- channels_last: model and batches in channels_last memory format;
- crop: 128-px crops (a quarter of the pixels per step: compare Mpx/s, not steps/s);
- compile: torch.compile(model) (inductor; its first steps, which compile, are left out of the timing);
- bf16: the forward pass under torch.autocast in bfloat16 (restore.train's `autocast = "bf16"`; weights and
  Adam in float32), alone and with channels_last (what `results --budget cpu` trains with);
- loader: the pairs read by 0 and 1 DataLoader worker processes (--data DIR: a folder written by
  `udc-render dataset`; without it the batches are random tensors and the loader cases are skipped).

Median seconds per step (the batch's loading included) over --steps steps after --warmup steps; output
Mpx/s = batch · crop² / s. The machine is shared: read the ratios to the baseline, taken in the same run.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_train.py [--model unet|resnet] [--data DIR] [--steps 8]
        [--out out/bench/train.md]
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import torch

from restore.models import RESNET_CONFIG, UNET_CONFIG, build_model
from udc_render.io.files import save_text

CONFIGS = {"unet": UNET_CONFIG, "resnet": RESNET_CONFIG}


def random_batches(batch: int, crop_px: int, seed: int = 0):
    """Endless (packed RAW [B, 4, c/2, c/2], target [B, 3, c, c]) of random values."""
    g = torch.Generator().manual_seed(seed)
    while True:
        yield (torch.rand(batch, 4, crop_px // 2, crop_px // 2, generator=g),
               torch.rand(batch, 3, crop_px, crop_px, generator=g))


def loader_batches(data: Path, batch: int, crop_px: int, workers: int):
    """Endless batches of real pairs (restore.data.PairDataset, T-OLED, train split) through a DataLoader."""
    from restore.data import PairDataset, list_pairs
    pairs = list_pairs(data, "train", ["toled"])
    ds = PairDataset(pairs, crop_px=crop_px, seed=0)
    epoch = 0
    while True:
        ds.set_epoch(epoch)
        loader = torch.utils.data.DataLoader(ds, batch_size=batch, shuffle=True, num_workers=workers,
                                             persistent_workers=False)
        yield from loader
        epoch += 1


def seconds_per_step(model_name: str, batches, steps: int, warmup: int, channels_last: bool = False,
                     compile_model: bool = False, bf16: bool = False) -> float:
    """Median wall seconds of one training step (restore.train.train_step: forward, L1, backward, Adam) after
    `warmup` steps."""
    from restore.train import TrainSettings, train_step
    settings = TrainSettings(model=CONFIGS[model_name], display="bench", autocast="bf16" if bf16 else None)
    torch.manual_seed(0)
    model = build_model(dict(CONFIGS[model_name]))
    fmt = torch.channels_last if channels_last else torch.contiguous_format
    model = model.to(memory_format=fmt)
    step_model = torch.compile(model) if compile_model else model
    opt = torch.optim.Adam(model.parameters(), lr=1e-4)
    times = []
    for i in range(warmup + steps):
        t0 = time.perf_counter()  # the batch's loading counts (random tensors: a few ms)
        x, y = next(batches)
        train_step(step_model, opt, x.to(memory_format=fmt), y.to(memory_format=fmt), torch.nn.functional.l1_loss,
                   settings)
        if i >= warmup:
            times.append(time.perf_counter() - t0)
    return statistics.median(times)


def cases(data: Path | None) -> list[dict]:
    """(name, threads, crop, channels_last, compile, bf16, loader workers or None for random tensors); unnamed
    fields are the baseline's."""
    base = dict(threads=None, crop=256, cl=False, compile=False, bf16=False, workers=None)
    out = [dict(base, name="baseline (contiguous, float32)"),
           dict(base, name="1 thread", threads=1),
           dict(base, name="2 threads", threads=2),
           dict(base, name="channels_last", cl=True),
           dict(base, name="128-px crops", crop=128),
           dict(base, name="torch.compile", compile=True),
           dict(base, name="channels_last + compile", cl=True, compile=True),
           dict(base, name="bf16 autocast", bf16=True),
           dict(base, name="channels_last + bf16 autocast", cl=True, bf16=True)]
    if data is not None:
        out += [dict(base, name="real pairs, loader in process", workers=0),
                dict(base, name="real pairs, 1 loader worker", workers=1)]
    return out


def run_case(c: dict, model: str, batch: int, steps: int, warmup: int, data: Path | None) -> dict:
    default_threads = torch.get_num_threads()
    torch.set_num_threads(c["threads"] or default_threads)
    try:
        batches = (random_batches(batch, c["crop"]) if c["workers"] is None
                   else loader_batches(data, batch, c["crop"], c["workers"]))
        s = seconds_per_step(model, batches, steps, warmup + (3 if c["compile"] else 0), c["cl"], c["compile"],
                             c["bf16"])
    except Exception as exc:  # a case this machine cannot run (e.g. no compiler for inductor): say so
        return {**c, "s_per_step": None, "mpx_per_s": None, "error": f"{type(exc).__name__}: {str(exc)[:120]}"}
    finally:
        torch.set_num_threads(default_threads)
    return {**c, "s_per_step": s, "mpx_per_s": batch * c["crop"] ** 2 / s / 1e6, "error": ""}


def table(rows: list[dict], model: str, batch: int, steps: int) -> str:
    base = rows[0]["mpx_per_s"]
    lines = [f"# Training throughput: {model}, batch {batch}, median of {steps} steps", "",
             f"torch {torch.__version__}, {torch.get_num_threads()} threads by default. Mpx/s: output pixels "
             "trained per second; ratio: against the baseline in the same run.", "",
             "| case | threads | crop px | s / step | Mpx/s | ratio | note |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        ok = r["mpx_per_s"] is not None
        lines.append(f"| {r['name']} | {r['threads'] or 'default'} | {r['crop']} | "
                     f"{r['s_per_step']:.3f} | {r['mpx_per_s']:.3f} | {r['mpx_per_s'] / base:.2f} | |" if ok else
                     f"| {r['name']} | {r['threads'] or 'default'} | {r['crop']} | – | – | – | {r['error']} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument("--model", choices=tuple(CONFIGS), default="unet")
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--steps", type=int, default=8)
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--data", type=Path, help="a dataset folder (udc-render dataset) for the loader cases")
    ap.add_argument("--out", type=Path, default=Path("out/bench/train.md"))
    args = ap.parse_args()
    rows = []
    for c in cases(args.data):
        rows.append(run_case(c, args.model, args.batch, args.steps, args.warmup, args.data))
        print(rows[-1]["name"], rows[-1]["mpx_per_s"], rows[-1]["error"], flush=True)
    text = table(rows, args.model, args.batch, args.steps)
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_text(args.out, text)


if __name__ == "__main__":
    main()
