"""How fast a training recipe starts: a few hundred steps of the cpu budget's recipe, then the validation
PSNR. A cheap probe (minutes, not hours) of why one model learns slower than another.

Each variant is `type:crop_px:lr[:json]`: the model type (restore.models; the paper's config of that type,
updated with the json, e.g. '{"width": 64}'), the training crop and a constant learning rate. The rest is
restore.train's recipe at the cpu budget (Adam (0.9, 0.999, 1e-8), L1, gradient norm clipped at 0.5,
batch 4, 2 Bayer-preserving crops per pair and epoch, seed 0, epochs shuffled by seed), so the UNet at
256 px reproduces the full run's first validation (epoch 4 = 300 steps: 19.82 dB on the T-OLED).
Validation: the central `val_crop_px` of every val frame, as restore.train's. `--autocast bf16` runs the
forward passes in bfloat16 (restore.train.train_step), to compare a budget's precision with float32.

    python -m restore.studies.early_training DATA --display toled --steps 300 \\
        --variant unet:256:2e-4 --variant unet:128:1e-3 --variant 'unet:128:2e-4:{"width": 64}'

Rows are appended to <out>/results.jsonl with the fingerprint of what made them (row_fingerprint: the dataset's
manifest, the variant, display, steps, precision and recipe); a variant already there under the same fingerprint is
not run again, one under another (another DATA, say, or a row logged before the fingerprints) is run again and
replaced, and the run says so. The table of all rows is printed.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from restore.studies.options import parse_options
from udc_render.errors import UdcError
from udc_render.io.files import save_text
from udc_render.studies.fingerprint import FIELD, digest, stale_note

BATCH, CROPS_PER_PAIR, CLIP_GRAD_NORM, SEED = 4, 2, 0.5, 0  # restore.studies.results.BUDGETS["cpu"]
VAL_CROP_PX = 768  # the central crop of every val frame validated on


def parse_variant(text: str) -> dict:
    """'type:crop_px:lr[:json]' → {"model": config, "crop_px", "lr", "variant": text}."""
    from restore.models import RESNET_CONFIG, UNET_CONFIG, ModelConfigError
    parts = text.split(":", 3)
    defaults = {"unet": UNET_CONFIG, "resnet": RESNET_CONFIG}
    try:
        kind, crop, lr = parts[0], int(parts[1]), float(parts[2])
        extra = json.loads(parts[3]) if len(parts) > 3 else {}
    except (IndexError, ValueError) as exc:
        raise ModelConfigError(f"--variant = {text!r}: expected type:crop_px:lr[:json] ({exc})") from None
    if kind not in defaults:
        raise ModelConfigError(f"--variant = {text!r}: type {kind!r}, expected one of {', '.join(defaults)}")
    return {"model": dict(defaults[kind], **extra), "crop_px": crop, "lr": lr, "variant": text}


def row_fingerprint(data_dir: Path, display: str, variant: dict, steps: int, autocast: str | None) -> str:
    """What decides a row: the dataset (restore.train.data_fingerprint: its manifest), the variant's model, crop
    and rate, the display, the steps, the forward precision and the recipe's constants."""
    from restore.train import data_fingerprint
    return digest({"data": data_fingerprint(data_dir), "display": display, "steps": steps, "autocast": autocast,
                   **{k: variant[k] for k in ("model", "crop_px", "lr")},
                   "recipe": [BATCH, CROPS_PER_PAIR, CLIP_GRAD_NORM, SEED, VAL_CROP_PX]})


def early_rows(data: Path, display: str, variants: list[dict], steps: int, autocast: str | None, path: Path) -> list:
    """The rows of `path` with each variant's row made now unless logged under the same fingerprint (a variant's
    row under another fingerprint is made again and replaces it)."""
    rows = [json.loads(line) for line in path.read_text().splitlines()] if path.is_file() else []
    fingerprints = {v["variant"]: row_fingerprint(data, display, v, steps, autocast) for v in variants}

    def stale(r):
        return (r["variant"] in fingerprints and r["display"] == display and r["steps"] == steps
                and r.get("autocast") == autocast and r.get(FIELD) != fingerprints[r["variant"]])
    kept = [r for r in rows if not stale(r)]
    if note := stale_note("early_training", len(rows) - len(kept), path):
        print(note)
    for v in variants:
        if not any(r["variant"] == v["variant"] and r.get(FIELD) == fingerprints[v["variant"]] for r in kept):
            kept.append({**early_psnr(data, display, v, steps, autocast=autocast), FIELD: fingerprints[v["variant"]]})
            save_text(path, "".join(json.dumps(r) + "\n" for r in kept))
    return kept


