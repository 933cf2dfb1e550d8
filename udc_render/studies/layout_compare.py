"""Layouts side by side from their `study layout --restore dep` runs (udc_render.studies.layout_restore):

- each layout's DeP PSNR over the crops (the study's: the crops' pooled MSE, per channel, and their mean);
- the paired difference to a reference layout, crop by crop: d_i = mean over channels of PSNR_i − PSNR_ref,i, its
  mean, its standard error s_d / √n and the crops where the layout wins. The crops, noise and sampler draws are the
  same for every layout (named streams keyed by crop and channel), so the pairs share the scene;
- study_layout_compare.png: the first crop, its truth and each layout's DeP estimate (study_layout_restored_*.png).

Each entry is a study folder and one of its tilings (repeated, turned):

    from udc_render.studies.layout_compare import run_compare
    run_compare(Path("out/compare"), {"T-OLED": (Path("out/toled"), "repeated"),
                                      "designed": (Path("out/design"), "turned")}, "T-OLED")
"""
from __future__ import annotations

import json
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from udc_render.io.files import save_figure, save_json, save_text
from udc_render.metrics import paired_differences

__all__ = ["paired", "run_compare"]


def _restored(folder: Path, tiling: str) -> dict:
    path = Path(folder) / "study_layout.json"
    try:
        doc = json.loads(path.read_text())
        d = doc["restored"][tiling]
        if "crop_psnr_db" not in d:  # a study from before each crop's PSNR was recorded
            raise KeyError("crop_psnr_db")
    except (OSError, ValueError, KeyError):
        raise ValueError(f"{path}: expected a `study layout --restore dep` run with each crop's PSNR "
                         f"(restored.{tiling}.crop_psnr_db)") from None
    return d


def paired(layout: dict, reference: dict) -> dict:
    """The paired difference of two layouts' restored dicts over their common crops (module doc)."""
    if layout["crops"] != reference["crops"] or layout["crop_px"] != reference["crop_px"]:
        raise ValueError(f"paired crops differ: {layout['crops']} at {layout['crop_px']} px against "
                         f"{reference['crops']} at {reference['crop_px']} px")
    d = np.mean(layout["crop_psnr_db"], axis=1) - np.mean(reference["crop_psnr_db"], axis=1)
    p = paired_differences(d)
    return {"mean_db": p["mean"], "standard_error_db": p["standard_error"], "wins": p["wins"], "crops": p["n"],
            "per_crop_db": d.tolist()}


def run_compare(out: Path, studies: dict[str, tuple[Path, str]], reference: str) -> dict:
    """study_layout_compare.json, .md and .png in `out` for the studies (label: (study folder, tiling)), each
    paired with `reference` (one of the labels)."""
    if reference not in studies:
        raise ValueError(f"reference {reference!r}: expected one of {', '.join(studies)}")
    restored = {name: _restored(folder, tiling) for name, (folder, tiling) in studies.items()}
    rows = {name: {"psnr_db": d["psnr_db"], "mean_psnr_db": d["mean_psnr_db"],
                   "paired": paired(d, restored[reference]) if name != reference else None}
            for name, d in restored.items()}
    first = restored[reference]
    doc = {"reference": reference, "crops": first["crops"], "crop_px": first["crop_px"],
           "studies": {k: [str(v[0]), v[1]] for k, v in studies.items()}, "layouts": rows}
    out.mkdir(parents=True, exist_ok=True)
    save_json(out / "study_layout_compare.json", doc)
    save_text(out / "study_layout_compare.md", _markdown(doc))
    _figure(studies, out / "study_layout_compare.png")
    return doc


def _markdown(doc: dict) -> str:
    n = len(doc["crops"])
    lines = ["# Layouts restored by DeP", "",
             f"{n} crops of {doc['crop_px']} px ({', '.join(sorted({c[0] for c in doc['crops']}))}); the same noise "
             f"and sampler draws for every layout. Paired: crop by crop against {doc['reference']}, the PSNR's mean "
             "over R, G, B (mean ± standard error over the crops).", "",
             "| layout | tiling | DeP PSNR R / G / B (dB) | mean | paired difference (dB) | crops won |",
             "|---|---|---|---|---|---|"]
    for name, r in doc["layouts"].items():
        p = r["paired"]
        diff = "reference" if p is None else f"{p['mean_db']:+.2f} ± {p['standard_error_db']:.2f}"
        wins = "" if p is None else f"{p['wins']} of {p['crops']}"
        lines.append(f"| {name} | {doc['studies'][name][1]} | {' / '.join(f'{v:.2f}' for v in r['psnr_db'])} | "
                     f"{r['mean_psnr_db']:.2f} | {diff} | {wins} |")
    return "\n".join(lines + [""])


def _figure(studies: dict[str, tuple[Path, str]], path: Path) -> None:
    """The first crop's truth and each layout's DeP estimate, from study_layout_restored_{tiling}.png (truth | input
    | estimate)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    panels = {name: iio.imread(Path(folder) / f"study_layout_restored_{tiling}.png")
              for name, (folder, tiling) in studies.items()}
    w = next(iter(panels.values())).shape[1] // 3
    images = [("truth", next(iter(panels.values()))[:, :w])] + [(f"{name}:\nDeP", img[:, 2 * w:])
                                                                for name, img in panels.items()]
    cols = min(5, len(images))
    rows = -(-len(images) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(2.7 * cols, 3.0 * rows), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for ax, (title, img) in zip(axes.ravel(), images):
        ax.imshow(img)
        ax.set_title(title, fontsize=8)
    save_figure(fig, path)
    plt.close(fig)
