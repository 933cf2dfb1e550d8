"""Capacity or budget? The paper's UNet on the T-OLED against one wider at its two finest levels and against
itself trained twice as long (issue 47, item 1).

Three runs on one dataset and display, the same seed, crops and data order, one recipe (a budget of
restore.studies.budgets: batch, crop, crops per pair, lr halved at half the epochs, gradient clip, precision;
no plateau stop, so every run trains all its epochs):

    unet            the paper's UNet (restore.models.UNET_CONFIG: 8.93 M parameters, 124.1 G MACs), E epochs
    unet-wide-fine  its two finest levels 32 channels wider (UNET_WIDE_FINE_CONFIG: 9.49 M, 242.9 G), E epochs
    unet-2x         the paper's UNet, 2E epochs: about the wide one's arithmetic (1.96× a step's MACs)

Each is scored on the test split (restore.evaluate: PSNR, SSIM, LPIPS) and its error split into octave bands on
the val split's first BAND_ITEMS frames' central BAND_CROP_PX (restore.studies.error_bands, as the results run
does). The figure that decides is the error in 1/16–1/8 cycle/px (the T-OLED's horizontal null) as a share of
the input's: RESULTS.md's UNet keeps 0.83, its ResNet 0.32. If the wide UNet's share falls well below the paper
UNet's and the 2× run's does not, the finest levels lack capacity; if the 2× run closes as much, the budget does.

    python -m restore.studies.capacity DATA --display toled [--budget cpu|paper|quick] [--epochs E]
        [--device auto] [--out out/capacity]

Resumable: each run trains, or resumes from its checkpoint (restore.checkpoints), in OUT/train/<variant>; a
variant already scored (test split and bands) with the same model.pt and scoring code (restore.studies.scoring.
evaluation_stamp) is not scored again. Writes OUT/capacity.json, OUT/capacity.md and OUT/error_bands_<display>.png.
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from restore.studies.budgets import BUDGETS
from restore.studies.error_bands import OCTAVE_EDGES, display_transfer, method_bands, plot
from restore.studies.options import parse_options
from udc_render.errors import UdcError
from udc_render.io.files import save_json, save_text

BAND = (1 / 16, 1 / 8)  # cycles per sensor pixel: the T-OLED's horizontal null (0.037–0.121 at 520 nm)
SCORES = ("psnr_db_paper", "ssim_paper", "psnr_db_srgb", "lpips_srgb")


@dataclass(frozen=True)
class Variant:
    """One run of the study: its name, model config and epochs as a multiple of the recipe's."""
    name: str
    model: dict
    epoch_factor: int


def variants(models: tuple[dict, dict] | None = None) -> tuple[Variant, ...]:
    """The paper's UNet, the one wider at its finest levels, and the paper's UNet at twice the epochs; `models`:
    other (paper, wide) configs in their place (the tests' tiny ones)."""
    from restore.models import UNET_CONFIG, UNET_WIDE_FINE_CONFIG
    paper, wide = models or (UNET_CONFIG, UNET_WIDE_FINE_CONFIG)
    return Variant("unet", paper, 1), Variant("unet-wide-fine", wide, 1), Variant("unet-2x", paper, 2)


@dataclass(frozen=True)
class Recipe:
    """The training recipe shared by the variants (restore.train.TrainSettings' fields) and the validation's
    period in epochs."""
    epochs: int
    batch: int
    crop_px: int
    crops_per_pair: int
    lr: float
    clip_grad_norm: float | None = None
    autocast: str | None = None
    val_crop_px: int | None = None
    val_every: int = 2

    @classmethod
    def of_budget(cls, budget: str, epochs: int | None = None) -> Recipe:
        """The UNet's recipe of BUDGETS[budget], its epoch cap or `epochs`."""
        if budget not in BUDGETS:
            raise UdcError(f"--budget = {budget!r}: expected one of {', '.join(BUDGETS)}")
        b = BUDGETS[budget]
        return cls(epochs=epochs or b["epochs"]["unet"], batch=b["batch"], crop_px=b["crop_px"]["unet"],
                   crops_per_pair=b["crops_per_pair"], lr=b["lr"], clip_grad_norm=b.get("clip_grad_norm"),
                   autocast=b.get("autocast"), val_crop_px=b.get("val_crop_px"), val_every=b.get("val_every", 2))


