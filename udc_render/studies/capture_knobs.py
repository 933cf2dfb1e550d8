"""Error-versus-run-time study of the capture synthesis's approximations.

    udc-render study capture --out DIR [--quick]

Scene: the default rig (scenes/monitor.toml, astronaut) on a 512 × 256 px sensor of 1.55 µm (the
paper's pitch, so kernels are the real 513 px; the camera is placed to fit the monitor in this
smaller frame). Noise off: every error is the approximation's alone. Error = ‖y − y_ref‖₂ / ‖y_ref‖₂
of the noise-free RAW mosaic (clean_dn) over the frame, for each display; time = seconds of
synthesize() for that display with the kernels computed (cache off: ``kernel_s``) and applied
(``apply_s``: optics + sensor, kernels loaded from the cache; each run has its own empty cache). Knobs, each against its own reference:

- ``bands``: K bands of step 50, 30, 20, 10 nm vs a 5 nm reference (60 bands), T-OLED and P-OLED,
  d = 0. The render is the same RGB render turned into bands by the primaries matrix (exact), so
  only the wavelength sampling of kernels, T(λ) and the sensitivities differs.
- ``channel``: the paper's per-channel form (3 camera-weighted kernels and the analytic γ of the
  display) vs the per-band reference: the error of collapsing wavelength into 3 channels.
- ``phases``: field phases P = 1, 2, 3, 4, 6 per axis at d = 1 mm (T-OLED, 6 bands of 50 nm) vs P = 8.
- ``precision``: float32 vs float64 optics FFTs and kernels (T-OLED, 10 nm bands).
- ``supersample``: render.supersample s = 1, 2 vs 3 (T-OLED and glass, 6 bands): the render pixel's
  box and the kernel's pixel integration count the sensor pixel twice at s = 1 (pipeline.py).

Outputs: study_capture.csv, study_capture.md (tables and the defaults they justify), study_capture.png.
``quick``: 128 × 64 px of 6.2 µm, fewer settings (a smoke run, about 70 s on 2 cores).
"""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from udc_render.optics import displays as D
from udc_render.io.files import csv_text, save_figure, save_text
from udc_render.render import render_scene
from udc_render.scene import Bands, load_scene
from udc_render.sensor import SensorConfig
from udc_render.pipeline import SynthConfig, synthesize

COLUMNS = ["study", "display", "setting", "reference", "rel_error", "kernel_s", "apply_s"]
FULL = {"sensor": (512, 256, 1.55), "steps": (50, 30, 20, 10), "ref_step": 5, "phases": (1, 2, 3, 4, 6),
        "ref_phases": 8, "supersample": (1, 2), "ref_supersample": 3}
QUICK = {"sensor": (128, 64, 6.2), "steps": (100,), "ref_step": 50, "phases": (1, 2), "ref_phases": 3,
         "supersample": (1,), "ref_supersample": 2}


def _scene(cfg, step_nm: float, supersample: int = 1):
    s = load_scene("monitor")
    w, h, p = cfg["sensor"]
    return replace(s, sensor=replace(s.sensor, width_px=w, height_px=h, pitch_um=p),
                   bands=Bands(range_nm=(400.0, 700.0), step_nm=float(step_nm))).with_render(supersample=supersample)


def _run(scene, band_image, display, synth_cfg):
    """(clean mosaic, kernel seconds, apply seconds) of one display: the kernels computed without a
    cache (timed), then the synthesis with them (timed)."""
    from udc_render.pipeline import plan_kernels
    t0 = time.perf_counter()
    kernels = plan_kernels(scene, [display], replace(synth_cfg, use_cache=False))
    t_kernels = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = synthesize(band_image, scene, [display], synth_cfg, kernels=kernels)
    t_apply = time.perf_counter() - t0
    return res.captures[display.name].clean_dn.astype(np.float64), t_kernels, t_apply


def _err(y, ref) -> float:
    return float(np.linalg.norm(y - ref) / np.linalg.norm(ref))


def _as_file(d: D.Display) -> D.Display:
    """The preset with the analytic γ (its own kernels and T(λ)) instead of the paper's measured γ."""
    return replace(d, source="study")


