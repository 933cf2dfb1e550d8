"""`udc-render fit`: the simulator fitted to a user's own panel from its measurements (issue 30), the way
the paper measured its panels (a 650 nm laser's PSF, l.122; a white square for γ, l.210; repeated frames for
the noise, l.265) plus a flat field for the display-to-lens distance (the bands of l.498).

    inputs.py      reading PNG/TIFF (8/16 bit) and DNG files, levels, saturation, hot pixels
    hdr.py         the exposures prepared and merged into one HDR PSF, each pixel's noise
    lattice.py     the orders' lattice in closed form: pitch (x, y) and rotation ± σ
    photometry.py  each order's power (a matched filter, the same on the model)
    families.py    the forward models: toled, poled, micrograph (psf.layouts, psf.micrograph)
    refine.py      least squares of the opening on the orders' powers (every row measured, the noise at the
                   model), the engine's kernel as the model; the minima that fit alike
    search.py      the opening's search: the grid's starts, the twins, the reweighted polish
    psf_fit.py     the PSF fit's stages, the family chosen, the synthesis check
    flat.py        d from a flat field's bands (T = z_i p / d), their contrast a check
    white.py       γ per RGGB channel from the white-square pair; T(λ) fitted to it
    noise.py       λ_read, λ_shot from repeated frames (the calibration's estimator); sensor.toml
    report.py      display.toml, fit.json, fit.md, fit.png
    synthetic.py   measurements made with the project itself (tests, the guide, the exposure study)

run_fit(spec, out) runs what the spec asks and writes the files into out (made and checked by the caller).
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from psf import Lens, MicrographLayout
from udc_render.fit.cfa import converged
from udc_render.fit.flat import CHECK_RATIO, fit_flat
from udc_render.fit.hdr import colour_gains, merge_psf
from udc_render.fit.inputs import FitError, read_frame, read_frames
from udc_render.fit.noise import fit_noise, sensor_toml
from udc_render.fit.photometry import Optics
from udc_render.fit.psf_fit import first_lattice, fit_psf, orders_table, refuse_synthesis, synthesis_check, trade_offs
from udc_render.fit.report import display_toml, pm, write_all, write_tile
from udc_render.fit.white import fit_white
from udc_render.io.files import save_text
from udc_render.optics.displays import parse_display

__all__ = ["FitSpec", "FitError", "run_fit", "FAMILY_CHOICES"]

FAMILY_CHOICES = ("auto", "toled", "poled", "micrograph")


@dataclass(frozen=True)
class FitSpec:
    """What to fit (the command's options): the PSF exposures and their optics, the family, the optional
    flat field, white-square pair and noise frames, and the output display's name."""
    psf: tuple
    wavelength_nm: float = 650.0
    pixel_um: float = 1.55
    black_dn: float | None = None
    saturation_dn: float | None = None
    focal_length_mm: float = 6.0
    f_number: float = 1.8
    family: str = "auto"
    micrograph: str | None = None
    micrograph_pixel_um: float = 1.0
    flat: str | None = None
    white: tuple | None = None
    white_gain: float = 1.0
    white_bands_nm: tuple = (400.0, 700.0, 10.0)
    noise_frames: str | None = None
    camera: str = "Nikon 5100 (NPL)"
    window_px: int = 511
    name: str = "fitted"
    notes: list = field(default_factory=list)

    def optics(self):
        f_um = self.focal_length_mm * 1000.0
        return Optics(Lens(focal_length_um=f_um, aperture_um=f_um / self.f_number), self.wavelength_nm, self.pixel_um)


def _file_layout(spec: FitSpec, cand, out: Path):
    """(the display file's [display.layout] table, its psf layout): one pitch, the inverse-variance mean of
    the lattice's two (the display files hold one); a micrograph's oriented tile written beside it."""
    (px, sx), (py, sy) = cand.pitch_um
    w = np.array([sx ** -2, sy ** -2])
    pitch = float(np.dot(w, [px, py]) / w.sum())
    fam, params = cand.family, cand.fit.params
    if fam.name == "toled":
        table = {"type": "toled", "pitch_um": pitch, "open_fraction": float(params[0] * params[1]),
                 "slit_height_fraction": float(params[1])}
        return table, fam.layout(pitch, pitch, params)
    if fam.name == "poled":
        table = {"type": "poled", "pitch_um": pitch, "open_fraction": float(params[0]),
                 "small_to_large": float(params[1])}
        return table, fam.layout(pitch, pitch, params)
    h, wd = fam.tile.shape
    pixel = 0.5 * (px / wd + py / h)
    write_tile(out / "micrograph.png", fam.tile)
    layout = MicrographLayout.load(out / "micrograph.png", pixel, "amplitude")
    return {"type": "micrograph", "file": "micrograph.png", "pixel_um": pixel, "values": "amplitude"}, layout


def _parameters(spec: FitSpec, cand) -> dict:
    """The family's parameters ± σ (the open fraction by the delta method from the width and height)."""
    fam, x, cov = cand.family, cand.fit.x, cand.fit.cov
    (px, sx), (py, sy) = cand.pitch_um
    if fam.name == "toled":
        w, h = x[0], x[1]
        g = np.array([h, w])
        return {"open_fraction": pm(w * h, math.sqrt(g @ cov[:2, :2] @ g)),
                "slit_height_fraction": pm(h, math.sqrt(cov[1, 1])), "width_fraction": pm(w, math.sqrt(cov[0, 0]))}
    if fam.name == "poled":
        return {"open_fraction": pm(x[0], math.sqrt(cov[0, 0])), "small_to_large": pm(x[1], math.sqrt(cov[1, 1]))}
    h, wd = fam.tile.shape
    pix = 0.5 * (px / wd + py / h)
    s = 0.5 * math.hypot(sx / wd, sy / h)
    return {"pixel_um": pm(pix, s, "um"), "scale": pm(pix / spec.micrograph_pixel_um, s / spec.micrograph_pixel_um),
            "open_fraction": pm(float(np.mean(fam.tile ** 2)), 0.0)}


def _candidate_record(c) -> dict:
    return {"family": c.family.name, "orientation": c.family.orientation, "chi2_red": c.fit.chi2_red,
            "chi2_red_signal": c.fit.chi2_signal_red, "rms_relative": c.fit.rms_rel, "rows": int(c.fit.used.sum()),
            "rows_with_signal": c.fit.signal_rows, "starts": c.fit.starts, "engine_kernels": int(c.fit.passes),
            "pitch_x_um": pm(*c.pitch_um[0], "um"), "pitch_y_um": pm(*c.pitch_um[1], "um")}


def _psf_record(psf, spec: FitSpec) -> dict:
    c = psf.chosen
    lat = c.lattice
    k = len(c.family.names)
    lin, sig = c.fit.x[k:], np.sqrt(np.diag(c.fit.cov))[k:]
    return {"family": c.family.name, "orientation": c.family.orientation, "exposures": len(psf.plane.exposures),
            "parameters": _parameters(spec, c),
            "lattice": {"pitch_x_um": pm(*c.pitch_um[0], "um"), "pitch_y_um": pm(*c.pitch_um[1], "um"),
                        "pitch_before_centroid_bias_um": [c.raw_pitch_um[0][0], c.raw_pitch_um[1][0]],
                        "rotation_deg": pm(*c.rotation_deg, "deg"), "skew_deg": c.skew_deg,
                        "origin_px": [psf.window.x0 + lat.origin[0], psf.window.y0 + lat.origin[1]],
                        "peaks": int(len(lat.index)), "rms_px": lat.rms_px, "floor_px": lat.floor_px},
            "window_px": psf.window.size, "aperture_px": c.radius_px,
            "vignetting": {"log_gradient_x": pm(lin[1], sig[1]), "log_gradient_y": pm(lin[2], sig[2]),
                           "log_radial_r2": pm(lin[3], sig[3]), "log_radial_r4": pm(lin[4], sig[4]),
                           "unit": "per window half side"},
            "exposure_factors": {"hdr_merge": list(psf.plane.factors),
                                 "fitted": {str(e): pm(math.exp(v), math.exp(v) * s) for e, v, s in
                                            zip(c.fit.exposures[1:], lin[5:], sig[5:])}},
            "dn_per_electron": psf.plane.dn_per_e, "chi2_red": c.fit.chi2_red, "dof": c.fit.dof,
            "chi2_red_signal": c.fit.chi2_signal_red, "rows_with_signal": c.fit.signal_rows,
            "rms_relative": c.fit.rms_rel, "starts": c.fit.starts,
            "correlation": {f"{a} × {b}": float(c.fit.correlation[i, j]) for i, a in enumerate(c.family.names)
                            for j, b in enumerate(c.family.names) if i < j},
            "trade_offs": trade_offs(c),
            "candidates": [_candidate_record(x) for x in psf.candidates], "skipped": psf.skipped,
            "orders": orders_table(c)}


def _flat_record(f) -> dict:
    axes = []
    for a in f.axes:
        ratio = a.a1 / a.a1_predicted if a.counts and a.a1_predicted > 0 else math.nan
        axes.append({"axis": a.axis, "period_px": pm(a.period_px, a.period_sigma_px, "px"),
                     "periods_in_frame": a.periods_in_frame, "a1": pm(a.a1, a.a1_sigma), "a1_predicted": a.a1_predicted,
                     "contrast_ratio": ratio, "check": "passes" if CHECK_RATIO[0] <= ratio <= CHECK_RATIO[1] else
                     ("not made" if not a.counts else "FAILS"),
                     "distance_mm": pm(a.distance_mm, a.distance_sigma_mm, "mm"), "counts": a.counts,
                     "harmonic": {"why": a.choice, "candidates": list(a.candidates)}})
    return {"distance_mm": pm(f.distance_mm, f.distance_sigma_mm, "mm"), "axes": axes}


def _transmission_table(white) -> dict:
    """[display.transmission]: the transmission's keys a display file takes (not its formula)."""
    return {k: v for k, v in white.transmission.describe().items() if k != "formula"}


def run_fit(spec: FitSpec, out: Path, progress=None) -> dict:
    """Fit, write display.toml (sensor.toml), fit.json, fit.md, fit.png into out; returns fit.json's dict.
    progress(text): told each stage."""
    say = progress or (lambda text: None)
    out, optics, written = Path(out), spec.optics(), []
    noise = None
    if spec.noise_frames:
        say("noise frames")
        noise = fit_noise(spec.noise_frames, spec.black_dn, spec.saturation_dn)
    say("reading the PSF exposures")
    frames = read_frames(spec.psf, spec.black_dn, spec.saturation_dn)
    dn_per_e = noise.dn_per_e() if noise else None
    plane, cfa = merge_psf(frames, spec.wavelength_nm, spec.camera, dn_per_e), None
    if frames[0].kind == "cfa":  # balanced by the orders themselves (fit.cfa)
        say("CFA sites' response from the orders")

        def locate(p):
            return first_lattice(p, optics, spec.family, spec.micrograph, spec.window_px)
        plane, cfa, passes = converged(frames, frames[0].colour_map(), spec.wavelength_nm, spec.camera, dn_per_e,
                                       locate, optics)
        cfa = cfa and replace(cfa, guess=tuple(float(g) for g in colour_gains(spec.wavelength_nm, spec.camera)),
                              passes=passes)
    psf = fit_psf(plane, optics, spec.family, spec.micrograph, spec.window_px, say)
    layout_table, layout = _file_layout(spec, psf.chosen, out)
    say("synthesis check")
    layout_text = display_toml(spec.name, layout_table, None, None, None, "the fitted layout alone")
    check, synthesised = synthesis_check(psf, parse_display(tomllib.loads(layout_text), out / "display.toml").layout,
                                         optics)
    refuse_synthesis(check, spec.family)
    flat = white = None
    if spec.flat:
        say("flat field")
        flat = fit_flat(read_frame(spec.flat, spec.black_dn, spec.saturation_dn), psf.chosen.pitch_um,
                        psf.chosen.rotation_deg[0], layout, optics)
    if spec.white:
        say("white square")
        lo, hi, step = spec.white_bands_nm
        white = fit_white(read_frame(spec.white[0], spec.black_dn, spec.saturation_dn),
                          read_frame(spec.white[1], spec.black_dn, spec.saturation_dn), layout, optics.lens,
                          np.arange(lo, hi + step / 2, step), spec.pixel_um, spec.camera, spec.white_gain)
    header = (f"fitted by udc-render fit from {', '.join(Path(p).name for p in spec.psf)} (fit.json: every value "
              "± σ)\nthe display's rotation against the camera is not a display-file key (fit.json: "
              "psf.lattice.rotation_deg)")
    save_text(out / "display.toml", display_toml(spec.name, layout_table, flat.distance_mm if flat else None,
                                                  spec.white_gain if white else None,
                                                  _transmission_table(white) if white else None, header))
    written += ["display.toml"] + (["micrograph.png"] if layout_table["type"] == "micrograph" else [])
    if noise:
        save_text(out / "sensor.toml", sensor_toml(noise, spec.noise_frames))
        written.append("sensor.toml")
    result = {"display": {"name": spec.name, "file": "display.toml", "layout": layout_table},
              "inputs": {"psf": [str(p) for p in spec.psf], "optics": f"λ {spec.wavelength_nm:g} nm, pixel "
                         f"{spec.pixel_um:g} um, f {spec.focal_length_mm:g} mm, f/{spec.f_number:g}",
                         "camera": spec.camera, "black_dn": frames[0].black_dn,
                         "saturation_dn": frames[0].saturation_dn},
              "psf": _psf_record(psf, spec), "synthesis_check": check,
              "notes": list(plane.notes) + (list(flat.notes) if flat else []) + list(spec.notes) +
              [f"warning: the {psf.chosen.family.name} opening's {t} trade off: the orders measure a combination "
               "better than each (fit.json: psf.correlation)" for t in trade_offs(psf.chosen)],
              "written": written + ["fit.json", "fit.md", "fit.png"]}
    if cfa:
        result["psf"]["cfa_response"] = cfa.record()
    if flat:
        result["flat"] = _flat_record(flat)
    if white:
        m = white.measured
        result["white"] = {"gamma": [pm(g, s) for g, s in zip(m.gamma, m.sigma)], "gain": white.gain,
                           "pixels": m.pixels, "square_px": list(m.square_xy_px), "region_px": list(m.region_xy_px),
                           "transmission": white.transmission.describe(),
                           "parameters": {k: pm(*v) for k, v in white.params.items()},
                           "gamma_model": list(white.gamma_model)}
    if noise:
        result["noise"] = {"frames": noise.frames, "series": noise.series, "pixels": list(noise.pixels),
                           "lambda_read": [pm(v, s) for v, s in zip(noise.lambda_read, noise.lambda_read_sigma)],
                           "lambda_shot": [pm(v, s) for v, s in zip(noise.lambda_shot, noise.lambda_shot_sigma)],
                           "notes": list(noise.notes)}
    say("report")
    w = psf.window
    figure = {"measured": w.crop(plane.value), "synthesised": synthesised, "var": w.crop(plane.var),
              "usable": w.crop(plane.usable), "orders": result["psf"]["orders"],
              "title": f"udc-render fit: {psf.chosen.family.name}, pitch {layout_table.get('pitch_um', 0):.4g} um"}
    write_all(out, result, figure)
    return result
