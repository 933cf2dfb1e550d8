"""The render study's outputs: study_render.csv, study_render.md (set-up, one table per scene and path,
the fits, the resolution checks and the recommended defaults in words), study_render.json and
study_render.png (error vs time, log-log, labelled with spp)."""
from __future__ import annotations

from pathlib import Path

from udc_render.io.files import save_json
from udc_render.studies.render_analysis import series_key, series_label
from udc_render.studies.render_config import COLUMNS, FULL_SENSOR, REPEAT_BELOW_S, Config
from udc_render.studies.report import (annotated_loglog, duration, finish_axes, fmt_cell, machine_text, md_table,
                                       pct, pyplot, save_plot, write_tables)

RUN_COLS = [("spp", "spp"), ("seconds", "seconds"), ("cpu_seconds", "CPU s"), ("rel_error", "rel_error"),
            ("rel_error_net", "rel_error_net"), ("noise_rel", "noise_rel"),
            ("err_over_noise", "err/noise"), ("rel_error_xyz", "rel_error_xyz"),
            ("rel_error_xyz_net", "xyz_net"), ("band_mean_dev", "band_mean_dev"), ("repeats", "repeats")]
PCT_COLS = {k: pct for k in ("rel_error", "rel_error_net", "noise_rel", "rel_error_xyz", "rel_error_xyz_net",
                             "band_mean_dev")}


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
        "# Rendering: error versus run time (spp, render path, bands per render)",
        "",
        ("QUICK smoke-test grid (not for decisions). " if cfg.quick else "") + machine_text(meta["elapsed_s"])
        + (f"; load average {la[0]:.1f} at start, {lb[0]:.1f} at end (a shared machine: times are noisy, read "
           "them as ratios)." if la else "."),
        f"Variants: {meta['variant_rgb']} (rgb_matrix), {meta['variant_spectral']} (spectral).",
        "",
        f"Scenes: scenes/monitor.toml with the sensor at {mon_w} × {mon_h} px of {mon_p:g} µm "
        f"(render grid with margin {grid['monitor'][0]} × {grid['monitor'][1]})"
        + (f", panel reduced to {cfg.monitor_panel_px[0]} × {cfg.monitor_panel_px[1]}" if cfg.monitor_panel_px else "")
        + f"; scenes/room.toml at {room_w} × {room_h} px of {room_p:g} µm (grid {grid['room'][0]} × "
        f"{grid['room'][1]}), no depth pass. The same physical sensor as the full {FULL_SENSOR[0]} × "
        f"{FULL_SENSOR[1]} px of {FULL_SENSOR[2]} µm (grid {full['monitor'][0]} × {full['monitor'][1]}), "
        "so the framing is unchanged.",
        "",
        "**rel_error** = ‖x − ref‖₂ / ‖ref‖₂ over all 30 bands and all grid pixels (margin included). "
        "**rel_error_net** = sqrt(rel_error² − ref_noise²): the reference's own noise taken out. "
        "**noise_rel**: the run's own noise estimate (spread of its passes, the renderer's meta; none at 1 spp); "
        "relative to the noise-free image, like rel_error. "
        "err/noise = rel_error_net / noise_rel: 1 when the error is all noise, above 1 with a bias. "
        "**rel_error_xyz**: the same error on the CIE XYZ image (bands weighted by the colour-matching "
        "functions), what a three-channel camera sees. band_mean_dev = max over bands of "
        "|Σ x_k / Σ ref_k − 1| (bias check). seconds = the renderer's meta['seconds'] for the whole "
        f"render_scene call (set-up included), median of up to {cfg.repeats} runs when under "
        f"{REPEAT_BELOW_S:g} s; kernels warmed by an untimed 2-spp render of each series. CPU s = this process's "
        "CPU time over the same call (all threads: about 2× the wall time while both cores render; less "
        "sensitive than wall time to other processes on the machine, so the cost ratios below use it).",
        "",
    ]


def _references(rows: list[dict]) -> list[str]:
    lines = ["References (mean of two renders with seeds 1 and 2; ref_noise from their difference, noise_meta "
             "from the halves' own noise_rel):", ""]
    for name, r in {r["scene"]: r for r in rows if r["role"] == "reference"}.items():
        bpr = f", {r['bands_per_render']} bands per render" if r["bands_per_render"] != "" else ""
        meta_n = r.get("ref_noise_meta")
        lines.append(f"- {name}: {r['path']}{bpr}, {r['spp']} spp in all, {r['seconds']:.1f} s; "
                     f"ref_noise {pct(r['ref_noise_rel'])} (bands), {pct(r['ref_noise_xyz'])} (XYZ)"
                     + (f"; noise_meta {pct(meta_n)}" if meta_n else "") + ".")
    return lines + [""]


