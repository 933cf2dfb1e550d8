"""`udc-render study design-bands --designs DIR,DIR`: the designs' bands at d = 2 mm on many D4 draws, paired with the
T-OLED at each design's open area (issue 48).

design.json's `banding` scores a design on 5 draws, and one draw's ratio to the T-OLED varies by about 8 % (sd), so a
ratio of 1.05 over 5 draws is one standard error from level. Here every design is scored as there
(udc_render.design.job: banding_sd on the 2 µm raster, R / G / B, against toled_banding_cell tiled the same way on the
same `study layout --tile-seed N` draws), on DRAWS draws: per channel the ratio's mean ± se, its sd over the draws and
the draws below 1. The reference is the preset on 2 µm squares with grey edges, the designs are exact on the raster;
on the first CHECK_DRAWS draws both are also scored on a 1 µm raster (the T-OLED on 1 µm squares), and the ratio's
change is stated beside the result: an estimate of the raster's error, not a bound (the T-OLED's grey edges do not
converge monotonically with the square: docs/guides/design.md). Designs may differ in squares and open area: each
is paired with the T-OLED at its own (computed once per open area). Beside, each design's bands over the repeated
T-OLED's (the same cell tiled plainly: one figure, no draw, over its registrations: udc_render.design.registration),
mean ± se over the draws: the reading of "no stronger
than the T-OLED's" where that T-OLED is the repeated one. An arranged design is periodic (its K × K super-cell): one
figure over its registrations, set against each turned T-OLED draw and against the repeated T-OLED, and beside them
the spread of its single registrations (one panel's alignment to the camera: min, median and max over every offset
of its period on the raster, over the repeated T-OLED) with their map in G; its 1 µm check is the change of its
ratio over the repeated T-OLED (both registered). Writes study_design_bands.{json,csv,md,png} and, per arranged
design, study_design_bands_registrations_<name>.png.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from udc_render.io.files import save_json
from udc_render.studies.design_held_out import saved_design
from udc_render.studies.report import md_table, pyplot, save_plot, write_tables

__all__ = ["NAME", "DRAWS", "QUICK_DRAWS", "CHECK_DRAWS", "CHECK_SAMPLE_UM", "check", "run_study"]

NAME = "study_design_bands"
DRAWS = 32  # the ratio's se to about 0.014 (sd 0.08 over draws)
QUICK_DRAWS = 2
CHECK_DRAWS = 2  # draws also scored on the finer raster (6 × the time of a draw)
CHECK_SAMPLE_UM = 1.0
CHANNELS = ("R", "G", "B")


def check(folders: list[Path]) -> dict:
    """{folder: (config, cell)}: every folder read before any scoring (one line on the first that fails)."""
    return {str(f): saved_design(f, arranged=True) for f in folders}


def _toled_sd(config, seeds, sample_um: float, cache: dict, tiling: str | None = None) -> list:
    """The T-OLED's bands at the design's cell and open area, tiled as the design is (or as `tiling`), on the draws,
    computed once per key."""
    from udc_render.design.job import banding_sd, toled_banding_cell
    tiling = tiling or config.tiling
    key = (config.cell_um, config.open_fraction, tiling, tuple(seeds), sample_um)
    if key not in cache:
        toled, toled_um = toled_banding_cell(config.cell_um, config.open_fraction, sample_um)
        cache[key] = banding_sd(toled, toled_um, tiling, seeds, sample_um)
    return cache[key]


def _se(summary: dict, draws: int) -> list:
    """The standard error of ratio_summary's mean over the draws."""
    return (np.asarray(summary["sd_of_ratio"]) / np.sqrt(draws)).tolist()


def _row(name: str, config, cell: np.ndarray, draws: int, checks: int, cache: dict) -> dict:
    """One design: its ratio over the draws (job.ratio_summary, with the se) and its change on the finer raster over
    the first `checks` draws (None for 0)."""
    from udc_render.design.job import banding_sd, ratio_summary
    from udc_render.design.tiling_power import SAMPLE_UM
    seeds = list(range(draws))
    sd = banding_sd(cell, config.feature_um, config.tiling, seeds)
    summary = ratio_summary(sd, _toled_sd(config, seeds, SAMPLE_UM, cache))
    repeated = ratio_summary(sd, _toled_sd(config, [0], SAMPLE_UM, cache, "repeated") * draws)  # no draw: one figure
    row = {"design": name, "feature_um": config.feature_um, "open_fraction": config.open_fraction,
           "tiling": config.tiling, "draws": draws, **summary, "se": _se(summary, draws), "sd": sd,
           "raster_change": None,
           "over_repeated": {"mean": repeated["mean"], "se": _se(repeated, draws), "below": repeated["below"]}}
    if checks:
        fine_seeds = seeds[:checks]
        fine = ratio_summary(banding_sd(cell, config.feature_um, config.tiling, fine_seeds, CHECK_SAMPLE_UM),
                             _toled_sd(config, fine_seeds, CHECK_SAMPLE_UM, cache))
        row["raster_change"] = (np.asarray(fine["mean"]) / np.mean(summary["ratio"][:checks], axis=0) - 1).tolist()
    return row


