"""The fit's files, each written atomically (udc_render.io.files): display.toml (and the micrograph tile it
names), sensor.toml (with --noise-frames), fit.json (every parameter ± σ, the residuals, the orders),
fit.md (the same for a reader) and fit.png (measured and synthesised PSF on a log scale, the residual map,
the orders' powers).
"""
from __future__ import annotations

import math
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from udc_render.io.files import atomic_path, save_json, save_text
from udc_render.io.plots import pyplot, save_plot


def pm(value: float, sigma: float, unit: str = "") -> dict:
    """A parameter for fit.json: value, σ, unit."""
    return {"value": float(value), "sigma": float(sigma), **({"unit": unit} if unit else {})}


def fmt(p: dict, digits: int = 4) -> str:
    """'v ± σ unit' with σ to two significant figures and v to the same decimal."""
    v, s = p["value"], p["sigma"]
    if not math.isfinite(s) or s <= 0:
        return f"{v:.{digits}g} {p.get('unit', '')}".strip()
    dec = max(0, 1 - int(math.floor(math.log10(s))))
    return f"{v:.{dec}f} ± {s:.{dec}f} {p.get('unit', '')}".strip()


def _toml_value(v) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return f"{float(v):.8g}" if isinstance(v, float) else str(v)


def display_toml(name: str, layout: dict, distance_mm: float | None, gain: float | None, transmission: dict | None,
                 header: str) -> str:
    """A display file (scenes/README.md, 'Display files'; optics.displays.parse_display reads it)."""
    lines = [f"# {line}" for line in header.splitlines()] + ["[display]", f"name = {_toml_value(name)}"]
    if gain is not None:
        lines.append(f"gain = {_toml_value(float(gain))}")
    if distance_mm is not None:
        lines.append(f"distance_mm = {_toml_value(float(distance_mm))}")
    lines += ["", "[display.layout]"] + [f"{k} = {_toml_value(v)}" for k, v in layout.items()]
    if transmission is not None:
        lines += ["", "[display.transmission]"] + [f"{k} = {_toml_value(v)}" for k, v in transmission.items()]
    return "\n".join(lines) + "\n"


def write_tile(path: Path, tile: np.ndarray) -> None:
    """The micrograph tile as a 16-bit grey PNG of its amplitude (psf.micrograph reads it back)."""
    with atomic_path(path, ".png") as tmp:
        iio.imwrite(tmp, np.round(np.clip(tile, 0, 1) * 65535).astype(np.uint16), extension=".png")


def _log(a: np.ndarray, top: float) -> np.ndarray:
    return np.log10(np.maximum(a / top, 1e-7))


def plot(path: Path, measured: np.ndarray, synthesised: np.ndarray, var: np.ndarray, usable: np.ndarray,
         orders: dict, title: str) -> None:
    """fit.png: measured | synthesised (log10, the measured peak = 0) | residual / σ | orders' powers."""
    plt = pyplot()
    fig, ax = plt.subplots(1, 4, figsize=(22, 4.8), gridspec_kw={"wspace": 0.35})
    top = float(measured[usable].max())
    h = measured.shape[0] // 2
    ext = (-h - 0.5, h + 0.5, h + 0.5, -h - 0.5)
    for a, img, what in ((ax[0], measured, "measured (HDR)"), (ax[1], synthesised, "synthesised from display.toml")):
        im = a.imshow(np.where(usable, _log(img, top), np.nan), extent=ext, cmap="magma", vmin=-7, vmax=0)
        a.set(title=f"{what}, log10 of the peak", xlabel="x (px)", ylabel="y (px)")
    fig.colorbar(im, ax=ax[1], fraction=0.046)
    res = np.where(usable, (measured - synthesised) / np.sqrt(np.where(usable, var, 1.0)), np.nan)
    im = ax[2].imshow(res, extent=ext, cmap="RdBu_r", vmin=-5, vmax=5)
    ax[2].set(title="residual / σ (measured − synthesised)", xlabel="x (px)")
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    p, m, s, used = (np.asarray(orders[k]) for k in ("power", "model", "sigma", "used"))
    ok = p > 0
    ok = ok & used & (m > 0)
    near = np.abs(p - m) <= 3 * s
    ax[3].errorbar(m[ok & near], p[ok & near], yerr=s[ok & near], fmt=".", ms=3, lw=0.5,
                   label="orders fitted, within 3 σ")
    ax[3].errorbar(m[ok & ~near], p[ok & ~near], yerr=s[ok & ~near], fmt=".", ms=3, lw=0.5, color="C3",
                   label="orders fitted, beyond 3 σ")
    lim = [max(min(m[ok].min(), p[ok].min()), p[ok].max() * 1e-7), p[ok].max() * 2]
    ax[3].plot(lim, lim, "k--", lw=0.8, label="measured = model")
    ax[3].set(xscale="log", yscale="log", xlim=lim, ylim=lim, title="orders' powers (brightest exposure's DN)",
              xlabel="model (fitted family)", ylabel="measured")
    ax[3].legend(fontsize=8)
    fig.suptitle(title)
    save_plot(fig, path)