def run_study(out_dir, quick: bool = False, progress: bool = True) -> list[dict]:
    from tqdm import tqdm
    cfg = QUICK if quick else FULL
    out = Path(out_dir)
    base = SynthConfig(sensor=SensorConfig(noise="none"), exposure_s=0.03)
    rows: list[dict] = []
    renders = {}

    def render(step, ss=1):
        if (step, ss) not in renders:
            sc = _scene(cfg, step, ss)
            renders[(step, ss)] = (sc, render_scene(sc, progress=False))
        return renders[(step, ss)]

    toled, poled, glass = D.preset("toled"), D.preset("poled"), D.preset("glass")
    jobs = [("bands", d, s) for d in (toled, poled) for s in cfg["steps"]] + [("channel", d, None) for d in (toled, poled)]
    jobs += [("phases", toled, p) for p in cfg["phases"]] + [("precision", toled, p) for p in ("float32", "float64")]
    jobs += [("supersample", d, s) for d in (toled, glass) for s in cfg["supersample"]]
    bar = tqdm(total=len(jobs), desc="study capture", unit="run", disable=not progress)
    refs = {}
    for study, d, setting in jobs:
        if study in ("bands", "channel"):
            ref_key = ("bands", d.name)
            if ref_key not in refs:
                sc, bi = render(cfg["ref_step"])
                refs[ref_key] = (_run(sc, bi, d, base)[0], f"{cfg['ref_step']} nm bands")
            if study == "bands":
                sc, bi = render(setting)
                y, tk, ta = _run(sc, bi, d, base)
                label = f"{setting} nm ({len(bi.centres_nm)} bands)"
            else:
                sc, bi = render(10)
                y, tk, ta = _run(sc, bi, _as_file(d), replace(base, form="per_channel"))
                label = "3 channel kernels, analytic γ"
        elif study == "phases":
            sc, bi = render(50)
            dd = d.with_distance(1.0)
            ref_key = ("phases", cfg["ref_phases"])
            if ref_key not in refs:
                refs[ref_key] = (_run(sc, bi, dd, replace(base, field_phases=cfg["ref_phases"]))[0],
                                 f"P = {cfg['ref_phases']}")
            y, tk, ta = _run(sc, bi, dd, replace(base, field_phases=setting))
            label = f"P = {setting} (d = 1 mm)"
        elif study == "precision":
            sc, bi = render(10)
            ref_key = ("precision",)
            if ref_key not in refs:
                refs[ref_key] = (_run(sc, bi, d, replace(base, precision="float64", kernel_precision="float64"))[0],
                                 "float64 kernels and FFTs")
            y, tk, ta = _run(sc, bi, d, replace(base, precision=setting, kernel_precision=setting))
            label = setting
        else:
            ref_key = ("supersample", d.name)
            if ref_key not in refs:
                sc, bi = render(50, cfg["ref_supersample"])
                refs[ref_key] = (_run(sc, bi, d, base)[0], f"s = {cfg['ref_supersample']}")
            sc, bi = render(50, setting)
            y, tk, ta = _run(sc, bi, d, base)
            label = f"s = {setting}"
        ref, ref_label = refs[ref_key]
        rows.append({"study": study, "display": d.name, "setting": label, "reference": ref_label,
                     "rel_error": _err(y, ref), "kernel_s": round(tk, 3), "apply_s": round(ta, 3)})
        bar.update()
    bar.close()
    out.mkdir(parents=True, exist_ok=True)
    save_text(out / "study_capture.csv", csv_text(rows, COLUMNS))
    save_text(out / "study_capture.md", markdown(rows, cfg))
    plot(rows, out / "study_capture.png")
    return rows


def markdown(rows: list[dict], cfg: dict) -> str:
    w, h, p = cfg["sensor"]
    lines = ["# Capture synthesis: error against run time", "",
             f"Default rig, astronaut, {w} × {h} px of {p} µm, noise off. Error: relative L2 of the noise-free "
             "RAW against each study's reference; kernel_s: computing the kernels (cache off); apply_s: "
             "optics + sensor with cached kernels. Regenerate with `udc-render study capture --out DIR`.", "",
             "| study | display | setting | reference | rel. error | kernel s | apply s |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['study']} | {r['display']} | {r['setting']} | {r['reference']} | {r['rel_error']:.2e} | "
                     f"{r['kernel_s']:.2f} | {r['apply_s']:.2f} |")
    return "\n".join(lines) + "\n"


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    studies = list(dict.fromkeys(r["study"] for r in rows))
    fig, axes = plt.subplots(1, len(studies), figsize=(4.2 * len(studies), 3.8), squeeze=False)
    for ax, st in zip(axes[0], studies):
        for disp in dict.fromkeys(r["display"] for r in rows if r["study"] == st):
            rs = [r for r in rows if r["study"] == st and r["display"] == disp]
            t = [r["kernel_s"] + r["apply_s"] for r in rs]
            e = [max(r["rel_error"], 1e-9) for r in rs]
            ax.loglog(t, e, "o-", label=disp)
            for ti, ei, r in zip(t, e, rs):
                ax.annotate(r["setting"].split(" (")[0], (ti, ei), fontsize=7, textcoords="offset points", xytext=(3, 3))
        ax.set_title(st)
        ax.set_xlabel("seconds (kernels + apply)")
        ax.set_ylabel("relative L2 error of the RAW")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    save_figure(fig, path)
    plt.close(fig)
