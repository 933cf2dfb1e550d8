"""study_banding.md and study_banding.png of the banding study (udc_render.studies.banding); `rig` is
its banding.Rig.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from psf.engine import DEFAULT_FIELD_PHASES
from udc_render.optics import displays as D
from udc_render.studies.banding_fit import DISPLAYS, HARMONICS, period_formula_um
from udc_render.studies.report import machine_text, md_table, pyplot, save_plot



def _fmt_range(r) -> str:
    return "none" if r is None else f"{r[0]:.3g}–{r[1]:.3g} mm"


def markdown(rows: list[dict], ranges: list[dict], rig, cfg: dict, elapsed_s: float) -> str:
    """study_banding.md: set-up, criteria, one table row per capture and the visible ranges."""
    w, h = cfg["sensor"]
    k = rig.band_image.bands.shape[0]
    lines = ["# Banding of a flat field against the display-to-lens distance", "",
             f"Monitor rig showing `pattern:white` (framing fill, the panel's spectrum extended over the render "
             f"margin), {w} × {h} px of {rig.pitch_um:g} µm, {k} bands of {cfg['step_nm']:g} nm, default synthesis "
             f"(blend 'source', field rank 2, Poisson + read noise), auto exposure {rig.exposure_s * 1e3:.3g} ms. "
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
             "The ratio measured / analytic is expected below 1: the synthesis interpolates P(s) linearly "
             "between P field phases per axis, keeping sinc²(h/P) of harmonic h (0.81 for h = 1, P = 4), and "
             "blend 'source' smooths the weighted source with the PSF. The sampling also aliases harmonics "
             "h = mP ± 1 into the first: where the exact first harmonic is weak against them (T-OLED along y) "
             "the synthesis' first harmonic exceeds the exact one. harmonic_order > 1: the fit found the "
             "period T/order (the first harmonic vanishes), compared with the analytic harmonic of that order. "
             "A1 interp.: the analytic P(s) sampled at the kernels' P × P field shifts and blended bilinearly "
             "as the synthesis does (no PSF, no rank-2 basis): the ratio to it is what the rest of the optics "
             "changes.", ""]
    lines += md_table(rows, [("axis", "bands along"), ("display", "display"), ("distance_mm", "d mm"),
                             ("field_phases", "P"),
                             ("period_formula_px", "T formula px"), ("period_error_rel", "T fit error"),
                             ("harmonic_order", "order"), ("a1_measured_rel", "A1 measured"),
                             ("a1_analytic_rel", "A1 analytic"), ("a1_interpolated_rel", "A1 interp."),
                             ("ratio_measured_analytic", "ratio"), ("ratio_measured_interpolated", "ratio to interp."),
                             ("sinc2_interp", "sinc²(h/P)"), ("a1_dn", "A1 DN"), ("sigma_dn", "σ DN"),
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
    return "\n".join(lines + ["", machine_text(elapsed_s) + "."]) + "\n"


def plot(rows: list[dict], curves: dict, rig, example, path: Path) -> None:
    """study_banding.png: period and first harmonic against d (measured points, analytic curves, the
    noise level), the ratio against P, and a flat-field example."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 4, figsize=(19, 4.2))
    ax_t, ax_a, ax_p, ax_e = axes
    for name, colour in zip(DISPLAYS, ("C0", "C1")):
        rs = [r for r in rows if r["display"] == name and r["axis"] == "x"
              and r["field_phases"] == DEFAULT_FIELD_PHASES]
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
                 and r["distance_mm"] == rig.cfg["phase_distance_mm"] and r["regime"] == "bands"),
                key=lambda r: r["field_phases"])
    Ps = np.linspace(3, 8, 100)
    ax_p.plot(Ps, np.sinc(1 / Ps) ** 2, "k-", lw=0.8, label="sinc²(1/P) (a pure sinusoid, P ≥ 3)")
    label = f"{rig.cfg['phase_display']}, d = {rig.cfg['phase_distance_mm']:g} mm"
    ax_p.plot([r["field_phases"] for r in ph], [r["ratio_measured_analytic"] for r in ph], "o-",
              label=f"{label}: measured")
    ax_p.plot([r["field_phases"] for r in ph], [r["a1_interpolated_rel"] / r["a1_analytic_rel"] for r in ph], "s--",
              mfc="none", label=f"{label}: P(s) interpolated alone")
    ax_p.set(xlabel="field phases P per axis", ylabel="A1 measured / analytic", title="interpolation in phase")
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
