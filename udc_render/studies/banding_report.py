"""study_banding.md and study_banding.png of the banding study (udc_render.studies.banding); `rig` is
its banding.Rig.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from psf.engine import DEFAULT_FIELD_PHASES
from udc_render.optics import displays as D
from udc_render.pipeline import SynthConfig
from udc_render.studies.banding_fit import DISPLAYS, HARMONICS, period_formula_um
from udc_render.studies.report import machine_text, md_table, pyplot, save_plot

DEFAULT_RANK = SynthConfig().field_rank



def _fmt_range(r) -> str:
    return "none" if r is None else f"{r[0]:.3g}–{r[1]:.3g} mm"


def markdown(rows: list[dict], ranges: list[dict], rig, cfg: dict, cost: dict, elapsed_s: float) -> str:
    """study_banding.md: set-up, criteria, one table row per capture, the visible ranges and the cost of the
    exact series (banding.synthesis_cost)."""
    w, h = cfg["sensor"]
    k = rig.band_image.bands.shape[0]
    lines = ["# Banding of a flat field against the display-to-lens distance", "",
             f"Monitor rig showing `pattern:white` (framing fill, the panel's spectrum extended over the render "
             f"margin), {w} × {h} px of {rig.pitch_um:g} µm, {k} bands of {cfg['step_nm']:g} nm, default synthesis "
             f"(blend 'source', field rank {DEFAULT_RANK}, Poisson + read noise; stray light off), "
             f"auto exposure {rig.exposure_s * 1e3:.3g} ms. "
             f"z_i = {rig.z_i_um:.1f} µm (bands along y: the sensor turned to {h} × {w} px, framed anew). "
             "Measured on the green (Gr) sites: the mean across the bands (column mean for x) of clean_dn / glass, "
             f"least-squares fit of a sinusoid + {HARMONICS - 1} harmonics with the period free (FFT start, bounded "
             "search); analytic: psf.banding.PowerSeries of the same rows and bands, T = z_i · p / d. "
             "Regenerate with `udc-render study banding --out DIR`.", "",
             "Criteria: bands are **visible per pixel** when the first harmonic A1 · mean ≥ σ, the per-pixel noise "
             "(std of the noisy minus the clean mosaic, Gr sites) at that level; **visible averaged** when "
             f"A1 · mean ≥ σ / √N after averaging the N = {rig.across_um.size} Gr sites of this frame along the "
             "bands (rows for bands along x; the y runs turn the sensor to portrait, N the same). "
             "A period longer than the frame is a gradient, not bands; below 4 px it is not resolved.", "",
             "power 'series' (the default): the blend takes its power from the exact series P(s) at every "
             "pixel's own mask shift (optics.field_power); 'interpolated': the same kernels without their "
             "series, the phases' powers interpolated bilinearly (the blend before the series), which keeps "
             "sinc²(h/P) of harmonic h (0.81 for h = 1, P = 4) and aliases harmonics h = mP ± 1 onto it. "
             "'ratio to analytic' is the synthesis' error against the exact series. rank: the field rank "
             "('all': every phase kernel, no basis). A1 expected: the analytic harmonic times each band's "
             "phase-averaged kernel OTF at the band frequency (MTF = expected / analytic), what a kernel shape "
             "independent of the phase would print; a rank-2 basis comes near it (it drops the shape's "
             "variation with the phase), the default rank and every phase kernel near the exact series. "
             "order: the harmonic the fit found (period T/order), compared with the "
             "analytic harmonic of that order; order analytic: the strongest analytic harmonic. A1 interp.: the "
             "analytic P(s) sampled at the kernels' P × P field shifts and blended bilinearly (no PSF, no "
             "basis), what the 'interpolated' power gives.", ""]
    lines += md_table(rows, [("axis", "bands along"), ("display", "display"), ("distance_mm", "d mm"),
                             ("field_phases", "P"), ("field_power", "power"), ("field_rank", "rank"),
                             ("period_formula_px", "T formula px"), ("period_error_rel", "T fit error"),
                             ("harmonic_order", "order"), ("analytic_order", "order analytic"),
                             ("a1_measured_rel", "A1 measured"), ("a1_analytic_rel", "A1 analytic"),
                             ("psf_mtf", "MTF"), ("a1_expected_rel", "A1 expected"),
                             ("ratio_measured_analytic", "ratio to analytic"),
                             ("ratio_measured_expected", "ratio to expected"), ("a1_interpolated_rel", "A1 interp."),
                             ("ratio_measured_interpolated", "ratio to interp."), ("a1_dn", "A1 DN"),
                             ("sigma_dn", "σ DN"),
                             ("snr_pixel", "A1/σ"), ("regime", "regime"), ("visible_pixel", "visible/pixel"),
                             ("visible_averaged", "visible averaged"), ("kernel_s", "kernel s")],
                      {"period_error_rel": lambda v: "" if v is None else f"{v:+.2e}"})
    lines += ["", "Visible ranges on the analytic grid of d, which holds the distance where the period equals "
              "the frame (the strongest analytic harmonic × the median measured/analytic ratio, against the "
              "measured σ / mean; its period within [4 px, frame]):", ""]
    lines += md_table([{**r, "pixel": _fmt_range(r["pixel"]), "averaged": _fmt_range(r["averaged"])} for r in ranges],
                      [("display", "display"), ("ratio_used", "ratio used"), ("noise_rel", "σ / mean"),
                       ("a1_max_rel", "strongest harmonic (× ratio), max over d"), ("pixel", "visible per pixel"),
                       ("averaged", f"visible averaged over {rig.across_um.size} rows")])
    lines += ["", f"Cost of the exact series: a synthesis of the {cfg['phase_display']} at "
              f"d = {cfg['phase_distance_mm']:g} mm, {DEFAULT_FIELD_PHASES} field phases, kernels made beforehand, "
              f"median of {cost['repeats']}: {cost['series_s']:.3g} s with the exact series, "
              f"{cost['interpolated_s']:.3g} s with the phases' powers interpolated ({cost['ratio']:.3g}×); "
              f"with the exact series at field rank {DEFAULT_RANK} (the default) {cost['series_s']:.3g} s, "
              + ", ".join(f"rank {r} {t:.3g} s ({t / cost['series_s']:.2f}×)" for r, t in cost["rank_s"].items())
              + "."]
    return "\n".join(lines + ["", machine_text(elapsed_s) + "."]) + "\n"


def plot(rows: list[dict], curves: dict, rig, example, path: Path) -> None:
    """study_banding.png: period and first harmonic against d (measured points, analytic curves, the
    noise level), the ratio against P, and a flat-field example."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 4, figsize=(19, 4.2))
    ax_t, ax_a, ax_p, ax_e = axes
    for name, colour in zip(DISPLAYS, ("C0", "C1")):
        rs = [r for r in rows if r["display"] == name and r["axis"] == "x" and r["field_phases"] == DEFAULT_FIELD_PHASES
              and r["field_power"] == "series" and r["field_rank"] == DEFAULT_RANK]
        ds, harmonics = curves[name]
        a1 = harmonics[:, 0]
        p = D.preset(name).layout.period_um[0]
        ax_t.loglog(ds, [period_formula_um(rig.z_i_um, p, d) / rig.pitch_um for d in ds], "-", color=colour,
                    label=f"{name}: z_i p / d")
        b = [r for r in rs if r["regime"] == "bands"]
        ax_t.loglog([r["distance_mm"] for r in b], [r["period_fit_um"] * r["harmonic_order"] / rig.pitch_um for r in b],
                    "o", color=colour, label=f"{name}: fit × order")
        ax_a.loglog(ds, np.maximum(a1, 1e-9), "-", color=colour, label=f"{name}: analytic h = 1")
        if np.any(harmonics.max(axis=1) > 1.5 * a1):
            ax_a.loglog(ds, harmonics.max(axis=1), "-.", color=colour, lw=0.8, label=f"{name}: analytic, strongest h")
        ax_a.loglog([r["distance_mm"] for r in b], [max(r["a1_measured_rel"], 1e-9) for r in b], "o", color=colour,
                    label=f"{name}: measured")
        noise = float(np.median([r["sigma_dn"] / r["mean_dn"] for r in rs]))
        ys = [r for r in rows if r["display"] == name and r["axis"] == "y" and r["regime"] == "bands"]
        if ys:
            ax_t.loglog([r["distance_mm"] for r in ys], [r["period_fit_um"] * r["harmonic_order"] / rig.pitch_um
                                                         for r in ys], "s", mfc="none", color=colour,
                        label=f"{name}: fit × order, along y")
            ax_a.loglog([r["distance_mm"] for r in ys], [max(r["a1_measured_rel"], 1e-9) for r in ys], "s", mfc="none",
                        color=colour, label=f"{name}: measured along y")
            ax_a.loglog([r["distance_mm"] for r in ys], [max(r["a1_analytic_rel"], 1e-9) for r in ys], "x",
                        color=colour, label=f"{name}: analytic along y")
        ax_a.axhline(noise, color=colour, ls="--", lw=0.8, label=f"{name}: σ / mean (per pixel)")
        ax_a.axhline(noise / math.sqrt(rig.across_um.size), color=colour, ls=":", lw=0.8, label=f"{name}: averaged")
    ax_t.axhline(rig.frame_um / rig.pitch_um, color="k", lw=0.8, ls="--", label="frame width")
    ax_t.set(xlabel="display-to-lens distance d (mm)", ylabel="band period on the sensor (px)", title="period")
    ax_a.set(xlabel="display-to-lens distance d (mm)", ylabel="first harmonic / mean", title="amplitude (green)")
    ph = sorted((r for r in rows if r["display"] == rig.cfg["phase_display"] and r["axis"] == "x"
                 and r["distance_mm"] == rig.cfg["phase_distance_mm"] and r["regime"] == "bands"
                 and r["field_rank"] == DEFAULT_RANK),
                key=lambda r: r["field_phases"])
    Ps = np.linspace(3, 8, 100)
    ax_p.plot(Ps, np.sinc(1 / Ps) ** 2, "k-", lw=0.8, label="sinc²(1/P) (a pure sinusoid, P ≥ 3)")
    label = f"{rig.cfg['phase_display']}, d = {rig.cfg['phase_distance_mm']:g} mm"
    for power, style in (("series", "o-"), ("interpolated", "s-")):
        rp = [r for r in ph if r["field_power"] == power]
        ax_p.plot([r["field_phases"] for r in rp], [r["ratio_measured_analytic"] for r in rp], style,
                  label=f"{label}: measured, power {power}")
    rp = [r for r in ph if r["field_power"] == "interpolated"]
    ax_p.plot([r["field_phases"] for r in rp], [r["a1_interpolated_rel"] / r["a1_analytic_rel"] for r in rp], "s--",
              mfc="none", label=f"{label}: P(s) interpolated alone (no PSF)")
    ax_p.axhspan(0.95, 1.05, color="k", alpha=0.08, label="± 5 %")
    ax_p.set(xlabel="field phases P per axis", ylabel="A1 measured / exact series",
             title="the blend's power against the phase count")
    if example is not None:
        name, d, x, prof, img = example
        ax_e.plot(x, prof, lw=0.8)
        ax_e.set(xlabel="x on the sensor (µm)", ylabel="column mean / glass / mean",
                 title=f"{name}, d = {d:g} mm: flat-field profile")
        inset = ax_e.inset_axes([0.0, 1.12, 1.0, 0.25])
        inset.imshow(img / img.mean(), cmap="gray", aspect="auto")
        inset.set_axis_off()
    for ax in axes[:3]:
        ax.grid(True, which="both", alpha=0.25)
        ax.legend(fontsize=7)
    save_plot(fig, path)
