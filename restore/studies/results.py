"""`udc-render results`: the whole loop in one resumable command, written up as RESULTS.md.

    datasets (udc-render dataset, builtin images, glass + T-OLED + P-OLED; physical and paper profiles)
      ─► train UNet and ResNet per display ─► evaluate input, DeP, ResNet, UNet on the test split
      ─► the same on held-out photographs (restore.studies.heldout)
      ─► face detection (restore.face_study) ─► RESULTS.md (tables, budget, the paper's ordering checked)

Every stage resumes: the dataset and training runs pick up where they stopped; evaluation and the
face study are re-run (minutes to an hour). BUDGETS holds the settings; 'cpu' makes the paper's framing
(2048 × 1024, 150/20/30 items per profile) and trains each model to its validation plateau under an epoch
cap, about a working day of this 2-core machine in all; 'quick' is a smoke run, 'paper' the paper's
schedule (for a GPU). Changing a budget's training values makes the existing run folders refuse to resume.
"""
from __future__ import annotations

import functools
import json
import platform
import time
from pathlib import Path

BUDGETS = {
    "quick": {"items": (4, 1, 2), "sensor_px": (256, 128), "epochs": {"unet": 2, "resnet": 1},
              "crop_px": {"unet": 64, "resnet": 32}, "crops_per_pair": 1, "batch": 2, "face_sensor_px": (512, 256),
              "heldout_items": 2, "lr": 1e-4, "plateau_db": 0.1, "val_every": 1,
              "models": {"unet": {"type": "unet", "width": 8}, "resnet": {"type": "resnet", "features": 8, "blocks": 2}}},
    # cpu: epoch caps, not targets; each model stops at the 0.1 dB plateau, which needs ≥ 6 validations in the
    # last two fifths, so ≥ 26 epochs at val_every 2. Validation on the central 768-px square (a ResNet validation
    # of 20 whole frames would take 6 min). The forward in bfloat16 (half the step time on this CPU,
    # bench_train) paid for the ResNet's cap of 80 (50 before: it had not plateaued there). Caps: about a
    # working day of this machine if nothing plateaus.
    "cpu": {"items": (150, 20, 30), "sensor_px": (2048, 1024), "epochs": {"unet": 80, "resnet": 80},
            "crop_px": {"unet": 256, "resnet": 128}, "crops_per_pair": 2, "batch": 4, "face_sensor_px": (2048, 1024),
            "heldout_items": None, "lr": 2e-4, "plateau_db": 0.1, "val_every": 2, "val_crop_px": 768,
            "clip_grad_norm": 0.5, "autocast": "bf16", "models": {"unet": None, "resnet": None},
            "carry": "restore/trained/cpu"},
    "paper": {"items": (400, 40, 60), "sensor_px": (2048, 1024), "epochs": {"unet": 400, "resnet": 400},
              "crop_px": {"unet": 256, "resnet": 256}, "crops_per_pair": 1, "batch": 4, "face_sensor_px": (2048, 1024),
              "lr": 1e-4,
              "models": {"unet": None, "resnet": None}},
}
DISPLAYS = ("toled", "poled")
DISPLAY_NAMES = {"toled": "T-OLED", "poled": "P-OLED"}
PROFILES = ("physical", "paper")  # udc_render.profiles: the captures, and the paper's synthesis (UNet (Syn))


def dataset_job(profile: str, sensor_px: tuple[int, int], folder: Path, split: tuple[int, int, int],
                images_dir: Path | None = None):
    """The DatasetJob of the monitor scene at sensor_px through glass, T-OLED and P-OLED under `profile`
    (the built-in content, or the images in images_dir)."""
    from udc_render.dataset import DatasetJob
    from udc_render.optics.displays import load_displays
    from udc_render.pipeline import SynthConfig
    from udc_render.profiles import resolve_profile
    from udc_render.scene import load_scene
    from udc_render.scene.overrides import with_overrides
    scene = with_overrides(load_scene("monitor"), sensor_px=sensor_px)
    cfg, displays = resolve_profile(profile, SynthConfig(), load_displays(",".join(DISPLAYS)))
    return DatasetJob(scene, displays, cfg, out=folder, split=split, images_dir=images_dir)