def settings_of(v: Variant, recipe: Recipe, display: str, data: Path):
    """restore.train.TrainSettings of variant `v` (seed 0 for all: the same crops in the same order)."""
    from restore.train import TrainSettings, data_fingerprint
    return TrainSettings(model=dict(v.model), display=display, epochs=recipe.epochs * v.epoch_factor,
                         batch=recipe.batch, crop_px=recipe.crop_px, crops_per_pair=recipe.crops_per_pair,
                         lr=recipe.lr, seed=0, data_fingerprint=data_fingerprint(data), plateau_db=None,
                         val_crop_px=recipe.val_crop_px, clip_grad_norm=recipe.clip_grad_norm,
                         autocast=recipe.autocast)


def train_variants(data: Path, display: str, recipe: Recipe, out: Path, device: str = "auto",
                   progress: bool = True, configs: tuple[dict, dict] | None = None) -> dict[str, Path]:
    """Each variant (variants(configs)) trained or resumed in out/train/<name>: {name: its model.pt}."""
    from restore.train import train
    models = {}
    for v in variants(configs):
        run = out / "train" / v.name
        train(data, run, settings_of(v, recipe, display, data), device=device, val_every=recipe.val_every,
              progress=progress)
        models[v.name] = run / "model.pt"
    return models


def score_variants(data: Path, display: str, models: dict[str, Path], out: Path, progress: bool = True) -> dict:
    """{name: {scores on the test split}} of the input and each model (restore.evaluate into out/eval), a variant
    scored before with the same evaluation_stamp taken from out/eval/results.json."""
    from restore.evaluate import EvalSettings, evaluate
    from restore.studies.scoring import evaluation_stamp
    ev = out / "eval"
    stamps_path = ev / "stamps.json"
    stamps = json.loads(stamps_path.read_text()) if stamps_path.is_file() else {}
    scored = json.loads((ev / "results.json").read_text())["methods"] if (ev / "results.json").is_file() else {}
    rows = {}
    for name, method in {"input": "input", **{k: str(p) for k, p in models.items()}}.items():
        stamp = evaluation_stamp(data, method)
        if stamps.get(name) != stamp or display not in scored.get(name, {}).get("displays", {}):
            entry = evaluate(data, method, ev, EvalSettings(name=name, displays=(display,), previews=0),
                             progress=progress)
            scored[name] = entry
            stamps[name] = stamp
            save_json(stamps_path, stamps)
        rows[name] = {k: scored[name]["displays"][display][k] for k in SCORES}
    return rows


def band_index(edges) -> int:
    """The octave band [1/16, 1/8) among restore.studies.error_bands.OCTAVE_EDGES."""
    return list(edges).index(BAND[0])


