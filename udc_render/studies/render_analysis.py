"""The render study's analysis: a fit per series (error ∝ spp^slope, error = c / sqrt(spp), time = a +
b · spp), the resolution checks, and the recommended defaults extrapolated to the full sensor."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from udc_render.scene import Scene, Sensor
from udc_render.studies.render_config import FULL_SENSOR, TARGETS, grid_px


def series_key(r: dict) -> tuple:
    """(scene, path, bands_per_render): the rows of one error-versus-spp line."""
    return (r["scene"], r["path"], r["bands_per_render"])


def series_label(key: tuple) -> str:
    scene, path, bpr = key
    return f"{scene} {path}" + (f", {bpr} bands/render" if bpr != "" else "")


def fit_series(rs: list[dict], metric: str = "rel_error_net") -> dict:
    """Error ∝ spp^slope (free slope) and error = c / sqrt(spp) (fixed slope); time = a + b · spp."""
    out: dict = {"n": len(rs)}
    pts = [(r["spp"], r[metric]) for r in rs if r.get(metric)]
    if len(pts) >= 2:
        s, e = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
        out["slope"] = float(np.polyfit(s, e, 1)[0]) if np.ptp(s) > 0 else None
        out["c"] = float(np.exp(np.mean(e + 0.5 * s)))
    spp = np.array([r["spp"] for r in rs], float)
    if len(rs) >= 2 and np.ptp(spp) > 0:
        for col, (ka, kb) in (("seconds", ("a", "b")), ("cpu_seconds", ("a_cpu", "b_cpu"))):
            sec = np.array([r.get(col, np.nan) for r in rs], float)
            if np.all(np.isfinite(sec)):
                b, a = np.polyfit(spp, sec, 1)
                out[ka], out[kb] = float(max(a, 0.0)), float(max(b, 1e-9))
    return out


def spp_for(fit: dict, target: float) -> float | None:
    """spp = (c / target)² of the fixed-slope fit."""
    return (fit["c"] / target) ** 2 if fit.get("c") else None


def seconds_for(fit: dict, spp: float, scale: float = 1.0) -> float | None:
    """Fitted run time at `spp`, the per-spp cost scaled by `scale` (render-grid pixel ratio)."""
    if fit.get("b") is None or spp is None:
        return None
    return fit["a"] + fit["b"] * scale * spp


def _tk(t: float) -> str:
    """A target's key in the analysis dicts (JSON keys must be strings)."""
    return f"{t:g}"


def _pow2_at_least(x: float) -> int:
    return 1 if x <= 1 else 2 ** math.ceil(math.log2(x) - 1e-9)


def _px(wh) -> int:
    return wh[0] * wh[1]


def fit_line(key: tuple, rs: list[dict], scale_to_full: float) -> dict:
    """The fits of one series (per band and on XYZ) and, per target error, the spp and seconds they give."""
    f, fx = fit_series(rs), fit_series(rs, "rel_error_xyz_net")
    out = {"label": series_label(key), "band": f, "xyz": fx, "groups": rs[0]["groups"],
           "scale_to_full": scale_to_full, "targets": {}}
    for t in TARGETS:
        entry = {}
        for name, fit, col in (("band", f, "rel_error_net"), ("xyz", fx, "rel_error_xyz_net")):
            spp = spp_for(fit, t)
            reached = [r for r in rs if r.get(col) is not None and r[col] <= t]
            entry[name] = {"spp_fit": spp, "seconds_fit": seconds_for(f, spp),
                           "smallest_spp_in_grid": min((r["spp"] for r in reached), default=None)}
        out["targets"][_tk(t)] = entry
    return out


def resolution_checks(rows: list[dict], sweep: list[dict], fits: dict, study_grid: dict) -> list[dict]:
    """noise_rel at a higher resolution against the study's run at the same settings (noise_factor)."""
    checks = []
    for c in (r for r in rows if r["role"] == "check"):
        twin = next((r for r in sweep if series_key(r) == series_key(c) and r["spp"] == c["spp"]), None)
        w, h = (int(v) for v in c["grid_px"].split("x"))
        fit = fits.get(series_key(c), {}).get("band", {})
        checks.append({"scene": c["scene"], "path": c["path"], "bands_per_render": c["bands_per_render"],
                       "spp": c["spp"], "groups": c["groups"], "sensor_px": c["sensor_px"], "grid_px": [w, h],
                       "noise_rel": c["noise_rel"], "seconds": c["seconds"],
                       "seconds_pred": seconds_for(fit, c["spp"], w * h / _px(study_grid[c["scene"]])),
                       "study_noise_rel": twin["noise_rel"] if twin else None,
                       "noise_factor": (c["noise_rel"] / twin["noise_rel"])
                       if twin and twin["noise_rel"] and c["noise_rel"] else None})
    return checks


