"""The render study's outputs: study_render.csv, study_render.md (set-up, one table per scene and path,
the fits, the samplers' times to the target errors, the noise estimate's honesty, the resolution checks
and the recommended defaults in words), study_render.json and study_render.png (error vs time, log-log,
labelled with spp, one line per scene, path and sampler)."""
from __future__ import annotations

from pathlib import Path

from udc_render.io.files import save_json
from udc_render.studies.render_analysis import series_key, series_label
from udc_render.studies.render_config import COLUMNS, FULL_SENSOR, REPEAT_BELOW_S, Config
from udc_render.studies.render_recommendations import recommendations, time_cell
from udc_render.studies.report import (
    annotated_loglog,
    finish_axes,
    fmt_cell,
    machine_text,
    md_table,
    pct,
    pyplot,
    save_plot,
    write_tables,
)

RUN_COLS = [("spp", "spp"), ("spp_requested", "requested"), ("seconds", "seconds"), ("cpu_seconds", "CPU s"),
            ("rel_error", "rel_error"), ("rel_error_net", "rel_error_net"), ("noise_rel", "noise_rel"),
            ("err_over_noise", "err/noise"), ("rel_error_xyz", "rel_error_xyz"),
            ("rel_error_xyz_net", "xyz_net"), ("band_mean_dev", "band_mean_dev"), ("repeats", "repeats")]
PCT_COLS = {k: pct for k in ("rel_error", "rel_error_net", "noise_rel", "rel_error_xyz", "rel_error_xyz_net",
                             "band_mean_dev")}
TABLE_TITLES = {"monitor_full": "Monitor, rgb_matrix, full {w} × {h} frame, per-band error against the analytic image",
                "monitor": "Monitor, rgb_matrix, study size, per-band error against the analytic image",
                "room_band": "Room, spectral, {bpr} bands per render, per-band error",
                "room_xyz": "Room, spectral, {bpr} bands per render, XYZ error"}


def write_report(out_dir: Path, rows: list[dict], analysis: dict, meta: dict, cfg: Config) -> None:
    """study_render.{csv,md,json,png} in out_dir."""
    write_tables(out_dir, "study_render", rows, COLUMNS, markdown(rows, analysis, meta, cfg))
    save_json(out_dir / "study_render.json", {"meta": meta, "analysis": analysis, "rows": rows})
    plot(rows, out_dir / "study_render.png", cfg)


# ----------------------------------------------------------------------------------------------
# Markdown


def _header(meta: dict, an: dict, cfg: Config) -> list[str]:
    la, lb = meta["load_start"], meta["load_end"]
    mon_w, mon_h, mon_p = cfg.monitor_sensor
    room_w, room_h, room_p = cfg.room_sensor
    grid, full = an["study_grid_px"], an["full_grid_px"]
    return [
        "# Rendering: error versus run time (spp, sampler, render path, bands per render)",
        "",
        ("QUICK smoke-test grid (not for decisions). " if cfg.quick else "") + machine_text(meta["elapsed_s"])
        + (f"; load average {la[0]:.1f} at start, {lb[0]:.1f} at end (a shared machine: times are noisy, read "
           "them as ratios)." if la else "."),
        f"Variants: {meta['variant_rgb']} (rgb_matrix), {meta['variant_spectral']} (spectral); the analytic "
        "path is numpy.",
        "",
        f"Scenes: scenes/monitor.toml with the sensor at {mon_w} × {mon_h} px of {mon_p:g} µm "
        f"(render grid with margin {grid['monitor'][0]} × {grid['monitor'][1]})"
        + (f", panel reduced to {cfg.monitor_panel_px[0]} × {cfg.monitor_panel_px[1]}" if cfg.monitor_panel_px else "")
        + (f", and at the full {FULL_SENSOR[0]} × {FULL_SENSOR[1]} px of {FULL_SENSOR[2]} µm for the samplers "
           f"(spp {', '.join(str(s) for s in cfg.full_spp)})" if cfg.full_spp else "")
        + f"; scenes/room.toml at {room_w} × {room_h} px of {room_p:g} µm (grid {grid['room'][0]} × "
        f"{grid['room'][1]}), no depth pass. The same physical sensor as the full {FULL_SENSOR[0]} × "
        f"{FULL_SENSOR[1]} px of {FULL_SENSOR[2]} µm (grid {full['monitor'][0]} × {full['monitor'][1]}), "
        "so the framing is unchanged.",
        "",
        "**rel_error** = ‖x − ref‖₂ / ‖ref‖₂ over all 30 bands and all grid pixels (margin included). "
        "The monitor's reference is the **analytic** render (the exact pixel-area means of the panel: no "
        "noise), the room's the mean of two independent-sampler renders. "
        "**rel_error_net** = sqrt(rel_error² − ref_noise²): the reference's own noise taken out (nothing to take "
        "out for the monitor). "
        "**noise_rel**: the run's own noise estimate (spread of its passes, each pass its own seed, the "
        "renderer's meta; none at 1 spp); relative to the noise-free image, like rel_error. "
        "**err/noise** = rel_error_net / noise_rel: 1 when the error is all noise and the noise estimate is "
        "honest, above 1 with a bias or an estimate too small. "
        "**rel_error_xyz**: the same error on the CIE XYZ image (bands weighted by the colour-matching "
        "functions), what a three-channel camera sees. band_mean_dev = max over bands of "
        "|Σ x_k / Σ ref_k − 1| (bias check). spp = the samples rendered (the sampler's rounding: ldsampler "
        "a power of 4 per pass, stratified a square, orthogonal a prime², multijitter x·y); requested = the "
        "spp asked for. seconds = the renderer's meta['seconds'] for the whole "
        f"render_scene call (set-up included), median of up to {cfg.repeats} runs when under "
        f"{REPEAT_BELOW_S:g} s; kernels warmed by an untimed 2-spp render of each series. CPU s = this process's "
        "CPU time over the same call (all threads: about 2× the wall time while both cores render; less "
        "sensitive than wall time to other processes on the machine, so the cost ratios below use it).",
        "",
    ]