def _arranged_row(name: str, config, period: np.ndarray, draws: int, checks: int, cache: dict) -> dict:
    """One arranged design (its super-cell `period`): its registered figure over each turned T-OLED draw and over
    the repeated T-OLED, its single registrations' ratios to the repeated T-OLED (min, median, max, the share
    below 1, and the G map), and with `checks` the change of its ratio over the repeated T-OLED on the finer
    raster (both registered there)."""
    from udc_render.design.job import banding_sd, ratio_summary, registered_variances
    from udc_render.design.tiling_power import SAMPLE_UM
    maps = registered_variances(period, config.feature_um)
    sd = [[float(np.sqrt(m.mean())) for m in maps]]
    seeds = list(range(draws))
    summary = ratio_summary(sd * draws, _toled_sd(config, seeds, SAMPLE_UM, cache, "turned"))
    toled = _toled_sd(config, [0], SAMPLE_UM, cache, "repeated")[0]
    repeated = ratio_summary(sd, [toled])
    single = [np.sqrt(m) / t for m, t in zip(maps, toled)]
    change = None
    if checks:
        fine = np.divide(banding_sd(period, config.feature_um, "repeated", [0], CHECK_SAMPLE_UM)[0],
                         _toled_sd(config, [0], CHECK_SAMPLE_UM, cache, "repeated")[0])
        change = (fine / np.asarray(repeated["mean"]) - 1).tolist()
    return {"design": name, "feature_um": config.feature_um, "open_fraction": config.open_fraction,
            "tiling": config.tiling, "draws": draws, **summary, "se": _se(summary, draws), "sd": sd,
            "raster_change": change, "over_repeated": {"mean": repeated["mean"], "se": [0.0] * 3,
                                                     "below": repeated["below"]},
            "registrations": {"offsets": int(single[0].size), "step_um": SAMPLE_UM,
                              **{k: [float(f(r)) for r in single] for k, f in
                                 (("min", np.min), ("median", np.median), ("max", np.max),
                                  ("below", lambda r: (r < 1).mean()))}},
            "registration_map_G": single[1]}


def _markdown(doc: dict) -> str:
    def pm(r, c):
        return f"{r['mean'][c]:.3f} ± {r['se'][c]:.3f} ({r['below'][c]})"

    def spread(r):
        g = r.get("registrations")
        return "—" if g is None else (f"{g['min'][1]:.3f} / {g['median'][1]:.3f} / {g['max'][1]:.3f} "
                                      f"({100 * g['below'][1]:.0f} % below)")

    def fine(r):
        return "—" if r["raster_change"] is None else " / ".join(f"{100 * v:+.1f}" for v in r["raster_change"])

    rows = [{"design": Path(r["design"]).name, "tiling": r["tiling"],
             **{ch: pm(r, c) for c, ch in enumerate(CHANNELS)}, "sd": f"{r['sd_of_ratio'][1]:.3f}", "fine": fine(r),
             "repeated": pm(r["over_repeated"], 1), "spread": spread(r)}
            for r in doc["rows"]]
    n = doc["draws"]
    lines = ["# The designs' bands at d = 2 mm over held-out D4 draws, paired with the T-OLED", "",
             f"The ratio of each design's bands (the relative sd of the power over the paper sensor's shifts, 2 µm "
             f"raster) to the turned T-OLED's at the design's open area on the same draw: mean ± se over {n} draws "
             f"(the draws below 1), its sd over the draws in G, and the mean ratio's change on a {CHECK_SAMPLE_UM:g} "
             f"µm raster over the first {doc['check_draws']} draws (%, R / G / B; an arranged design's: of its "
             f"ratio over the repeated T-OLED); then the design's bands over "
             f"the repeated T-OLED's (one figure over its registrations: a periodic display has no draw), G. An "
             f"arranged design is periodic: its one figure over its registrations is set against every turned "
             f"T-OLED draw, and its single registrations (one panel's alignment) over the repeated T-OLED's span "
             f"the last column (min / median / max, G, and the share of offsets below 1).", ""]
    lines += md_table(rows, [("design", "design"), ("tiling", "tiling"), ("R", "R"), ("G", "G"), ("B", "B"),
                             ("sd", "sd over draws, G"), ("fine", f"change on {CHECK_SAMPLE_UM:g} µm (%)"),
                             ("repeated", "over the repeated T-OLED, G"),
                             ("spread", "one registration over the repeated T-OLED, G")], {})
    return "\n".join(lines) + "\n"