def make_datasets(out: Path, b: dict, progress: bool) -> dict[str, Path]:
    """The budget's datasets, made or resumed: the built-in images and charts through glass, T-OLED and
    P-OLED at the budget's framing, once per profile (physical: the tables' train and test pairs; paper:
    the UNet (Syn) row's training pairs, the paper's own synthesis). {profile: folder}."""
    from udc_render.dataset import run_dataset
    folders = {p: out / f"dataset_{p}" for p in PROFILES}
    for profile, folder in folders.items():
        run_dataset(dataset_job(profile, b["sensor_px"], folder, tuple(b["items"])), progress=progress)
    return folders


# (row, model kind, the profile whose pairs train it): the paper's rows; UNet (Syn) is trained on the paper's
# own synthesis and tested on the physical captures, as the paper's synthetic-to-real row.
# Trained in this order: the ResNet, the slowest, last.
ROWS = (("unet", "unet", "physical"), ("unet_syn", "unet", "paper"), ("resnet", "resnet", "physical"))


def run_dir(out: Path, row: str, display: str) -> Path:
    """The training run folder of one row's model for one display."""
    return out / "train" / f"{row}_{display}"


def train_models(datasets: dict[str, Path], out: Path, b: dict, progress: bool, times: dict,
                 carry: Path | None = None) -> dict:
    """Every row's model per display, trained or resumed in out/train/<row>_<display>: {(row, display):
    model.pt}. With `carry`, each finished model is kept in carry/<row>_<display> and brought back from
    there into a run folder that lacks it (restore.studies.carry)."""
    from restore.models import RESNET_CONFIG, UNET_CONFIG
    from restore.studies.carry import bring_back, keep
    from restore.train import TrainSettings, data_fingerprint, train
    defaults = {"unet": UNET_CONFIG, "resnet": RESNET_CONFIG}
    models = {}
    for row, kind, profile in ROWS:
        cfg = dict(b["models"][kind] or defaults[kind])
        data = datasets[profile]
        for d in DISPLAYS:
            t = time.perf_counter()
            run = run_dir(out, row, d)
            settings = TrainSettings(model=cfg, display=d, epochs=b["epochs"][kind], batch=b["batch"],
                                     crop_px=b["crop_px"][kind], crops_per_pair=b["crops_per_pair"], lr=b["lr"],
                                     data_fingerprint=data_fingerprint(data), plateau_db=b.get("plateau_db"),
                                     val_crop_px=b.get("val_crop_px"), clip_grad_norm=b.get("clip_grad_norm"),
                                     autocast=b.get("autocast"))
            if carry:
                bring_back(carry / run.name, run, settings)
            train(data, run, settings, val_every=b.get("val_every", 10), progress=progress)
            if carry:
                keep(run, carry / run.name)
            models[(row, d)] = run / "model.pt"
            times[f"train_{row}_{d}_s"] = time.perf_counter() - t
    return models


def run_results(out: Path, budget: str = "cpu", write: Path | None = None, progress: bool = True,
                carry: Path | None = None) -> dict:
    """Run every stage into `out` and write `out`/RESULTS.md with its figures in `out`/figures; with
    `write`, the document there too, its figures in docs/figures/results beside it; with `carry`, the
    finished models kept there and brought back from there (train_models)."""
    from restore.studies.faces import face_experiment
    from restore.studies.heldout import make_held_out_dataset
    b, out = BUDGETS[budget], Path(out)
    t0, times = time.perf_counter(), {}
    datasets = make_datasets(out, b, progress)
    data = datasets["physical"]  # every row is tested on the physical captures
    times["dataset_s"] = time.perf_counter() - t0
    models = train_models(datasets, out, b, progress, times, carry)
    t = time.perf_counter()
    results = evaluate_rows(data, models, out / "eval", progress)
    times["evaluate_s"] = time.perf_counter() - t
    t = time.perf_counter()
    heldout = make_held_out_dataset(out, b["sensor_px"], b.get("heldout_items"), progress)
    heldout_results = evaluate_rows(heldout, models, out / "eval_heldout", progress)
    times["heldout_s"] = time.perf_counter() - t
    t = time.perf_counter()
    bands = error_band_rows(data, models, out / "error_bands")
    times["error_bands_s"] = time.perf_counter() - t
    t = time.perf_counter()
    faces = face_experiment(out / "faces", {d: [models[(kind, d)] for kind in ("unet", "resnet")] for d in DISPLAYS},
                            b["face_sensor_px"], progress=progress, train_level=training_levels(data))
    times["faces_s"] = time.perf_counter() - t
    times["total_s"] = time.perf_counter() - t0
    from udc_render.io.files import save_text
    targets = [(out / "RESULTS.md", out / "figures")]  # (document, its figures' folder)
    if write:
        targets.append((Path(write), Path(write).parent / "docs" / "figures" / "results"))
    plot_training_curves(out, out / "train" / "training_curves.png")  # drawn once, copied per document
    for doc, fig_dir in targets:
        figures = copy_figures(out, fig_dir)
        save_text(doc, results_document(results, heldout_results, bands, faces, b, budget, datasets, out, times, figures,
                                        doc.parent, carry))
    return {"results": results, "heldout": heldout_results, "error_bands": bands, "faces": faces, "times": times}


