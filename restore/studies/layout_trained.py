"""`udc-render study layout-trained`: pixel layouts compared by restorers through the simulator (issue 48).

For each layout given (a display file, a preset or a micrograph; `@edge` frames its cell with the first opening at
the tile's edge, `@turned` tiles it with a random quarter-turn per tile: a preset exactly, from its Fourier series
(psf.turned), a micrograph by its own pixels (udc_render.design.cells.frame_cell, psf.MicrographLayout)), at equal
footing:
    d = 2 mm (the physical profile's), the stack's T(λ) as the display gives it, and a gain of 1 / the layout's
    power transmittance, so that every capture's mean level is glass's;
1. a kernel bank of the layout (udc_render.dataset.bank_make) under the `physical` profile at the robustness study's
   rig (restore.studies.robustness.BUDGETS: 'full' 512 × 256 px of 6.2 µm, 129-px kernels; 'quick' 128 × 64 px of
   12.4 µm): per-channel kernels with the field blend over d, the far field past the window, γ, fixed-pattern noise,
   Poisson and read noise, quantisation, dead and hot pixels;
2. a small UNet (the budget's: width 16, depth 4, EPOCHS = 80 epochs of 4 crops of 128 px from 48 images) trained
   online through that bank (restore.train, --degrade online): one specialist per layout, the same recipe and seeds;
3. scored on the budget's validation images (colour dead leaves; score_images: more, score_set) each degraded once
   through the layout (restore.studies.robustness.score_panel): the packed input, DeP given the layout's own kernels
   and γ, DeP on the same capture without the sensor's noise, DeP on the capture without the far field (the light
   past the kernel window, which DeP's kernel does not hold: dep_nofar), DeP given the far field too (its light
   taken out of DeP's output on the same capture: restore.dep_far, dep_far), and the UNet; the paper protocol's PSNR
   and the level-matched PSNR.
The clean images, noise draws and training seeds are the same for every layout, so the per-image differences to
the reference layout (the first given) are paired: mean, standard error s_d / √n and the images won.
Not the spectral synthesis of `udc-render dataset`: the bank's per-channel form (one kernel and one γ per camera
channel for the monitor's white).

Resumable: the banks through make_bank, the training through restore.train's checkpoints, each layout's score row
kept in scores.jsonl under the fingerprint of its bank, images and model (robustness.score_fingerprints' recipe).
Writes study_layout_trained.md / .json / .png (the PSNRs) and study_layout_trained_restored.png (the first
validation image: truth, DeP and the UNet per layout).
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from psf.layouts import PeriodicLayout
from psf.turned import TurnedLayout, edge_framed
from restore.dep_far import subtract_far
from restore.online import clean_images, images_fingerprint
from restore.studies.robustness import (
    BUDGETS as ROBUSTNESS_BUDGETS,
    SCORE_SEED,
    TRAIN_SEED,
    dep_outputs,
    model_outputs,
    output_scores,
    panel_pairs,
    read_scores,
    score_panel,
    study_scene,
    train_settings,
    write_clean_images,
)
from restore.studies.stage_times import StageTimes
from restore.train import load_model, train
from udc_render.dataset.bank import read_bank
from udc_render.dataset.bank_make import bank_settings, make_bank, preset_specs
from udc_render.design.cells import SIMULATOR_TILE_SEED, frame_cell, layout_cell
from udc_render.errors import UdcError
from udc_render.io.exr import save_exr
from udc_render.io.files import save_json, save_text
from udc_render.io.plots import save_plot
from udc_render.metrics import paired_differences
from udc_render.optics.displays import Display, load_display, micrograph_display
from udc_render.pipeline import SynthConfig
from udc_render.profiles import describe, resolve_profile
from udc_render.scene.geometry import sensor_kernel_px
from udc_render.studies.fingerprint import FIELD, digest, file_digest, stale_note

__all__ = ["DISTANCE_MM", "MAX_SCORE_IMAGES", "MODIFIERS", "NAME", "check_score_images", "entry_display", "paired",
           "score_set", "study_budget", "run_study"]

DISTANCE_MM = 2.0  # the physical profile's d for the presets, and the banding distance
MODIFIERS = ("edge", "turned")
NAME = "study_layout_trained"
ROW_KEYS = ("input", "dep", "dep_noiseless", "dep_nofar", "dep_far", "unet")
VERSION = 3  # 2: the dep_nofar row; 3: dep_far
EPOCHS = 80  # by time: 80 (3840 steps) take 5-6 min a layout on 2 cores with nothing beside them (3.7-4.7 s an epoch
# with the physical profile's online degradation at d = 2 mm; 8.5 s beside other work), the robustness recipe's 240
# take 17 min (--train-epochs 240: docs/guides/design.md has both)
MAX_SCORE_IMAGES = 256  # --score-images: 1.6 s an image a layout on 2 cores (DeP, its variants, the UNet): 7 min at 256
BUDGETS = {"quick": ROBUSTNESS_BUDGETS["quick"], "full": replace(ROBUSTNESS_BUDGETS["full"], epochs=EPOCHS)}


def _cell_display(display: Display, frame: str, turned: bool, folder: Path) -> Display:
    """The display framed ('edge': its first opening at the tile's edge) and tiled turned or not (tile seed
    SIMULATOR_TILE_SEED), its T(λ) kept: a preset exactly (psf.turned: its Fourier series, no raster); a micrograph
    as its own pixels, framed, written as an EXR in `folder` and tiled as a micrograph."""
    name = display.name + ("_edge" if frame == "edge" else "") + ("_turned" if turned else "")
    source = (f"{display.source}, cell {'framed at the edge, ' if frame == 'edge' else ''}"
              f"{'turned per tile' if turned else 'repeated'}")
    if isinstance(display.layout, PeriodicLayout):
        layout = edge_framed(display.layout) if frame == "edge" else display.layout
        layout = TurnedLayout(layout, SIMULATOR_TILE_SEED) if turned else layout
        return replace(display, name=name, layout=layout, source=source)
    cell, pixel_um = layout_cell(display.layout)
    path = folder / f"{name}.exr"
    folder.mkdir(parents=True, exist_ok=True)
    save_exr(path, {c: frame_cell(cell, frame).astype(np.float32) for c in "RGB"})
    tiled = micrograph_display(path, pixel_um, "amplitude", turned, SIMULATOR_TILE_SEED)
    return replace(tiled, name=name, transmission=display.transmission, source=source)


def entry_display(spec: str, folder: Path) -> Display:
    """The display of one entry, DISPLAY[@edge][@turned] (module doc), with the gain 1 / its power transmittance
    (its T(λ) and its distance as loaded: the study sets d)."""
    base, *mods = spec.split("@")
    bad = [m for m in mods if m not in MODIFIERS]
    if bad or len(set(mods)) != len(mods):
        raise UdcError(f"--display {spec}: unknown or repeated modifier @{(bad or mods)[0]}; allowed: "
                       + ", ".join("@" + m for m in MODIFIERS))
    display = load_display(base)
    if display.layout is None:
        raise UdcError(f"--display {spec}: glass has no pixel layout to compare")
    if mods:
        display = _cell_display(display, "edge" if "edge" in mods else "as_given", "turned" in mods, folder)
    return replace(display, gain=1.0 / float(display.layout.power_transmittance))


def _banks(out: Path, displays: list[Display], b, times: StageTimes, cache_dir: str | None, progress: bool) -> dict:
    """{display name: its bank} under out/banks (make_bank resumes)."""
    scene = study_scene(b)
    cfg, placed = resolve_profile("physical", SynthConfig(field_phases=b.field_phases, kernel_cache=cache_dir),
                                  displays, distance_mm=DISTANCE_MM)
    size = sensor_kernel_px(scene)
    banks = {}
    for display in placed:
        t0 = time.perf_counter()
        folder = out / "banks" / display.name
        specs = preset_specs([display], scene, cfg)
        extra = {"profile": describe(cfg.profile), "study": "layout-trained", "budget": b.name}
        if make_bank(folder, specs, bank_settings(scene, cfg, size, specs, extra), size, progress=progress)["made"]:
            times.add(f"bank {display.name}", time.perf_counter() - t0)
        banks[display.name] = read_bank(folder)
    return banks


def check_score_images(images: int | None) -> None:
    """Refuse, in one line, a score set outside 2 … MAX_SCORE_IMAGES images (None: the budget's)."""
    if images is not None and not 2 <= images <= MAX_SCORE_IMAGES:
        raise UdcError(f"--score-images {images}: expected a count in 2 … {MAX_SCORE_IMAGES} (paired differences "
                       "need two)")


def score_set(out: Path, b, images: int | None) -> Path:
    """The clean set the layouts are scored on: the training set's (out/clean) or, with `images`, one whose
    validation split holds that many: the budget's items 0 … train + val − 1 and more of the same generator
    (clean_image), so its first validation images are the training set's (out/clean_score_<n>)."""
    if images is None or images == b.val_images:
        return out / "clean"
    return write_clean_images(out / f"clean_score_{images}", replace(b, val_images=int(images)))


def _fingerprint(out: Path, bank, data: Path, name: str) -> str:
    return digest({"version": VERSION, "images": images_fingerprint(data), "score_seed": SCORE_SEED,
                   "bank": bank.fingerprint, "model": file_digest(out / "train" / name / "model.pt")})


def _score(out: Path, banks: dict, data: Path, progress: bool) -> list[dict]:
    """Each layout's score row (score_panel) in scores.jsonl, kept under its fingerprint (module doc)."""
    path = out / "scores.jsonl"
    logged = read_scores(path)
    prints = {name: _fingerprint(out, bank, data, name) for name, bank in banks.items()}
    rows = [r for r in logged if prints.get(r["layout"]) == r.get(FIELD)]
    if note := stale_note("study layout-trained", len(logged) - len(rows), path):
        print(note)
    images = clean_images(data, "val")
    done = {r["layout"] for r in rows}
    for name in tqdm([n for n in banks if n not in done], desc="score", unit="layout", disable=not progress):
        t0 = time.perf_counter()
        model = load_model(out / "train" / name / "model.pt", "cpu")[0]
        per_image = {**score_panel({"unet": model}, banks[name], 0, images, {"dep_far": subtract_far}),
                     **_dep_without_far(banks[name], images)}
        rows.append({"layout": name, "images": len(images), **{f"psnr_{k}_db": float(np.mean(v))
                                                                for k, v in per_image.items()},
                     "per_image_db": per_image, "seconds": round(time.perf_counter() - t0, 2), FIELD: prints[name]})
        save_text(path, "".join(json.dumps(r) + "\n" for r in rows))
    order = list(banks)
    return sorted(rows, key=lambda r: order.index(r["layout"]))


def _dep_without_far(bank, images: list) -> dict:
    """DeP (PSNR and level-matched) on captures of panel 0 made without its far field: what the light past the kernel
    window costs DeP, whose kernel holds only the window (the same noise draws as score_panel's)."""
    panel = replace(bank.panels[0], far=None)
    pairs = panel_pairs(bank, panel, images)
    return output_scores("dep_nofar", dep_outputs(panel, pairs), pairs)


def paired(values: list[float], reference: list[float]) -> dict:
    """Paired differences d_i = values_i − reference_i: mean, standard error s_d / √n (n ≥ 2) and the wins
    (udc_render.metrics.paired_differences)."""
    p = paired_differences(np.asarray(values, float) - np.asarray(reference, float))
    return {"mean_db": p["mean"], "se_db": p["standard_error"], "wins": p["wins"], "n": p["n"]}


def _figure(out: Path, banks: dict, data: Path, rows: list[dict]) -> None:
    """The first validation image: its truth, then DeP's and the UNet's restorations per layout (paper PSNR)."""
    import matplotlib.pyplot as plt
    image = clean_images(data, "val")[:1]
    fig, axes = plt.subplots(len(banks), 3, figsize=(9, 1.6 * len(banks) + 0.4), squeeze=False)
    for i, (name, bank) in enumerate(banks.items()):
        pairs = panel_pairs(bank, bank.panels[0], image)
        model = load_model(out / "train" / name / "model.pt", "cpu")[0]
        row = next(r for r in rows if r["layout"] == name)["per_image_db"]
        shown = [(pairs[0][1], "truth"), (dep_outputs(bank.panels[0], pairs)[0], f"DeP {row['dep'][0]:.2f} dB"),
                 (model_outputs(model, bank, bank.panels[0], pairs)[0], f"UNet {row['unet'][0]:.2f} dB")]
        for ax, (img, title) in zip(axes[i], shown):
            ax.imshow(np.clip(np.asarray(img).transpose(1, 2, 0), 0, 1) ** (1 / 2.2))
            ax.set_title(f"{name}: {title}" if title != "truth" else name, fontsize=8)
            ax.axis("off")
    fig.tight_layout()
    save_plot(fig, out / f"{NAME}_restored.png")


def _plot(out: Path, rows: list[dict]) -> None:
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 3.2))
    x = np.arange(len(rows))
    for j, (key, label) in enumerate((("input", "input"), ("dep", "DeP"), ("dep_far", "DeP given the far field"),
                                      ("unet", "UNet"))):
        ax.bar(x + (j - 1.5) * 0.2, [r[f"psnr_{key}_db"] for r in rows], 0.2, label=label)
    ax.set_xticks(x, [r["layout"] for r in rows], fontsize=8)
    ax.set_ylabel("PSNR (paper protocol), dB")
    ax.set_ylim(0, 1.3 * max(r[f"psnr_{k}_db"] for r in rows for k in ROW_KEYS))  # room for the legend
    ax.legend(fontsize=8, ncol=4, loc="upper center")
    ax.set_title("validation images through each layout's bank (d = 2 mm, gain 1/T)", fontsize=9)
    fig.tight_layout()
    save_plot(fig, out / f"{NAME}.png")


