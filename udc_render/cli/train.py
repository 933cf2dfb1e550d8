"""`udc-render train --data DIR --model {unet,unet-wide-fine,resnet,wiener-unet} --display D --out RUN`: train a
restorer on a dataset's pairs; `--degrade online --bank DIR`: on crops of clean images degraded on the fly through a
kernel bank's panels (restore/online.py; wiener-unet, which is given each crop's panel description, trains only so).
torch is imported when the command runs, not when the command line is built."""
from __future__ import annotations

import argparse
from pathlib import Path

from udc_render.cli.args import UserError, add_display_argument, out_dir, positive
from udc_render.dataset.bank import read_bank


def _even(text: str) -> int:
    v = positive("--crop-px", int)(text)
    if v % 2:
        raise argparse.ArgumentTypeError(f"--crop-px = {v}: expected an even number (whole RGGB cells)")
    return v


def set_threads(n: int | None) -> None:
    if n:
        import torch
        torch.set_num_threads(n)


def register(sub) -> None:
    p = sub.add_parser("train", help="train a restorer (UNet or ResNet) on one display's pairs of a dataset")
    p.add_argument("--data", type=Path, required=True,
                   help="a folder written by `udc-render dataset`; with --degrade online its gt.exr images, or a "
                        "folder of clean linear RGB .exr images (1.0 = white; all for training, no validation)")
    p.add_argument("--degrade", choices=("dataset", "online"), default="dataset",
                   help="dataset: the dataset's captures; online: a fresh degradation of every crop of the clean "
                        "images, each through a panel drawn from --bank, on the training device [dataset]")
    p.add_argument("--bank", type=Path, help="with --degrade online: a kernel bank written by `udc-render bank`")
    p.add_argument("--capture-draws", metavar="bank|default|FILE.toml",
                   help="with --degrade online: every crop draws its own sensor and exposure (gain, read noise, "
                        "FPN amplitudes, exposure scale, brightness) from these distributions' sensor.* and "
                        "exposure.* (docs/guides/randomize.md; bank: those a randomized --bank was drawn from) "
                        "instead of taking its panel's [off: the panel's]")
    p.add_argument("--degrade-workers", type=int, default=None,
                   help="with --degrade online: on the CPU, processes that degrade the next crops while the model "
                        "trains (one thread each); on a GPU, 1: a thread on its own CUDA stream; the same numbers "
                        "as 0, in this process [1]")
    p.add_argument("--model", required=True, choices=("unet", "unet-wide-fine", "resnet", "wiener-unet"),
                   help="the model type (restore/models.py): unet: the paper's UNet with two sub-encoders; "
                        "unet-wide-fine: the same, its two finest levels 32 channels wider (the capacity study); "
                        "resnet: the paper's ResNet baseline; wiener-unet: a UNet given the panel's description "
                        "(kernels, γ, gain, noise: Wiener-deconvolved features and kernel codes), trained with "
                        "--degrade online")
    p.add_argument("--config", type=Path, help="a model TOML file: type = ... and the model's arguments")
    add_display_argument(p, "the display whose captures to restore, by its name in the dataset (a file: the "
                            "name it gives; any other word: a display name of the dataset); required with "
                            "--degrade dataset. With --degrade online: the bank's panels to draw from, by name, "
                            "comma-separated", unset="online: every panel of the bank")
    p.add_argument("--out", type=Path, required=True, help="run folder (re-run the same command to resume)")
    p.add_argument("--epochs", type=positive("--epochs", int), default=400, help="epochs [400, the paper's]")
    p.add_argument("--batch", type=positive("--batch", int), default=4, help="crops per step [4]")
    p.add_argument("--crop-px", type=_even, default=256, help="crop size in sensor pixels [256]")
    p.add_argument("--crops-per-pair", type=positive("--crops-per-pair", int), default=1,
                   help="random crops of each pair per epoch [1]")
    p.add_argument("--lr", type=positive("--lr"), default=1e-4, help="learning rate [1e-4], halved at half the epochs")
    p.add_argument("--loss", choices=("l1", "l1+ssim"), default="l1",
                   help="training loss: l1: mean absolute error (default); l1+ssim: L1 + (1 − SSIM) [l1]")
    p.add_argument("--seed", type=int, default=0, help="initialisation, crops and order [0]")
    p.add_argument("--autocast", choices=("bf16",),
                   help="bf16: the forward pass in bfloat16 (weights and Adam in float32), 2× faster on a CPU "
                        "with AVX512-BF16; refused where bf16 is emulated (AVX2 only: 13-30× slower) [off: float32]")
    p.add_argument("--device", default="auto", help="auto (a GPU when present), cpu, cuda, cuda:N [auto]")
    p.add_argument("--threads", type=positive("--threads", int), help="CPU threads for torch [torch's default]")
    p.add_argument("--checkpoint-s", type=positive("--checkpoint-s"), default=60.0,
                   help="seconds between checkpoints (written at an epoch's end) [60]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")

    p.set_defaults(run=run)