BAND_ITEMS, BAND_CROP_PX = 6, 512  # the error bands' val frames and central crop (a diagnosis, not a score)


def error_band_rows(data: Path, models: dict, folder: Path) -> dict:
    """{display: {"bands": {row: [bands] MSE}, "transfer": [bands] mean |OTF|}} of input, DeP and the
    display's trained rows on the val split's central crops (restore.studies.error_bands); plots in `folder`."""
    from restore.studies.error_bands import display_transfer, method_bands, plot
    res = {}
    for d in DISPLAYS:
        methods = {"input": "input", "dep": "dep", **{row: str(p) for (row, md), p in models.items() if md == d}}
        transfer = display_transfer(data, d)
        bands = method_bands(data, d, methods, "val", BAND_ITEMS, BAND_CROP_PX)
        plot(bands, transfer, folder / f"error_bands_{d}.png",
             f"{d}: error by spatial frequency (val, {BAND_ITEMS} frames, central {BAND_CROP_PX} px)")
        res[d] = {"bands": bands, "transfer": transfer}
    return res


def error_bands_section(bands: dict, fig: dict[str, str]) -> list[str]:
    """Per display: the rows' error per octave band beside the display's transfer, the sentence on its
    weakest band, and the plot."""
    from restore.studies.error_bands import markdown, weakest_band_text
    lines = ["## Where the error lies (spatial frequency)", "",
             f"Each row's MSE on the central {BAND_CROP_PX} px of the first {BAND_ITEMS} val frames, split into octave "
             "bands of spatial frequency (cycles per sensor pixel; by Parseval the bands sum to the MSE), beside the "
             "display's mean |OTF| in each band (its known green kernel at d = 0, defined up to 1/4 cycle per pixel). "
             "A diagnosis of the orderings, not a score: `python -m restore.studies.error_bands`.", ""]
    for d, r in bands.items():
        lines += [f"### {d}", "", markdown(r["bands"], r["transfer"]), "", weakest_band_text(r["bands"], r["transfer"]),
                  "", *([f"![error bands, {d}]({fig[f'error_bands_{d}']})", ""] if f"error_bands_{d}" in fig else [])]
    return lines


SCORING_MODULES = ("restore.evaluate", "restore.metrics", "restore.dep", "restore.known", "restore.lpips",
                   "restore.data", "restore.models", "restore.train", "udc_render.metrics")
"""The code a score depends on beyond the data and the checkpoint: its source is part of evaluation_stamp."""


def training_levels(data: Path) -> dict[str, float]:
    """Display → the median over the training captures of their mean green level (fraction of white − black,
    the captures' summary.json): the exposure range the models learnt on."""
    import numpy as np
    from restore.data import list_pairs
    return {d: float(np.median([json.loads((p.folder / "summary.json").read_text())["views"][d]["mean_level"]["Gr"]
                                for p in list_pairs(data, "train", [d])])) for d in DISPLAYS}


def evaluation_stamp(data: Path, method: str) -> str:
    """sha256 of what decides a row's scores: the dataset's manifest (restore.train.data_fingerprint), the
    method ('input', 'dep', or the checkpoint's bytes) and the source of SCORING_MODULES. Deeper code (the
    optics behind DeP's known kernels) is not in it: a change there needs `rm -r <out>/eval*`."""
    import hashlib
    from restore.train import data_fingerprint
    h = hashlib.sha256(data_fingerprint(data).encode())
    h.update(method.encode() if method in ("input", "dep") else Path(method).read_bytes())
    h.update(_scoring_source())
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=1)
def _scoring_source() -> bytes:
    """The source of SCORING_MODULES, read once per process: the code this process scores with."""
    import importlib.util
    return b"".join(Path(importlib.util.find_spec(name).origin).read_bytes() for name in SCORING_MODULES)