def _references(rows: list[dict]) -> list[str]:
    lines = ["## References", ""]
    for r in (r for r in rows if r["role"] == "reference"):
        if r["path"] == "analytic":
            lines.append(f"- {r['scene']} ({r['sensor_px']} px): **analytic**, exact (noise 0), "
                         f"{r['seconds']:.2g} s (median of {r['repeats']}); its rows below have error 0 by "
                         "construction.")
        else:
            bpr = f", {r['bands_per_render']} bands per render" if r["bands_per_render"] != "" else ""
            meta_n = r.get("ref_noise_meta")
            lines.append(f"- {r['scene']}: {r['path']} {r['sampler']}{bpr}, two halves (seeds 1 and 2), "
                         f"{r['spp']} spp in all, {r['seconds']:.1f} s; ref_noise {pct(r['ref_noise_rel'])} (bands), "
                         f"{pct(r['ref_noise_xyz'])} (XYZ), from the halves' difference"
                         + (f"; from the halves' own noise_rel: {pct(meta_n)}" if meta_n else "") + ".")
    for r in (r for r in rows if r["role"] == "exact_check"):
        lines.append(f"- Check that the analytic image is exact: Mitsuba rgb_matrix, {r['sampler']}, {r['spp']} spp "
                     f"({r['seconds']:.2g} s), differs from it by {pct(r['rel_error'])}, its own noise estimate "
                     f"being {pct(r['noise_rel'])} (err/noise {fmt_cell(r.get('err_over_noise'))}; band means "
                     f"within {pct(r['band_mean_dev'])}): the difference is that render's noise, no bias.")
    return lines + [""]


def _sweep_tables(rows: list[dict], cfg: Config) -> list[str]:
    sweep = [r for r in rows if r["role"] == "sweep"]
    smp_cols = [("sampler", "sampler")]
    lines = ["## Monitor, rgb_matrix path, per sampler (study size)", ""]
    lines += md_table([r for r in sweep if r["scene"] == "monitor" and r["path"] == "rgb_matrix"],
                      smp_cols + RUN_COLS, PCT_COLS)
    full = [r for r in rows if r["role"] == "full"]
    if full:
        lines += ["", f"## Monitor, rgb_matrix path, per sampler at the full {FULL_SENSOR[0]} × {FULL_SENSOR[1]} "
                  "frame", "", "full/study = this run's error / the study-size run's at the same sampler and "
                  "requested spp (each pixel covers fewer panel pixels at full size).", ""]
        lines += md_table(full, smp_cols + RUN_COLS + [("error_full_over_study", "full/study")], PCT_COLS)
    lines += ["", "## Monitor, spectral path (independent sampler, against the analytic reference)", ""]
    lines += md_table([r for r in sweep if r["scene"] == "monitor" and r["path"] == "spectral"],
                      [("bands_per_render", "bands/render"), ("groups", "renders")] + RUN_COLS, PCT_COLS)
    lines += ["", "## Room, spectral path", "",
              "Each line spends the same budget renders × spp (columns 'renders', 'requested'), "
              f"{', '.join(str(b) for b in cfg.room_budgets)} (spp rounded to a power of two; the sampler may "
              "round it up further: column spp). The bands_per_render lines use the independent sampler; every "
              "sampler is run at the scene's bands_per_render.", ""]
    lines += md_table([r for r in sweep if r["scene"] == "room"],
                      [("sampler", "sampler"), ("bands_per_render", "bands/render"), ("groups", "renders"),
                       ("renders_x_spp", "renders×spp")] + RUN_COLS, PCT_COLS)
    return lines