def _sweep_tables(rows: list[dict], cfg: Config) -> list[str]:
    sweep = [r for r in rows if r["role"] == "sweep"]
    lines = ["## Monitor, rgb_matrix path", ""]
    lines += md_table([r for r in sweep if r["scene"] == "monitor" and r["path"] == "rgb_matrix"], RUN_COLS,
                      PCT_COLS)
    lines += ["", "## Monitor, spectral path (against the rgb_matrix reference)", ""]
    lines += md_table([r for r in sweep if r["scene"] == "monitor" and r["path"] == "spectral"],
                      [("bands_per_render", "bands/render"), ("groups", "renders")] + RUN_COLS, PCT_COLS)
    lines += ["", "## Room, spectral path", "",
              "Each bands_per_render line spends the same budget renders × spp (columns 'renders', 'spp'), "
              f"{', '.join(str(b) for b in cfg.room_budgets)} (spp rounded to a power of two).", ""]
    lines += md_table([r for r in sweep if r["scene"] == "room"],
                      [("bands_per_render", "bands/render"), ("groups", "renders"), ("renders_x_spp", "renders×spp")]
                      + RUN_COLS, PCT_COLS)
    return lines


def _fits(an: dict) -> list[str]:
    lines = ["", "## Fits", "",
             "Per line: error ∝ spp^slope (least squares in log-log; −0.5 for pure Monte Carlo noise), "
             "c = error · sqrt(spp) (slope fixed at −1/2, geometric mean), wall time = a + b · spp (b_cpu: "
             "the same fit on CPU time). Cost at equal error ∝ b · c².", ""]
    fit_rows = []
    for label, f in an["fits"].items():
        fit_rows.append({"line": label, "slope": f["band"].get("slope"), "c": f["band"].get("c"),
                         "slope_xyz": f["xyz"].get("slope"), "c_xyz": f["xyz"].get("c"), "a": f["band"].get("a"),
                         "b": f["band"].get("b"), "b_cpu": f["band"].get("b_cpu"),
                         "spp2": f["targets"]["0.02"]["band"]["spp_fit"],
                         "spp1": f["targets"]["0.01"]["band"]["spp_fit"],
                         "s2": f["targets"]["0.02"]["band"]["seconds_fit"]})
    return lines + md_table(fit_rows, [("line", "line"), ("slope", "slope"), ("c", "c"), ("slope_xyz", "slope (XYZ)"),
                                       ("c_xyz", "c (XYZ)"), ("a", "a (s)"), ("b", "b (s/spp)"),
                                       ("b_cpu", "b_cpu (CPU s/spp)"), ("spp2", "spp for 2 %"),
                                       ("spp1", "spp for 1 %"), ("s2", "seconds for 2 %")])


def _checks(an: dict) -> list[str]:
    if not an["checks"]:
        return []
    lines = ["", "## Resolution checks (noise_rel only: no reference at that size)", ""]
    lines += md_table(an["checks"], [("scene", "scene"), ("path", "path"), ("bands_per_render", "bands/render"),
                                     ("spp", "spp"), ("sensor_px", "sensor"), ("seconds", "seconds"),
                                     ("seconds_pred", "seconds predicted"),
                                     ("noise_rel", "noise_rel"), ("study_noise_rel", "study noise_rel"),
                                     ("noise_factor", "factor")],
                      {"noise_rel": pct, "study_noise_rel": pct})
    return lines + ["", "factor = noise at the higher resolution / noise at the study's resolution, same spp: "
                    "used below to carry the study's spp over to the full sensor. seconds predicted = the "
                    "study's fit a + b · spp with b scaled by the render grid's pixel count (the rule used for "
                    "the full-size times below)."]


def markdown(rows: list[dict], an: dict, meta: dict, cfg: Config) -> str:
    """study_render.md: set-up and metrics, references, the sweep tables, fits, checks, recommendations."""
    lines = _header(meta, an, cfg) + _references(rows) + _sweep_tables(rows, cfg) + _fits(an) + _checks(an)
    lines += ["", "## Recommended defaults (derived from the data above)", ""]
    lines += recommendations(an, cfg)
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------------
# Recommendations in words