def run(args) -> int:
    out_dir(args.out)
    from restore.models import RESNET_CONFIG, UNET_CONFIG, UNET_WIDE_FINE_CONFIG, load_config
    from restore.models_conditioned import WIENER_UNET_CONFIG
    from restore.train import TrainSettings, train
    set_threads(args.threads)
    cfg = dict({"unet": UNET_CONFIG, "unet-wide-fine": UNET_WIDE_FINE_CONFIG, "resnet": RESNET_CONFIG,
                "wiener-unet": WIENER_UNET_CONFIG}[args.model])
    if args.config:
        cfg = load_config(args.config)
        if cfg.get("type") != args.model:
            raise UserError(f"{args.config}: type = {cfg.get('type')!r} but --model is {args.model!r}")
    display, fingerprint, degrade = _source(args)
    settings = TrainSettings(model=cfg, display=display, epochs=args.epochs, batch=args.batch,
                             crop_px=args.crop_px, crops_per_pair=args.crops_per_pair, lr=args.lr,
                             loss=args.loss, seed=args.seed, data_fingerprint=fingerprint,
                             autocast=args.autocast, degrade=degrade)
    if args.degrade_workers is not None and (args.degrade_workers < 0 or args.degrade != "online"):
        raise UserError(f"--degrade-workers {args.degrade_workers}: expected a count ≥ 0, with --degrade online")
    s = train(args.data, args.out, settings, args.device, args.checkpoint_s, progress=not args.quiet, bank=args.bank,
              degrade_workers=args.degrade_workers)
    what = (f"clean images degraded online through {settings.display}" if degrade
            else f"{settings.display} pairs")
    print(f"trained {cfg['type']} on {s['train_pairs']} {what}, {s['epochs']} epochs ({s['steps']} "
          f"steps) on {s['device']}: final loss {s['final_loss']:.4g}"
          + (f", validation PSNR {s['val_psnr_db']:.2f} dB" if s["val_psnr_db"] is not None else "")
          + f"; {args.out / 'model.pt'}")
    return 0




def _source(args) -> tuple[str, str, dict | None]:
    """(the display the run restores, the data's fingerprint, the online degradation's record or None)."""
    if args.degrade == "online":
        if args.bank is None:
            raise UserError("--degrade online needs --bank DIR (a kernel bank written by `udc-render bank`)")
        from restore.online import images_fingerprint
        bank = read_bank(args.bank, [n.strip() for n in args.display.split(",")] if args.display else None)
        names = [p.name for p in bank.panels]
        degrade = {"mode": "online", "bank_fingerprint": bank.fingerprint, "panels": names}
        if args.capture_draws is not None:
            from restore.captures import load_capture_draws
            degrade["captures"] = load_capture_draws(args.capture_draws, bank).describe()
        return ",".join(names), images_fingerprint(args.data), degrade
    if args.capture_draws is not None:
        raise UserError(f"--capture-draws {args.capture_draws}: goes with --degrade online (a dataset's captures "
                        "were drawn when it was made)")
    if args.bank is not None:
        raise UserError("--bank goes with --degrade online (the dataset's own captures need none)")
    if args.display is None:
        raise UserError("--display is required with --degrade dataset: the display whose captures to restore")
    from restore.train import data_fingerprint
    from udc_render.optics.displays import display_name
    return display_name(args.display), data_fingerprint(args.data), None