def _fits(an: dict) -> list[str]:
    lines = ["", "## Fits", "",
             "Per line: error ∝ spp^slope (least squares in log-log over all runs; −0.5 for independent Monte Carlo "
             "noise, steeper for the correlated samplers), slope (tail) the same through the last two runs (the "
             "extrapolation beyond the last run), c = error · sqrt(spp) (slope fixed at −1/2, geometric mean: "
             "meaningful for the independent sampler only), wall time = a + b · spp (b_cpu: the same fit on CPU "
             "time). Independent sampler: cost at equal error ∝ b · c².", ""]
    fit_rows = []
    for label, f in list(an["fits"].items()) + [(k + " (full frame)", v) for k, v in an.get("full_fits", {}).items()]:
        fit_rows.append({"line": label, "slope": f["band"].get("slope"), "slope_tail": f["band"].get("slope_tail"),
                         "c": f["band"].get("c"), "slope_xyz": f["xyz"].get("slope"), "c_xyz": f["xyz"].get("c"),
                         "a": f["band"].get("a"), "b": f["band"].get("b"), "b_cpu": f["band"].get("b_cpu")})
    return lines + md_table(fit_rows, [("line", "line"), ("slope", "slope"), ("slope_tail", "slope (tail)"),
                                       ("c", "c"), ("slope_xyz", "slope (XYZ)"), ("c_xyz", "c (XYZ)"),
                                       ("a", "a (s)"), ("b", "b (s/spp)"), ("b_cpu", "b_cpu (CPU s/spp)")])


def sampler_section(an: dict) -> list[str]:
    """One table per scene: per sampler the time (and spp) to reach each target error."""
    lines = ["", "## Samplers: time to reach a target error", "",
             "Read from the measured runs: log-log interpolation between the two runs (in spp order) that bracket "
             "the target; '≤' = the first run is already below it (an upper bound); '~ … ext.' = beyond the last "
             "run, extrapolated along the local slope through the last two runs (column 'slope (tail)'; each "
             "error is a norm over 10⁵–10⁶ values, so the local slope is precise) with the time fit a + b · spp. "
             "Not the fixed-slope c/√spp fit: the correlated samplers converge faster than 1/√spp (up to the pass "
             "size: beyond 2 passes, more spp means more passes, and those average as 1/√passes). Times: CPU "
             "seconds of this process (all threads; about 2× the wall time on an idle 2-core machine) and wall "
             "seconds; **bold**: the fastest sampler by CPU time (wall times on this shared machine vary with the "
             "other jobs' load).", ""]
    for key in ("monitor_full", "monitor", "room_band", "room_xyz"):
        tab = an["samplers"].get(key)
        if not tab or not tab["rows"]:
            continue
        title = TABLE_TITLES[key].format(w=FULL_SENSOR[0], h=FULL_SENSOR[1], bpr=tab["bands_per_render"])
        cols = [("sampler", "sampler"), ("slope", "slope"), ("slope_tail", "slope (tail)")] + [
            (t, f"to {pct(float(t))}") for t in tab["targets"]]
        rows = []
        for r in tab["rows"]:
            row = {k: r[k] for k in ("sampler", "slope", "slope_tail")}
            for t in tab["targets"]:
                cell = time_cell(r[t])
                best = tab["best"].get(t)
                row[t] = f"**{cell}**" if best and best["sampler"] == r["sampler"] else cell
            rows.append(row)
        lines += [f"### {title}", ""] + md_table(rows, cols, {t: str for t in tab["targets"]}) + [""]
    return lines


def honesty_section(an: dict) -> list[str]:
    if not an["honesty"]:
        return []
    lines = ["## Is the noise estimate honest? err/noise per sampler", "",
             "err/noise = true error (reference noise taken out) / the run's own estimate from the spread of its "
             "passes; each pass is its own randomisation of the sampler, so the estimate stays honest for the "
             "correlated samplers (≈ 1). The room's values scatter more: its reference noise is taken out in "
             "quadrature.", ""]
    return lines + md_table(an["honesty"], [("scene", "scene"), ("path", "path"), ("sampler", "sampler"),
                                            ("size", "size"), ("n", "runs"), ("min", "min"), ("median", "median"),
                                            ("max", "max")]) + [""]


