"""The PSF study's outputs: study_psf.csv, study_psf.md (one section per knob: how it was measured,
its table, the cheapest setting within tolerance) and study_psf.png (error vs time per knob)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from udc_render.studies.psf_config import BANDS_NM, COLUMNS, KNOB_TITLES, PIXEL_UM, TOLERANCE_L1, WAVELENGTHS_NM, Config
from udc_render.studies.report import (
    annotated_loglog,
    finish_axes,
    machine_text,
    md_table,
    pyplot,
    save_plot,
    write_tables,
)

BASE_COLS = [("value", "value"), ("error_L1", "error_L1 (Σ|Δk|)"), ("error_max_rel", "error_max_rel"),
             ("energy_outside", "energy_outside"), ("time_s", "time_s"), ("time_min_s", "time_min_s"),
             ("is_default", "default"), ("warning", "warning")]


def write_report(out_dir: Path, rows: list[dict], meta: dict) -> None:
    """study_psf.csv, study_psf.md and study_psf.png in out_dir."""
    write_tables(out_dir, "study_psf", rows, COLUMNS, markdown(rows, meta))
    plot(rows, out_dir / "study_psf.png", meta["cfg"])


# ----------------------------------------------------------------------------------------------
# Markdown


def short_warning(text: str) -> str:
    """The warning categories of a ' | '-joined warning text, each once."""
    if not text:
        return ""
    return ", ".join(dict.fromkeys(part.split(":")[0].strip() for part in text.split(" | ")))


def _table(rows: list[dict], cols: list[tuple[str, str]]) -> list[str]:
    return md_table(rows, cols, {"warning": short_warning})


def fmt_value(value) -> str:
    """A knob value for labels: floats to 3 significant figures, anything else as it is."""
    return f"{value:.3g}" if isinstance(value, float) else str(value)


def recommend(rows: list[dict], tol: float = TOLERANCE_L1, key: str = "error_L1") -> str:
    """Per (display, series): the fastest setting with rows[key] ≤ tol."""
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["display"], r["series"]), []).append(r)
    parts = []
    for (d, s), rs in groups.items():
        ok = [r for r in rs if r.get(key) is not None and r[key] <= tol]
        if ok:
            best = min(ok, key=lambda r: r["time_s"])
            parts.append(f"{d}/{s}: {fmt_value(best['value'])} ({key} {best[key]:.2g}, {best['time_s']:.2g} s)")
        else:
            parts.append(f"{d}/{s}: none within {tol:g}")
    return f"Cheapest setting with {key} ≤ {tol:g}: " + "; ".join(parts) + "."


def _ref_line(meta, key, what: str) -> str:
    info = meta["refs"][key]
    eo = ", ".join(f"{v:.3g}" for v in np.atleast_1d(info["energy_outside"]))
    w = f"; warning: {info['warning']}" if info["warning"] else ""
    return (f"Reference: {what} (pupil {info['params']['pupil_shape'][1]}² samples across the window crop, "
            f"single run {info['time_s']:.1f} s, its energy_outside {eo}{w}).")


def _header(meta: dict) -> list[str]:
    cfg: Config = meta["cfg"]
    la, lb = meta["load_start"], meta["load_end"]
    return [
        "# PSF approximation knobs: error versus run time",
        "",
        f"{'QUICK smoke-test grid (not for decisions). ' if cfg.quick else ''}{machine_text(meta['elapsed_s'])}"
        f"; load average {la[0]:.1f} at start, {lb[0]:.1f} at end (the machine is shared: timings are noisy)."
        if la else f"Total study time {meta['elapsed_s']:.0f} s.",
        "",
        f"Rig defaults: Lens() (f = 6 mm, D = 3.333 mm), {PIXEL_UM} µm pixels, T-OLED toled() "
        f"(P-OLED poled() for the pupil knob), d = 0 unless stated. time_s = median of {cfg.repeats} "
        f"run(s) (time.perf_counter, whole compute_kernels / band_kernels call, scipy.fft on all cores); "
        f"time_min_s = fastest.",
        "",
        "Metrics: **error_L1 = Σ|k − k_ref| over the unit-sum kernels** (each kernel sums to 1 inside its "
        "window), maximum over the wavelengths (or bands) of the run; error_max_rel = max|k − k_ref| / "
        "max k_ref, maximum over wavelengths; energy_outside = the engine's fraction of the transmitted "
        "power outside the window (maximum over wavelengths). **default** marks the engine's current "
        "default. Warnings are recorded, not printed (full text in study_psf.csv).",
        "",
    ]


def _pupil_section(rows: list[dict], meta: dict, cfg: Config) -> list[str]:
    lines = [f"## {KNOB_TITLES['pupil_samples']}", "",
             f"Wavelengths {', '.join(f'{w:g}' for w in WAVELENGTHS_NM)} nm, S = {cfg.size_px}, mft, float32. "
             + _ref_line(meta, ("pupil", "toled"), f"N = {cfg.pupil_ref_n}, band_limited, mft, float64 "
                         f"(T-OLED)") + " P-OLED: " + _ref_line(meta, ("pupil", "poled"), "same settings")
             + f" The engine's auto N for this rig is {meta['auto_n']} (the display grid then equals "
             f"N = {cfg.default_n}'s: same samples per period). pupil_shape = samples over the aperture crop.",
             ""]
    lines += _table(rows, [("display", "display"), ("series", "mask_raster")] + BASE_COLS
                    + [("pupil_shape", "pupil_shape")])
    return lines + ["", recommend(rows), ""]


def _method_section(rows: list[dict], meta: dict, cfg: Config) -> list[str]:
    lines = [f"## {KNOB_TITLES['method']}", "",
             "T-OLED, band_limited, float32, S = {0}. Same reference as knob 1 (N = {1} mft float64); the mft "
             "rows are the very runs of knob 1 (same call, measured once). "
             "'paper' = the paper's recipe as printed, psf.paper.paper_kernel (2× zero-padded FFT of the "
             "pupil, |·|², cubic down-sampling by the printed r: the pattern sampled at 0.90 ρ, so its error "
             "is mostly that scale). L1_same_N_ref (paper only): against the float64 MFT "
             "at the same N, i.e. the recipe's own error with the pupil sampling error taken out."
             .format(cfg.size_px, cfg.pupil_ref_n), ""]
    lines += _table(rows, [("series", "method"), ("value", "N")] + BASE_COLS[1:3]
                    + [("L1_same_N_ref", "L1_same_N_ref")] + BASE_COLS[3:])
    return lines + ["", recommend(rows), ""]


def _precision_section(rows: list[dict], meta: dict, cfg: Config) -> list[str]:
    lines = [f"## {KNOB_TITLES['precision']}", "",
             f"T-OLED, auto N ({meta['auto_n']}), band_limited, mft, S = {cfg.size_px}. Same reference as "
             "knob 1 (so error_L1 is dominated by the pupil sampling). L1_same_N_ref (float32 row): against "
             "the float64 run at the same N, i.e. the precision error alone.", ""]
    lines += _table(rows, BASE_COLS[:3] + [("L1_same_N_ref", "L1_same_N_ref")] + BASE_COLS[3:]
                    + [("pupil_shape", "pupil_shape")])
    return lines + [""]


def _band_section(rows: list[dict], meta: dict, cfg: Config) -> list[str]:
    lines = [f"## {KNOB_TITLES['band_step_nm']}", "",
             f"Bands {', '.join(f'{lo:g}-{hi:g}' for lo, hi in BANDS_NM)} nm, flat weight; "
             f"**S = {cfg.band_size} and N = {cfg.band_n or 'auto'} for every run and the reference** "
             "(float32), so only the wavelength sampling differs. "
             + _ref_line(meta, ("band", "toled"), f"step {cfg.band_ref_step:g} nm "
                         f"({int(100 / cfg.band_ref_step)} samples per band), same S, N, float32")
             + " error_L1 is the worst of the three bands. The default row is the engine's auto step "
             "λ_lo / S per band (shown: the first band's); the needed step shrinks as S grows.", ""]
    lines += _table(rows, [("value", "step_nm"), ("samples_per_band", "samples/band")] + BASE_COLS[1:])
    return lines + ["", recommend(rows), ""]


def _field_section(rows: list[dict], meta: dict, cfg: Config) -> list[str]:
    lines = [f"## {KNOB_TITLES['field_phases']}", "",
             f"T-OLED, λ = {cfg.field_wavelength_nm:g} nm, d = {cfg.field_distance_mm:g} mm, N = {cfg.field_n}, "
             f"S = {cfg.field_size}, float32. "
             + _ref_line(meta, ("field", "toled"), f"P = {cfg.field_ref_p} (same λ, d, N, S, float32)")
             + f" Reference banding amplitude max|field_power − 1| = {meta['banding_ref']:.3g}. "
             "error_L1 compares the phase-averaged (power-weighted) `kernels`. "
             f"field_kernel_L1_interp: max over the reference's {cfg.field_ref_p}² phases of Σ|k_field − "
             "k_field,ref| when the P-phase field kernels are interpolated periodically-bilinearly to the "
             "reference's shifts (what a renderer holding P phases would use between them). "
             "banding_err_interp: the same for field_power (max abs). banding_err_matched: max "
             "|field_power − reference| at the reference's coinciding phases (P dividing "
             f"{cfg.field_ref_p}; identical kernels there, differences only from the mean normalisation).",
             ""]
    lines += _table(rows, [("value", "P")] + BASE_COLS[1:3] + [
        ("field_kernel_L1_interp", "field_kernel_L1_interp"), ("banding_err_interp", "banding_err_interp"),
        ("banding_err_matched", "banding_err_matched")] + BASE_COLS[3:])
    return lines + ["", recommend(rows), ""]


def _size_section(rows: list[dict], meta: dict, cfg: Config) -> list[str]:
    size_n = "auto N (the engine default: N grows with S to stay alias-free)" if cfg.size_n is None else \
        f"N = {cfg.size_n}"
    lines = [f"## {KNOB_TITLES['size_px']}", "",
             f"T-OLED, {', '.join(f'{w:g}' for w in WAVELENGTHS_NM)} nm, {size_n}, float32. "
             + _ref_line(meta, ("size", "toled"), f"S = {cfg.size_ref}, {size_n}, float32")
             + " **The window's error is energy_outside** (the power the S² kernel loses; the renderer "
             "renormalises it into the window). error_L1: the S kernel against the reference's S² centre "
             "crop renormalised to unit sum (values inside the window do not depend on S, so this measures "
             "only the different auto N). L1_vs_full_ref: the S kernel zero-padded to "
             f"{cfg.size_ref}² against the unit-sum reference (≈ 2 × the power between the windows). "
             "energy_outside_check = 1 − (1 − e_ref) · Σ(reference crop): should equal energy_outside.",
             ""]
    lines += _table(rows, [("value", "S")] + BASE_COLS[1:3] + [
        ("L1_vs_full_ref", "L1_vs_full_ref"), ("energy_outside", "energy_outside"),
        ("energy_outside_check", "energy_outside_check"), ("time_s", "time_s"), ("time_min_s", "time_min_s"),
        ("is_default", "default"), ("pupil_samples_used", "N used"), ("warning", "warning")])
    return lines + ["", recommend(rows, key="energy_outside", tol=0.05), ""]


SECTIONS = {"pupil_samples": _pupil_section, "method": _method_section, "precision": _precision_section,
            "band_step_nm": _band_section, "field_phases": _field_section, "size_px": _size_section}


def markdown(rows: list[dict], meta: dict) -> str:
    """study_psf.md: the header (machine, rig, metrics), then one section per knob in KNOB_TITLES order."""
    lines = _header(meta)
    for knob, section in SECTIONS.items():
        lines += section([r for r in rows if r["knob"] == knob], meta, meta["cfg"])
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------------
# Plot


def _series(knob: str, rs: list[dict], cfg: Config) -> dict:
    """label → [(row, error)] of one knob's panel."""
    series: dict = {}
    for r in rs:
        if knob == "field_phases":
            series.setdefault("averaged kernel L1", []).append((r, r["error_L1"]))
            series.setdefault("field kernel L1 (interp.)", []).append((r, r.get("field_kernel_L1_interp")))
            series.setdefault("banding abs err (interp.)", []).append((r, r.get("banding_err_interp")))
        elif knob == "size_px":
            series.setdefault("energy_outside", []).append((r, r["energy_outside"]))
            series.setdefault("L1 vs full reference", []).append((r, r.get("L1_vs_full_ref")))
            series.setdefault("L1 vs renormalised crop", []).append((r, r["error_L1"]))
        elif knob == "precision":
            series.setdefault("vs N=%d float64 reference" % cfg.pupil_ref_n, []).append((r, r["error_L1"]))
            if r.get("L1_same_N_ref") is not None:
                series.setdefault("float32 vs float64 at the same N", []).append((r, r["L1_same_N_ref"]))
        else:
            label = r["series"] if knob != "pupil_samples" else f"{r['display']} {r['series']}"
            series.setdefault(label, []).append((r, r["error_L1"]))
    return series


