"""The defocus study's outputs: study_defocus.csv, study_defocus.md (checks, depth of field, blur against
distance, what the display changes), study_defocus.png (blur and MTF against object vergence, DoF bars),
study_defocus_psf.png (through-focus PSFs, log scale) and study_defocus_mtf.png (MTF curves)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from udc_render.studies import defocus_measures as D
from udc_render.studies.report import machine_text, md_table, pyplot, save_plot, write_tables

NAMES = {"glass": "glass", "toled": "T-OLED", "poled": "P-OLED", "toled_gap": f"T-OLED d={D.D_GAP_MM:g} mm"}
STYLES = {"toled_gap": "--"}  # the T-OLED at d > 0 lies on its d = 0 line: dashed over it
COLOURS = {"glass": "tab:blue", "toled": "tab:orange", "poled": "tab:green", "toled_gap": "tab:red"}
DISTANCE_TICKS_MM = (math.inf, 1000.0, 600.0, 500.0, 450.0, 300.0, 100.0)
SYMLOG_LINTHRESH = 0.1  # m⁻¹: the defocus axis is linear within ±0.1 of focus, logarithmic beyond


def write_report(out: Path, result: dict, panels: dict) -> None:
    """All the study's files in out."""
    write_tables(out, "study_defocus", result["rows"], D.COLUMNS, markdown(result))
    plot_summary(result, out / "study_defocus.png")
    plot_psfs(panels, result["meta"]["cfg"], out / "study_defocus_psf.png")
    plot_mtfs(panels, result["meta"]["cfg"], out / "study_defocus_mtf.png")