def _checks(an: dict) -> list[str]:
    if not an["checks"]:
        return []
    lines = ["", "## Resolution checks (noise_rel only: no reference at that size)", ""]
    lines += md_table(an["checks"], [("scene", "scene"), ("path", "path"), ("sampler", "sampler"),
                                     ("bands_per_render", "bands/render"), ("spp", "spp"), ("sensor_px", "sensor"),
                                     ("seconds", "seconds"), ("seconds_pred", "seconds predicted"),
                                     ("noise_rel", "noise_rel"), ("study_noise_rel", "study noise_rel"),
                                     ("noise_factor", "factor")],
                      {"noise_rel": pct, "study_noise_rel": pct})
    return lines + ["", "factor = noise at the higher resolution / noise at the study's resolution, same sampler and "
                    "spp: used below to carry the study's spp over to the full sensor. seconds predicted = the "
                    "study's fit a + b · spp with b scaled by the render grid's pixel count (the rule used for "
                    "the full-size times below)."]


def markdown(rows: list[dict], an: dict, meta: dict, cfg: Config) -> str:
    """study_render.md: set-up and metrics, references, the sweep tables, fits, samplers, honesty, checks,
    recommendations."""
    lines = _header(meta, an, cfg) + _references(rows) + _sweep_tables(rows, cfg) + _fits(an)
    lines += sampler_section(an) + honesty_section(an) + _checks(an)
    lines += ["", "## Recommended defaults (derived from the data above)", ""]
    lines += recommendations(an, cfg)
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------------
# Plot


def plot(rows: list[dict], path: Path, cfg: Config) -> None:
    """study_render.png: net error vs CPU time (the sampler tables' ranking; wall time on a shared machine
    follows the other jobs' load) per (scene, path, sampler[, bpr]) line: the monitor at study size and at the
    full frame, the room per band and on XYZ."""
    plt = pyplot()
    panels = [("monitor", "sweep", "rel_error_net", "monitor, study size: per-band error"),
              ("monitor", "full", "rel_error_net",
               f"monitor, full {FULL_SENSOR[0]} × {FULL_SENSOR[1]}: per-band error"),
              ("room", "sweep", "rel_error_net", "room: per-band error"),
              ("room", "sweep", "rel_error_xyz_net", "room: XYZ error")]
    panels = [p for p in panels if any(r["scene"] == p[0] and r["role"] == p[1] for r in rows)]
    full_px = f"{FULL_SENSOR[0]}x{FULL_SENSOR[1]}"
    fig, axes = plt.subplots(1, len(panels), figsize=(6 * len(panels), 5.8), squeeze=False)
    for ax, (scene, role, metric, title) in zip(axes[0], panels):
        series: dict = {}
        for r in rows:
            if r["scene"] == scene and r["role"] == role:
                series.setdefault(series_key(r), []).append(r)
        # dashed: the monitor's spectral lines and the room's bands_per_render lines other than the samplers' one
        sampler_bpr = {k[2] for k in series if k[3] != "independent"}
        for key, rs in series.items():
            pts = sorted((r["cpu_seconds"], r[metric], r["spp"]) for r in rs if r.get(metric) and r.get("cpu_seconds"))
            if pts:
                line = annotated_loglog(ax, [p[0] for p in pts], [p[1] for p in pts], [str(p[2]) for p in pts],
                                        series_label(key).replace(f"{scene} ", ""), lw=1.2)
                if (scene == "monitor" and key[1] == "spectral") or (scene == "room" and key[2] not in sampler_bpr):
                    line.set_linestyle("--")
        ref = next((r for r in rows if r["role"] == "reference" and r["scene"] == scene
                    and (r["sensor_px"] == full_px) == (role == "full")), None)
        if ref and ref["path"] == "analytic" and ref.get("cpu_seconds"):
            ax.axvline(ref["cpu_seconds"], color="k", ls=":", lw=0.9,
                       label=f"analytic (exact, error 0): {ref['cpu_seconds']:.2g} CPU s")
        elif ref:
            floor = ref["ref_noise_xyz"] if metric == "rel_error_xyz_net" else ref["ref_noise_rel"]
            if floor:
                ax.axhline(floor, color="k", ls=":", lw=0.8, label=f"reference noise ({pct(floor)}, subtracted)")
        for t in (0.01, 0.001) if scene == "monitor" else (0.05, 0.02):
            ax.axhline(t, color="grey", ls="--", lw=0.6)
        finish_axes(ax, title + " (labels: spp)", "CPU time of render_scene (s, all threads, median)",
                    "relative L2 error, reference noise removed")
    fig.suptitle(("QUICK grid — " if cfg.quick else "") + "Rendering: error vs CPU time per path and sampler "
                 "(dashed grey: monitor 1 % and 0.1 %, room 5 % and 2 %)", fontsize=12)
    fig.tight_layout()
    save_plot(fig, path)