def _panel(ax, knob: str, series: dict, floor: float = 1e-12) -> None:
    """The knob's lines (errors clipped below at `floor`), the engine default ringed in red."""
    default_done = False
    for label, pts in series.items():
        pts = [(r, e) for r, e in pts if e is not None]
        if not pts:
            continue
        t = [r["time_s"] for r, _ in pts]
        e = [max(e, floor) for _, e in pts]
        annotated_loglog(ax, t, e, [fmt_value(r["value"]) for r, _ in pts], label, lw=1)
        for (r, _), ti, ei in zip(pts, t, e):
            if r["is_default"]:
                ax.scatter([ti], [ei], s=160, facecolors="none", edgecolors="red", linewidths=2, zorder=5,
                           label=None if default_done else "default")
                default_done = True
    ax.axhline(TOLERANCE_L1, color="grey", ls=":", lw=0.8)
    lo, hi = ax.get_xlim()
    if hi / lo < 4:  # a narrow time range: widen it so the log axis keeps readable major ticks
        mid = math.sqrt(lo * hi)
        ax.set_xlim(mid / 2.5, mid * 2.5)
    finish_axes(ax, KNOB_TITLES[knob], "run time (s, median)",
                "energy lost / L1" if knob == "size_px" else "error (L1 = Σ|k − k_ref|)")


def plot(rows: list[dict], path: Path, cfg: Config) -> None:
    """study_psf.png: one log-log error-versus-time panel per knob (dotted: L1 = TOLERANCE_L1)."""
    plt = pyplot()
    fig, axes = plt.subplots(2, 3, figsize=(17, 10.5))
    for ax, knob in zip(axes.ravel(), KNOB_TITLES):
        _panel(ax, knob, _series(knob, [r for r in rows if r["knob"] == knob], cfg))
    fig.suptitle(("QUICK grid — " if cfg.quick else "") + "PSF knobs: error vs run time (dotted: L1 = 1e-3; "
                 "red ring: engine default)", fontsize=12)
    fig.tight_layout()
    save_plot(fig, path, tight_bbox=False)
