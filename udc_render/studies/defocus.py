"""`udc-render study defocus`: through-focus PSFs and MTFs of glass, T-OLED and P-OLED, the blur
against object distance and the depth of field with and without a display (issue 14).

    udc-render study defocus --out DIR [--quick]

The rig is the paper's: f = 6 mm, f/1.8 (D = 3333 µm), 1.55 µm pixels, the display at d = 0, the lens
focused at z_f = FOCUS_MM; the sensor sits at z_i = 1 / (1/f − 1/z_f). Object distances z are swept
in vergence v = 1/z (m⁻¹, v = 0 at infinity); the engine puts the paraxial defocus π c r² / λ in the
pupil, c = 1/z − 1/z_f. Geometric circle of confusion (thin lens): b = D · z_i · |1/z_f − 1/z|.

Blur measures (each kernel: unit sum inside its window, pixel-integrated, centred at S // 2):
- edge spread: LSF_x = Σ_y k, ESF = its running sum (the ESF at the pixel edges), the 10–90 % rise
  width w by linear interpolation; w_x, w_y and their mean;
- equivalent disc diameter: the diameter b' of the uniform disc whose pixel-integrated LSF gives the
  same w (disc ESF F(x) = 1/2 + (t√(1−t²) + asin t)/π, t = 2x/b; pixel LSF F(j + ½) − F(j − ½));
  w of a point is 0.8 px (the sampling floor), below which b' = 0;
- MTF of the sampled kernel: along x and y, |Σ_j LSF[j] e^(−2πi f (j − S//2))| (f in cycles/px), at
  F_REF_CPP; the reference MTF, the 2-D |DFT|'s mean over F_REF_CPP ± F_BAND_CPP and all orientations (a
  display's MTF is a comb of period p·pixel/(λ z_i) cycles/px, at 520 nm P-OLED 0.031, T-OLED 0.16: a point value
  depends on where f falls between its teeth); MTF50 of the orientation-averaged MTF.

Depth of field: the range of v around v_f where the reference MTF stays ≥ a threshold (crossings
interpolated linearly in v): relative, REL_LEVEL × the same display's in-focus value; absolute, a fixed
ABS_MTF for every display. Beside it the geometric DoF of a COC_GEOM_PX circle of confusion,
v_f ± COC_GEOM_PX · p / (D z_i).

Checks (pass/fail with the numbers): (a) glass at b ≥ GEOM_MIN_PX: w within GEOM_TOL of the w of a
disc of diameter b; (b) glass in focus: MTF_x within DIFF_TOL of the diffraction limit
Σ_k M(ν_k) sinc(f + k), M(ν) = (2/π)(acos ν − ν√(1 − ν²)), ν_k = |f + k| λ N_w / p, N_w = z_i / D
(the k ≠ 0 terms are the pixel sampling's folding; the unfolded k = 0 term alone is reported too).

Outputs in DIR: study_defocus.csv (one row per display, wavelength, object distance), study_defocus.md,
study_defocus.png (blur and MTF against distance, DoF bars), study_defocus_psf.png (through-focus
PSFs, log scale), study_defocus_mtf.png (MTF curves at several distances); defocus_report.py. The full
run adds the T-OLED at d = D_GAP_MM (the engine's field-averaged kernels) to the three at d = 0.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from psf import compute_kernels
from udc_render.studies.defocus_measures import (
    APERTURE_UM,
    DIFF_TOL,
    DISPLAY_SPECS,
    FREQS_CPP,
    FULL,
    GEOM_MIN_PX,
    GEOM_TOL,
    PIXEL_UM,
    QUICK,
    Config,
    blur_measures,
    diffraction_limit,
    disc_esf_width_px,
    dof_rows,
    focus_vergence_per_m,
    geometric_coc_px,
    lens_at,
    lsf,
    mtf_of_line,
    object_distance_mm,
)
from udc_render.studies.defocus_report import write_report
from udc_render.studies.report import load_average

# ----------------------------------------------------------------------------------------------
# Measuring


def display_layout(name: str):
    """The layout of a DISPLAY_SPECS name: None (glass), layouts.toled() or layouts.poled()."""
    return DISPLAY_SPECS[name][0]()


def through_focus_kernels(display, vergence_per_m: float, cfg: Config, distance_mm: float = 0.0):
    """compute_kernels of the display at gap d and the vergence, all the sweep's wavelengths (no cache;
    d > 0: the mean over the engine's default field phases)."""
    return compute_kernels(display, lens_at(vergence_per_m), wavelengths_nm=list(cfg.wavelengths_nm),
                           pixel_um=PIXEL_UM, size_px=cfg.size_px, distance_mm=distance_mm,
                           pupil_samples=cfg.pupil_samples)


