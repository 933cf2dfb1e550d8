"""Layouts side by side from their `study layout --restore dep` runs (udc_render.studies.layout_restore):

- each layout's DeP PSNR over the crops (the study's: the crops' pooled MSE, per channel, and their mean);
- the paired difference to a reference layout, crop by crop: d_i = mean over channels of PSNR_i − PSNR_ref,i, its
  mean, its standard error s_d / √n and the crops where the layout wins. The crops, noise and sampler draws are the
  same for every layout (named streams keyed by crop and channel), so the pairs share the scene;
- study_layout_compare.png: the first crop, its truth and each layout's DeP estimate (study_layout_restored_*.png).

    from udc_render.studies.layout_compare import run_compare
    run_compare(Path("out/compare"), {"T-OLED": Path("out/toled"), "designed": Path("out/design")}, "T-OLED")
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from udc_render.io.files import save_figure, save_json, save_text

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
    se = float(np.std(d, ddof=1) / math.sqrt(d.size)) if d.size > 1 else math.nan
    return {"mean_db": float(d.mean()), "standard_error_db": se, "wins": int((d > 0).sum()), "crops": int(d.size),
            "per_crop_db": d.tolist()}


def run_compare(out: Path, studies: dict[str, Path], reference: str, tiling: str = "turned") -> dict:
    """study_layout_compare.json, .md and .png in `out` for the study folders `studies` (label: folder), each layout
    paired with `reference` (one of the labels)."""
    if reference not in studies:
        raise ValueError(f"reference {reference!r}: expected one of {', '.join(studies)}")
    restored = {name: _restored(folder, tiling) for name, folder in studies.items()}
    rows = {name: {"psnr_db": d["psnr_db"], "mean_psnr_db": d["mean_psnr_db"],
                   "paired": paired(d, restored[reference]) if name != reference else None}
            for name, d in restored.items()}
    first = restored[reference]
    doc = {"tiling": tiling, "reference": reference, "crops": first["crops"], "crop_px": first["crop_px"],
           "studies": {k: str(v) for k, v in studies.items()}, "layouts": rows}
    out.mkdir(parents=True, exist_ok=True)
    save_json(out / "study_layout_compare.json", doc)
    save_text(out / "study_layout_compare.md", _markdown(doc))
    _figure(studies, tiling, out / "study_layout_compare.png")
    return doc


def _markdown(doc: dict) -> str:
    n = len(doc["crops"])
    lines = [f"# Layouts restored by DeP, {doc['tiling']} tilings", "",
             f"{n} crops of {doc['crop_px']} px ({', '.join(sorted({c[0] for c in doc['crops']}))}); the same noise "
             f"and sampler draws for every layout. Paired: crop by crop against {doc['reference']}, the PSNR's mean "
             "over R, G, B (mean ± standard error over the crops).", "",
             "| layout | DeP PSNR R / G / B (dB) | mean | paired difference (dB) | crops won |",
             "|---|---|---|---|---|"]
    for name, r in doc["layouts"].items():
        p = r["paired"]
        diff = "reference" if p is None else f"{p['mean_db']:+.2f} ± {p['standard_error_db']:.2f}"
        wins = "" if p is None else f"{p['wins']} of {p['crops']}"
        lines.append(f"| {name} | {' / '.join(f'{v:.2f}' for v in r['psnr_db'])} | {r['mean_psnr_db']:.2f} | {diff} | "
                     f"{wins} |")
    return "\n".join(lines + [""])


def _figure(studies: dict[str, Path], tiling: str, path: Path) -> None:
    """The first crop's truth and each layout's DeP estimate, from study_layout_restored_{tiling}.png (truth | input
    | estimate)."""
    import imageio.v3 as iio
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    panels = {name: iio.imread(Path(folder) / f"study_layout_restored_{tiling}.png")
              for name, folder in studies.items()}
    w = next(iter(panels.values())).shape[1] // 3
    fig, axes = plt.subplots(1, len(panels) + 1, figsize=(2.6 * (len(panels) + 1), 2.9))
    axes[0].imshow(next(iter(panels.values()))[:, :w])
    axes[0].set_title("truth", fontsize=9)
    for ax, (name, img) in zip(axes[1:], panels.items()):
        ax.imshow(img[:, 2 * w:])
        ax.set_title(f"{name}: DeP", fontsize=9)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    save_figure(fig, path)
    plt.close(fig)
