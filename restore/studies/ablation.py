"""Which conditioning? The parts of the conditioned restorer against the blind UNet on held-out randomized panels, at
a CPU budget (issue 47, item 3: kernel codes as DISCNet, Wiener-deconvolved features as deep Wiener deconvolution,
or both).

Six arms, trained with one recipe (restore.studies.robustness.train_settings: the same clean images, seed, crops,
panels, noise and steps) on one bank of randomized panels (randomize `default`, robustness.RANDOMIZE_SEED):

    unet       the blind UNet, the robustness study's "UNet (randomized)" recipe: the budget's UNet on the capture
    wide       the blind twin of the conditioned arms' backbone (unet-wide-fine: the same widths, levels and
               sub-encoders) on the capture: the blind UNet at the conditioned arms' capacity
    level      wiener-unet with both parts off (wiener = false, kernel_codes = false): its backbone on x / γ, the
               description giving the input's level only; the control for the backbone's width and for γ
    codes      kernel codes alone (kernel_codes, FiLM at every level; wiener = false)
    features   Wiener-deconvolved features alone (wiener; kernel_codes = false)
    both       the default wiener-unet (restore.models_conditioned.WIENER_UNET_CONFIG)

The conditioned arms are robustness.conditioned_config at the budget (its UNet's width and depth, the rig's kernel
window) with the switches above. Each is scored on the held-out draws (randomize `default`, HELDOUT_SEED), every
validation image degraded once through each panel (robustness.panel_pairs, SCORE_SEED) and restored with that
panel's own description (robustness.model_outputs), beside the input and DeP given the panel's kernels and γ
(robustness.dep_outputs): the paper protocol's PSNR and the level-matched one (restore.metrics), per panel.

    python -m restore.studies.ablation [--out out/ablation] [--budget cpu] [--seed 0] [--banks RUN] [--threads 1]

--seed: the arms' training seed (TRAIN_SEED by default); --banks: another run's folder whose banks to use.

Resumable: the banks through make_bank, each arm's training through restore.train's checkpoint, each panel's score
row kept in scores.jsonl under the fingerprint of what made it (the bank, the images, the score seed, the arms'
model files); stage seconds summed over re-runs (times.json). The report: restore.studies.ablation_report.
"""
from __future__ import annotations

import json
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from restore.counting import count_parameters
from restore.metrics import level_matched_psnr_db, paper_metrics
from restore.online import clean_images, images_fingerprint
from restore.studies.ablation_report import ARMS, write_report
from restore.studies.options import parse_options
from restore.studies.robustness import (
    HELDOUT_SEED,
    RANDOMIZE_SEED,
    SCORE_SEED,
    TRAIN_SEED,
    Budget,
    conditioned_config,
    dep_outputs,
    model_outputs,
    panel_pairs,
    read_scores,
    study_scene,
    train_settings,
    write_clean_images,
)
from restore.studies.stage_times import StageTimes
from restore.train import load_model, train
from udc_render.dataset.bank import read_bank
from udc_render.dataset.bank_make import bank_settings, make_bank, random_specs
from udc_render.dataset.randomize import load_distributions
from udc_render.errors import UdcError
from udc_render.io.files import save_text
from udc_render.pipeline import SynthConfig
from udc_render.profiles import describe, resolve_profile
from udc_render.scene.geometry import sensor_kernel_px
from udc_render.studies.fingerprint import FIELD, digest, file_digest, stale_note

SCORES_FILE, TIMES_FILE = "scores.jsonl", "times.json"
SWITCHES = {"level": {"wiener": False, "kernel_codes": False}, "codes": {"wiener": False},
            "features": {"kernel_codes": False}, "both": {}}  # the conditioned arms' switches (module doc)
BUDGETS = {
    # the robustness study's quick rig (128 × 64 px of 12.4 µm, 65-px kernels: 33 at the packed pitch, 3 bands,
    # 2 × 2 field phases) with its full budget's 16 training and 8 held-out panels; 64-px crops; 800 steps an arm
    "cpu": Budget("ablation-cpu", (128, 64), 12.4, "400:700:100", 2, train_images=32, val_images=8, train_panels=16,
                  heldout_panels=8, model={"type": "unet", "width": 8, "depth": 3}, crop_px=64, batch=4,
                  crops_per_image=2, epochs=50, lr=1e-3, clip_grad_norm=0.5),
    # the mechanics test's (its banks given, not made: 9-px blurs): 4 steps an arm of tiny models
    "tiny": Budget("ablation-tiny", (64, 32), 12.4, "400:700:100", 2, train_images=2, val_images=2, train_panels=2,
                   heldout_panels=2, model={"type": "unet", "width": 4, "depth": 2}, crop_px=16, batch=2,
                   crops_per_image=2, epochs=2, lr=1e-3,
                   conditioned={"type": "wiener-unet", "width": 4, "depth": 2, "fine_levels": 1, "fine_extra_width": 4,
                                "wiener_features": 1, "code_dim": 8, "kernel_px": 9}),
}