def middle_wavelength(cfg: D.Config) -> float:
    """The wavelength the tables and plots show (the middle one of the sweep)."""
    return cfg.wavelengths_nm[len(cfg.wavelengths_nm) // 2]


def mm(v) -> str:
    """A distance in mm as metres (3 significant figures), ∞ for infinity, '—' for nan."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    return "∞" if math.isinf(v) else f"{v / 1000:.3g} m"


# ----------------------------------------------------------------------------------------------
# Markdown


def check_lines(checks: list[dict]) -> list[str]:
    rows = []
    for c in checks:
        if "worst_ratio" in c:
            z, wl, b = c["worst_at"] or (math.nan, math.nan, math.nan)
            got = (f"{c['points']} points (b = {c['b_range_px'][0]:.0f}–{c['b_range_px'][1]:.0f} px, every λ), "
                   f"ratios {min(c['ratios']):.3f}–{max(c['ratios']):.3f}; worst {c['worst_ratio']:.3f} at "
                   f"z = {mm(z)}, {wl:g} nm, b = {b:.1f} px")
        else:
            per_wl = ", ".join(f"{v:.4f}" for v in c["max_diff_per_wl"])
            got = (f"max diff {c['max_diff']:.4f} (per λ: {per_wl}); N_w = z_i/D = {c['f_number_working']:.3f}; "
                   f"unfolded k = 0 term alone: {c['max_diff_unfolded']:.3f}")
        rows.append({"name": c["name"], "criterion": c["criterion"], "got": got,
                     "verdict": "**pass**" if c["passed"] else "**FAIL**"})
    return md_table(rows, [("name", "check"), ("criterion", "criterion"), ("got", "measured"),
                           ("verdict", "verdict")])


def dof_lines(dof: list[dict]) -> list[str]:
    cols = [("display", "display"), ("wavelength_nm", "λ (nm)"), ("mtf_ref_focus", "ref. MTF in focus"),
            ("rel", "relative DoF (far – near)"), ("rel_width_per_m", "rel. width (m⁻¹)"),
            ("abs", "absolute DoF (far – near)"), ("abs_width_per_m", "abs. width (m⁻¹)"),
            ("geom", f"geometric, b ≤ {D.COC_GEOM_PX:g} px"), ("geom_width_per_m", "geom. width (m⁻¹)")]
    rows = [dict(r, display=NAMES[r["display"]], rel=f"{mm(r['rel_far_mm'])} – {mm(r['rel_near_mm'])}",
                 abs=f"{mm(r['abs_far_mm'])} – {mm(r['abs_near_mm'])}" if not math.isnan(r["abs_width_per_m"])
                 else "none (below at focus)", geom=f"{mm(r['geom_far_mm'])} – {mm(r['geom_near_mm'])}")
            for r in dof]
    return md_table(rows, cols)


def blur_lines(rows: list[dict], wl: float, displays: tuple) -> list[str]:
    """One line per object distance at wavelength wl: geometric b, and per display w, b', MTF(f_ref), MTF50."""
    table = []
    for v in sorted({r["vergence_per_m"] for r in rows}):
        line = {}
        for disp in displays:
            r = D.row_at(rows, disp, wl, v)
            line.update({"z": mm(r["object_distance_mm"]), "b": r["coc_geom_px"], "wd": r["disc_width_geom_px"],
                         f"{disp}_w": r["esf_width_px"], f"{disp}_eq": r["disc_equiv_px"],
                         f"{disp}_m": r["mtf_ref"], f"{disp}_m50": r["mtf50_cpp"]})
        table.append(line)
    cols = [("z", "z"), ("b", "b geom (px)"), ("wd", "w disc(b) (px)")]
    for disp in displays:
        n = NAMES[disp]
        cols += [(f"{disp}_w", f"{n} w"), (f"{disp}_eq", f"{n} b'"), (f"{disp}_m", f"{n} ref. MTF"),
                 (f"{disp}_m50", f"{n} MTF50")]
    return md_table(table, cols)


def display_effect_lines(result: dict, wl: float) -> list[str]:
    """What the display changes, in the run's own numbers at wavelength wl."""
    rows, dof = result["rows"], {r["display"]: r for r in result["dof"] if r["wavelength_nm"] == wl}
    v_f = D.focus_vergence_per_m()
    g = D.row_at(rows, "glass", wl, v_f)
    out = []
    for disp in result["meta"]["cfg"].displays[1:]:
        r, d = D.row_at(rows, disp, wl, v_f), dof[disp]
        absolute = (f"absolute DoF {d['abs_width_per_m']:.3g} m⁻¹ against the glass's "
                    f"{dof['glass']['abs_width_per_m']:.3g} m⁻¹" if not math.isnan(d["abs_width_per_m"])
                    else f"no absolute DoF (its in-focus reference MTF is below {D.ABS_MTF:g})")
        out.append(f"- {NAMES[disp]} at {wl:g} nm: in-focus reference MTF {r['mtf_ref']:.3f} against the "
                   f"glass's {g['mtf_ref']:.3f} ({r['mtf_ref'] / g['mtf_ref']:.0%}, beside the display's transmittance "
                   f"τ = {r['transmittance']:.0%}; at {D.F_REF_CPP:g} cycles/px along x "
                   f"{r['mtf_ref_x']:.3f}, along y {r['mtf_ref_y']:.3f}, glass {g['mtf_ref_x']:.3f}); in-focus edge "
                   f"width {r['esf_width_px']:.3g} px against "
                   f"{g['esf_width_px']:.3g} px; relative DoF {d['rel_width_per_m']:.3g} m⁻¹ against the glass's "
                   f"{dof['glass']['rel_width_per_m']:.3g} m⁻¹ "
                   f"({d['rel_width_per_m'] / dof['glass']['rel_width_per_m']:.2f}×); "
                   f"{absolute}; energy outside the {result['meta']['cfg'].size_px}-px window "
                   f"{r['energy_outside']:.1%}.")
    return out


def markdown(result: dict) -> str:
    cfg, meta = result["meta"]["cfg"], result["meta"]
    lens, wl = meta["lens"], middle_wavelength(cfg)
    load = meta.get("load_start")
    gap = (f" (and the T-OLED at d = {D.D_GAP_MM:g} mm: the engine's kernels averaged over its field phases)"
           if "toled_gap" in cfg.displays else "")
    lines = [
        "# Defocus study: through-focus PSF, blur and depth of field with and without a display", "",
        f"`udc-render study defocus{' --quick' if cfg.quick else ''}` (udc_render/studies/defocus.py). "
        f"{machine_text(meta['measure_s'])} (kernels and measures)"
        f"{'' if load is None else f', load {load[0]:.2f} at the start'}.",
        "",
        f"Rig: f = {lens.focal_length_um / 1000:g} mm, D = {lens.aperture_um:g} µm "
        f"(f/{lens.focal_length_um / lens.aperture_um:.2g}), "
        f"{D.PIXEL_UM} µm pixels, display at d = 0{gap}, focus z_f = {mm(lens.focus_distance_mm)} (sensor at z_i = "
        f"{lens.image_distance_um:.1f} µm, working f-number N_w = z_i/D = "
        f"{lens.image_distance_um / lens.aperture_um:.3f}); "
        f"{cfg.size_px}² kernels, pupil samples {cfg.pupil_samples or 'auto'}, wavelengths "
        f"{', '.join(f'{w:g}' for w in cfg.wavelengths_nm)} nm (monochromatic); {len(cfg.vergences_per_m)} object "
        f"distances from {mm(D.object_distance_mm(max(cfg.vergences_per_m)))} to "
        f"{mm(D.object_distance_mm(min(cfg.vergences_per_m)))}, swept in vergence v = 1/z (m⁻¹).", "",
        "Measures: w = 10–90 % edge-spread width (px; the LSF's running sum at the pixel edges, mean of x and y); "
        "b' = the diameter of the uniform disc whose pixel-integrated edge has the same w (0 below a point's "
        "0.8 px); reference MTF = the mean of the sampled kernel's 2-D |DFT| over "
        f"{D.F_REF_CPP - D.F_BAND_CPP:g} ≤ |f| < {D.F_REF_CPP + D.F_BAND_CPP:g} cycles/px, all orientations "
        "(a display's MTF is a comb whose period, p·pixel/(λ z_i) cycles/px, is the reciprocal of the orders' "
        "spacing: P-OLED 0.031, T-OLED 0.16 at 520 nm, so a point value depends on where f falls between its "
        "teeth; the x and y values at "
        f"{D.F_REF_CPP:g} cycles/px are in the CSV); MTF50 = lowest frequency where the orientation-averaged MTF "
        "(annuli of 0.01 cycles/px) is 0.5. "
        "Geometric blur b = D·z_i·|1/z_f − 1/z| (thin lens), w disc(b) = the w of that disc convolved with "
        "the pixel.",
        "",
        f"Depth of field (vergence range around the focus, crossings interpolated linearly in v): relative, "
        f"reference MTF ≥ {D.REL_LEVEL:g} × the same display's in-focus value; absolute, reference MTF ≥ "
        f"{D.ABS_MTF:g} whatever the display; geometric, b ≤ {D.COC_GEOM_PX:g} px. The paraxial defocus phase "
        "makes the blur symmetric in 1/z − 1/z_f (equal on both sides in vergence, not in metres).", "",
        "## Checks", "", *check_lines(result["checks"]), "",
        "## Depth of field", "", *dof_lines(result["dof"]), "",
        "## What the display changes", "", *display_effect_lines(result, wl), "",
        "The display's diffraction orders take energy from the core: the OTF is about the glass's OTF times the "
        "orders' interference factor, which does not depend on the defocus (at d = 0 the mask and the defocus "
        "phase multiply in the same pupil), so the MTF plateau drops, to about the zero order's share "
        "|⟨t⟩|²/⟨|t|²⟩ = τ for an open/opaque mask, while the through-focus shape of the core's MTF stays the "
        "glass's. The relative DoF is therefore close to the glass's; the absolute DoF shrinks, since a lower "
        "in-focus MTF reaches a fixed level sooner. The plateau counts only what falls inside the kernel window "
        "(kernels are unit sum inside it): a window that cuts off most orders (the quick run's P-OLED) shows a "
        "higher plateau. The 10–90 % edge width of a display kernel measures the orders' spread (tens of pixels) "
        "more than the defocus, so b' is a defocus measure for glass only; the MTF carries the defocus for all "
        "three.", "",
        f"## Blur against object distance ({wl:g} nm)", "", *blur_lines(result["rows"], wl, cfg.displays), "",
        "Files: study_defocus.csv (every display, wavelength and distance), study_defocus.png (blur and MTF "
        "against vergence, DoF bars), study_defocus_psf.png (through-focus PSFs, log scale), "
        "study_defocus_mtf.png (MTF curves).", ""]
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------------
# Plots


def _distance_axis(ax, v_f: float) -> None:
    """A top axis labelled with object distances at their defocus v − v_f (the bottom axis's scale)."""
    top = ax.twiny()
    top.set_xscale(ax.get_xscale(), **({"linthresh": SYMLOG_LINTHRESH} if ax.get_xscale() == "symlog" else {}))
    lo, hi = ax.get_xlim()
    ticks = [((0.0 if math.isinf(z) else 1000.0 / z) - v_f, "∞" if math.isinf(z) else f"{z / 1000:g} m")
             for z in DISTANCE_TICKS_MM]
    ticks = [(v, t) for v, t in ticks if lo <= v <= hi]
    top.set_xlim(lo, hi)
    top.set_xticks([v for v, _ in ticks], [t for _, t in ticks], fontsize=7)
    top.minorticks_off()


def plot_summary(result: dict, path: Path) -> None:
    """Blur (b') and MTF(f_ref) against vergence with the geometric b, and the DoF bars."""
    plt = pyplot()
    cfg, rows = result["meta"]["cfg"], result["rows"]
    wl, v_f = middle_wavelength(cfg), D.focus_vergence_per_m()
    fig, axes = plt.subplots(1, 3, figsize=(18, 4.8), gridspec_kw={"width_ratios": (1, 1, 1.1), "wspace": 0.45})
    for disp in cfg.displays:
        sel = sorted((r for r in rows if r["display"] == disp and r["wavelength_nm"] == wl),
                     key=lambda r: r["vergence_per_m"])
        dv = [r["defocus_per_m"] for r in sel]
        style = {"marker": "o", "ms": 3, "ls": STYLES.get(disp, "-"), "color": COLOURS[disp]}
        axes[0].plot(dv, [max(r["disc_equiv_px"], 0.1) for r in sel], label=f"{NAMES[disp]} b' (edge width)", **style)
        axes[1].plot(dv, [r["mtf_ref"] for r in sel], label=NAMES[disp], **style)
    vv = np.concatenate([np.linspace(min(cfg.vergences_per_m), v_f, 300),
                         np.linspace(v_f, max(cfg.vergences_per_m), 300)])
    b = [max(D.geometric_coc_px(D.lens_at(x)), 0.1) for x in vv]
    axes[0].plot(vv - v_f, b, "k--", lw=1, label="geometric b = D z_i |1/z_f − 1/z|")
    axes[0].set_yscale("log")
    axes[0].set_ylabel("blur diameter (px)")
    axes[0].set_title(f"Blur against defocus ({wl:g} nm)", fontsize=10)
    axes[1].axhline(D.ABS_MTF, color="k", ls=":", lw=1, label="absolute DoF threshold")
    axes[1].set_ylabel(f"MTF, mean over {D.F_REF_CPP - D.F_BAND_CPP:g}–{D.F_REF_CPP + D.F_BAND_CPP:g} cycles/px")
    axes[1].set_title("Through-focus MTF", fontsize=10)
    for ax in axes[:2]:
        ax.set_xscale("symlog", linthresh=SYMLOG_LINTHRESH)
        ax.axvline(0.0, color="grey", lw=0.8)
        ax.set_xlabel(f"defocus 1/z − 1/z_f (m⁻¹), symlog (linear within ±{SYMLOG_LINTHRESH:g})")
        ax.grid(True, which="both", alpha=0.25)
        _distance_axis(ax, v_f)
    axes[0].legend(fontsize=7, loc="lower center")
    axes[1].legend(fontsize=7, loc="upper right")
    plot_dof_bars(axes[2], [r for r in result["dof"] if r["wavelength_nm"] == wl], v_f)
    save_plot(fig, path)


def plot_dof_bars(ax, dof: list[dict], v_f: float) -> None:
    """Horizontal bars over vergence: each display's relative and absolute DoF, and the geometric one."""

    def inv(z):
        return 0.0 if math.isinf(z) else 1000.0 / z
    labels, y = [], 0
    for r in dof:
        for kind, hatch in (("rel", ""), ("abs", "//")):
            far, near = r[f"{kind}_far_mm"], r[f"{kind}_near_mm"]
            if not math.isnan(far):
                ax.barh(y, inv(near) - inv(far), left=inv(far), color=COLOURS[r["display"]], hatch=hatch,
                        alpha=0.8, edgecolor="k")
                ax.text(inv(near), y, f" {mm(far)}–{mm(near)}", va="center", fontsize=7)
            else:
                ax.text(v_f, y, "none", va="center", ha="center", fontsize=7)
            labels.append(f"{NAMES[r['display']]} {'relative' if kind == 'rel' else 'absolute'}")
            y += 1
    g = dof[0]
    ax.barh(y, inv(g["geom_near_mm"]) - inv(g["geom_far_mm"]), left=inv(g["geom_far_mm"]), color="lightgrey",
            edgecolor="k")
    labels.append(f"geometric (b ≤ {D.COC_GEOM_PX:g} px)")
    ax.set_yticks(range(len(labels)), labels, fontsize=8)
    ax.axvline(v_f, color="grey", lw=0.8)
    lo = min(inv(r["rel_far_mm"]) for r in dof if not math.isnan(r["rel_far_mm"]))
    hi = max(inv(r["rel_near_mm"]) for r in dof if not math.isnan(r["rel_near_mm"]))
    pad = hi - lo
    ax.set_xlim(lo - 0.3 * pad, hi + 0.8 * pad)
    ax.set_xlabel("object vergence 1/z (m⁻¹)")
    ax.set_title("Depth of field (reference MTF; geometric: b ≤ 2 px)", fontsize=10)
    ax.grid(True, axis="x", alpha=0.25)


def plot_psfs(panels: dict, cfg: D.Config, path: Path, crop_px: int = 191) -> None:
    """Rows: displays; columns: the panel vergences; log10 kernel at the middle wavelength."""
    plt = pyplot()
    wl = middle_wavelength(cfg)
    k_wl = cfg.wavelengths_nm.index(wl)
    vs = sorted(cfg.panel_vergences_per_m)
    n = len(cfg.displays)
    fig, axes = plt.subplots(n, len(vs), figsize=(2.3 * len(vs), 2.4 * n), squeeze=False)
    s = min(crop_px, cfg.size_px)
    half = s // 2 * D.PIXEL_UM
    for i, disp in enumerate(cfg.displays):
        for j, v in enumerate(vs):
            k = panels[(disp, v)].kernels[k_wl]
            lo = k.shape[-1] // 2 - s // 2
            img = np.log10(np.maximum(k[lo:lo + s, lo:lo + s], 1e-12))
            ax = axes[i, j]
            ax.imshow(img, extent=(-half, half, -half, half), vmin=-7, vmax=-0.5, cmap="inferno", origin="lower")
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(f"z = {mm(D.object_distance_mm(v))}", fontsize=9)
            if j == 0:
                ax.set_ylabel(NAMES[disp])
    fig.suptitle(f"Through-focus PSFs, log10 energy per pixel (−7 … −0.5), {wl:g} nm, focus "
                 f"{mm(D.FOCUS_MM)}, {s} px = {s * D.PIXEL_UM:.0f} µm shown", fontsize=10)
    save_plot(fig, path)


def plot_mtfs(panels: dict, cfg: D.Config, path: Path) -> None:
    """MTF along x, along y and averaged over orientations, per display at the panel vergences; the
    diffraction limit on glass."""
    plt = pyplot()
    wl = middle_wavelength(cfg)
    k_wl = cfg.wavelengths_nm.index(wl)
    vs = sorted(cfg.panel_vergences_per_m)
    cmap = plt.get_cmap("viridis")
    fig, axes = plt.subplots(3, len(cfg.displays), figsize=(5 * len(cfg.displays), 10), sharex=True, sharey=True,
                             squeeze=False)
    f_number = D.lens_at(D.focus_vergence_per_m()).image_distance_um / D.APERTURE_UM
    for j, disp in enumerate(cfg.displays):
        for i, axis in enumerate(("x", "y", "all orientations")):
            ax = axes[i, j]
            for n, v in enumerate(vs):
                k = panels[(disp, v)].kernels[k_wl]
                f, m = D.radial_mtf(k) if i == 2 else (D.FREQS_CPP, D.mtf_of_line(D.lsf(k, axis)))
                ax.plot(f, m, color=cmap(n / max(len(vs) - 1, 1)), lw=1.2, label=f"z = {mm(D.object_distance_mm(v))}")
            if disp == "glass" and i < 2:
                ax.plot(D.FREQS_CPP, np.abs(D.diffraction_limit(D.FREQS_CPP, wl, f_number)), "k--", lw=1,
                        label="diffraction limit × pixel (folded)")
            ax.axvspan(D.F_REF_CPP - D.F_BAND_CPP, D.F_REF_CPP + D.F_BAND_CPP, color="grey", alpha=0.1)
            ax.set_title(f"{NAMES[disp]}, MTF {'along ' + axis if i < 2 else axis} ({wl:g} nm)", fontsize=10)
            ax.grid(True, alpha=0.25)
            if i == 2:
                ax.set_xlabel("frequency (cycles/px)")
            if j == 0:
                ax.set_ylabel("MTF of the sampled kernel")
    axes[0, 0].legend(fontsize=7)
    save_plot(fig, path)