def recommend_monitor(rgb: dict, chk: dict | None, full_grid: dict) -> dict:
    """rgb_matrix spp for 2 % and 1 %, at study resolution and at the full sensor (noise × noise_factor;
    time per spp from the full-size check run, else the fit's b scaled by the pixel count)."""
    fct = chk["noise_factor"] if chk else 1.0
    a = rgb["band"]["a"]
    if chk:  # full-size time per spp from the full-size run itself
        per_spp_full = max(chk["seconds"] - a, 0.0) / chk["spp"] * _px(full_grid["monitor"]) / _px(chk["grid_px"])
    else:
        per_spp_full = rgb["band"]["b"] * rgb["scale_to_full"]
    m = {"noise_factor_full": chk["noise_factor"] if chk else None, "setup_s": a, "per_spp_full_s": per_spp_full}
    for t in (0.02, 0.01):
        spp_full = spp_for({"c": rgb["band"]["c"] * fct}, t)
        m[_tk(t)] = {"spp_study_fit": spp_for(rgb["band"], t),
                     "smallest_spp_in_grid": rgb["targets"][_tk(t)]["band"]["smallest_spp_in_grid"],
                     "spp_full_est": spp_full, "spp_full_pow2": _pow2_at_least(spp_full),
                     "seconds_full_est": a + per_spp_full * _pow2_at_least(spp_full)}
    m["recommended_spp"] = m["0.01"]["spp_full_pow2"]
    m["recommended_error_full"] = rgb["band"]["c"] * fct / math.sqrt(m["recommended_spp"])
    return m


def _cost(fit: dict, c: str, b: str = "b") -> float | None:
    """Time per unit 1/error²: b · c² (asymptotic, set-up excluded)."""
    return fit["band"][b] * fit[c]["c"] ** 2 if fit["band"].get(b) and fit[c].get("c") else None


def _ratio(x, y):
    return x / y if x is not None and y else None


def spectral_vs_rgb(fits: dict, series: dict, rgb: dict) -> list[dict]:
    """Per monitor spectral line: run time per spp and at equal error relative to rgb_matrix."""
    ratios = []
    for key, f in fits.items():
        if key[0] == "monitor" and key[1] == "spectral" and f["band"].get("c") and f["band"].get("b"):
            top = max(series[key], key=lambda r: r["spp"])
            same = next((r for r in series[("monitor", "rgb_matrix", "")] if r["spp"] == top["spp"]), None)
            ratios.append({
                "bands_per_render": key[2],
                "seconds_ratio_same_spp": top["seconds"] / same["seconds"] if same else None,
                "per_spp_cost_ratio": _ratio(f["band"]["b"], rgb["band"]["b"]),
                "per_spp_cost_ratio_cpu": _ratio(f["band"].get("b_cpu"), rgb["band"].get("b_cpu")),
                "equal_error_cost_ratio": _ratio(_cost(f, "band"), _cost(rgb, "band")),
                "equal_error_cost_ratio_xyz": _ratio(_cost(f, "xyz"), _cost(rgb, "xyz")),
                "equal_error_cost_ratio_cpu": _ratio(_cost(f, "band", "b_cpu"), _cost(rgb, "band", "b_cpu")),
                "equal_error_cost_ratio_xyz_cpu": _ratio(_cost(f, "xyz", "b_cpu"), _cost(rgb, "xyz", "b_cpu")),
                "max_spp": top["spp"], "rel_error_net_at_max_spp": top["rel_error_net"],
                "noise_rel_at_max_spp": top["noise_rel"], "err_over_noise_at_max_spp": top.get("err_over_noise"),
                "band_mean_dev_at_max_spp": top["band_mean_dev"]})
    return ratios


def room_cost_table(room: dict) -> list[dict]:
    """Per room bands_per_render line: samples (renders × c²) and CPU time (b_cpu · c²) for unit 1/error²,
    per band and on XYZ, absolute and relative to the cheapest line."""
    table = []
    for key, f in sorted(room.items(), key=lambda kv: kv[0][2]):
        g = f["groups"]
        table.append({"bands_per_render": key[2], "groups": g, "slope": f["band"].get("slope"),
                      "slope_xyz": f["xyz"].get("slope"), "c": f["band"]["c"], "c_xyz": f["xyz"]["c"],
                      "samples_band": g * f["band"]["c"] ** 2, "samples_xyz": g * f["xyz"]["c"] ** 2,
                      "time_band": f["band"].get("b_cpu", 0) * f["band"]["c"] ** 2,
                      "time_xyz": f["band"].get("b_cpu", 0) * f["xyz"]["c"] ** 2,
                      "render_spp_s": f["band"].get("b", 0) / g})
    for m in ("band", "xyz"):
        lo = min(e[f"samples_{m}"] for e in table)
        lo_t = min(e[f"time_{m}"] for e in table)
        for e in table:
            e[f"samples_{m}_rel"] = e[f"samples_{m}"] / lo
            e[f"time_{m}_rel"] = e[f"time_{m}"] / lo_t
    return table


