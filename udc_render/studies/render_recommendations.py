"""The recommendations of the render study's report (udc_render.studies.render_report) in words: which
sampler, samples per pixel and bounces the measured error and time support.
"""
from __future__ import annotations

from udc_render.studies.render_config import Config
from udc_render.studies.report import duration, fmt_cell, pct


def time_cell(e: dict) -> str:
    if not e or e.get("seconds") is None:
        return "not reached"
    how = e["how"]
    mark = "≤ " if how.startswith("≤") else ("~" if how.startswith("extrap") else "")
    cpu = f"CPU {mark}{duration(e['cpu_seconds'])}, " if e.get("cpu_seconds") is not None else ""
    return f"{cpu}wall {mark}{duration(e['seconds'])} ({fmt_cell(e['spp'], 2)} spp)" + (" ext." if mark == "~" else "")


def _ratios_text(score: dict) -> str:
    return ", ".join(f"{s} {v:.2g}" for s, v in sorted(score.items(), key=lambda kv: kv[1]))


def _best_text(tab: dict, metric_word: str) -> str:
    parts = []
    for t in tab["targets"]:
        b = tab["best"].get(t)
        if b:
            le = "≤ " if b["how"].startswith("≤") else ""
            parts.append(f"{pct(float(t))} {metric_word}: {b['sampler']} in {le}{duration(b['cpu_seconds'])} CPU "
                         f"({le}{duration(b['seconds'])} wall, {fmt_cell(b['spp'], 2)} spp"
                         + (", extrapolated" if b["how"].startswith("extrap") else "") + ")")
    return "; ".join(parts)


def _sampler_text(an: dict) -> list[str]:
    s = an["recommend"].get("sampler")
    tabs = an["samplers"]
    if not s or not s.get("recommended"):
        return []
    out = [f"- **Sampler of the Monte Carlo paths: {s['recommended']}** (render.sampler). Rule: the smallest "
           "geometric mean, over the room's targets (per band and XYZ), of the CPU time to reach the target "
           "relative to the fastest sampler — the room (3D, spectral) is where Monte Carlo is needed; "
           f"the monitor alone renders exactly by default. Room: {_ratios_text(s['score_room'])}."]
    if s.get("score_monitor"):
        mon = "monitor_full" if "monitor_full" in tabs else "monitor"
        out.append(f"- Monitor through Mitsuba (rgb_matrix: a thin lens, or `path = \"rgb_matrix\"`): fastest "
                   f"**{s['best_monitor']}** (ratios {_ratios_text(s['score_monitor'])}); "
                   + _best_text(tabs[mon], "per band") + ".")
    for key, word in (("room_xyz", "XYZ"), ("room_band", "per band")):
        if tabs.get(key) and tabs[key]["best"]:
            out.append(f"- Room ({word}, study size): " + _best_text(tabs[key], word) + ".")
    return out


def _monitor_text(m: dict) -> str:
    tab = m["table"]
    parts = []
    for r in tab["rows"]:
        cells = ", ".join(f"{pct(float(t))} {time_cell(r[t])}" for t in tab["targets"])
        parts.append(f"{r['sampler']}: {cells}")
    return (f"- **Monitor: path = analytic** (auto for the monitor through a pinhole): exact, "
            f"{duration(m['analytic_seconds'])} at {m['sensor_px'][0]} × {m['sensor_px'][1]}. Mitsuba's rgb_matrix "
            f"at the same size against it — {'; '.join(parts)}"
            + ("." if m["full_frame"] else " (study size: no full-frame runs in this grid)."))


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
                f"{fmt_cell(r['equal_error_cost_ratio'], 2)}×**")
    return (f"- **Monitor, spectral vs rgb_matrix** ({r['bands_per_render']} bands per render, both independent): "
            f"{same}{cost} (fitted b · c², set-up excluded). At {r['max_spp']} spp its error against the analytic "
            f"reference is {pct(r['rel_error_net_at_max_spp'])}, "
            f"err/noise {fmt_cell(r.get('err_over_noise_at_max_spp'))}, "
            f"band means within {pct(r['band_mean_dev_at_max_spp'])}: the spectral path converges to the same "
            "image. Keep path = auto for the monitor alone.")


