"""RESULTS.md of `udc-render results` (restore.studies.results): its sections, the paper's orderings
checked on the tables (ordering_checks), the machine time per stage and the figures.
"""
from __future__ import annotations

import json
import platform
import shutil
from pathlib import Path

import torch

from restore.evaluate import level_table, protocol_table, results_markdown
from restore.studies.budgets import DISPLAY_NAMES, DISPLAYS, ROWS, run_dir
from restore.studies.error_bands import markdown, weakest_band_text
from restore.studies.faces import faces_markdown
from restore.studies.heldout import HELD_OUT
from restore.studies.orderings import ordering_checks
from restore.studies.random_row import bank_hours
from restore.studies.scoring import BAND_CROP_PX, BAND_ITEMS
from restore.studies.stage_times import EPOCH_CAP_X_MEDIAN, active_seconds
from restore.train import PLATEAU_MIN_VALIDATIONS, read_log, trend_db_per_fifth, validations
from udc_render.io.plots import pyplot, save_plot


def error_bands_section(bands: dict, fig: dict[str, str]) -> list[str]:
    """Per display: the rows' error per octave band beside the display's transfer, the sentence on its
    weakest band, and the plot."""
    lines = ["## Where the error lies (spatial frequency)", "",
             f"Each row's MSE on the central {BAND_CROP_PX} px of the first {BAND_ITEMS} val frames, split into octave "
             "bands of spatial frequency (cycles per sensor pixel; by Parseval the bands sum to the MSE), beside the "
             "display's mean |OTF| in each band (its known green kernel at d = 0, defined up to 1/4 cycle per pixel). "
             "A diagnosis of the orderings, not a score: `python -m restore.studies.error_bands`.", ""]
    for d, r in bands.items():
        lines += [f"### {d}", "", markdown(r["bands"], r["transfer"]), "", weakest_band_text(r["bands"], r["transfer"]),
                  "", *([f"![error bands, {d}]({fig[f'error_bands_{d}']})", ""] if f"error_bands_{d}" in fig else [])]
    return lines


PAPER_TABLE = ("The paper (real captures): DeP 28.50/0.9117 and 16.97/0.7084; ResNet 36.26/0.9703 and 27.42/0.9176; "
               "UNet (Syn) 32.42/0.9343 and 25.88/0.9006; UNet 36.71/0.9713 and 30.45/0.9427 (T-OLED and P-OLED "
               "PSNR/SSIM); UNet 8.93 M, 124.36 G MACs, 21.37 ms/MP on a Titan X.")
def training_logs(out: Path) -> dict[tuple[str, str], list[dict]]:
    """{(row, display): the run's loss.csv rows as numbers} for every run that has one."""
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
                "grey dead leaves" if image.startswith("pattern:dead_leaves") else
                "charts" if image.startswith("pattern:")
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
    """{(row, display): the run's active time (h), stage_times.active_seconds of its loss.csv (its
    train_summary.json's wall time where a run has no log)}."""
    hours = {}
    for row, _, _ in ROWS:
        for d in DISPLAYS:
            run = run_dir(out, row, d)
            summary = run / "train_summary.json"
            if (run / "loss.csv").is_file() and summary.is_file():
                hours[(row, d)] = active_seconds(read_log(run / "loss.csv")) / 3600
            elif summary.is_file() and json.loads(summary.read_text()).get("seconds") is not None:
                hours[(row, d)] = json.loads(summary.read_text())["seconds"] / 3600
    return hours


ACTIVE_TIME_RULE = f"each epoch counted at most {EPOCH_CAP_X_MEDIAN:g}× the median epoch"


WORKING_DAY_H = 8.0  # the budget: "about one working day of this machine in total"