def _monitor_text(m: dict, cfg: Config) -> str:
    f = m.get("noise_factor_full")
    return (
        f"- **Monitor (rgb_matrix): spp = {m['recommended_spp']}** (the smallest power of two reaching 1 % "
        f"at the full sensor: ≈ {pct(m['recommended_error_full'])}, ≈ {duration(m['0.01']['seconds_full_est'])}). "
        f"In the study ({cfg.monitor_sensor[0]} × {cfg.monitor_sensor[1]} px) the smallest spp of the grid "
        f"reaching 2 % is {m['0.02']['smallest_spp_in_grid'] or 'none'} and 1 %: "
        f"{m['0.01']['smallest_spp_in_grid'] or 'none'} (fit: {fmt_cell(m['0.02']['spp_study_fit'])} and "
        f"{fmt_cell(m['0.01']['spp_study_fit'])} spp). "
        + (f"At the full sensor the noise at equal spp is {f:.2f}× the study's (resolution check: each pixel "
           f"covers fewer panel pixels, so less of the image's detail is averaged by Monte Carlo), so 2 % needs "
           f"≈ {fmt_cell(m['0.02']['spp_full_est'])} spp and 1 % ≈ {fmt_cell(m['0.01']['spp_full_est'])} spp. "
           if f else "Without a resolution check the study's spp is used as is. ")
        + f"Time at full size: ≈ {m['setup_s']:.1f} s of scene set-up (panel image, primaries) + "
        f"{m['per_spp_full_s']:.2g} s per spp.")


def _spectral_text(r: dict) -> str:
    same = (f"{r['seconds_ratio_same_spp']:.2g}× the wall time at {r['max_spp']} spp (set-up included), "
            if r.get("seconds_ratio_same_spp") else "")
    if r.get("equal_error_cost_ratio_cpu"):
        cost = (f"{r['per_spp_cost_ratio_cpu']:.0f}× the CPU time per additional spp (wall: "
                f"{r['per_spp_cost_ratio']:.0f}×); **at equal per-band error "
                f"{r['equal_error_cost_ratio_cpu']:.0f}×** "
                f"(wall: {r['equal_error_cost_ratio']:.0f}×)"
                + (f", on the XYZ image {r['equal_error_cost_ratio_xyz_cpu']:.0f}×"
                   if r.get("equal_error_cost_ratio_xyz_cpu") else ""))
    else:
        cost = (f"{r['per_spp_cost_ratio']:.0f}× per additional spp; **at equal per-band error "
                f"{r['equal_error_cost_ratio']:.0f}×**")
    return (f"- **Monitor, spectral vs rgb_matrix** ({r['bands_per_render']} bands per render): {same}{cost} "
            f"(fitted b · c², set-up excluded). At {r['max_spp']} spp its error against the rgb_matrix "
            f"reference is {pct(r['rel_error_net_at_max_spp'])}, "
            f"err/noise {fmt_cell(r.get('err_over_noise_at_max_spp'))}, "
            f"band means within {pct(r['band_mean_dev_at_max_spp'])}: no bias between the paths is visible. "
            "Keep path = auto (rgb_matrix) for the monitor alone.")


def _room_bpr_text(room: dict) -> str:
    t = room["table"]
    per_band = ", ".join(f"{e['bands_per_render']}: {e['samples_band_rel']:.2g}" for e in t)
    per_xyz = ", ".join(f"{e['bands_per_render']}: {e['samples_xyz_rel']:.2g}" for e in t)
    time_band = ", ".join(f"{e['bands_per_render']}: {e['time_band_rel']:.2g}" for e in t)
    time_xyz = ", ".join(f"{e['bands_per_render']}: {e['time_xyz_rel']:.2g}" for e in t)
    return (
        f"- **Room: bands_per_render = {room['recommended_bpr']}** (the cheapest at equal error on the XYZ "
        f"image, i.e. for what a camera records). Samples (renders × spp) needed for equal error, relative to "
        f"the cheapest — per band: {per_band}; on XYZ: {per_xyz}. CPU time at equal error "
        f"(b_cpu · c², study size, per-render overheads included) — per band: {time_band}; on XYZ: {time_xyz}. "
        f"Per band, {room['fastest_bpr_band']} bands per render is cheapest: a render's 4 wavelengths per "
        "path then all land in its few bands; with all bands in one render a band gets a wavelength on only "
        "a few paths, but every path covers the whole spectrum, which is what the camera's broad channels "
        f"integrate. If per-band images are the product, use {room['fastest_bpr_band']}.")