def arm_config(b: Budget, arm: str) -> dict:
    """The model config of `arm` (module doc) at budget b: the conditioned arms' b.conditioned (None:
    robustness.conditioned_config) with the arm's switches; 'wide' its backbone's keys as a unet-wide-fine."""
    if arm == "unet":
        return dict(b.model)
    cond = b.conditioned or conditioned_config(b)
    if arm == "wide":
        keys = ("out_channels", "width", "depth", "fine_levels", "fine_extra_width", "sub_encoders", "negative_slope")
        return {"type": "unet-wide-fine", **{k: cond[k] for k in keys if k in cond}}
    return {**cond, **SWITCHES[arm]}


def make_study_banks(out: Path, b: Budget, cache_dir: str | None, progress: bool) -> dict:
    """{'random': the training bank, 'heldout': the test bank} under out/banks (made or finished: make_bank
    resumes), on the robustness study's rig and draws at budget b."""
    scene, dists = study_scene(b), load_distributions("default")
    cfg, _ = resolve_profile("physical", SynthConfig(field_phases=b.field_phases, kernel_cache=cache_dir), [])
    size = sensor_kernel_px(scene)
    banks = {}
    for name, n, seed in (("random", b.train_panels, RANDOMIZE_SEED), ("heldout", b.heldout_panels, HELDOUT_SEED)):
        specs = random_specs(dists, n, seed, scene, cfg)
        extra = {"profile": describe(cfg.profile), "study": "ablation", "budget": b.name, "bank": name}
        make_bank(out / "banks" / name, specs, bank_settings(scene, cfg, size, specs, extra), size, progress=progress)
        banks[name] = read_bank(out / "banks" / name)
    return banks