def _figure(doc: dict, out: Path) -> None:
    plt = pyplot()
    rows = doc["rows"]
    fig, ax = plt.subplots(figsize=(7, 0.45 * len(rows) + 1.5))
    for y, r in enumerate(rows):
        g = np.asarray(r["ratio"])[:, 1]
        ax.plot(g, np.full(len(g), y) + np.linspace(-0.2, 0.2, len(g)), ".", color="0.6", ms=3)
        ax.errorbar(r["mean"][1], y, xerr=2 * r["se"][1], fmt="o", color="C0")
        if "registrations" in r:
            reg = r["registrations"]
            ax.hlines(y + 0.3, reg["min"][1], reg["max"][1], color="C1")
            ax.plot(r["over_repeated"]["mean"][1], y + 0.3, "|", color="C1", ms=10)
    ax.axvline(1, color="0.3", lw=0.8)
    ax.set_yticks(range(len(rows)), [Path(r["design"]).name for r in rows])
    ax.set_xlabel(f"bands at d = 2 mm, design / turned T-OLED, G (each draw; mean ± 2 se over {doc['draws']});\n"
                  "orange: an arranged design's single registrations over the repeated T-OLED (range; | registered)")
    save_plot(fig, out / f"{NAME}.png")


def _registration_figure(row: dict, out: Path) -> None:
    """The G ratio of one registration to the repeated T-OLED over the offsets of an arranged design's period."""
    plt = pyplot()
    m = np.asarray(row["registration_map_G"])
    step = row["registrations"]["step_um"]
    half = m.shape[0] // 2 * step
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    dev = max(float(np.abs(m - 1).max()), 1e-3)  # a diverging scale centred on level with the T-OLED
    extent = (-half, m.shape[1] * step - half, m.shape[0] * step - half, -half)
    im = ax.imshow(m, cmap="RdBu_r", vmin=1 - dev, vmax=1 + dev, extent=extent)
    fig.colorbar(im, ax=ax, label="bands / repeated T-OLED's (registered), G")
    ax.set_xlabel("offset x (µm)")
    ax.set_ylabel("offset y (µm)")
    ax.set_title(f"{Path(row['design']).name}: one registration per offset", fontsize=9)
    save_plot(fig, out / f"{NAME}_registrations_{Path(row['design']).name}.png")


def run_study(out: Path, designs: list[Path], quick: bool = False) -> dict:
    """Every folder read (a bad one refused) before any scoring; then the module doc's files."""
    found = check(designs)
    draws, checks = (QUICK_DRAWS, 1) if quick else (DRAWS, CHECK_DRAWS)
    start, cache, rows = time.perf_counter(), {}, []
    for name, (config, cell) in tqdm(found.items(), desc="study design-bands"):
        rows.append(_arranged_row(name, config, cell, draws, checks, cache) if config.tiling == "arranged"
                    else _row(name, config, cell, draws, checks, cache))
    for row in rows:
        if "registrations" in row:
            _registration_figure(row, out)
            del row["registration_map_G"]  # in the PNG, not the JSON
    doc = {"draws": draws, "check_draws": checks, "check_sample_um": CHECK_SAMPLE_UM, "rows": rows,
           "toled_sd": {f"{k[0]:g} µm, {k[1]:.6g}, {k[2]}, {k[4]:g} µm raster": v for k, v in cache.items()},
           "seconds": time.perf_counter() - start}
    save_json(out / f"{NAME}.json", doc)
    flat = [{"design": r["design"], "tiling": r["tiling"],
             **{f"{k}_{ch}": r[k][c] for k in ("mean", "se", "below") for c, ch in enumerate(CHANNELS)},
             **{f"raster_change_{ch}": None if r["raster_change"] is None else r["raster_change"][c]
                for c, ch in enumerate(CHANNELS)},
             **{f"over_repeated_{ch}": r["over_repeated"]["mean"][c] for c, ch in enumerate(CHANNELS)},
             **{f"registration_{k}_G": r["registrations"][k][1] if "registrations" in r else None
                for k in ("min", "median", "max")}} for r in rows]
    write_tables(out, NAME, flat, list(flat[0]), _markdown(doc))
    _figure(doc, out)
    return doc
