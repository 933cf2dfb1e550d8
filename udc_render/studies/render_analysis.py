"""The render study's analysis: a fit per series (error ∝ spp^slope, error = c / sqrt(spp), time = a +
b · spp), the time each series needs to reach a target error (time_to: interpolated between measured
runs), the samplers compared per scene (sampler_tables), the resolution checks, and the recommended
defaults extrapolated to the full sensor."""
from __future__ import annotations

import math
import statistics
from dataclasses import replace

import numpy as np

from udc_render.scene import Scene, Sensor
from udc_render.studies.render_config import FULL_SENSOR, MONITOR_TARGETS, TARGETS, grid_px

TAIL = 2  # runs of a series' tail fit (the extrapolation beyond its last run): the local slope between the last two
# (each error is an L2 norm over ~10⁵–10⁶ values: precise; the curvature of a correlated sampler's line is real)


def series_key(r: dict) -> tuple:
    """(scene, path, bands_per_render, sampler): the rows of one error-versus-spp line."""
    return (r["scene"], r["path"], r["bands_per_render"], r["sampler"])


def series_label(key: tuple) -> str:
    scene, path, bpr, sampler = key
    return f"{scene} {path}" + (f" {sampler}" if sampler else "") + (f", {bpr} bands/render" if bpr != "" else "")


def _loglog(pts: list[tuple]) -> tuple[float, float] | None:
    """(slope, intercept) of log y against log x, None with fewer than two distinct x."""
    if len(pts) < 2:
        return None
    s, e = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    if np.ptp(s) == 0:
        return None
    slope, icpt = np.polyfit(s, e, 1)
    return float(slope), float(icpt)


def fit_series(rs: list[dict], metric: str = "rel_error_net") -> dict:
    """Error ∝ spp^slope (free slope, all runs; and through the last TAIL runs: slope_tail, icpt_tail),
    error = c / sqrt(spp) (fixed slope); time = a + b · spp (and on CPU time)."""
    out: dict = {"n": len(rs)}
    pts = sorted((r["spp"], r[metric]) for r in rs if r.get(metric))
    if len(pts) >= 2:
        fit = _loglog(pts)
        out["slope"] = fit[0] if fit else None
        s, e = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
        out["c"] = float(np.exp(np.mean(e + 0.5 * s)))
        tail = _loglog(pts[-TAIL:])
        if tail:
            out["slope_tail"], out["icpt_tail"] = tail
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


def time_to(rs: list[dict], target: float, metric: str, fit: dict, col: str = "seconds") -> dict:
    """Time (column `col`: wall 'seconds' or 'cpu_seconds') and spp for the error `target` on a series: the
    first run (in spp order) at or below it, log-log interpolated (time and spp against error) with the run
    before it ('interpolated'); the first run itself when already there ('≤ first run': an upper bound);
    beyond the last run, the tail's free-slope fit gives spp and the time fit a + b · spp (a_cpu, b_cpu for
    CPU time) gives the time ('extrapolated'). None where nothing applies (no falling tail)."""
    pts = sorted(((r["spp"], r.get(col), r.get(metric)) for r in rs if r.get(metric) is not None))
    if any(p[1] is None for p in pts):
        return {"seconds": None, "spp": None, "how": None}
    for i, (spp, sec, err) in enumerate(pts):
        if err <= target:
            if i == 0 or err <= 0:
                return {"seconds": sec, "spp": spp, "how": "≤ first run" if i == 0 else "≤ run"}
            s0, t0, e0 = pts[i - 1]
            f = (math.log(e0) - math.log(target)) / (math.log(e0) - math.log(err))
            return {"seconds": math.exp(math.log(t0) + f * (math.log(sec) - math.log(t0))),
                    "spp": math.exp(math.log(s0) + f * (math.log(spp) - math.log(s0))), "how": "interpolated"}
    slope = fit.get("slope_tail")
    ka, kb = ("a", "b") if col == "seconds" else ("a_cpu", "b_cpu")
    if slope is None or slope >= 0 or fit.get(kb) is None:
        return {"seconds": None, "spp": None, "how": None}
    spp = math.exp((math.log(target) - fit["icpt_tail"]) / slope)
    return {"seconds": fit[ka] + fit[kb] * spp, "spp": spp, "how": f"extrapolated (slope {slope:.2f})"}


def _tk(t: float) -> str:
    """A target's key in the analysis dicts (JSON keys must be strings)."""
    return f"{t:g}"


def _pow2_at_least(x: float) -> int:
    return 1 if x <= 1 else 2 ** math.ceil(math.log2(x) - 1e-9)


def _px(wh) -> int:
    return wh[0] * wh[1]


def _time_fit(f: dict) -> dict:
    return {k: f.get(k) for k in ("a", "b", "a_cpu", "b_cpu")}