def measure(cfg: Config, progress=None) -> tuple[list[dict], dict]:
    """One row per display, wavelength and vergence; and the kernels at the panel vergences
    {(display, v): KernelSet}."""
    rows, panels = [], {}
    v_f = focus_vergence_per_m()
    for disp in cfg.displays:
        layout, gap_mm = display_layout(disp), DISPLAY_SPECS[disp][1]
        for v in cfg.vergences_per_m:
            ks = through_focus_kernels(layout, v, cfg, gap_mm)
            lens = lens_at(v)
            b = geometric_coc_px(lens)
            for k, wl in enumerate(cfg.wavelengths_nm):
                row = {"display": disp, "wavelength_nm": wl, "object_distance_mm": object_distance_mm(v),
                       "vergence_per_m": v, "defocus_per_m": v - v_f, "coc_geom_px": b,
                       "disc_width_geom_px": disc_esf_width_px(b), "energy_outside": float(ks.energy_outside[k]),
                       "transmittance": float(ks.transmittance[k])}
                row.update(blur_measures(ks.kernels[k]))
                rows.append(row)
            if v in cfg.panel_vergences_per_m or v == v_f:
                panels[(disp, v)] = ks
            if progress:
                progress(1)
    return rows, panels


# ----------------------------------------------------------------------------------------------
# The checks


def geometric_check(rows: list[dict], cfg: Config) -> dict:
    """(a) glass, b ≥ GEOM_MIN_PX and the disc inside the window (b ≤ 0.85 S): the ratio of the measured
    w_x to the disc's w; pass when every |ratio − 1| ≤ GEOM_TOL."""
    sel = [r for r in rows if r["display"] == "glass" and GEOM_MIN_PX <= r["coc_geom_px"] <= 0.85 * cfg.size_px]
    ratios = [r["esf_width_x_px"] / r["disc_width_geom_px"] for r in sel]
    worst = max(range(len(sel)), key=lambda i: abs(ratios[i] - 1)) if sel else None
    return {"name": "(a) defocused glass edge spread vs thin-lens disc",
            "criterion": f"|w / w_disc(b) − 1| ≤ {GEOM_TOL:.0%} at b ≥ {GEOM_MIN_PX:g} px",
            "points": len(sel), "ratios": ratios,
            "b_range_px": (min(r["coc_geom_px"] for r in sel), max(r["coc_geom_px"] for r in sel)) if sel else None,
            "worst_ratio": ratios[worst] if sel else math.nan,
            "worst_at": (sel[worst]["object_distance_mm"], sel[worst]["wavelength_nm"], sel[worst]["coc_geom_px"])
            if sel else None,
            "passed": bool(sel) and all(abs(x - 1) <= GEOM_TOL for x in ratios)}


def diffraction_check(panels: dict, cfg: Config) -> dict:
    """(b) glass in focus: max over 0…0.5 cycles/px and the wavelengths of |MTF_x − diffraction limit|
    (folded), ≤ DIFF_TOL; the unfolded (k = 0 only) difference is reported beside it."""
    v_f = focus_vergence_per_m()
    ks = panels[("glass", v_f)]
    f_number = lens_at(v_f).image_distance_um / APERTURE_UM
    folded, unfolded = [], []
    for k, wl in enumerate(cfg.wavelengths_nm):
        m = mtf_of_line(lsf(ks.kernels[k], "x"))
        folded.append(float(np.max(np.abs(m - np.abs(diffraction_limit(FREQS_CPP, wl, f_number))))))
        unfolded.append(float(np.max(np.abs(m - diffraction_limit(FREQS_CPP, wl, f_number, folded=False)))))
    return {"name": "(b) in-focus glass MTF vs diffraction limit × pixel sinc",
            "criterion": f"max |MTF_x − Σ_k M(ν_k) sinc(f+k)| ≤ {DIFF_TOL} over 0–0.5 cycles/px",
            "f_number_working": f_number, "max_diff": max(folded), "max_diff_per_wl": folded,
            "max_diff_unfolded": max(unfolded), "passed": max(folded) <= DIFF_TOL}


def run_study(out: Path, quick: bool = False, progress: bool = True) -> dict:
    """Measure the sweep, run the checks, write study_defocus.{csv,md,png} and the extra PNGs into out;
    returns {"rows", "dof", "checks", "meta"}."""
    cfg = QUICK if quick else FULL
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0, load0 = time.perf_counter(), load_average()
    with tqdm(total=len(cfg.displays) * len(cfg.vergences_per_m), disable=not progress, desc="study defocus",
              unit="kernel set", dynamic_ncols=True) as bar:
        rows, panels = measure(cfg, bar.update)
    result = {"rows": rows, "dof": dof_rows(rows, cfg),
              "checks": [geometric_check(rows, cfg), diffraction_check(panels, cfg)],
              "meta": {"cfg": cfg, "measure_s": time.perf_counter() - t0, "load_start": load0,
                       "lens": lens_at(focus_vergence_per_m())}}
    write_report(out, result, panels)
    result["meta"]["elapsed_s"] = time.perf_counter() - t0
    result["meta"]["load_end"] = load_average()
    return result