def markdown(result: dict) -> str:
    """fit.md: the parameters ± σ, the families, the check, the other measurements, the notes."""
    p, lat = result["psf"], result["psf"]["lattice"]
    out = [f"# udc-render fit: {result['display']['name']}", "",
           f"Inputs: {', '.join(result['inputs']['psf'])} ({p['exposures']} exposure(s)); "
           f"{result['inputs']['optics']}.", "",
           f"## Display layout: {p['family']}", "", "| parameter | value |", "|---|---|"]
    out += [f"| {k} | {fmt(v)} |" for k, v in p["parameters"].items()]
    out += [f"| correlation of {k} | {v:+.3f} |" for k, v in p["correlation"].items()]
    out += [f"| pitch along x (lattice) | {fmt(lat['pitch_x_um'])} |",
            f"| pitch along y (lattice) | {fmt(lat['pitch_y_um'])} |",
            f"| rotation of the display's x axis (towards +y) | {fmt(lat['rotation_deg'])} |",
            f"| skew of its y axis | {lat['skew_deg']:.3g} ° |", "",
            f"Lattice: {lat['peaks']} peaks, RMS residual {lat['rms_px']:.3g} px, scatter beyond the noise "
            f"{lat['floor_px']:.3g} px; the pitch is λ z_i / spacing: a focal-length error passes into it one to "
            "one.", "",
            "| family | χ²/dof (rows with signal) | orders' powers off (noise-weighted RMS) | rows (with signal) | "
            "starts | kernels |", "|---|---|---|---|---|---|"]
    out += [f"| {c['family']}{' (' + c['orientation'] + ')' if c.get('orientation') else ''} | {c['chi2_red']:.3g} "
            f"({c['chi2_red_signal']:.3g}) | {c['rms_relative']:.2%} | {c['rows']} ({c['rows_with_signal']}) | "
            f"{c['starts']} | {c['engine_kernels']} |" for c in p["candidates"]]
    out += [f"| {k} | not fitted: {v} | | | | |" for k, v in p["skipped"].items()]
    s = result["synthesis_check"]
    out += ["", "## Synthesis with display.toml", "",
            f"The display file's layout through the PSF engine, placed where the measurement's spot is and turned "
            "by its rotation, against the measurement: orders' powers relative L2 "
            f"{s['orders_relative_l2']:.4f} (noise "
            f"alone {s['orders_noise_l2']:.4f}), median |ln(measured / synthesised)| {s['orders_median_abs_log']:.4f}; "
            f"image relative L2 {s['image_relative_l2']:.4f} (noise alone {s['image_noise_l2']:.4f})."]
    if result.get("flat"):
        f = result["flat"]
        out += ["", "## Distance from the flat field", "", f"d = {fmt(f['distance_mm'])}", ""]
        out += [f"- along {a['axis']}: period {fmt(a['period_px'])}, {a['periods_in_frame']:.1f} periods, first "
                "harmonic "
                f"{fmt(a['a1'])} (predicted {a['a1_predicted']:.3g}: ratio {a['contrast_ratio']:.3g}, check "
                f"{a['check']}), d = {fmt(a['distance_mm'])}{'' if a['counts'] else ' (not counted)'}"
                for a in f["axes"]]
    if result.get("white"):
        w = result["white"]
        out += ["", "## γ and transmission from the white square", "",
                "γ R/Gr/Gb/B: " + ", ".join(fmt(g) for g in w["gamma"]) +
                f" (gain {w['gain']:g}, {w['pixels']} px per channel)",
                "the square {0} × {1} px, the region {2} × {3} px (its far field counted in the gains)".format(
                    *w["square_px"], *w["region_px"]),
                f"T(λ): {w['transmission']['type']}: " +
                ", ".join(f"{k} {fmt(v)}" for k, v in w["parameters"].items()),
                "γ it gives: " + "/".join(f"{g:.4f}" for g in w["gamma_model"])]
    if result.get("noise"):
        n = result["noise"]
        out += ["", "## Noise", "", f"{n['frames']} frames in {n['series']} series; per R/Gr/Gb/B:",
                "λ_read " + ", ".join(fmt(v) for v in n["lambda_read"]),
                "λ_shot " + ", ".join(fmt(v) for v in n["lambda_shot"])]
    if result["notes"]:
        out += ["", "## Notes", ""] + [f"- {n}" for n in result["notes"]]
    out += ["", f"Written: {', '.join(result['written'])}."]
    return "\n".join(out) + "\n"


def write_all(out: Path, result: dict, figure: dict) -> None:
    """fit.json, fit.md and fit.png (display.toml and sensor.toml are written by the caller)."""
    save_json(out / "fit.json", result)
    save_text(out / "fit.md", markdown(result))
    plot(out / "fit.png", **figure)