def fit_line(key: tuple, rs: list[dict], scale_to_full: float, targets=TARGETS) -> dict:
    """The fits of one series (per band and on XYZ) and, per target error, the spp and seconds they give."""
    f, fx = fit_series(rs), fit_series(rs, "rel_error_xyz_net")
    out = {"label": series_label(key), "sampler": key[3], "band": f, "xyz": fx, "groups": rs[0]["groups"],
           "scale_to_full": scale_to_full, "targets": {}}
    for t in targets:
        entry = {}
        for name, fit, col in (("band", f, "rel_error_net"), ("xyz", fx, "rel_error_xyz_net")):
            spp = spp_for(fit, t)
            reached = [r for r in rs if r.get(col) is not None and r[col] <= t]
            entry[name] = {"spp_fit": spp, "seconds_fit": seconds_for(f, spp),
                           "smallest_spp_in_grid": min((r["spp"] for r in reached), default=None),
                           "time_to": time_to(rs, t, col, fit | _time_fit(f)) | {
                               "cpu_seconds": time_to(rs, t, col, fit | _time_fit(f), "cpu_seconds")["seconds"]}}
        out["targets"][_tk(t)] = entry
    return out


def sampler_table(fits: dict, scene: str, path: str, bpr, metric: str, targets) -> dict:
    """The samplers' lines of (scene, path, bpr): per sampler and target the time_to entry (wall and CPU
    seconds), and per target the fastest sampler by CPU time (this process's: less disturbed than wall time
    by other jobs on a shared machine)."""
    lines = {k[3]: f for k, f in fits.items() if k[:3] == (scene, path, bpr)}
    rows = []
    for smp, f in lines.items():
        row = {"sampler": smp, "slope": f[metric].get("slope"), "slope_tail": f[metric].get("slope_tail")}
        for t in targets:
            row[_tk(t)] = f["targets"][_tk(t)][metric]["time_to"]
        rows.append(row)
    best = {}
    for t in targets:
        have = [r for r in rows if r[_tk(t)]["cpu_seconds"] is not None]
        if have:
            b = min(have, key=lambda r: r[_tk(t)]["cpu_seconds"])
            best[_tk(t)] = {"sampler": b["sampler"], **b[_tk(t)]}
    return {"scene": scene, "path": path, "bands_per_render": bpr, "metric": metric,
            "targets": [_tk(t) for t in targets], "rows": rows, "best": best}


def sampler_score(tables: list[dict]) -> dict:
    """Per sampler, the geometric mean over the tables' targets of its CPU time / the fastest sampler's
    (1 = fastest everywhere); only targets that every sampler of the table reaches or extrapolates to."""
    logs: dict[str, list[float]] = {}
    for tab in tables:
        for t in tab["targets"]:
            secs = {r["sampler"]: r[t]["cpu_seconds"] for r in tab["rows"]}
            if len(secs) < 2 or any(v is None or v <= 0 for v in secs.values()):
                continue
            lo = min(secs.values())
            for s, v in secs.items():
                logs.setdefault(s, []).append(math.log(v / lo))
    return {s: math.exp(statistics.fmean(v)) for s, v in logs.items() if v}


def resolution_checks(rows: list[dict], sweep: list[dict], fits: dict, study_grid: dict) -> list[dict]:
    """noise_rel at a higher resolution against the study's run at the same settings and requested spp
    (noise_factor), per sampler."""
    checks = []
    for c in (r for r in rows if r["role"] == "check"):
        twin = next((r for r in sweep if series_key(r) == series_key(c) and r["spp_requested"] == c["spp_requested"]),
                    None)
        w, h = (int(v) for v in c["grid_px"].split("x"))
        fit = fits.get(series_key(c), {}).get("band", {})
        checks.append({"scene": c["scene"], "path": c["path"], "sampler": c["sampler"],
                       "bands_per_render": c["bands_per_render"], "spp": c["spp"], "groups": c["groups"],
                       "sensor_px": c["sensor_px"], "grid_px": [w, h],
                       "noise_rel": c["noise_rel"], "seconds": c["seconds"],
                       "seconds_pred": seconds_for(fit, c["spp"], w * h / _px(study_grid[c["scene"]])),
                       "study_noise_rel": twin["noise_rel"] if twin else None,
                       "noise_factor": (c["noise_rel"] / twin["noise_rel"])
                       if twin and twin["noise_rel"] and c["noise_rel"] else None})
    return checks