def _room_bpr_text(room: dict) -> str:
    t = room["table"]
    per_band = ", ".join(f"{e['bands_per_render']}: {e['samples_band_rel']:.2g}" for e in t)
    per_xyz = ", ".join(f"{e['bands_per_render']}: {e['samples_xyz_rel']:.2g}" for e in t)
    time_band = ", ".join(f"{e['bands_per_render']}: {fmt_cell(e['time_band_rel'], 2)}" for e in t)
    time_xyz = ", ".join(f"{e['bands_per_render']}: {fmt_cell(e['time_xyz_rel'], 2)}" for e in t)
    return (
        f"- **Room: bands_per_render = {room['recommended_bpr']}** (independent sampler; the cheapest at equal "
        f"error on the XYZ image, i.e. for what a camera records). Samples (renders × spp) needed for equal error, "
        f"relative to the cheapest — per band: {per_band}; on XYZ: {per_xyz}. CPU time at equal error "
        f"(b_cpu · c², study size, per-render overheads included) — per band: {time_band}; on XYZ: {time_xyz}. "
        f"Per band, {room['fastest_bpr_band']} bands per render is cheapest: a render's 4 wavelengths per "
        "path then all land in its few bands; with all bands in one render a band gets a wavelength on only "
        "a few paths, but every path covers the whole spectrum, which is what the camera's broad channels "
        f"integrate. If per-band images are the product, use {room['fastest_bpr_band']}.")


def _room_spp_text(room: dict) -> str:
    f, d = room.get("noise_factor_full"), room.get("scene_default")
    x5, x2 = room["xyz_0.05"], room["xyz_0.02"]
    return (
        f"- **Room spp = {room['recommended_spp']}** (independent sampler, {room['recommended_bpr']} bands per "
        f"render: the smallest power of two reaching 5 % on XYZ at the full sensor"
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
    """One bullet per recommendation of the analysis (sampler, monitor path, spectral vs rgb_matrix, room bpr
    and spp)."""
    rec = an["recommend"]
    out = _sampler_text(an)
    if rec.get("monitor_exact") and rec["monitor_exact"]["analytic_seconds"] is not None:
        out.append(_monitor_text(rec["monitor_exact"]))
    out += [_spectral_text(r) for r in rec.get("monitor_spectral_vs_rgb", [])]
    if rec.get("room"):
        out += [_room_bpr_text(rec["room"]), _room_spp_text(rec["room"])]
        if rec["room"].get("with_sampler"):
            out.append(_room_sampler_text(rec["room"]["with_sampler"]))
    return out or ["(not enough data)"]


def _room_sampler_text(w: dict) -> str:
    r, d = w["at_recommended_spp"], w.get("at_scene_spp")
    f = w.get("noise_factor_full")
    return (
        f"- **Room with the {w['sampler']} sampler** (its line at the scene's bands per render: slope "
        f"{fmt_cell(w['slope'], 3)} per band, {fmt_cell(w['slope_xyz'], 3)} on XYZ, so c / sqrt(spp) holds"
        + (f"; noise factor {f:.2f} from its resolution check" if f else "") + f"): at {r['spp']} spp XYZ ≈ "
        f"{pct(r['xyz_error'])}, per band ≈ {pct(r['band_error'])}"
        + (f"; the scene file's {d['spp']} spp: XYZ ≈ {pct(d['xyz_error'])}, per band ≈ {pct(d['band_error'])}"
           if d and d["spp"] != r["spp"] else "")
        + f". 5 % on XYZ needs {w['xyz_0.05']['spp']} spp, 2 % {w['xyz_0.02']['spp']} spp (≈ "
        f"{duration(w['xyz_0.02']['seconds_full'])} at the independent sampler's cost per spp; the samplers' costs per "
        "spp are within the timing noise of each other, column CPU s).")
