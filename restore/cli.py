"""`udc-render train`, `udc-render evaluate` and `udc-render results` (registered by udc_render.cli).

    udc-render train --data DIR --model {unet,resnet} [--config FILE] --display toled --out DIR
    udc-render evaluate --data DIR --model {input,dep,CHECKPOINT} --out DIR
    udc-render results --out DIR [--budget {cpu,quick,paper}] [--write RESULTS.md]

torch is imported when a command runs, not when the command line is built.
"""
from __future__ import annotations

import contextlib
from pathlib import Path

from udc_render.cli import UserError, _positive


@contextlib.contextmanager
def user_errors():
    """The restore package's one-line errors, shown like every other udc-render error."""
    from restore.data import DataError
    from restore.dep import DePError
    from restore.lpips import LPIPSWeightsError
    from restore.mtcnn import MTCNNWeightsError
    from restore.models import ModelConfigError
    from restore.train import TrainError
    try:
        yield
    except (DataError, DePError, ModelConfigError, TrainError, LPIPSWeightsError, MTCNNWeightsError) as exc:
        raise UserError(str(exc)) from None


def _even(text: str) -> int:
    v = _positive("--crop-px", int)(text)
    if v % 2:
        raise UserError(f"--crop-px = {v}: expected an even number (whole RGGB cells)")
    return v


def register(sub) -> dict:
    p = sub.add_parser("train", help="train a restorer (UNet or ResNet) on one display's pairs of a dataset")
    p.add_argument("--data", type=Path, required=True, help="a folder written by `udc-render dataset`")
    p.add_argument("--model", required=True, choices=("unet", "resnet"), help="the model type")
    p.add_argument("--config", type=Path, help="a model TOML file: type = ... and the model's arguments")
    p.add_argument("--display", required=True, help="the display whose captures to restore (e.g. toled, poled)")
    p.add_argument("--out", type=Path, required=True, help="run folder (re-run the same command to resume)")
    p.add_argument("--epochs", type=_positive("--epochs", int), default=400, help="epochs [400, the paper's]")
    p.add_argument("--batch", type=_positive("--batch", int), default=4, help="crops per step [4]")
    p.add_argument("--crop-px", type=_even, default=256, help="crop size in sensor pixels [256]")
    p.add_argument("--crops-per-pair", type=_positive("--crops-per-pair", int), default=1,
                   help="random crops of each pair per epoch [1]")
    p.add_argument("--lr", type=_positive("--lr"), default=1e-4, help="learning rate [1e-4], halved at half the epochs")
    p.add_argument("--loss", choices=("l1", "l1+ssim"), default="l1", help="training loss [l1]")
    p.add_argument("--seed", type=int, default=0, help="initialisation, crops and order [0]")
    p.add_argument("--device", default="auto", help="auto (a GPU when present), cpu, cuda, cuda:N [auto]")
    p.add_argument("--threads", type=_positive("--threads", int), help="CPU threads for torch [torch's default]")
    p.add_argument("--checkpoint-s", type=_positive("--checkpoint-s"), default=60.0,
                   help="seconds between checkpoints (written at an epoch's end) [60]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")

    e = sub.add_parser("evaluate", help="score a restorer on a dataset split: PSNR, SSIM, LPIPS, MACs, ms/MP")
    e.add_argument("--data", type=Path, required=True, help="a folder written by `udc-render dataset`")
    e.add_argument("--model", required=True, help="input (the degraded capture), dep, or a model.pt/checkpoint.pt")
    e.add_argument("--out", type=Path, required=True, help="results folder (rows of several runs are merged)")
    e.add_argument("--split", default="test", choices=("train", "val", "test"), help="split to score [test]")
    e.add_argument("--display", help="comma-separated displays [a checkpoint's own; all of the dataset's for dep]")
    e.add_argument("--name", help="row name in the tables [input, dep, or the model type]")
    e.add_argument("--denoiser", help="DeP's denoiser [restore.dep's default]")
    e.add_argument("--kernel-px", type=_positive("--kernel-px", int),
                   help="DeP's kernel size at the packed-plane pitch, odd [half the synthesis kernel: 257]")
    e.add_argument("--previews", type=int, default=4, help="side-by-side previews per display [4]")
    e.add_argument("--device", default="auto", help="auto, cpu, cuda [auto]")
    e.add_argument("--threads", type=_positive("--threads", int), help="CPU threads for torch")
    e.add_argument("--quiet", action="store_true", help="no progress bar")
    from restore.results import register as register_results
    return {"train": run_train, "evaluate": run_evaluate, **register_results(sub)}


def _threads(n):
    if n:
        import torch
        torch.set_num_threads(n)


def run_train(args) -> int:
    from restore.models import RESNET_CONFIG, UNET_CONFIG, load_config
    from restore.train import TrainSettings, data_fingerprint, train
    with user_errors():
        _threads(args.threads)
        cfg = dict({"unet": UNET_CONFIG, "resnet": RESNET_CONFIG}[args.model])
        if args.config:
            cfg = load_config(args.config)
            if cfg.get("type") != args.model:
                raise UserError(f"{args.config}: type = {cfg.get('type')!r} but --model is {args.model!r}")
        settings = TrainSettings(model=cfg, display=args.display, epochs=args.epochs, batch=args.batch,
                                 crop_px=args.crop_px, crops_per_pair=args.crops_per_pair, lr=args.lr,
                                 loss=args.loss, seed=args.seed, data_fingerprint=data_fingerprint(args.data))
        s = train(args.data, args.out, settings, args.device, args.checkpoint_s, progress=not args.quiet)
    print(f"trained {cfg['type']} on {s['train_pairs']} {args.display} pairs, {s['epochs']} epochs ({s['steps']} "
          f"steps) on {s['device']}: final loss {s['final_loss']:.4g}"
          + (f", validation PSNR {s['val_psnr_db']:.2f} dB" if s["val_psnr_db"] is not None else "")
          + f"; {args.out / 'model.pt'}")
    return 0


def run_evaluate(args) -> int:
    from restore.evaluate import evaluate
    with user_errors():
        _threads(args.threads)
        displays = args.display.split(",") if args.display else None
        entry = evaluate(args.data, args.model, args.out, args.split, displays, args.name, args.device,
                         args.previews, args.denoiser, progress=not args.quiet, kernel_px=args.kernel_px)
    for d, r in entry["displays"].items():
        print(f"{entry['name']} {d}: PSNR {r['psnr_db']:.2f} dB, SSIM {r['ssim']:.4f}, LPIPS {r['lpips']:.4f}, "
              f"{r['ms_per_mp']:.0f} ms/MP over {r['images']} images")
    print(f"tables: {args.out / 'results.md'}, {args.out / 'results.csv'}")
    return 0