def monitor_full(rows: list[dict], sweep: list[dict]) -> dict | None:
    """The monitor's full-frame runs: per sampler the fits and the time to MONITOR_TARGETS (against the
    analytic image at that size), the analytic render's own time there, and per run the ratio of its
    error to the study-size run's at the same sampler and requested spp."""
    full = [r for r in rows if r["role"] == "full"]
    if not full:
        return None
    series: dict = {}
    for r in full:
        series.setdefault(series_key(r), []).append(r)
        twin = next((s for s in sweep if series_key(s) == series_key(r) and s["spp_requested"] == r["spp_requested"]),
                    None)
        r["error_full_over_study"] = (r["rel_error_net"] / twin["rel_error_net"]
                                      if twin and twin["rel_error_net"] else None)
    fits = {k: fit_line(k, rs, 1.0, MONITOR_TARGETS) for k, rs in series.items()}
    ref = next((r for r in rows if r["role"] == "reference" and r["path"] == "analytic"
                and r["sensor_px"] == f"{FULL_SENSOR[0]}x{FULL_SENSOR[1]}"), None)
    return {"fits": fits, "table": sampler_table(fits, "monitor", "rgb_matrix", "", "band", MONITOR_TARGETS),
            "analytic_seconds": ref["seconds"] if ref else None, "sensor_px": list(FULL_SENSOR[:2]),
            "ratios": [{"sampler": r["sampler"], "spp": r["spp"], "error_full_over_study": r["error_full_over_study"]}
                       for r in full]}


def honesty(rows: list[dict]) -> list[dict]:
    """err_over_noise (true error / the run's own pass estimate) per scene, path and sampler: min, median, max."""
    groups: dict = {}
    for r in rows:
        if r["role"] in ("sweep", "full", "exact_check") and r.get("err_over_noise") is not None:
            size = "full" if r["role"] == "full" else ("check" if r["role"] == "exact_check" else "study")
            groups.setdefault((r["scene"], r["path"], r["sampler"], size), []).append(r["err_over_noise"])
    return [{"scene": k[0], "path": k[1], "sampler": k[2], "size": k[3], "n": len(v), "min": min(v),
             "median": statistics.median(v), "max": max(v)} for k, v in groups.items()]


def _cost(fit: dict, c: str, b: str = "b") -> float | None:
    """Time per unit 1/error²: b · c² (asymptotic, set-up excluded)."""
    return fit["band"][b] * fit[c]["c"] ** 2 if fit["band"].get(b) and fit[c].get("c") else None


def _ratio(x, y):
    return x / y if x is not None and y else None


RGB_INDEPENDENT = ("monitor", "rgb_matrix", "", "independent")