def evaluate_rows(data: Path, models: dict, ev: Path, progress: bool) -> dict:
    """Input, DeP and every trained row on `data`'s test split into `ev`; returns its results.json, holding
    these rows only. Resumes: a row whose evaluation_stamp matches the one recorded in `ev`/stamps.json when
    it was scored, and whose displays are all in results.json, is not scored again. The seconds each row's
    scoring took go to `ev`/row_seconds.json (evaluation_hours)."""
    from restore.data import dataset_displays
    from restore.evaluate import EvalSettings, evaluate, results_csv, results_markdown
    from udc_render.io.files import save_json, save_text
    path, stamps_path, seconds_path = ev / "results.json", ev / "stamps.json", ev / "row_seconds.json"
    stamps = json.loads(stamps_path.read_text()) if stamps_path.is_file() and path.is_file() else {}
    seconds = json.loads(seconds_path.read_text()) if seconds_path.is_file() else {}
    rows = [("input", "input", dataset_displays(data)), ("dep", "dep", dataset_displays(data))]
    rows += [(row, str(p), [d]) for (row, d), p in models.items()]
    scored = json.loads(path.read_text())["methods"] if path.is_file() else {}  # before this call's rows
    for name, method, displays in rows:
        stamp = evaluation_stamp(data, method)
        if stamps.get(method) == stamp and all(d in scored.get(name, {}).get("displays", {}) for d in displays):
            continue
        t = time.perf_counter()
        evaluate(data, method, ev, EvalSettings(name=None if method in ("input", "dep") else name), progress=progress)
        seconds[name] = time.perf_counter() - t
        stamps[method] = stamp
        save_json(seconds_path, seconds)
        save_json(stamps_path, stamps)
    results = json.loads(path.read_text())
    names = {name for name, _, _ in rows}
    if set(results["methods"]) - names:  # rows of an earlier budget or model list
        results["methods"] = {k: v for k, v in results["methods"].items() if k in names}
        save_json(path, results)
        save_text(ev / "results.md", results_markdown(results))
        save_text(ev / "results.csv", results_csv(results))
    return results


PAPER_TABLE = ("The paper (real captures): DeP 28.50/0.9117 and 16.97/0.7084; ResNet 36.26/0.9703 and 27.42/0.9176; "
               "UNet (Syn) 32.42/0.9343 and 25.88/0.9006; UNet 36.71/0.9713 and 30.45/0.9427 (T-OLED and P-OLED "
               "PSNR/SSIM); UNet 8.93 M, 124.36 G MACs, 21.37 ms/MP on a Titan X.")
PAPER_SYN_GAP_DB = {"toled": 4.3, "poled": 4.6}  # the paper: UNet trained on its synthetic data, on real data
UNET_OVER_DEP_DB = 3.0  # the ordering the issue asks for: UNet at least this far above DeP


def ordering_checks(results: dict) -> list[tuple[str, bool, str]]:
    """The paper's findings, checked on our numbers under the paper protocol: (claim, holds, values)."""
    m = results["methods"]

    def psnr(name, d):
        return m.get(name, {}).get("displays", {}).get(d, {}).get("psnr_db_paper")

    checks = []
    for d in DISPLAYS:
        u, p, s = psnr("unet", d), psnr("dep", d), psnr("unet_syn", d)
        if u is not None and p is not None:
            checks.append((f"UNet above DeP by ≥ {UNET_OVER_DEP_DB:g} dB on {d} (PSNR)", u - p >= UNET_OVER_DEP_DB,
                           f"{u:.2f} vs {p:.2f} dB ({u - p:+.2f})"))
        if u is not None and s is not None:
            checks.append((f"UNet (Syn) below UNet on {d} (PSNR)", s < u,
                           f"{s:.2f} vs {u:.2f} dB: gap {u - s:.2f} dB (paper {PAPER_SYN_GAP_DB[d]:g} dB)"))
    for name in ("input", "dep", "resnet", "unet_syn", "unet"):
        t, p = psnr(name, "toled"), psnr(name, "poled")
        if t is not None and p is not None:
            checks.append((f"P-OLED harder than T-OLED for {name} (PSNR)", p < t, f"{p:.2f} vs {t:.2f} dB"))
    return checks