def train_arms(out: Path, b: Budget, bank, data: Path, arms: tuple, progress: bool, seed: int = TRAIN_SEED) -> dict:
    """{arm: restore.train's summary} of each arm trained on `bank` with the shared recipe and training `seed`
    (resumed from its checkpoint; a finished run kept)."""
    return {arm: train(data, out / "train" / arm, replace(train_settings(b, bank, data, arm_config(b, arm)), seed=seed),
                       device="cpu", checkpoint_s=60.0, val_every=max(1, b.epochs // 5), progress=progress,
                       bank=bank.folder) for arm in arms}


def score_fingerprint(out: Path, bank, data: Path, arms: tuple) -> str:
    """The fingerprint of the score rows: the held-out bank, the validation images, the score seed and the arms'
    model files (sha256 of model.pt: a retrained arm is another)."""
    return digest({"bank": bank.fingerprint, "images": images_fingerprint(data), "score_seed": SCORE_SEED,
                   "models": {a: file_digest(out / "train" / a / "model.pt") for a in arms}})


def score_panel(models: dict, bank, index: int, images: list) -> dict[str, list[float]]:
    """{row: per-image PSNR} of the input, DeP with the panel's kernels and γ and each arm on the validation images
    through panel `index`, each also level-matched ('<row>_level')."""
    panel = bank.panels[index]
    pairs = panel_pairs(bank, panel, images)
    gts = [gt for _, gt in pairs]
    per_image = {"input": [paper_metrics(None, gt, packed=x)["psnr_db_paper"] for x, gt in pairs],
                 "input_level": [level_matched_psnr_db(None, gt, packed=x) for x, gt in pairs]}
    outputs = {"dep": dep_outputs(panel, pairs)}
    outputs.update({arm: model_outputs(m, bank, panel, pairs) for arm, m in models.items()})
    for key, ys in outputs.items():
        per_image[key] = [paper_metrics(y, gt)["psnr_db_paper"] for y, gt in zip(ys, gts)]
        per_image[f"{key}_level"] = [level_matched_psnr_db(y, gt) for y, gt in zip(ys, gts)]
    return per_image


def score_arms(out: Path, bank, data: Path, arms: tuple, progress: bool) -> list[dict]:
    """One row per held-out panel (its family, d, per-image and mean PSNRs of score_panel), appended to scores.jsonl;
    logged rows kept under the same fingerprint only (score_fingerprint)."""
    path, fingerprint = out / SCORES_FILE, score_fingerprint(out, bank, data, arms)
    logged = read_scores(path)
    rows = [r for r in logged if r.get(FIELD) == fingerprint]
    if note := stale_note("ablation", len(logged) - len(rows), path):
        print(note)
    done = {r["panel"] for r in rows}
    models = {a: load_model(out / "train" / a / "model.pt", "cpu")[0] for a in arms}
    images = clean_images(data, "val")
    todo = [i for i, p in enumerate(bank.panels) if p.name not in done]
    for i in tqdm(todo, desc="score", unit="panel", disable=not progress):
        t0, panel = time.perf_counter(), bank.panels[i]
        per_image = score_panel(models, bank, i, images)
        rows.append({"panel": panel.name, "family": panel.record.get("panel_draw", {}).get("family", "?"),
                     "distance_mm": panel.record.get("display", {}).get("distance_mm", 0.0),
                     "images": len(images),
                     **{f"psnr_{k}_db": float(np.mean(v)) for k, v in per_image.items()}, "per_image_db": per_image,
                     "seconds": round(time.perf_counter() - t0, 2), FIELD: fingerprint})
        save_text(path, "".join(json.dumps(r) + "\n" for r in rows))
    order = {p.name: i for i, p in enumerate(bank.panels)}
    return sorted(rows, key=lambda r: order[r["panel"]])


def parameters(out: Path, arms: tuple) -> dict[str, int]:
    """{arm: its trained model's parameters}."""
    return {a: count_parameters(load_model(out / "train" / a / "model.pt", "cpu")[0]) for a in arms}


def run_ablation(out: Path, budget: str = "cpu", banks: dict | None = None, cache_dir: str | None = None,
                 progress: bool = True, seed: int = TRAIN_SEED) -> dict:
    """The study (module doc) in `out`, or the rest of an interrupted one; writes the report and returns its result.
    banks: {'random', 'heldout'} given instead of made (the mechanics test's, or another run's: --banks); seed: the
    arms' training seed (initial weights, crops, panels and noise)."""
    if budget not in BUDGETS:
        raise UdcError(f"--budget {budget}: expected one of {', '.join(BUDGETS)}")
    out, b, arms = Path(out).resolve(), BUDGETS[budget], tuple(ARMS)
    out.mkdir(parents=True, exist_ok=True)
    times = StageTimes(out / TIMES_FILE)
    stages = (("clean images", lambda: write_clean_images(out / "clean", b)),
              ("banks", lambda: banks or make_study_banks(out, b, cache_dir, progress)))
    done = []
    for stage, make in stages:
        t0 = time.perf_counter()
        done.append(make())
        times.add(stage, time.perf_counter() - t0)
    data, banks = done
    summaries = train_arms(out, b, banks["random"], data, arms, progress, seed)
    t0 = time.perf_counter()
    rows = score_arms(out, banks["heldout"], data, arms, progress)
    times.add("score", time.perf_counter() - t0)
    config = dict(asdict(b), steps=b.steps,
                  arms={a: arm_config(b, a) for a in arms},
                  seeds={"train": seed, "randomize": RANDOMIZE_SEED, "heldout": HELDOUT_SEED,
                         "score": SCORE_SEED},
                  panels={k: [p.name for p in bank.panels] for k, bank in banks.items()})
    result = {"budget": config, "rows": rows, "train": summaries, "parameters": parameters(out, arms),
              "times": dict(times.seconds)}
    write_report(out, result)
    return result


def main(argv: list[str]) -> None:
    usage = ("python -m restore.studies.ablation [--out out/ablation] [--budget cpu] [--seed 0] [--banks RUN] "
             "[--cache DIR] [--threads 1]")
    pos, o = parse_options(argv, usage)
    if pos:
        sys.exit(f"usage: {usage}")
    out = Path(o.get("out", "out/ablation"))
    torch.set_num_threads(int(o.get("threads", 1)))  # 2 threads on 2 shared cores: ~10x slower epochs here
    try:
        banks = {k: read_bank(Path(o["banks"]) / "banks" / k) for k in ("random", "heldout")} if "banks" in o else None
        run_ablation(out, o.get("budget", "cpu"), banks, o.get("cache"), seed=int(o.get("seed", TRAIN_SEED)))
    except (UdcError, OSError, ValueError) as exc:
        sys.exit(f"error: {exc}")
    print(f"wrote {out}/ablation.md, ablation.json, ablation.png")


if __name__ == "__main__":
    main(sys.argv[1:])
