"""The design-knob study's outputs (udc_render.studies.design_knobs): study_design.json, .csv, .md and .png,
written atomically (udc_render.io.files)."""
from __future__ import annotations

import csv
import io
from pathlib import Path

from udc_render.io.files import save_figure, save_json, save_text

__all__ = ["COLUMNS", "markdown", "write"]

COLUMNS = ["part", "cell", "pupil_samples", "samples_per_cell", "steps", "steps_done", "evaluations", "psnr_db",
           "error_psnr_db", "error_ring_means_rel", "error_ring_minima_rel", "objective", "open_area", "sample_um",
           "error_profile_rel", "error_peak_to_peak_rel", "turned_peak_to_peak", "turned_rms", "error_turned_rel",
           "phases", "exact_sd", "blend_sd", "blend_error_rms", "one_tile_sd", "one_tile_error_rms", "draws", "blocks",
           "error_toled_rel", "error_scatter_rel", "error_ratio_rel", "kick_swaps", "kicks", "search_psnr_db", "cpu_s",
           "cpu_gradient_s", "search_tilings", "held_psnr_db", "gain_db", "gain_se_db", "tiles", "period_um",
           "best_psnr_db", "gap_db", "bands_over_repeated", "cpu_bands_s", "sweep_cpu_s", "axis", "size_px",
           "step_nm", "pupil_used", "wavelengths", "turned_db", "turned_sd_db", "pattern_db", "error_turned_db",
           "error_gap_db"]


def _cell(v) -> str:
    if isinstance(v, list):
        return " / ".join(f"{x:.4g}" for x in v)
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _csv(rows: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, COLUMNS, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: _cell(r[k]) if k in r else "" for k in COLUMNS})
    return buf.getvalue()


def markdown(doc: dict) -> str:
    c = doc["config"]
    lines = ["# Error against run time of the design's knobs", "",
             f"Cells of {c['cell_um']:g} µm in {c['feature_um']:g} µm squares, {c['open_fraction']:.0%} open, turned "
             f"tilings (seed {c['seed']}); the rig's kernels at {c['kernel_px']} px of 3.1 µm, "
             f"{' / '.join(f'{w:g}' for w in c['wavelengths_nm'])} nm; {c['threads']} torch threads.", "",
             "## The torch PSF's pupil samples (errors against the finest setting)", "",
             "| cell | pupil samples | samples per cell | Wiener PSNR (dB) | PSNR error (dB) | ring means error | "
             "ring minima error | CPU s | CPU s with the gradient |", "|---|---|---|---|---|---|---|---|---|"]
    for r in doc["sampling"]:
        lines.append(f"| {r['cell']} | {r['pupil_samples']} | {r['samples_per_cell']} | {_cell(r['psnr_db'])} | "
                     f"{r['error_psnr_db']:.2g} | {r['error_ring_means_rel']:.2g} | {r['error_ring_minima_rel']:.2g} | "
                     f"{r['cpu_s']:.2f} | {r['cpu_gradient_s']:.2f} |")
    lines += ["", "## The search's steps (one run; its cell after each step count on the held-out tiling; 0: the "
              "initial random scatter)", "",
              "| steps | steps done | objective (mean Wiener MSE) | its PSNR (dB) | open area | exact scores | CPU s |",
              "|---|---|---|---|---|---|---|"]
    for r in doc["steps"]:
        lines.append(f"| {r['steps']} | {r['steps_done']}{' (converged)' if r['converged'] else ''} | "
                     f"{r['objective']:.4g} | {r['psnr_db']:.2f} | {r['open_area']:.4f} | {r['evaluations']} | "
                     f"{r['cpu_s']:.0f} |")
    return "\n".join(lines + _banding_lines(doc) + _field_lines(doc) + _ceiling_lines(doc)
                     + _kicks_lines(doc) + _tilings_lines(doc) + _arrangement_lines(doc) + _blur_lines(doc)) + "\n"