def training_logs(out: Path) -> dict[tuple[str, str], list[dict]]:
    """{(row, display): the run's loss.csv rows as numbers} for every run that has one."""
    from restore.train import read_log
    logs = {}
    for row, _, _ in ROWS:
        for d in DISPLAYS:
            path = run_dir(out, row, d) / "loss.csv"
            if path.is_file():
                logs[(row, d)] = read_log(path)
    return logs


def plot_training_curves(out: Path, path: Path) -> None:
    """Validation PSNR (left) and training L1 loss (right) against epoch for every run; a cross marks
    where a run reached its plateau."""
    from udc_render.io.plots import pyplot, save_plot
    plt, logs = pyplot(), training_logs(out)
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    for i, ((row, d), log) in enumerate(logs.items()):
        style = dict(color=f"C{i}", label=f"{row} {d}")
        val = [(r["epoch"], r["val_psnr_db"]) for r in log if r["val_psnr_db"] is not None]
        if val:
            a.plot(*zip(*val), "o-", ms=3, **style)
        summary = run_dir(out, row, d) / "train_summary.json"
        if summary.is_file() and json.loads(summary.read_text()).get("plateaued") and val:
            a.plot(*val[-1], "kx", ms=9)
        b.semilogy([r["epoch"] for r in log], [r["loss"] for r in log], **style)
    a.set(xlabel="epoch", ylabel="validation PSNR (dB, linear, central crop)", title="validation (× = plateau)")
    b.set(xlabel="epoch", ylabel="training L1 loss", title="training loss")
    b.legend(fontsize=8)
    save_plot(fig, path)


def content_counts(data: Path) -> dict[str, dict[str, int]]:
    """{split: {content kind: items}} from the dataset's manifest: scikit-image photographs, charts,
    dead leaves in a photograph's colours (each a new seed), grey dead leaves and the user's --images files."""
    counts: dict[str, dict[str, int]] = {}
    for line in (data / "manifest.jsonl").read_text().splitlines():
        item = json.loads(line)
        image = item.get("image") or ""
        kind = ("colour dead leaves" if image.startswith("pattern:dead_leaves_colour") else
                "grey dead leaves" if image.startswith("pattern:dead_leaves") else "charts" if image.startswith("pattern:")
                else "photographs (scikit-image)" if image.startswith("builtin:") else "--images files")
        split = counts.setdefault(item["split"], {})
        split[kind] = split.get(kind, 0) + 1
    return counts


def dataset_hours(data: Path) -> float:
    """The dataset's generation time (h): the sum of its items' recorded seconds (timing.jsonl), so a
    dataset made in resumed parts counts every part."""
    rows = [json.loads(line) for line in (data / "timing.jsonl").read_text().splitlines() if line.strip()]
    return sum(r.get("seconds", 0.0) for r in rows) / 3600


def evaluation_hours(ev: Path) -> float:
    """The scoring time (h) of the rows in the evaluation folder `ev`: the seconds evaluate_rows recorded
    for the latest scoring of each row (0 for a folder scored before they were recorded)."""
    path = ev / "row_seconds.json"
    return sum(json.loads(path.read_text()).values()) / 3600 if path.is_file() else 0.0


def training_hours(out: Path) -> dict[tuple[str, str], float]:
    """{(row, display): the run's wall time (h) from its train_summary.json, summed over resumed parts}."""
    hours = {}
    for row, _, _ in ROWS:
        for d in DISPLAYS:
            path = run_dir(out, row, d) / "train_summary.json"
            if path.is_file() and json.loads(path.read_text()).get("seconds") is not None:
                hours[(row, d)] = json.loads(path.read_text())["seconds"] / 3600
    return hours


WORKING_DAY_H = 8.0  # the budget: "about one working day of this machine in total"