def early_psnr(data_dir: Path, display: str, variant: dict, steps: int, val_crop_px: int = VAL_CROP_PX,
               autocast: str | None = None) -> dict:
    """Train `variant` for `steps` steps from seed 0 (restore.train.train_step; `autocast`: its forward
    precision); its validation PSNR, mean loss of the last 75 steps and seconds."""
    import torch

    from restore.data import PairDataset, list_pairs, load_pair
    from restore.losses import loss_fn
    from restore.models import build_model
    from restore.precision import check_autocast
    from restore.train import TrainSettings, centre_crop, train_step, validation_psnr
    settings = TrainSettings(model=variant["model"], display=display, batch=BATCH, crop_px=variant["crop_px"],
                             crops_per_pair=CROPS_PER_PAIR, lr=variant["lr"], seed=SEED,
                             clip_grad_norm=CLIP_GRAD_NORM, autocast=autocast)
    check_autocast(autocast, torch.device("cpu"))  # bf16 where it is emulated: refused at once
    torch.manual_seed(SEED)
    data = PairDataset(list_pairs(data_dir, "train", [display]), settings.crop_px, augment=True, seed=SEED,
                       crops_per_pair=CROPS_PER_PAIR)
    val = [centre_crop(*load_pair(p), val_crop_px) for p in list_pairs(data_dir, "val", [display])]
    model = build_model(settings.model).to(memory_format=torch.channels_last)
    opt = torch.optim.Adam(model.parameters(), lr=settings.lr, betas=(0.9, 0.999), eps=1e-8)
    l1, losses, epoch, t0 = loss_fn("l1"), [], 0, time.perf_counter()
    while len(losses) < steps:
        data.set_epoch(epoch)
        order = torch.Generator().manual_seed(SEED * 1_000_003 + epoch)
        for x, y in torch.utils.data.DataLoader(data, batch_size=BATCH, shuffle=True, generator=order):
            losses.append(train_step(model, opt, x.to(memory_format=torch.channels_last),
                                     y.to(memory_format=torch.channels_last), l1, settings))
            if len(losses) == steps:
                break
        epoch += 1
    return {"variant": variant["variant"], "display": display, "steps": steps, "autocast": autocast,
            "val_psnr_db": validation_psnr(model, val, torch.device("cpu")),
            "loss_last75": float(np.mean(losses[-75:])), "seconds": time.perf_counter() - t0}


def main(argv: list[str]) -> None:
    usage = ("python -m restore.studies.early_training DATA --display D --variant type:crop_px:lr[:json] "
             "[--variant ...] [--steps 300] [--autocast bf16] [--out out/early_training]")
    pos, o = parse_options(argv, usage, repeated=("variant",))
    if len(pos) != 1 or "display" not in o or not o["variant"]:
        sys.exit(f"usage: {usage}")
    data, display, steps = Path(pos[0]), o["display"], int(o.get("steps", 300))
    out = Path(o.get("out", "out/early_training"))
    autocast = o.get("autocast")
    if autocast not in (None, "bf16"):
        sys.exit(f"error: --autocast = {autocast!r}: expected bf16 (or leave it out for float32)")
    path = out / "results.jsonl"
    try:
        variants = [parse_variant(v) for v in o["variant"]]
        out.mkdir(parents=True, exist_ok=True)
        rows = early_rows(data, display, variants, steps, autocast, path)
    except (UdcError, OSError) as exc:
        sys.exit(f"error: {exc}")
    print("| variant | forward | display | steps | val PSNR (dB) | loss, last 75 steps | s |\n"
          "|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| `{r['variant']}` | {r.get('autocast') or 'float32'} | {r['display']} | {r['steps']} | "
              f"{r['val_psnr_db']:.2f} | {r['loss_last75']:.4f} | "
              f"{r['seconds']:.0f} |")


if __name__ == "__main__":
    main(sys.argv[1:])