def _markdown(result: dict) -> str:
    rows, ref = result["rows"], result["rows"][0]
    b = result["budget"]
    lines = [f"# `study layout-trained` ({b['name']} budget)", "",
             f"Rig: {b['sensor_px'][0]} × {b['sensor_px'][1]} px of {b['pitch_um']:g} µm (DeP on packed planes of "
             f"{2 * b['pitch_um']:g} µm).", "",
             f"Reference for the paired differences: {ref['layout']} ({ref['images']} validation images, "
             "the same noise draws for every layout). PSNR: the paper protocol's; level: level-matched.", "",
             "| layout | T | input | DeP | DeP, no sensor noise | DeP, no far field | DeP given the far field | UNet | "
             "UNet level | DeP − ref | DeP given the far field − ref | UNet − ref |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        p = result["paired"][r["layout"]]
        diff = {k: "—" if r is ref else f"{p[k]['mean_db']:+.2f} ± {p[k]['se_db']:.2f} ({p[k]['wins']}/{p[k]['n']})"
                for k in ("dep", "dep_far", "unet")}
        lines.append(f"| {r['layout']} | {result['transmission'][r['layout']]:.4f} | {r['psnr_input_db']:.2f} | "
                     f"{r['psnr_dep_db']:.2f} | {r['psnr_dep_noiseless_db']:.2f} | {r['psnr_dep_nofar_db']:.2f} | "
                     f"{r['psnr_dep_far_db']:.2f} | {r['psnr_unet_db']:.2f} | "
                     f"{r['psnr_unet_level_db']:.2f} | {diff['dep']} | {diff['dep_far']} | {diff['unet']} |")
    seconds = {**result["times"], **{f"train {k}": t["seconds"] for k, t in result["train"].items()}}
    lines += ["", "Seconds (2 cores unless said): " + ", ".join(f"{k} {v:.0f}" for k, v in seconds.items()), ""]
    return "\n".join(lines)


def study_budget(quick: bool = False, epochs: int | None = None, pitch_um: float | None = None):
    """The robustness budget ('quick' or 'full') with the UNets' epochs and the rig's sensor pitch given (None: the
    budget's): the frame keeps its pixels, so a finer pitch sees a smaller field, and the bank's kernels take the
    render margin at that pitch (sensor_kernel_px: 129 px at 6.2 µm, 257 at 3.1)."""
    b = BUDGETS["quick" if quick else "full"]
    b = b if epochs is None else replace(b, epochs=int(epochs))
    return b if pitch_um is None else replace(b, pitch_um=float(pitch_um))


def run_study(out: Path, specs: list[str], quick: bool = False, cache_dir: str | None = None,
              progress: bool = True, train_seed: int = TRAIN_SEED, epochs: int | None = None,
              pitch_um: float | None = None, score_images: int | None = None) -> dict:
    """The study (module doc) of the layouts `specs` (DISPLAY[@edge][@turned]; the first is the reference) in `out`,
    or the rest of an interrupted one; writes the report and returns its JSON document. train_seed: the UNets'
    (the score's images and noise draws do not change with it); epochs: the UNets' (None: the budget's); pitch_um:
    the rig's sensor pitch (None: the budget's; the frame's pixels stay, the kernels take the render margin);
    score_images: the validation images scored (None: the budget's; score_set)."""
    check_score_images(score_images)
    out = Path(out).resolve()
    displays = [entry_display(s, out / "panels") for s in specs]
    names = [d.name for d in displays]
    if len(set(names)) != len(names):
        raise UdcError(f"--display {','.join(specs)}: expected distinct layouts, got the names {', '.join(names)}")
    out.mkdir(parents=True, exist_ok=True)
    b = study_budget(quick, epochs, pitch_um)
    times = StageTimes(out / "times.json")
    data = write_clean_images(out / "clean", b)
    banks = _banks(out, displays, b, times, cache_dir, progress)
    summaries = {}
    for name, bank in banks.items():
        summaries[name] = train(data, out / "train" / name, replace(train_settings(b, bank, data), seed=train_seed),
                                device="cpu",
                                checkpoint_s=60.0, val_every=max(1, b.epochs // 5), progress=progress,
                                bank=bank.folder)
    t0 = time.perf_counter()
    rows = _score(out, banks, score_set(out, b, score_images), progress)
    times.add("score", time.perf_counter() - t0)
    ref = rows[0]["per_image_db"]
    result = {"budget": dict(asdict(b), steps=b.steps), "distance_mm": DISTANCE_MM, "specs": list(specs),
              "transmission": {d.name: float(d.layout.power_transmittance) for d in displays},
              "gain": {d.name: d.gain for d in displays}, "rows": rows, "times": dict(times.seconds),
              "train": summaries, "seeds": {"train": train_seed, "score": SCORE_SEED},
              "paired": {r["layout"]: {k: paired(r["per_image_db"][k], ref[k]) for k in ROW_KEYS} for r in rows}}
    bad = [(r["layout"], k) for r in rows for k in ROW_KEYS if not math.isfinite(r[f"psnr_{k}_db"])]
    if bad:
        raise UdcError(f"study layout-trained: non-finite PSNR for {bad[0]}")
    save_json(out / f"{NAME}.json", result)
    save_text(out / f"{NAME}.md", _markdown(result))
    _plot(out, rows)
    _figure(out, banks, data, rows)
    return result