def budget_section(out: Path, datasets: dict[str, Path], times: dict) -> list[str]:
    """The run's machine time per stage, each summed from what the stage recorded of itself over every
    invocation that did its work (datasets: the items' seconds; training: the models' summaries; scoring:
    the rows' seconds), and the stages that are redone at every invocation from this one's times."""
    rows = [(f"dataset, {p} profile", dataset_hours(f), "sum of the items' recorded seconds")
            for p, f in datasets.items()]
    trained = training_hours(out)
    rows.append((f"training, {len(trained)} models", sum(trained.values()),
                 "the models' train_summary.json (each in the table above)"))
    heldout = out / "dataset_heldout"
    rows += [("scoring, test split", evaluation_hours(out / "eval"), "sum of the rows' recorded seconds"),
             ("held-out photographs: dataset", dataset_hours(heldout) if (heldout / "timing.jsonl").is_file() else 0.0,
              "sum of the items' recorded seconds"),
             ("held-out photographs: scoring", evaluation_hours(out / "eval_heldout"), "sum of the rows' recorded seconds"),
             ("error by spatial frequency", times.get("error_bands_s", 0.0) / 3600, "this invocation (redone each time)"),
             ("faces", times.get("faces_s", 0.0) / 3600, "this invocation (redone each time)")]
    total = sum(h for _, h, _ in rows)
    return ["| stage | machine time (h) | counted from |", "|---|---|---|",
            *(f"| {name} | {h:.2f} | {how} |" for name, h, how in rows),
            f"| **total** | **{total:.2f}** | |", "",
            f"The issue's budget is about one working day ({WORKING_DAY_H:g} h) of this machine: this run took "
            f"{total / WORKING_DAY_H:.2f} of it. Time lost to interrupted parts (an item or epoch under way when a "
            "session ended) is not counted."]


def copy_figures(out: Path, fig_dir: Path) -> dict[str, Path]:
    """The document's figures into fig_dir: the training curves (out/train/training_curves.png), the face
    detections and the UNet previews of the first test item and the first held-out photograph; {name: path}."""
    import shutil
    fig_dir.mkdir(parents=True, exist_ok=True)
    figures = {}
    sources = {"training_curves": out / "train" / "training_curves.png", "faces": out / "faces" / "detections.png",
               **{f"error_bands_{d}": out / "error_bands" / f"error_bands_{d}.png" for d in DISPLAYS}}
    for ev, prefix in (("eval", "unet"), ("eval_heldout", "heldout_unet")):
        for d in DISPLAYS:
            previews = sorted((out / ev / "unet" / "previews").glob(f"{d}_*.png"))
            if previews:
                sources[f"{prefix}_{d}"] = previews[0]
    for name, src in sources.items():
        if src.is_file():
            figures[name] = fig_dir / f"{name}.png"
            shutil.copyfile(src, figures[name])
    return figures


def _link(path: Path, base: Path) -> str:
    try:
        return str(Path(path).resolve().relative_to(Path(base).resolve()))
    except ValueError:
        return str(path)


def data_section(b: dict, data: Path, datasets: dict[str, Path]) -> list[str]:
    n, counts = b["items"], content_counts(data)
    kinds = sorted({k for c in counts.values() for k in c})
    lines = [f"- {sum(n)} items per profile (train {n[0]}, val {n[1]}, test {n[2]}; the paper: 240/30/30 real pairs), "
             f"`udc-render dataset` of the monitor scene with the built-in content: sensor {b['sensor_px'][0]} × "
             f"{b['sensor_px'][1]} px of 1.55 µm (the paper's framing), the default monitor rig; each item one render "
             "seen through glass (the ground truth), T-OLED and P-OLED, with the sensor's noise.",
             "- Profiles: `physical` (the calibrated displays, d = 2 mm; every row is tested on it) and `paper` (the "
             "paper's own synthesis, d = 0; it trains the UNet (Syn) row only). Generation time (sum of the items' "
             "recorded seconds): " + ", ".join(f"{p} {dataset_hours(f):.1f} h" for p, f in datasets.items()) + ".",
             "", "| split | " + " | ".join(kinds) + " |", "|---|" + "---|" * len(kinds)]
    lines += [f"| {split} | " + " | ".join(str(counts[split].get(k, 0)) for k in kinds) + " |" for split in counts]
    lines += ["", "The built-in list is cycled once (6 scikit-image photographs, 5 charts with one grey dead "
              "leaves), then every further item is "
              "a new seed of `pattern:dead_leaves_colour`: dead leaves painted with the pixels of one of the 5 "
              "colour photographs (Achddou et al. 2021), so the val and test splits are all colour dead leaves: "
              "scale-invariant occlusions in natural colours and brightness, but not photographs. A user with "
              f"DIV2K passes `--images DIR` to `udc-render dataset`. Every setting: `{data / 'job.json'}`."]
    return lines


