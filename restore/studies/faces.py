"""Downstream face detection through the displays (the paper's §6.3): MTCNN recall on clean,
degraded and restored captures of a face chart shown on the virtual monitor.

    face chart (restore.faces) ─► monitor scene, render ─► synthesis (glass, T-OLED, P-OLED)
      ─► clean: the ground truth · degraded: the capture (bilinear demosaic, not scaled)
      ─► restored: DeP, and each display's trained model when one is given ─► MTCNN ─► recall

Images reach MTCNN as 8-bit sRGB previews (daylight balance, clipped: what a phone would show).
True boxes: the chart's boxes mapped onto the sensor through the rig's geometry (the panel is seen
centred, one panel pixel = panel pitch · z_i / D sensor pixels); the clean recall and mean IoU check
that mapping. Recall: greedy one-to-one matches at IoU ≥ 0.5 over the chart's faces.
"""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from restore.data import Pair, load_packed
from restore.dep import dep_restore
from restore.mtcnn import MTCNN, box_iou, recall
from restore.studies.face_chart import STUDY_CONTRAST, STUDY_FACE_PX, face_chart
from udc_render.io.capture import write_synthesis
from udc_render.io.files import atomic_path, save_figure, save_json, save_text
from udc_render.io.plots import pyplot
from udc_render.io.previews import daylight_balance, preview_srgb
from udc_render.scene import load_scene
from udc_render.sensor import demosaic_bilinear, unpack_rggb

CHART_PX = (1920, 1080)


def chart_boxes_on_sensor(boxes: np.ndarray, meta: dict, chart_px=CHART_PX) -> np.ndarray:
    """Chart boxes [N, 4] (chart pixels) → sensor pixels via the render's record (module doc)."""
    r = meta["render"]
    disp, cam = r["display"], r["camera"]
    panel_w_px = disp["shown_px"][0] + 2 * disp["offset_px"][0]
    panel_h_px = disp["shown_px"][1] + 2 * disp["offset_px"][1]
    panel_pitch_m = r["monitor_size_m"][0] / panel_w_px
    footprint_m = cam["pitch_um"] * r["monitor_distance_m"] / cam["image_distance_um"]
    k = panel_pitch_m / footprint_m  # sensor pixels per panel pixel
    s = disp["scale"]
    px = (np.asarray(boxes, float)[:, [0, 2]] * s + disp["offset_px"][0] - panel_w_px / 2) * k
    py = (np.asarray(boxes, float)[:, [1, 3]] * s + disp["offset_px"][1] - panel_h_px / 2) * k
    w, h = r["sensor"]["width_px"], r["sensor"]["height_px"]
    return np.stack([px[:, 0] + w / 2, py[:, 0] + h / 2, px[:, 1] + w / 2, py[:, 1] + h / 2], axis=1)


def _overlay(panels: list, path: Path) -> None:
    plt = pyplot()
    from matplotlib.patches import Rectangle
    cols = 3
    rows = -(-len(panels) // cols)
    h, w = panels[0][1].shape[:2]
    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 5 * rows * h / w + 0.4 * rows), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for ax, (title, img, truth, found) in zip(axes.ravel(), panels):
        ax.imshow(img)
        for b in truth:
            ax.add_patch(Rectangle(b[:2], b[2] - b[0], b[3] - b[1], fill=False, ec="white", lw=0.6, ls="--"))
        for b in found:
            ax.add_patch(Rectangle(b[:2], b[2] - b[0], b[3] - b[1], fill=False, ec="lime", lw=0.9))
        ax.set_title(title, fontsize=9)
    fig.suptitle("MTCNN detections (green) and true faces (white, dashed)", fontsize=10)
    save_figure(fig, path)
    plt.close(fig)