def _room_spp_text(room: dict) -> str:
    f, d = room.get("noise_factor_full"), room.get("scene_default")
    x5, x2 = room["xyz_0.05"], room["xyz_0.02"]
    return (
        f"- **Room spp = {room['recommended_spp']}** (with {room['recommended_bpr']} bands per render: the "
        f"smallest power of two reaching 5 % on XYZ at the full sensor"
        + (f", noise factor {f:.2f} from the resolution check" if f else "")
        + f"): XYZ ≈ {pct(x5['xyz_error'])}, per band ≈ {pct(x5['band_error'])}, ≈ "
        f"{duration(x5['seconds_full'])} at 2048 × 1024 ({room['render_spp_full_s']:.2g} s per render × spp "
        f"there). 2 % on XYZ needs {x2['spp']} spp (≈ {duration(x2['seconds_full'])}). "
        + (f"The scene file's current {d['bands_per_render']} bands per render × {d['spp']} spp gives XYZ ≈ "
           f"{pct(d['xyz_error'])}, per band ≈ {pct(d['band_error'])} in ≈ {duration(d['seconds_full'])}. "
           if d else "")
        + f"Per band, 5 % needs {room['per_band_best']['spp']} spp with {room['per_band_best']['bands_per_render']} "
        f"bands per render (≈ {duration(room['per_band_best']['seconds_full'])}). Noise falls as 1/sqrt(spp) "
        "and a 3D scene costs hours at 2048 × 1024 on 2 cores for per-band errors of a few %: pick spp by "
        "the time available, or use render.noise (spp from pilot renders).")


def recommendations(an: dict, cfg: Config) -> list[str]:
    """One bullet per recommendation of the analysis (monitor spp, spectral vs rgb_matrix, room bpr and spp)."""
    rec = an["recommend"]
    out = [_monitor_text(rec["monitor"], cfg)] if rec.get("monitor") else []
    out += [_spectral_text(r) for r in rec.get("monitor_spectral_vs_rgb", [])]
    if rec.get("room"):
        out += [_room_bpr_text(rec["room"]), _room_spp_text(rec["room"])]
    return out or ["(not enough data)"]


# ----------------------------------------------------------------------------------------------
# Plot


def plot(rows: list[dict], path: Path, cfg: Config) -> None:
    """study_render.png: net error vs run time per line, for the monitor and the room (per band, XYZ)."""
    plt = pyplot()
    sweep = [r for r in rows if r["role"] == "sweep"]
    panels = [("monitor", "rel_error_net", "monitor: per-band error"),
              ("room", "rel_error_net", "room: per-band error"),
              ("room", "rel_error_xyz_net", "room: XYZ error")]
    fig, axes = plt.subplots(1, 3, figsize=(18, 5.5))
    for ax, (scene, metric, title) in zip(axes, panels):
        series: dict = {}
        for r in sweep:
            if r["scene"] == scene:
                series.setdefault(series_key(r), []).append(r)
        for key, rs in series.items():
            pts = [(r["seconds"], r[metric], r["spp"]) for r in rs if r.get(metric)]
            if pts:
                annotated_loglog(ax, [p[0] for p in pts], [p[1] for p in pts], [str(p[2]) for p in pts],
                                 series_label(key).replace(f"{scene} ", ""), lw=1.2)
        ref = next((r for r in rows if r["role"] == "reference" and r["scene"] == scene), None)
        if ref:
            floor = ref["ref_noise_xyz"] if metric == "rel_error_xyz_net" else ref["ref_noise_rel"]
            ax.axhline(floor, color="k", ls=":", lw=0.8, label=f"reference noise ({pct(floor)}, subtracted)")
        for t in (0.02, 0.01):
            ax.axhline(t, color="grey", ls="--", lw=0.6)
        finish_axes(ax, title + " (labels: spp)", "run time (s, render_scene, median)",
                    "relative L2 error, reference noise removed")
    fig.suptitle(("QUICK grid — " if cfg.quick else "") + "Rendering: error vs run time (dashed: 2 % and 1 %)",
                 fontsize=12)
    fig.tight_layout()
    save_plot(fig, path)