def training_section(b: dict, budget: str, out: Path) -> list[str]:
    from restore.train import PLATEAU_MIN_VALIDATIONS
    clip = b.get("clip_grad_norm")
    return [f"Adam (0.9, 0.999, 1e-8), L1 loss, lr {b['lr']:g} halved at half the epoch cap, batch {b['batch']}, "
            + ("" if clip is None else f"gradient norm clipped at {clip:g}, ") +
            f"{b['crops_per_pair']} random crops per pair and epoch with Bayer-preserving flips, "
            + ("the forward pass in bfloat16 (torch.autocast; weights, loss and Adam in float32; validation and "
               "scoring in float32); " if b.get("autocast") == "bf16" else "") + f"UNet "
            f"{b['crop_px']['unet']}-px crops, at most {b['epochs']['unet']} epochs; ResNet {b['crop_px']['resnet']}-px "
            f"crops, at most {b['epochs']['resnet']} epochs. Each model stops at its plateau: validation PSNR "
            f"(linear, on the central {b.get('val_crop_px') or 'whole'}-px square of the {b['items'][1]} val frames, "
            f"every {b.get('val_every', 10)} epochs) changing by less than {b.get('plateau_db')} dB over a fifth of "
            f"the steps, by the least-squares line through the validations of the last two fifths (at least "
            f"{PLATEAU_MIN_VALIDATIONS} of them: `restore.train.plateau_step`; the validations jitter by 0.1–0.4 dB, "
            "and a line through the last fifth alone stopped UNets that were still rising). The paper trains 400 "
            "epochs at lr 1e-4 on a GPU. The cpu budget's lr is 2e-4: at 5e-4 the UNet diverged at epoch 8 (loss "
            "0.066 → 0.50, validation PSNR 20.1 → 8.9 dB), and at 1e-4 an earlier UNet (1024 × 512 data) sat at a "
            "loss of 0.11 from epoch 8 to 20. At 2e-4 without clipping it spiked at epoch 24 (loss 0.058 → 0.10, "
            "validation −1.6 dB); its gradient norms were 0.09–0.33 with outliers to 0.74, hence the clip at 0.5.", "",
            *training_table(out, b)]


def training_table(out: Path, b: dict) -> list[str]:
    """One line per trained model from its train_summary.json and loss.csv: epochs, steps, wall time, whether
    validation PSNR reached the plateau (restore.train.plateau_step) and where, and its trend at the end."""
    from restore.train import read_log, trend_db_per_fifth, validations
    lines = ["| row | display | epochs (cap) | steps | wall time (h) | plateau | last val PSNR (dB) | "
             "trend at the end (dB per fifth of the steps) |", "|---|---|---|---|---|---|---|---|"]
    for row, _, _ in ROWS:
        for d in DISPLAYS:
            run = run_dir(out, row, d)
            if not (run / "train_summary.json").is_file():
                continue
            t = json.loads((run / "train_summary.json").read_text())
            plateau = f"at step {t['plateau_step']}" if t.get("plateaued") else "**not reached**"
            val = "—" if t.get("val_psnr_db") is None else f"{t['val_psnr_db']:.2f}"
            hours = "—" if t.get("seconds") is None else f"{t['seconds'] / 3600:.2f}"
            vals = validations(read_log(run / "loss.csv"))
            trend = trend_db_per_fifth(vals) if vals else None
            lines.append(f"| {row} | {d} | {t['epochs']} ({t.get('epochs_planned', t['epochs'])}) | {t['steps']} | "
                         f"{hours} | {plateau} | {val} | {'—' if trend is None else f'{trend:+.2f}'} |")
    return lines


def ordering_table(results: dict) -> list[str]:
    """The ordering checks of `results` as a Markdown table."""
    return ["| claim | holds | values |", "|---|---|---|",
            *(f"| {c} | {'yes' if ok else '**no**'} | {v} |" for c, ok, v in ordering_checks(results))]


