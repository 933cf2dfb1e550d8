"""`udc-render study robustness`: what training on randomized panels buys on panels the training never saw.

Two UNets are trained with the online degradation (restore.online, restore.train), the same model, steps, seeds
and clean crops, on
    (a) the default panel: a bank of the `physical` profile's P-OLED preset (d = 2 mm, its field bases);
    (b) randomized panels: a bank of N panels drawn from the documented ranges (randomize `default`, seed 0).
Both are scored with the paper protocol's PSNR (restore.metrics.paper_metrics: linear, clipped to [0, 1], border
cropped) on the validation images, each degraded once through each panel of a test set (restore.online.
validation_pairs: image j's noise from (SCORE_SEED, 'val', j)), beside the input (the packed RAW, as
restore.evaluate scores the input row) and DeP (restore.dep) given the panel's own kernels (the bank's, a
power-weighted mean over the field phases, at the packed pitch: restore.known.packed_from_sensor) and γ: a reference
that knows the panel, blind only to its field dependence; and DeP on the same captures without the sensor's
noise, fixed-pattern noise and defects (quantised all the same): what the noise costs. Each also with the
level-matched PSNR (restore.metrics.level_matched_psnr_db: each channel's level solved with the truth; randomized T
and brightness make the absolute level ambiguous):
    default      the default P-OLED (a's training panel);
    heldout      draws within the ranges that neither model trained on (randomize `default`, seed 1);
    disordered   the P-OLED with fabrication disorder (psf.layouts.disordered: a 2 × 2 supercell, openings moved
                 by N(0, 2.5 µm), sized by 1 + N(0, 0.15)); the default ranges hold no disorder;
    micrograph   a micrograph-type layout (MicrographLayout of a synthetic 64 µm tile of diamond openings, 24 %
                 open, 1 µm pixels), with the P-OLED's T(λ), gain and d;
    far          the P-OLED at d = 8 mm, beyond the ranges' 0.5–5 mm (its bands are ~1e-4 of the mean at any d,
                 study banding: its d changes little);
    toled        the T-OLED preset at d = 2 mm (within the ranges: the other family);
    toled_far    the T-OLED at d = 8 mm (its bands print: toled_far − toled is what d beyond the ranges costs).
The clean images are colour dead leaves (udc_render.content.charts, image i's palette from (IMAGES_SEED, i)), in
units of the white level, at most WHITE_FILL: a dataset folder's layout (manifest.jsonl, gt.exr) under out/clean.

Resumable: each bank through make_bank, each training run through restore.train's checkpoint, each score row
(set, panel) appended to scores.jsonl with the fingerprint of what made it (score_fingerprints: its bank, the
validation images, the score seed, the rows, and the sha256 of both models' files) and kept on a re-run only
under the same fingerprint (a retrained model, another bank or an older row without one: recomputed, and said
in one line); stage seconds are summed over re-runs (times.json). The report: robustness_report
(study_robustness.md / .csv / .png).
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import torch
from tqdm import tqdm

from psf import layouts
from restore.conditioning import (
    bank_descriptions,
    check_model_description,
    needs_description,
    predict_described,
    spec_kernel_px,
)
from restore.degrade import Degrader
from restore.dep import dep_restore
from restore.known import packed_from_sensor
from restore.metrics import level_matched_psnr_db, paper_metrics
from restore.online import clean_images, images_fingerprint, validation_pairs
from restore.studies.robustness_report import MODELS, ROWS, SETS, UNETS, write_report
from restore.studies.stage_times import StageTimes
from restore.train import TrainSettings, load_model, predict, train
from udc_render.content.charts import dead_leaves_colour
from udc_render.dataset.bank import Bank, read_bank
from udc_render.dataset.bank_make import bank_settings, make_bank, preset_specs, random_specs
from udc_render.dataset.randomize import load_distributions
from udc_render.errors import UdcError
from udc_render.io.exr import read_exr, save_exr
from udc_render.io.files import save_text
from udc_render.optics.displays import Display, micrograph_display, preset
from udc_render.pipeline import SynthConfig
from udc_render.profiles import describe, resolve_profile
from udc_render.scene import load_scene
from udc_render.scene.geometry import sensor_kernel_px
from udc_render.scene.overrides import with_overrides
from udc_render.studies.fingerprint import FIELD, digest, file_digest, stale_note

TRAIN_SEED, RANDOMIZE_SEED, HELDOUT_SEED, SCORE_SEED, IMAGES_SEED = 0, 0, 1, 2026, 31
WHITE_FILL = 0.8  # the clean images' brightest value: the rig's white at 0.8 of the full well (pipeline.py)
FAR_DISTANCE_MM = 8.0  # beyond the default ranges' 0.5-5 mm
DISORDER = {"cells": 2, "position_sd_um": 2.5, "size_sd": 0.15, "seed": 0}
TILE = {"period_px": 64, "pixel_um": 1.0, "large_half_diagonal_px": 13, "small_half_diagonal_px": 9}
SCORES_FILE, TIMES_FILE = "scores.jsonl", "times.json"
SCORES_VERSION = 2  # 2: a score row has a fingerprint (score_fingerprints); rows without one are recomputed


@dataclass(frozen=True)
class Budget:
    """What a run of the study costs: the rig (frame, pitch, bands, field phases), the images, the panels and the
    training recipe shared by both models."""
    name: str
    sensor_px: tuple[int, int]  # (width, height)
    pitch_um: float
    bands_nm: str | None  # None: the monitor scene's
    field_phases: int
    train_images: int
    val_images: int
    train_panels: int
    heldout_panels: int
    model: dict
    crop_px: int
    batch: int
    crops_per_image: int
    epochs: int
    lr: float
    clip_grad_norm: float | None = None
    # the conditioned restorer (restore.models_conditioned's config), trained like (b) on the randomized panels and
    # scored with each test panel's description (describe_panel of the bank's panel); None: not in the study
    conditioned: dict | None = None

    @property
    def models(self) -> tuple[str, ...]:
        """The models the budget trains and scores (robustness_report.MODELS' keys)."""
        return UNETS + (("conditioned",) if self.conditioned else ())

    @property
    def steps(self) -> int:
        return math.ceil(self.train_images * self.crops_per_image / self.batch) * self.epochs


BUDGETS = {
    # the smoke run: 128 × 64 px of 12.4 µm (a quarter of the default frame's field of view; 65-px kernels),
    # 3 bands, 2 × 2 field phases
    "quick": Budget("quick", (128, 64), 12.4, "400:700:100", 2, train_images=8, val_images=4, train_panels=4,
                    heldout_panels=2, model={"type": "unet", "width": 8, "depth": 3}, crop_px=32, batch=4,
                    crops_per_image=2, epochs=40, lr=3e-3),
    # the CPU budget: 512 × 256 px of 6.2 µm (the default frame's field of view, 129-px kernels), the scene's bands
    "full": Budget("full", (512, 256), 6.2, None, 4, train_images=48, val_images=8, train_panels=16,
                   heldout_panels=8, model={"type": "unet", "width": 16, "depth": 4}, crop_px=128, batch=4,
                   crops_per_image=4, epochs=240, lr=5e-4, clip_grad_norm=0.5),
}


def study_scene(b: Budget):
    """The monitor scene at the budget's frame, pitch and bands."""
    return with_overrides(load_scene("monitor"), bands_nm=b.bands_nm, sensor_px=b.sensor_px, pitch_um=b.pitch_um)


def clean_manifest(b: Budget) -> list[dict]:
    """The manifest lines of the budget's clean set (module doc)."""
    splits = ["train" if i < b.train_images else "val" for i in range(b.train_images + b.val_images)]
    return [{"item": i, "split": split, "folder": str(Path(split) / f"item_{i:04d}"), "image": f"dead_leaves:{i}",
             "displays": ["glass"]} for i, split in enumerate(splits)]


def check_clean_images(folder: Path, b: Budget) -> None:
    """Refuse, in one line, a clean set in `folder` that another budget made (its items or frame differ)."""
    manifest = folder / "manifest.jsonl"
    lines = [json.loads(line) for line in manifest.read_text().splitlines() if line.strip()]
    h, w = read_exr(folder / lines[0]["folder"] / "gt.exr")["R"].shape if lines else (0, 0)
    if lines != clean_manifest(b) or (w, h) != tuple(b.sensor_px):
        raise UdcError(f"{manifest}: another budget's clean images ({len(lines)} of {w}×{h} px; the {b.name} budget "
                       f"makes {b.train_images + b.val_images} of {b.sensor_px[0]}×{b.sensor_px[1]} px); use another "
                       "--out or delete the folder")


def clean_image(b: Budget, i: int) -> np.ndarray:
    """[3, h, w] float32: item i of the budget's clean set (module doc)."""
    # [IMAGES_SEED, 0] is default_rng(IMAGES_SEED) (zero padding), which nothing else draws from
    palette = np.random.default_rng([IMAGES_SEED, i]).uniform(0.0, WHITE_FILL, (16, 3))
    return dead_leaves_colour(*b.sensor_px, IMAGES_SEED * 1000 + i, palette).astype(np.float32)


def write_clean_images(folder: Path, b: Budget) -> Path:
    """The clean set (module doc) in `folder`, a dataset layout; kept when its manifest is there and is this
    budget's (check_clean_images)."""
    if (folder / "manifest.jsonl").is_file():
        check_clean_images(folder, b)
        return folder
    lines = []
    for i, line in enumerate(clean_manifest(b)):
        split = line["split"]
        rgb = clean_image(b, i)
        item = Path(split) / f"item_{i:04d}"
        (folder / item).mkdir(parents=True, exist_ok=True)
        save_exr(folder / item / "gt.exr", {c: rgb[k] for k, c in enumerate("RGB")})
        lines.append(json.dumps(line))
    save_text(folder / "manifest.jsonl", "\n".join(lines) + "\n")
    return folder


def diamond_tile(path: Path) -> Path:
    """The micrograph-type tile (module doc): intensity 1 inside |x − cx| + |y − cy| ≤ a, large diamonds on one
    diagonal of the 2 × 2 cell, small ones on the other; written as an 8-bit PNG."""
    n, big, small = TILE["period_px"], TILE["large_half_diagonal_px"], TILE["small_half_diagonal_px"]
    y, x = np.mgrid[:n, :n] + 0.5
    tile = np.zeros((n, n), bool)
    for cx, cy, a in ((n / 4, n / 4, big), (3 * n / 4, 3 * n / 4, big), (3 * n / 4, n / 4, small),
                      (n / 4, 3 * n / 4, small)):
        tile |= np.abs(x - cx) + np.abs(y - cy) <= a
    path.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(path, (tile * 255).astype(np.uint8))
    return path


def outside_displays(out: Path, poled: Display, toled: Display) -> dict:
    """{set: its displays} of the test sets made from the physical profile's presets `poled` and `toled` (module
    doc): the disordered P-OLED, the micrograph tile, both presets at FAR_DISTANCE_MM, the T-OLED as it is."""
    d = DISORDER
    disordered = replace(poled, name="poled_disordered", source="robustness study: the P-OLED preset, disordered",
                         layout=layouts.disordered(poled.layout, d["cells"], d["position_sd_um"], d["size_sd"],
                                                   d["seed"]))
    tile = micrograph_display(diamond_tile(out / "panels" / "diamond_tile.png"), TILE["pixel_um"], "intensity")
    micro = replace(poled, name=tile.name, layout=tile.layout, source=tile.source)
    return {"disordered": [disordered], "micrograph": [micro],
            "far": [poled.with_distance(FAR_DISTANCE_MM)], "toled": [toled],
            "toled_far": [toled.with_distance(FAR_DISTANCE_MM)]}


def bank_specs(out: Path, b: Budget, scene, cfg: SynthConfig) -> dict:
    """{bank name: the specs of its panels}: 'default' (a's training panel and the first test set), 'random'
    (b's), 'heldout', 'disordered', 'micrograph', 'far', 'toled', 'toled_far'."""
    dists = load_distributions("default")
    _, (poled, toled) = resolve_profile("physical", cfg, [preset("poled"), preset("toled")])
    specs = {"default": preset_specs([poled], scene, cfg),
             "random": random_specs(dists, b.train_panels, RANDOMIZE_SEED, scene, cfg),
             "heldout": random_specs(dists, b.heldout_panels, HELDOUT_SEED, scene, cfg)}
    specs.update({k: preset_specs(d, scene, cfg) for k, d in outside_displays(out, poled, toled).items()})
    return specs


def make_banks(out: Path, b: Budget, times: StageTimes, cache_dir: str | None, progress: bool) -> dict[str, Bank]:
    """Every bank of the study under out/banks (made or finished now; make_bank resumes)."""
    scene = study_scene(b)
    cfg, _ = resolve_profile("physical", SynthConfig(field_phases=b.field_phases, kernel_cache=cache_dir), [])
    size = sensor_kernel_px(scene)
    extra = {"profile": describe(cfg.profile), "study": "robustness", "budget": b.name}
    banks = {}
    for name, specs in bank_specs(out, b, scene, cfg).items():
        t0 = time.perf_counter()
        folder = out / "banks" / name
        s = make_bank(folder, specs, bank_settings(scene, cfg, size, specs, dict(extra, bank=name)), size,
                      progress=progress)
        if s["made"]:
            times.add(f"bank {name}", time.perf_counter() - t0)
        banks[name] = read_bank(folder)
    return banks


def train_settings(b: Budget, bank: Bank, data: Path, model: dict | None = None) -> TrainSettings:
    """The recipe the models share (module doc), on `bank`'s panels, for `model` (None: the budget's UNet)."""
    names = [p.name for p in bank.panels]
    return TrainSettings(model=model or b.model, display=",".join(names), epochs=b.epochs, batch=b.batch,
                         crop_px=b.crop_px, crops_per_pair=b.crops_per_image, lr=b.lr, seed=TRAIN_SEED,
                         data_fingerprint=images_fingerprint(data), clip_grad_norm=b.clip_grad_norm,
                         degrade={"mode": "online", "bank_fingerprint": bank.fingerprint, "panels": names})


def train_models(out: Path, b: Budget, banks: dict, data: Path, progress: bool) -> dict:
    """{model key: train summary} of the budget's models ('fixed': a, on the default panel; 'randomized': b; with
    b.conditioned, 'conditioned': that model on b's panels) (restore.train: resumed from a checkpoint, a finished
    run kept)."""
    summaries = {}
    plan = {"fixed": ("default", None), "randomized": ("random", None), "conditioned": ("random", b.conditioned)}
    for key in b.models:
        bank = banks[plan[key][0]]
        summaries[key] = train(data, out / "train" / key, train_settings(b, bank, data, plan[key][1]), device="cpu",
                               checkpoint_s=60.0, val_every=max(1, b.epochs // 5), progress=progress,
                               bank=bank.folder)
    return summaries


def read_scores(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()] if path.is_file() else []


def dep_outputs(panel, pairs: list) -> list[np.ndarray]:
    """DeP (restore.dep) of each packed input with the panel's own kernels (restore.known.packed_from_sensor) and γ:
    the reference that knows the panel exactly (module doc); the Wiener sampler of image j seeded (SCORE_SEED, j)
    (j = 0: default_rng(SCORE_SEED), zero padding; the validation noise draws from named streams of SCORE_SEED,
    restore.online.validation_pairs, not from that root stream)."""
    kernels = packed_from_sensor(panel.kernels)
    return [dep_restore(x, panel.gamma_rgb, kernels, rng=[SCORE_SEED, j]).rgb for j, (x, _) in enumerate(pairs)]


def panel_pairs(bank: Bank, panel, images: list) -> list[tuple]:
    """The validation images degraded once through `panel` (restore.online.validation_pairs, SCORE_SEED)."""
    return validation_pairs(images, Bank(bank.folder, bank.settings, [panel]), Degrader([panel], "cpu", torch.float32),
                            SCORE_SEED)


def model_outputs(model, bank: Bank, panel, pairs: list) -> list[np.ndarray]:
    """The model's restorations of the packed inputs of `pairs`; a model that needs the panel's description
    (restore.conditioning) is given `panel`'s (describe_panel on the bank's frame, in the model's kernel window),
    checked against the sensor and frame it was trained for."""
    if not needs_description(model):
        return [predict(model, x, torch.device("cpu")) for x, _ in pairs]
    description = bank_descriptions(Bank(bank.folder, bank.settings, [panel]), spec_kernel_px(model))[0]
    check_model_description(model, description, f"the study's {type(model).__name__}")
    return [predict_described(model, x, description, torch.device("cpu")) for x, _ in pairs]


def score_panel(models: dict, bank: Bank, index: int, images: list, dep_after: dict | None = None) -> dict[str, dict]:
    """{row key: scores} of the input, DeP with the panel's kernel (on the capture, and on the capture without the
    sensor's noise) and each model on `images` degraded once through panel `index` (module doc; model_outputs);
    dep_after: {row key: f} more rows, f(DeP's output on the capture, panel) (e.g. restore.dep_far.subtract_far)."""
    panel = bank.panels[index]
    pairs = panel_pairs(bank, panel, images)
    per_image = {"input": [paper_metrics(None, gt, packed=x)["psnr_db_paper"] for x, gt in pairs],
                 "input_level": [level_matched_psnr_db(None, gt, packed=x) for x, gt in pairs]}
    dep = dep_outputs(panel, pairs)
    per_image.update(output_scores("dep", dep, pairs))
    for key, after in (dep_after or {}).items():
        per_image.update(output_scores(key, [after(rgb, panel) for rgb in dep], pairs))
    quiet = replace(panel, sensor=replace(panel.sensor, noise="none"), defects=None, fpn=None)
    quiet_pairs = panel_pairs(bank, quiet, images)
    per_image.update(output_scores("dep_noiseless", dep_outputs(quiet, quiet_pairs), quiet_pairs))
    for key, model in models.items():
        per_image.update(output_scores(key, model_outputs(model, bank, panel, pairs), pairs))
    return per_image


def output_scores(key: str, outputs: list, pairs: list) -> dict[str, list]:
    """{key: paper-protocol PSNRs, key_level: level-matched PSNRs} of restorations `outputs` against the truths of
    `pairs` (restore.metrics)."""
    truths = [gt for _, gt in pairs]
    return {key: [paper_metrics(y, gt)["psnr_db_paper"] for y, gt in zip(outputs, truths)],
            f"{key}_level": [level_matched_psnr_db(y, gt) for y, gt in zip(outputs, truths)]}


def score_fingerprints(out: Path, banks: dict, data: Path, keys: tuple = UNETS) -> dict[str, str]:
    """{set: the fingerprint of its score rows}: the set's bank (bank.json's fingerprint), the validation images,
    the score seed, the rows scored and the models' files (`keys`; sha256 of model.pt: a retrained model is
    another)."""
    models = {key: file_digest(out / "train" / key / "model.pt") for key in keys}
    rows = [k for k in ROWS if k not in MODELS or k in keys]
    common = {"version": SCORES_VERSION, "images": images_fingerprint(data), "score_seed": SCORE_SEED,
              "rows": rows, "models": models}
    return {s: digest({**common, "bank": banks[s].fingerprint}) for s in SETS}


def score(out: Path, banks: dict, data: Path, progress: bool, keys: tuple = UNETS) -> list[dict]:
    """Every (set, panel) row of scores.jsonl: the paper PSNR of the input, DeP and the models `keys`, per image and
    mean; logged rows are kept under their set's fingerprint only (score_fingerprints), the others recomputed."""
    path = out / SCORES_FILE
    fingerprints, logged = score_fingerprints(out, banks, data, keys), read_scores(path)
    rows = [r for r in logged if r.get(FIELD) == fingerprints.get(r["set"])]
    if note := stale_note("study robustness", len(logged) - len(rows), path):
        print(note)
    done = {(r["set"], r["panel"]) for r in rows}
    models = {key: load_model(out / "train" / key / "model.pt", "cpu")[0] for key in keys}
    images = clean_images(data, "val")
    todo = [(s, i) for s in SETS for i, p in enumerate(banks[s].panels) if (s, p.name) not in done]
    for s, i in tqdm(todo, desc="score", unit="panel", disable=not progress):
        t0 = time.perf_counter()
        panel = banks[s].panels[i]
        per_image = score_panel(models, banks[s], i, images)
        rows.append({"set": s, "panel": panel.name, "distance_mm": panel.record["display"]["distance_mm"],
                     "family": panel.record.get("panel_draw", {}).get("family", panel.record["display"]["name"]),
                     "images": len(images), "score_seed": SCORE_SEED,
                     **{f"psnr_{k}_db": float(np.mean(v)) for k, v in per_image.items()},
                     "per_image_db": per_image, "seconds": round(time.perf_counter() - t0, 2), FIELD: fingerprints[s]})
        save_text(path, "".join(json.dumps(r) + "\n" for r in rows))
    return rows


def conditioned_config(b: Budget) -> dict:
    """The conditioned restorer of budget b (`study robustness --conditioned`): restore.models_conditioned's
    defaults at the budget UNet's width and depth, its descriptions' window the rig's kernel at the packed pitch
    (half the sensor kernel's size, odd)."""
    from restore.models_conditioned import WIENER_UNET_CONFIG
    size = sensor_kernel_px(study_scene(b)) // 2 | 1
    return {**WIENER_UNET_CONFIG, **{k: b.model[k] for k in ("width", "depth") if k in b.model}, "kernel_px": size}


def run_study(out: Path, quick: bool = False, cache_dir: str | None = None, progress: bool = True,
              conditioned: bool = False) -> dict:
    """The study (module doc) in `out`, or the rest of an interrupted one; writes the report and returns
    {"rows", "budget", "times", "train"}. conditioned: the budget's conditioned model (conditioned_config) trained
    and scored beside the two UNets."""
    out = Path(out).resolve()  # the tile's path is in the micrograph bank's settings: one spelling per folder
    out.mkdir(parents=True, exist_ok=True)
    b = BUDGETS["quick" if quick else "full"]
    if conditioned:
        b = replace(b, conditioned=conditioned_config(b))
    times = StageTimes(out / TIMES_FILE)
    t0 = time.perf_counter()
    data = write_clean_images(out / "clean", b)
    if "clean images" not in times.seconds:
        times.add("clean images", time.perf_counter() - t0)
    banks = make_banks(out, b, times, cache_dir, progress)
    summaries = train_models(out, b, banks, data, progress)
    rows = score(out, banks, data, progress, b.models)
    budget = dict(asdict(b), steps=b.steps, seeds={"train": TRAIN_SEED, "randomize": RANDOMIZE_SEED,
                                                  "heldout": HELDOUT_SEED, "score": SCORE_SEED, "images": IMAGES_SEED},
                  panels={name: [p.name for p in bank.panels] for name, bank in banks.items()})
    result = {"rows": rows, "budget": budget, "times": dict(times.seconds), "train": summaries}
    write_report(out, result)
    return result