def face_experiment(out: Path, models: dict | None = None, sensor_px=(1024, 512), seed: int = 0,
                    denoiser: str | None = None, progress: bool = True, chart: dict | None = None,
                    train_level: dict | None = None) -> dict:
    """Run the experiment into `out` (faces.json, faces.md, detections.png); `models`: display → the
    model.pt files of trained restorers (optional; a row per model type); `chart`: face_chart's face_px
    and contrast (None: the study's hard chart); `train_level`: display → the training captures' mean
    green level (fraction of white): each model gets a second row, "<type> ×k", on the capture scaled by
    k = train_level / the chart capture's green level and its output divided by k (a diagnostic of the
    models' exposure range, not a method of the paper). Returns the recall table."""
    import torch

    from restore.known import known_gamma_rggb, known_kernels_rggb
    from restore.train import load_model, predict
    from udc_render.optics.displays import preset
    from udc_render.pipeline import SynthConfig, capture_scene
    out, models = Path(out), models or {}
    out.mkdir(parents=True, exist_ok=True)
    chart_image, boxes = face_chart(*CHART_PX, seed=seed, **(chart or {}))
    with atomic_path(out / "chart.png", ".png") as tmp:
        iio.imwrite(tmp, chart_image)
    scene = load_scene("monitor")
    scene = replace(scene, content=replace(scene.content, image=str((out / "chart.png").resolve())),
                    sensor=replace(scene.sensor, width_px=int(sensor_px[0]), height_px=int(sensor_px[1])))
    _, result = capture_scene(scene, [preset(n) for n in ("glass", "toled", "poled")],
                              SynthConfig(seed=seed), progress=progress)
    summary = write_synthesis(out / "capture", result, SynthConfig().sensor.camera, side_by_side=False)
    truth = chart_boxes_on_sensor(boxes, result.meta)
    balance, detector = daylight_balance(), MTCNN()
    images, levels, gains = {("clean", "glass"): result.gt}, {}, {}
    for d in ("toled", "poled"):
        pair = Pair(0, "test", out / "capture", d, "face chart")
        packed = load_packed(out / "capture" / d)
        images[("degraded", d)] = demosaic_bilinear(unpack_rggb(packed))
        kwargs = {} if denoiser is None else {"denoiser": denoiser}
        images[("DeP", d)] = dep_restore(packed, known_gamma_rggb(pair), known_kernels_rggb(pair),
                                         rng=np.random.default_rng(seed), **kwargs).rgb
        levels[d] = float(summary["views"][d]["mean_level"]["Gr"])
        if models.get(d) and train_level and d in train_level and levels[d] > 0:  # black: no level to match
            gains[d] = train_level[d] / levels[d]
        for path in models.get(d, []):
            model, record = load_model(Path(path), "auto")
            kind, dev = record["model_config"]["type"], next(model.parameters()).device
            images[(kind, d)] = predict(model, packed, dev)
            if d in gains:
                images[(f"{kind} ×k", d)] = predict(model, packed * gains[d], dev) / gains[d]
            del model
            if torch.cuda.is_available():
                torch.cuda.empty_cache()
    rows, panels = [], []
    for (condition, d), rgb in images.items():
        img = preview_srgb(rgb, balance)
        found, probs, _ = detector.detect(img)
        matched, total = recall(found, truth)
        iou = box_iou(found, truth).max(axis=0) if len(found) else np.zeros(len(truth))
        rows.append({"condition": condition, "display": d, "faces": total, "found": matched,
                     "recall": matched / total, "detections": int(len(found)),
                     "mean_iou_of_matches": float(iou[iou >= 0.5].mean()) if np.any(iou >= 0.5) else None})
        panels.append((f"{condition} · {d}: recall {matched}/{total}", img, truth, found))
    _overlay(panels, out / "detections.png")
    chart_args = {"face_px": list(STUDY_FACE_PX), "contrast": list(STUDY_CONTRAST),
                  **{k: list(v) for k, v in (chart or {}).items()}}
    table = {"rows": rows, "sensor_px": list(sensor_px), "chart_px": list(CHART_PX), "faces": int(len(truth)),
             "chart": chart_args, "seed": seed, "protocol": __doc__.split("\n\n")[1].replace("\n", " "),
             "chart_level": levels, "train_level": dict(train_level or {}), "level_gain": gains}
    save_json(out / "faces.json", table)
    save_text(out / "faces.md", faces_markdown(table))
    return table


PAPER_RECALL_PCT = {"clean": (60, 60), "degraded": (8, 0), "unet": (56, 39)}  # Zhou et al. (T-OLED, P-OLED)


def faces_markdown(table: dict) -> str:
    """Recall per condition (rows) and display (columns), the paper's layout, with the paper's recall
    (PAPER_RECALL_PCT; it has no DeP row) beside ours."""
    conds = list(dict.fromkeys(r["condition"] for r in table["rows"]))
    lines = ["| MTCNN recall | T-OLED | paper | P-OLED | paper |", "|---|---|---|---|---|"]
    for c in conds:
        cells = []
        for i, d in enumerate(("toled", "poled")):
            r = next((r for r in table["rows"] if r["condition"] == c and r["display"] in (d, "glass")), None)
            paper = PAPER_RECALL_PCT.get(c)
            cells += ["—" if r is None else f"{100 * r['recall']:.0f} % ({r['found']}/{r['faces']})",
                      "—" if paper is None else f"{paper[i]} %"]
        lines.append(f"| {c} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def load_table(out: Path) -> dict:
    return json.loads((Path(out) / "faces.json").read_text())