def _predict(e: dict, spp: int, fct: float, rs_full: float) -> dict:
    """Errors c · fct / sqrt(spp) and seconds renders · spp · rs_full of a cost-table line at the full sensor."""
    return {"spp": spp, "band_error": e["c"] * fct / math.sqrt(spp),
            "xyz_error": e["c_xyz"] * fct / math.sqrt(spp), "seconds_full": e["groups"] * spp * rs_full}


def recommend_room(room: dict, chk: dict | None, full_grid: dict, scale: float, default) -> dict:
    """bands_per_render (cheapest on XYZ) and spp (5 % on XYZ at the full sensor) for the room, with the
    scene file's `default` render settings and the per-band optimum predicted alongside."""
    fct = chk["noise_factor"] if chk else 1.0
    table = room_cost_table(room)
    best_band = min(table, key=lambda e: e["samples_band"])
    best_xyz = min(table, key=lambda e: e["samples_xyz"])
    if chk:  # seconds per render × spp at full size, from the larger check render
        rs_full = chk["seconds"] / (chk["groups"] * chk["spp"]) * _px(full_grid["room"]) / _px(chk["grid_px"])
    else:
        rs_full = best_xyz["render_spp_s"] * scale
    r = {"noise_factor_full": chk["noise_factor"] if chk else None, "table": table,
         "fastest_bpr_band": best_band["bands_per_render"], "fastest_bpr_xyz": best_xyz["bands_per_render"],
         "render_spp_full_s": rs_full, "recommended_bpr": best_xyz["bands_per_render"]}
    for t in (0.05, 0.02):
        r[f"xyz_{_tk(t)}"] = _predict(best_xyz, _pow2_at_least((best_xyz["c_xyz"] * fct / t) ** 2), fct, rs_full)
    r["recommended_spp"] = r["xyz_0.05"]["spp"]
    e_def = next((e for e in table if e["bands_per_render"] == default.bands_per_render), None)
    if e_def and default.spp:
        r["scene_default"] = {"bands_per_render": default.bands_per_render,
                              **_predict(e_def, default.spp, fct, rs_full)}
    r["per_band_best"] = {"bands_per_render": best_band["bands_per_render"],
                          **_predict(best_band, _pow2_at_least((best_band["c"] * fct / 0.05) ** 2), fct, rs_full)}
    return r


def analyse(rows: list[dict], scenes: dict[str, Scene]) -> dict:
    """The fits of every sweep line, the resolution checks and the recommendations (keys: fits by
    series label, checks, recommend, full_grid_px, study_grid_px)."""
    sweep = [r for r in rows if r["role"] == "sweep"]
    series: dict = {}
    for r in sweep:
        series.setdefault(series_key(r), []).append(r)
    full_grid = {name: grid_px(replace(s, sensor=Sensor(*FULL_SENSOR))) for name, s in scenes.items()}
    study_grid = {name: grid_px(s) for name, s in scenes.items()}
    scale = {name: _px(full_grid[name]) / _px(study_grid[name]) for name in scenes}
    fits = {key: fit_line(key, rs, scale[key[0]]) for key, rs in series.items()}
    checks = resolution_checks(rows, sweep, fits, study_grid)

    def check(scene):
        return next((c for c in checks if c["scene"] == scene and c["noise_factor"]), None)

    rec: dict = {}
    rgb = fits.get(("monitor", "rgb_matrix", ""))
    if rgb and rgb["band"].get("c") and rgb["band"].get("b") is not None:
        rec["monitor"] = recommend_monitor(rgb, check("monitor"), full_grid)
        rec["monitor_spectral_vs_rgb"] = spectral_vs_rgb(fits, series, rgb)
    room = {key: f for key, f in fits.items() if key[0] == "room" and f["band"].get("c") and f["xyz"].get("c")}
    if room:
        rec["room"] = recommend_room(room, check("room"), full_grid, scale["room"], scenes["room"].render)
    return {"fits": {series_label(k): v for k, v in fits.items()}, "checks": checks, "recommend": rec,
            "full_grid_px": full_grid, "study_grid_px": study_grid}