def budget_section(out: Path, datasets: dict[str, Path], times: dict) -> list[str]:
    """The run's machine time per stage, each summed from what the stage recorded of itself over every
    invocation that did its work (datasets: the items' seconds; training: the models' summaries; scoring:
    the rows' seconds), and the stages that are redone at every invocation from this one's times."""
    rows = [(f"dataset, {p} profile", dataset_hours(f), "sum of the items' recorded seconds")
            for p, f in datasets.items()]
    trained = training_hours(out)
    rows.append(("kernel banks, UNet (randomized)", bank_hours(out), "banks/seconds.json, summed over invocations"))
    rows.append((f"training, {len(trained)} models", sum(trained.values()),
                 f"the models' active time (table above): loss.csv, {ACTIVE_TIME_RULE}"))
    heldout = out / "dataset_heldout"
    rows += [("scoring, test split", evaluation_hours(out / "eval"), "sum of the rows' recorded seconds"),
             ("held-out photographs: dataset", dataset_hours(heldout) if (heldout / "timing.jsonl").is_file() else 0.0,
              "sum of the items' recorded seconds"),
             ("held-out photographs: scoring", evaluation_hours(out / "eval_heldout"),
              "sum of the rows' recorded seconds"),
             ("error by spatial frequency", times.get("error_bands_s", 0.0) / 3600,
              "this invocation (redone each time)"),
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
    clip = b.get("clip_grad_norm")
    return [f"Adam (0.9, 0.999, 1e-8), L1 loss, lr {b['lr']:g} halved at half the epoch cap, batch {b['batch']}, "
            + ("" if clip is None else f"gradient norm clipped at {clip:g}, ") +
            f"{b['crops_per_pair']} random crops per pair and epoch with Bayer-preserving flips, "
            + ("the forward pass in bfloat16 (torch.autocast; weights, loss and Adam in float32; validation and "
               "scoring in float32); " if b.get("autocast") == "bf16" else "") + f"UNet "
            f"{b['crop_px']['unet']}-px crops, at most {b['epochs']['unet']} epochs; "
            f"ResNet {b['crop_px']['resnet']}-px "
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
            *random_row_text(b), "", *training_table(out, b), "",
            "Wall time is from start to end over the resumed parts; active time is the loss log's, "
            f"{ACTIVE_TIME_RULE} (restore.studies.stage_times.active_seconds): a run paused while another job had "
            "the cores, or sharing them, stretches a few epochs by up to hours."]


def random_row_text(b: dict) -> list[str]:
    """How the UNet (randomized) row trains (restore.studies.random_row)."""
    return [f"UNet (randomized), `unet_random`: the UNet's recipe, its pairs made on the fly (`udc-render train "
            f"--degrade online`, restore.online): every crop of the physical dataset's clean renders (the train "
            f"split's ground truths) degraded at every step through one of {b.get('random_panels')} panels of the "
            "display's family drawn from the documented ranges (`--randomize default`, seed 0: pitch, layout "
            "ratios, d 0.5–5 mm, T(λ), haze, focus, read noise, defects, FPN, brightness; the bank in "
            "`banks/random_<display>`), in the per-channel form (restore.degrade). Its validation is the val "
            "renders through those panels (image j through panel j mod N), so its last val PSNR is on randomized "
            "panels, not on the captures; it is scored on the physical test captures like every row: the default "
            "panel, a point inside its ranges, made by the spectral synthesis it did not train on."]


def training_table(out: Path, b: dict) -> list[str]:
    """One line per trained model from its train_summary.json and loss.csv: epochs, steps, wall time, whether
    validation PSNR reached the plateau (restore.train.plateau_step) and where, and its trend at the end."""
    lines = ["| row | display | epochs (cap) | steps | wall time (h) | active time (h) | plateau | "
             "last val PSNR (dB) | trend at the end (dB per fifth of the steps) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for row, _, _ in ROWS:
        for d in DISPLAYS:
            run = run_dir(out, row, d)
            if not (run / "train_summary.json").is_file():
                continue
            t = json.loads((run / "train_summary.json").read_text())
            plateau = f"at step {t['plateau_step']}" if t.get("plateaued") else "**not reached**"
            val = "—" if t.get("val_psnr_db") is None else f"{t['val_psnr_db']:.2f}"
            hours = "—" if t.get("seconds") is None else f"{t['seconds'] / 3600:.2f}"
            log = read_log(run / "loss.csv")
            vals = validations(log)
            trend = trend_db_per_fifth(vals) if vals else None
            lines.append(f"| {row} | {d} | {t['epochs']} ({t.get('epochs_planned', t['epochs'])}) | {t['steps']} | "
                         f"{hours} | {active_seconds(log) / 3600:.2f} | {plateau} | {val} | "
                         f"{'—' if trend is None else f'{trend:+.2f}'} |")
    return lines


def ordering_table(results: dict) -> list[str]:
    """The ordering checks of `results` as a Markdown table."""
    return ["| claim | holds | values |", "|---|---|---|",
            *(f"| {c} | {'yes' if ok else '**no**'} | {v} |" for c, ok, v in ordering_checks(results))]


def level_section(results: dict) -> list[str]:
    """Level and structure: each row's PSNR beside its level-matched PSNR and output level (restore.evaluate.
    level_table), the split between an error of level (a restorer that cannot tell a dim panel from a dim scene)
    and one of structure."""
    return ["## Level and structure (test split, paper protocol)", "",
            "Each row's PSNR beside its level-matched PSNR: each channel of each output scaled by its least-squares "
            "gain onto the truth before the PSNR (an oracle, `restore.metrics.level_scores`). Their difference is "
            "what the output's level and colour balance cost; the matched PSNR is the error of its structure. "
            "Level: the output's least-squares level against the truth per channel (1 = the truth's; the input "
            "row: its RAW, the display's transmission γ at the captures' exposure), the mean over images.", "",
            level_table(results)]


def heldout_section(heldout: dict, out: Path, fig: dict[str, str]) -> list[str]:
    """The held-out photographs' paper-protocol table, the orderings computed from it, and the UNet
    previews in `fig` (figure links by name)."""
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


def _shown(path: Path) -> Path:
    """`path` relative to the working folder when it lies under it (the carry slot: restore/trained/...)."""
    try:
        return Path(path).resolve().relative_to(Path.cwd().resolve())
    except ValueError:
        return Path(path)


def results_document(results: dict, heldout: dict, bands: dict, faces: dict, b: dict, budget: str,
                     datasets: dict[str, Path], out: Path, times: dict, figures: dict[str, Path], base: Path,
                     carry: Path | None = None) -> str:
    """RESULTS.md: data, training, both tables (paper protocol first), the orderings checked from the
    tables, the held-out photographs' table and orderings, the error by spatial frequency, the face table;
    figure links relative to `base` (the document's folder); `carry`: the folder the models were kept in."""
    data = datasets["physical"]
    fig = {k: _link(v, base) for k, v in figures.items()}
    lines = [
        "# Restoration results", "",
        f"Generated by `udc-render results --budget {budget} --out {out}{f' --carry {_shown(carry)}' if carry else ''} "
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
        *level_section(results), "",
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