def band_rows(data: Path, display: str, models: dict[str, Path], out: Path) -> dict:
    """{"bands": {name: [bands] MSE}, "transfer": [bands] or None, "band_share": {name: error in BAND / the
    input's}} on the val split (module doc), plotted in out/error_bands_<display>.png. The display's transfer
    needs the dataset's synthesis record (synth.json): None without it."""
    from restore.data import list_pairs
    from restore.studies.scoring import BAND_CROP_PX, BAND_ITEMS, evaluation_stamp
    first = list_pairs(data, "val", [display])[0]
    transfer = display_transfer(data, display) if (first.folder / "synth.json").is_file() else None
    crop = min(BAND_CROP_PX, *(2 * (s // 2) for s in _frame_hw(first)))
    methods = {"input": "input", **{k: str(p) for k, p in models.items()}}
    stamps = {k: evaluation_stamp(data, m) for k, m in methods.items()}
    path = out / "bands.json"  # {name: {"stamp", "bands"}}: a method's bands are made again only when it changed
    kept = json.loads(path.read_text()) if path.is_file() else {}
    todo = {k: m for k, m in methods.items() if kept.get(k, {}).get("stamp") != stamps[k]}
    if todo:
        made = method_bands(data, display, todo, "val", BAND_ITEMS, crop)
        kept.update({k: {"stamp": stamps[k], "bands": v.tolist()} for k, v in made.items()})
        save_json(path, kept)
    bands = {k: np.array(kept[k]["bands"]) for k in methods}
    i = band_index(OCTAVE_EDGES)
    shares = {k: float(v[i] / bands["input"][i]) for k, v in bands.items() if k != "input"}
    plot(bands, np.full(len(OCTAVE_EDGES) - 1, np.nan) if transfer is None else transfer,
         out / f"error_bands_{display}.png",
         f"{display}: error by spatial frequency (val, {BAND_ITEMS} frames, central {crop} px)")
    return {"bands": {k: v.tolist() for k, v in bands.items()},
            "transfer": None if transfer is None else transfer.tolist(), "band_share": shares, "crop_px": crop}


def _frame_hw(pair) -> tuple[int, int]:
    from restore.data import load_gt
    return load_gt(pair.folder).shape[1:]


def capacity_study(data: Path, display: str, recipe: Recipe, out: Path, device: str = "auto",
                   progress: bool = True, configs: tuple[dict, dict] | None = None) -> dict:
    """Train, score and compare the variants (module doc; `configs`: variants'); writes out/capacity.json and
    out/capacity.md."""
    from restore.counting import count_macs, count_parameters
    from restore.models import build_model
    data, out = Path(data), Path(out)
    out.mkdir(parents=True, exist_ok=True)
    models = train_variants(data, display, recipe, out, device, progress, configs)
    scores = score_variants(data, display, models, out, progress)
    bands = band_rows(data, display, models, out)
    runs = {}
    for v in variants(configs):
        summary = json.loads((out / "train" / v.name / "train_summary.json").read_text())
        runs[v.name] = {"model": v.model, "parameters": count_parameters(build_model(v.model)),
                        "macs_paper_input": count_macs(v.model), "epochs": summary["epochs"],
                        "steps": summary["steps"], "final_loss": summary["final_loss"],
                        "val_psnr_db": summary["val_psnr_db"], "seconds": summary["seconds"]}
    result = {"display": display, "data": str(data), "recipe": recipe.__dict__, "band_cycles_per_px": list(BAND),
              "runs": runs, "scores": scores, **bands}
    save_json(out / "capacity.json", result)
    save_text(out / "capacity.md", markdown(result))
    return result


def markdown(r: dict) -> str:
    """The study's table: per run its size, steps, loss and scores, and its error in BAND as a share of the
    input's."""
    lines = [f"Display {r['display']}; error band {BAND[0]:.4g}–{BAND[1]:.4g} cycle/px on the val split's central "
             f"{r['crop_px']} px; scores on the test split.", "",
             "| run | parameters | G MACs (4 × 512 × 1024) | steps | final loss | PSNR (dB, paper) | SSIM | LPIPS "
             "| band error / input's |", "|---|---|---|---|---|---|---|---|---|"]
    s = r["scores"]["input"]
    lines.append(f"| input | | | | | {s['psnr_db_paper']:.2f} | {s['ssim_paper']:.4f} | {s['lpips_srgb']:.4f} | 1 |")
    for name, run in r["runs"].items():
        s = r["scores"][name]
        lines.append(f"| {name} | {run['parameters']:,} | {run['macs_paper_input'] / 1e9:.1f} | {run['steps']} | "
                     f"{run['final_loss']:.4f} | {s['psnr_db_paper']:.2f} | {s['ssim_paper']:.4f} | "
                     f"{s['lpips_srgb']:.4f} | {r['band_share'][name]:.3f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> None:
    usage = ("python -m restore.studies.capacity DATA --display D [--budget cpu|paper|quick] [--epochs E] "
             "[--device auto] [--out out/capacity]")
    pos, o = parse_options(argv, usage)
    if len(pos) != 1 or "display" not in o:
        sys.exit(f"usage: {usage}")
    try:
        epochs = int(o["epochs"]) if "epochs" in o else None
        recipe = Recipe.of_budget(o.get("budget", "cpu"), epochs)
        result = capacity_study(Path(pos[0]), o["display"], recipe, Path(o.get("out", "out/capacity")),
                                o.get("device", "auto"))
    except (UdcError, OSError, ValueError) as exc:
        sys.exit(f"error: {exc}")
    print(markdown(result))


if __name__ == "__main__":
    main(sys.argv[1:])