def heldout_section(heldout: dict, out: Path, fig: dict[str, str]) -> list[str]:
    """The held-out photographs' paper-protocol table, the orderings computed from it, and the UNet
    previews in `fig` (figure links by name)."""
    from restore.evaluate import protocol_table
    from restore.studies.heldout import HELD_OUT
    n = {m["displays"][d]["images"] for m in heldout["methods"].values() for d in m["displays"]}
    return ["## Held-out photographs (a content check)", "",
            f"{'/'.join(map(str, sorted(n)))} photographs and micrographs that scikit-image ships and no split uses "
            f"(of {', '.join(HELD_OUT)}; `restore.studies.heldout`), rendered as the test split is, through the "
            f"physical profile, and scored by the same models (`{out / 'eval_heldout'}`). Not the paper's test split "
            "and not part of the orderings above: it asks whether they depend on the dead-leaves content. Most are "
            "square or 4:3, shown letterboxed on the 16:9 monitor: the black margins raise every row's PSNR.", "",
            protocol_table(heldout, "paper"), "", PAPER_TABLE + " Its test images were DIV2K photographs.", "",
            "The orderings on these photographs:", "", *ordering_table(heldout),
            "", *(f"![UNet on a held-out photograph, {d}]({fig[f'heldout_unet_{d}']})" for d in DISPLAYS
                  if f"heldout_unet_{d}" in fig)]


def faces_levels_text(faces: dict) -> list[str]:
    """The face chart's exposure against the training captures' (faces.json), and what the ×k rows are."""
    lv, tr, k = faces.get("chart_level", {}), faces.get("train_level", {}), faces.get("level_gain", {})
    if not (lv and tr and k):
        return []
    each = "; ".join(f"{DISPLAY_NAMES[d]} {lv[d]:.3f} against {tr[d]:.3f} (k = {k[d]:.2f})" for d in DISPLAYS if d in k)
    return [f"Exposure (mean green level, fraction of white), the chart's capture against the training captures' "
            f"median: {each}. A `×k` row restores the capture scaled by k to the training level and divides the "
            "output by k: a diagnostic of the models' exposure range, not a method of the paper.", ""]


def results_document(results: dict, heldout: dict, bands: dict, faces: dict, b: dict, budget: str,
                     datasets: dict[str, Path], out: Path, times: dict, figures: dict[str, Path], base: Path,
                     carry: Path | None = None) -> str:
    """RESULTS.md: data, training, both tables (paper protocol first), the orderings checked from the
    tables, the held-out photographs' table and orderings, the error by spatial frequency, the face table;
    figure links relative to `base` (the document's folder); `carry`: the folder the models were kept in."""
    from restore.evaluate import results_markdown
    from restore.studies.faces import faces_markdown
    import torch
    data = datasets["physical"]
    fig = {k: _link(v, base) for k, v in figures.items()}
    lines = [
        "# Restoration results", "",
        f"Generated by `udc-render results --budget {budget} --out {out}{f' --carry {carry}' if carry else ''} "
        f"--write RESULTS.md` on {platform.machine()}, "
        f"{torch.get_num_threads()} torch threads, "
        f"{'GPU ' + torch.cuda.get_device_name() if torch.cuda.is_available() else 'CPU only'}. "
        "This invocation's stage times (s): " + ", ".join(f"{k[:-2]} {v:.0f}" for k, v in times.items()) +
        "; the datasets' and models' own times, summed over resumed parts, are below.", "",
        "## Data", "", *data_section(b, data, datasets), "",
        f"## Training ({budget} budget)", "", *training_section(b, budget, out), "",
        "## Machine time", "", *budget_section(out, datasets, times), "",
        *([f"![training curves]({fig['training_curves']})", ""] if "training_curves" in fig else []),
        "## Pipeline comparison (test split)", "",
        results_markdown(results), "",
        PAPER_TABLE, "",
        *[f"![UNet on the first test item, {d}]({fig[f'unet_{d}']})" for d in DISPLAYS if f"unet_{d}" in fig], "",
        "## The paper's ordering", "",
        "Computed from the paper-protocol table above (`restore.studies.results.ordering_checks`).", "",
        *ordering_table(results), "",
        *heldout_section(heldout, out, fig), "",
        *error_bands_section(bands, fig),
        "## Face detection (MTCNN recall)", "",
        f"{faces['faces']} faces (scikit-image's LFW subset on a {faces['chart_px'][0]} × {faces['chart_px'][1]} "
        f"chart, {faces['chart']['face_px'][0]}–{faces['chart']['face_px'][1]} px at contrasts "
        f"{faces['chart']['contrast'][0]:g}–{faces['chart']['contrast'][1]:g}) shown on the virtual monitor, "
        f"sensor {faces['sensor_px'][0]} × {faces['sensor_px'][1]} px; clean = the ground truth (the same for "
        "both columns); unet, resnet = those rows' models.", "", *faces_levels_text(faces), faces_markdown(faces),
        *([f"![detections]({fig['faces']})", ""] if "faces" in fig else []),
    ]
    return "\n".join(lines)