def spectral_vs_rgb(fits: dict, series: dict, rgb: dict) -> list[dict]:
    """Per monitor spectral line (independent sampler): run time per spp and at equal error relative to
    rgb_matrix with the same sampler."""
    ratios = []
    for key, f in fits.items():
        if key[0] == "monitor" and key[1] == "spectral" and f["band"].get("c") and f["band"].get("b"):
            top = max(series[key], key=lambda r: r["spp"])
            same = next((r for r in series[RGB_INDEPENDENT] if r["spp"] == top["spp"]), None)
            ratios.append({
                "bands_per_render": key[2], "sampler": key[3],
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
    """Per room bands_per_render line (independent sampler): samples (renders × c²) and CPU time (b_cpu · c²)
    for unit 1/error², per band and on XYZ, absolute and relative to the cheapest line."""
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
            e[f"time_{m}_rel"] = e[f"time_{m}"] / lo_t if lo_t else None
    return table


def _predict(e: dict, spp: int, fct: float, rs_full: float) -> dict:
    """Errors c · fct / sqrt(spp) and seconds renders · spp · rs_full of a cost-table line at the full sensor."""
    return {"spp": spp, "band_error": e["c"] * fct / math.sqrt(spp),
            "xyz_error": e["c_xyz"] * fct / math.sqrt(spp), "seconds_full": e["groups"] * spp * rs_full}


def recommend_room(room: dict, chk: dict | None, full_grid: dict, scale: float, default) -> dict:
    """bands_per_render (cheapest on XYZ) and spp (5 % on XYZ at the full sensor) for the room with the
    independent sampler (1/sqrt(spp) holds), with the scene file's `default` render settings and the
    per-band optimum predicted alongside."""
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


def room_with_sampler(line: dict, chk: dict | None, room: dict, default) -> dict:
    """The room's errors at the recommended spp and the scene file's spp with the recommended sampler (its
    line at the scene's bands_per_render: slope −1/2 there, so c / sqrt(spp) holds; its own resolution
    check's noise factor), and the spp it needs for 5 % and 2 % on XYZ at the full sensor."""
    fct = chk["noise_factor"] if chk else 1.0
    e = {"c": line["band"]["c"], "c_xyz": line["xyz"]["c"], "groups": line["groups"]}
    rs_full = room["render_spp_full_s"]
    out = {"sampler": line["sampler"], "noise_factor_full": chk["noise_factor"] if chk else None,
           "slope": line["band"].get("slope"), "slope_xyz": line["xyz"].get("slope"),
           "at_recommended_spp": _predict(e, room["recommended_spp"], fct, rs_full)}
    if default.spp:
        out["at_scene_spp"] = _predict(e, default.spp, fct, rs_full)
    for t in (0.05, 0.02):
        out[f"xyz_{_tk(t)}"] = _predict(e, _pow2_at_least((e["c_xyz"] * fct / t) ** 2), fct, rs_full)
    return out


def recommend_sampler(tables: dict) -> dict:
    """The default sampler of the Monte Carlo paths: the smallest geometric-mean time ratio to the fastest
    over the room's tables (per band and XYZ: 3D scenes are what Monte Carlo is for; the monitor's default is
    the analytic path), the monitor rgb_matrix table's own ranking alongside."""
    room = [tables[k] for k in ("room_band", "room_xyz") if k in tables]
    mon = [tables[k] for k in ("monitor_full",) if k in tables] or [tables[k] for k in ("monitor",) if k in tables]
    out = {"score_room": sampler_score(room), "score_monitor": sampler_score(mon),
           "score_all": sampler_score(room + mon)}
    for k in ("room", "monitor", "all"):
        sc = out[f"score_{k}"]
        out[f"best_{k}"] = min(sc, key=sc.get) if sc else None
    out["recommended"] = out["best_room"] or out["best_all"]
    return out


def analyse(rows: list[dict], scenes: dict[str, Scene]) -> dict:
    """The fits of every sweep line, the sampler tables, the resolution checks and the recommendations
    (keys: fits by series label, samplers, checks, honesty, recommend, full_grid_px, study_grid_px)."""
    sweep = [r for r in rows if r["role"] == "sweep"]
    series: dict = {}
    for r in sweep:
        series.setdefault(series_key(r), []).append(r)
    full_grid = {name: grid_px(replace(s, sensor=Sensor(*FULL_SENSOR))) for name, s in scenes.items()}
    study_grid = {name: grid_px(s) for name, s in scenes.items()}
    scale = {name: _px(full_grid[name]) / _px(study_grid[name]) for name in scenes}
    mon_targets = tuple(sorted(set(TARGETS) | set(MONITOR_TARGETS), reverse=True))
    fits = {key: fit_line(key, rs, scale[key[0]], mon_targets if key[0] == "monitor" else TARGETS)
            for key, rs in series.items()}
    checks = resolution_checks(rows, sweep, fits, study_grid)

    def check(scene, sampler="independent"):
        return next((c for c in checks if c["scene"] == scene and c["sampler"] == sampler and c["noise_factor"]), None)

    bpr0 = scenes["room"].render.bands_per_render
    tables = {"monitor": sampler_table(fits, "monitor", "rgb_matrix", "", "band", mon_targets),
              "room_band": sampler_table(fits, "room", "spectral", bpr0, "band", TARGETS),
              "room_xyz": sampler_table(fits, "room", "spectral", bpr0, "xyz", TARGETS)}
    full = monitor_full(rows, sweep)
    if full:
        tables["monitor_full"] = full["table"]
    rec: dict = {"sampler": recommend_sampler(tables)}
    if full:
        rec["monitor_exact"] = {k: v for k, v in full.items() if k != "fits"} | {"full_frame": True}
    else:  # the study's size
        ref = next((r for r in rows
                    if r["role"] == "reference" and r["scene"] == "monitor" and r["path"] == "analytic"), None)
        rec["monitor_exact"] = {"table": tables["monitor"], "analytic_seconds": ref["seconds"] if ref else None,
                                "sensor_px": [int(v) for v in ref["sensor_px"].split("x")] if ref else None,
                                "full_frame": False}
    rgb = fits.get(RGB_INDEPENDENT)
    if rgb and rgb["band"].get("c") and rgb["band"].get("b") is not None:
        rec["monitor_spectral_vs_rgb"] = spectral_vs_rgb(fits, series, rgb)
    room = {key: f for key, f in fits.items() if key[0] == "room" and key[3] == "independent"
            and f["band"].get("c") and f["xyz"].get("c")}
    if room:
        rec["room"] = recommend_room(room, check("room"), full_grid, scale["room"], scenes["room"].render)
        smp = rec["sampler"]["recommended"]
        line = fits.get(("room", "spectral", bpr0, smp))
        if smp and line and line["band"].get("c") and line["xyz"].get("c"):
            rec["room"]["with_sampler"] = room_with_sampler(line, check("room", smp), rec["room"],
                                                           scenes["room"].render)
    return {"fits": {series_label(k): v for k, v in fits.items()},
            "full_fits": {series_label(k): v for k, v in full["fits"].items()} if full else {},
            "samplers": tables, "checks": checks, "honesty": honesty(rows), "recommend": rec,
            "full_grid_px": full_grid, "study_grid_px": study_grid}