def _section(title: str, header: list[str], rows: list[list[str]]) -> list[str]:
    """A markdown section: its title, then a table of header and rows."""
    return (["", f"## {title}", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
            + ["| " + " | ".join(r) + " |" for r in rows])


def _banding_lines(doc: dict) -> list[str]:
    """Part (c): the sampled banding's raster step (absent from a study run before it)."""
    if not doc.get("banding"):
        return []
    return _section(f"The sampled banding's raster step (d = {doc['config']['banding_distance_mm']:g} mm, the paper "
                    "sensor's shifts; repeated: against the exact series; turned: against the finest step)",
                    ["cell", "step (µm)", "repeated: profile error", "repeated: peak-to-peak error",
                     "turned: peak-to-peak", "turned: sd", "turned: error", "CPU s"],
                    [[r["cell"], f"{r['sample_um']:g}", f"{r['error_profile_rel']:.2g}",
                      f"{r['error_peak_to_peak_rel']:.2g}", _cell(r["turned_peak_to_peak"]), _cell(r["turned_rms"]),
                      f"{r['error_turned_rel']:.2g}", f"{r['cpu_s']:.1f}"] for r in doc["banding"]])


def _field_lines(doc: dict) -> list[str]:
    """Part (d): the engine's field phases of a turned tiling (absent from a study run before it)."""
    if not doc.get("field"):
        return []
    c = doc["config"]
    return _section(f"The engine's field phases of a turned tiling (d = {c['banding_distance_mm']:g} mm, "
                    f"{c.get('field_wavelength_nm', 520):g} nm, the paper sensor; relative power P / P̄ over the "
                    "whole-sample shifts between the outer phases, against the window's exact P(s); psf-4: the "
                    "phases over one tile, wrapped)",
                    ["cell", "P", "phase step x / y (µm)", "shifts ± x / y (µm)", "exact sd", "blend sd",
                     "blend rms error", "psf-4 sd", "psf-4 rms error", "CPU s"],
                    [[r["cell"], str(r["phases"]), _cell(r["phase_step_um"]), _cell(r["shifts_um"]),
                      f"{r['exact_sd']:.2e}", f"{r['blend_sd']:.2e}", f"{r['blend_error_rms']:.2e}",
                      f"{r['one_tile_sd']:.2e}", f"{r['one_tile_error_rms']:.2e}", f"{r['cpu_s']:.1f}"]
                     for r in doc["field"]])


def _ceiling_lines(doc: dict) -> list[str]:
    """Part (e): the banding ceiling's draws (absent from a study run before it)."""
    if not doc.get("ceiling"):
        return []
    return _section(f"The banding ceiling's draws (d = {doc['config']['banding_distance_mm']:g} mm, the cell's own "
                    f"squares; errors against the expectation, from {doc['config']['ceiling_truth']} draws in disjoint "
                    "blocks)",
                    ["draws", "blocks", "T-OLED's sd: error", "scatter's sd: error", "ratio: error",
                     "CPU s, one pass"],
                    [[str(r["draws"]), str(r["blocks"]), f"{r['error_toled_rel']:.2g}",
                      f"{r['error_scatter_rel']:.2g}", f"{r['error_ratio_rel']:.2g}", f"{r['cpu_s']:.2f}"]
                     for r in doc["ceiling"]])


def _kicks_lines(doc: dict) -> list[str]:
    """Part (f): the search's kicks (absent from a study run before it)."""
    if not doc.get("kicks"):
        return []
    return _section("The search's kicks (iterated local search from part (b)'s start; the best cell after each kick "
                    "count, held out and on the search's tiling)",
                    ["swaps a kick", "kicks", "steps done", "held-out PSNR (dB)", "search's PSNR (dB)",
                     "exact scores", "CPU s"],
                    [[str(r["kick_swaps"]), str(r["kicks"]), str(r["steps_done"]), f"{r['psnr_db']:.3f}",
                      f"{r['search_psnr_db']:.3f}", str(r["evaluations"]), f"{r['cpu_s']:.0f}"]
                     for r in doc["kicks"]])


def _tilings_lines(doc: dict) -> list[str]:
    """Part (g): the search's tilings (absent from a study run before it)."""
    if not doc.get("tilings"):
        return []
    n = len(doc["tilings"][0]["held_draws_psnr_db"])
    return _section(f"The search's tilings (part (b)'s run searching the mean over M D4 draws; its cell on {n} "
                    "held-out draws, paired with M = 1's)",
                    ["M", "steps done", "held-out PSNR (dB)", "gain over M = 1 (dB, ± se)", "search's PSNR (dB)",
                     "search's excess (dB)", "exact scores", "CPU s"],
                    [[str(r["search_tilings"]), str(r["steps_done"]), f"{r['held_psnr_db']:.3f}",
                      f"{r['gain_db']:+.3f} ± {r['gain_se_db']:.3f}", f"{r['search_psnr_db']:.3f}",
                      f"{r['search_psnr_db'] - r['held_psnr_db']:+.3f}", str(r["evaluations"]), f"{r['cpu_s']:.0f}"]
                     for r in doc["tilings"]])


def _arrangement_lines(doc: dict) -> list[str]:
    """Part (h): the arranged tiling's K (absent from a study run before it)."""
    if not doc.get("arrangement"):
        return []
    n = len(next(r for r in doc["arrangement"] if r["tiles"])["psnr_draws_db"])
    rows = []
    for r in doc["arrangement"]:
        bands = " / ".join(f"{v:.3f}" for v in r["bands_over_repeated"])
        if r["tiles"] is None:
            rows.append([r["cell"], "turned", f"{r['psnr_db']:.3f}", "", "reference", bands, "", "", ""])
            continue
        rows.append([r["cell"], str(r["tiles"]), f"{r['psnr_db']:.3f}", f"{r['best_psnr_db']:.3f}",
                     f"{r['gap_db']:+.3f}", bands, f"{r['cpu_s']:.2f}", f"{r['cpu_bands_s']:.2f}",
                     f"{r['sweep_cpu_s']:.0f}"])
    return _section(f"The arranged tiling's K ({n} random K × K patterns of the cell's D4 elements; the cell turned "
                    f"on {doc['config']['held_tilings']} held-out draws)",
                    ["cell", "K", "PSNR, mean over patterns (dB)", "best pattern (dB)", "mean − turned (dB)",
                     "bands / repeated T-OLED, R / G / B (registered)", "CPU s, a score", "CPU s, the bands",
                     "CPU s, a sweep (7 K² of both)"], rows)


def _blur_lines(doc: dict) -> list[str]:
    """Part (i): the blur floor's rig (absent from a study run before it)."""
    if not doc.get("blur"):
        return []
    c = doc["config"]
    rows = [[r["cell"], r["axis"], str(r["pupil_used"]), str(r["size_px"]),
             f"G, {r['step_nm']:g} nm ({r['wavelengths']})" if r["step_nm"] else "520 nm",
             f"{r['turned_db']:.4f} ± {r['turned_sd_db']:.4f}", f"{r['gap_db']:+.4f}",
             "" if r["error_turned_db"] is None else f"{r['error_turned_db']:.1e}", f"{r['error_gap_db']:.1e}",
             f"{r['cpu_s']:.2f}"] for r in doc["blur"]]
    return _section(f"The blur floor's rig (design.pattern.blur_error_db; the cell turned over {c['blur_draws']} D4 "
                    f"draws, {c['blur_patterns']} random {c['blur_tiles']} × {c['blur_tiles']} patterns; errors "
                    "against the axis's last row)",
                    ["cell", "axis", "pupil samples", "window (px)", "wavelengths", "turned (dB), mean ± sd",
                     "patterns − turned (dB)", "turned's error (dB)", "gap's error (dB)", "CPU s, a check"], rows)


def _blur_axes(ax, rows: list[dict]) -> None:
    for i, axis in enumerate(("pupil", "window", "wavelengths")):
        for name, style in (("toled_edge", "o-"), ("scatter", "s--")):
            these = [r for r in rows if r["cell"] == name and r["axis"] == axis][:-1]  # the reference has no error
            ax.loglog([r["cpu_s"] for r in these], [max(r["error_gap_db"], 1e-6) for r in these], style,
                      color=f"C{i}", label=f"{axis}: {name}")
    if rows:
        sd = max(r["turned_sd_db"] for r in rows)
        ax.axhline(sd, color="0.5", ls=":", label=f"a turned draw's sd ({sd:.3f} dB)")
    _label(ax, "CPU s, one check", "error of patterns − turned (dB)", "blur floor: its rig", bool(rows))


def _arrangement_axes(ax, rows: list[dict]) -> None:
    for name, colour in (("toled_edge", "C0"), ("scatter", "C3")):
        these = [r for r in rows if r["cell"] == name]
        if not these:
            continue
        arranged = [r for r in these if r["tiles"]]
        ax.plot([r["bands_over_repeated"][1] for r in arranged], [r["gap_db"] for r in arranged], "o-",
                color=colour, label=f"{name}: arranged, K beside each")
        for r in arranged:
            ax.annotate(str(r["tiles"]), (r["bands_over_repeated"][1], r["gap_db"]), fontsize=7)
        ax.plot([r["bands_over_repeated"][1] for r in these if not r["tiles"]], [0.0], "*", color=colour, ms=10,
                label=f"{name}: turned")
    _label(ax, "bands / the repeated T-OLED's, G", "objective: mean − the cell turned (dB)",
           "arranged tiling: K", bool(rows))


def _tilings_axes(ax, rows: list[dict]) -> None:
    t = [r["cpu_s"] for r in rows]
    ax.plot(t, [r["held_psnr_db"] for r in rows], "o-", label="held-out draws (mean MSE)")
    ax.plot(t, [r["search_psnr_db"] for r in rows], "x:", label="the search's own M draws")
    for r in rows:
        ax.annotate(f"M = {r['search_tilings']}", (r["cpu_s"], r["held_psnr_db"]), fontsize=7)
    _label(ax, "CPU s of the search", "designed cell: Wiener PSNR (dB)", "design: search tilings", bool(rows))


def _kicks_axes(ax, rows: list[dict]) -> None:
    for i, swaps in enumerate(sorted({r["kick_swaps"] for r in rows})):
        these = [r for r in rows if r["kick_swaps"] == swaps]
        t = [r["cpu_s"] for r in these]
        ax.plot(t, [r["psnr_db"] for r in these], "o-", color=f"C{i}", label=f"{swaps} swaps a kick: held out")
        ax.plot(t, [r["search_psnr_db"] for r in these], "x:", color=f"C{i}", label=f"{swaps}: the search's tiling")
        for r in these:
            ax.annotate(str(r["kicks"]), (r["cpu_s"], r["psnr_db"]), fontsize=7)
    _label(ax, "CPU s of the search (kicks beside each)", "best cell: Wiener PSNR (dB)", "design: kicks", bool(rows))


def _label(ax, xlabel: str, ylabel: str, title: str, legend: bool) -> None:
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    if legend:
        ax.legend(fontsize=7)


def _ceiling_axes(ax, rows: list[dict]) -> None:
    t = [r["cpu_s"] for r in rows]
    for key, label, style in (("error_ratio_rel", "scatter / T-OLED: the ceiling's ratio", "o-"),
                              ("error_toled_rel", "T-OLED's sd", "s--"), ("error_scatter_rel", "scatter's sd", "^:")):
        ax.loglog(t, [max(r[key], 1e-6) for r in rows], style, label=label)
    for r in rows:
        ax.annotate(f"{r['draws']}", (r["cpu_s"], max(r["error_ratio_rel"], 1e-6)), fontsize=7)
    _label(ax, "CPU s, one forward pass (3 channels)", "relative error (RMS over blocks)", "banding ceiling: D4 draws",
           bool(rows))


def _figure(doc: dict, out: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter
    fig, (a, b, c, e, f, g, h, k, m) = plt.subplots(1, 9, figsize=(46, 4))
    for name, colour in (("toled_edge", "C0"), ("scatter", "C3")):
        rows = [r for r in doc["sampling"] if r["cell"] == name][:-1]  # the reference has no error
        t = [r["cpu_gradient_s"] for r in rows]
        a.loglog(t, [max(r["error_psnr_db"], 1e-6) for r in rows], "o-", color=colour, label=f"{name}: PSNR (dB)")
        a.loglog(t, [max(r["error_ring_minima_rel"], 1e-6) for r in rows], "s--", color=colour,
                 label=f"{name}: ring minima (rel.)")
        for r in rows:
            a.annotate(str(r["pupil_samples"]), (r["cpu_gradient_s"], max(r["error_psnr_db"], 1e-6)), fontsize=7)
    a.set_xlabel("CPU s, kernels and gradient")
    a.set_ylabel("error against the finest setting")
    a.set_title("torch PSF: pupil samples")
    a.legend(fontsize=7)
    steps = [r for r in doc["steps"] if r["steps"] > 0]
    b.plot([r["steps"] for r in steps], [r["psnr_db"] for r in steps], "o-", label="designed")
    if doc["steps"][0]["steps"] == 0:
        b.axhline(doc["steps"][0]["psnr_db"], color="0.5", ls="--", label="0 steps: the initial random scatter")
    b.plot([r["steps_done"] for r in steps], [r["psnr_db"] for r in steps], "x", color="C1", label="steps done")
    b.legend(fontsize=7)
    for r in steps:
        b.annotate(f"{r['cpu_s']:.0f} s", (r["steps"], r["psnr_db"]), fontsize=7)
    b.set_xscale("log")
    _banding_axes(c, doc.get("banding", []))
    _field_axes(e, doc.get("field", []))
    _ceiling_axes(f, doc.get("ceiling", []))
    _kicks_axes(g, doc.get("kicks", []))
    _tilings_axes(h, doc.get("tilings", []))
    _arrangement_axes(k, doc.get("arrangement", []))
    _blur_axes(m, doc.get("blur", []))
    for axis in (a.xaxis, b.xaxis):
        axis.set_minor_formatter(NullFormatter())
    b.set_xlabel("search steps, accepted swaps (CPU s beside each)")
    b.set_ylabel("final cell: Wiener PSNR (dB, mean MSE over R, G, B)")
    b.set_title("design: steps")
    save_figure(fig, out / "study_design.png")
    plt.close(fig)


def _banding_axes(ax, rows: list[dict]) -> None:
    for name, colour in (("toled_edge", "C0"), ("scatter", "C3")):
        these = [r for r in rows if r["cell"] == name]
        t = [r["cpu_s"] for r in these]
        ax.loglog(t, [max(r["error_profile_rel"], 1e-9) for r in these], "o-", color=colour,
                  label=f"{name}: repeated, profile vs series")
        ax.loglog(t[:-1], [max(r["error_turned_rel"], 1e-9) for r in these[:-1]], "s--", color=colour,
                  label=f"{name}: turned, figures vs finest")
        for r in these:
            ax.annotate(f"{r['sample_um']:g} µm", (r["cpu_s"], max(r["error_profile_rel"], 1e-9)), fontsize=7)
    _label(ax, "CPU s, both tilings, 3 channels", "relative error", "sampled banding: raster step", bool(rows))


def _field_axes(ax, rows: list[dict]) -> None:
    for name, colour in (("toled_edge", "C0"), ("scatter", "C3")):
        these = [r for r in rows if r["cell"] == name]
        t = [r["cpu_s"] for r in these]
        ax.loglog(t, [r["blend_error_rms"] / r["exact_sd"] for r in these], "o-", color=colour,
                  label=f"{name}: blend (psf-5)")
        ax.loglog(t, [r["one_tile_error_rms"] / r["exact_sd"] for r in these], "s--", color=colour,
                  label=f"{name}: one tile, wrapped (psf-4)")
        for r in these:
            ax.annotate(f"P = {r['phases']}", (r["cpu_s"], r["blend_error_rms"] / r["exact_sd"]), fontsize=7)
    _label(ax, "CPU s, kernels at one wavelength", "rms error of P / P̄ over the exact sd",
           "turned tiling: field phases", bool(rows))


def write(doc: dict, out: Path) -> list[str]:
    save_json(out / "study_design.json", doc)
    parts = ("banding", "field", "ceiling", "kicks", "tilings", "arrangement", "blur")  # absent from older runs
    save_text(out / "study_design.csv", _csv(doc["sampling"] + doc["steps"] + sum((doc.get(p, []) for p in parts), [])))
    save_text(out / "study_design.md", markdown(doc))
    _figure(doc, out)
    return ["study_design.json", "study_design.csv", "study_design.md", "study_design.png"]
