"""Error-versus-run-time study of the far field (optics.far_field: the light past the kernel window).

    udc-render study far_field --out DIR [--quick]

Rig: the paper's (scenes/monitor.toml, astronaut, 2048 × 1024 px of 1.55 µm, the default margin's 513-px core
window; the far field needs the whole frame to land where it does on the paper's sensor), bands of 50 nm, d = 0,
noise off, exposure 0.03 s (`study capture`'s; nothing clips). Errors against a reference with the far field
everywhere: the relative L2 of the noise-free RAW (each display's; the ground truth's image for 'gt') and the
relative error of the frame's total light. kernel_s: the far kernels (psf.far, cache off); apply_s: synthesize()
with the kernels given (optics + sensor of glass and the display).

- ``threshold``: the lost share above which a view's band gets its far field (off, 0.02 … 0.0001) against 0
  (every band of every view, the bare lens's too), at the default coarse factor.
- ``coarse``: render pixels per coarse pixel c = 45 … 5 against 3, threshold 0 (T-OLED, P-OLED).

``quick``: the same frame at 256 × 128 px of 12.4 µm (the same ±0.4 mm core window, coarse pixels 8 × as
wide), two thresholds and one coarse factor against 5 (a smoke run).
"""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from udc_render.optics import displays as D
from udc_render.pipeline import SynthConfig, plan_kernels, synthesize
from udc_render.render import render_scene
from udc_render.scene import Bands, load_scene
from udc_render.scene.geometry import psf_lens
from udc_render.sensor import SensorConfig
from udc_render.studies.report import md_table, pyplot, save_plot, write_tables
from udc_render.synth_config import DEFAULT_FAR_FIELD_COARSE, DEFAULT_FAR_FIELD_THRESHOLD
from udc_render.synth_kernels import far_field

COLUMNS = ["study", "display", "setting", "reference", "rel_error", "light_error", "far_share", "kernel_s", "apply_s"]
FULL = {"sensor": (2048, 1024, 1.55), "thresholds": (None, 0.02, 0.01, 0.005, 0.001, 0.0001),
        "coarse": (45, 25, 15, 9, 5), "ref_coarse": 3}
QUICK = {"sensor": (256, 128, 12.4), "thresholds": (None, 0.005), "coarse": (15,), "ref_coarse": 5}
BASE = SynthConfig(sensor=SensorConfig(noise="none"), field_rank=None, use_cache=False)


def _base(cfg) -> SynthConfig:
    """`study capture`'s 0.03 s at 1.55 µm, scaled by the pixel's area (the same electrons per µm²)."""
    return replace(BASE, exposure_s=0.03 * (1.55 / cfg["sensor"][2]) ** 2)


def _scene(cfg):
    s = load_scene("monitor")
    w, h, p = cfg["sensor"]
    return replace(s, sensor=replace(s.sensor, width_px=w, height_px=h, pitch_um=p),
                   bands=Bands(range_nm=(400.0, 700.0), step_nm=50.0))


def _run(scene, band_image, display, synth_cfg, core) -> dict:
    """{view: image} (the display's noise-free RAW, the ground truth), far kernel seconds, apply seconds,
    the display's mean far share."""
    frame_um = (scene.sensor.width_px * scene.sensor.pitch_um, scene.sensor.height_px * scene.sensor.pitch_um)
    t0 = time.perf_counter()
    lens = psf_lens(scene, core.object_distance_m)
    layouts = {"glass": None, display.name: display.layout}
    far = {n: f for n, ks in core.band.items()
           if (f := far_field(layouts[n], lens, core.grid, ks, frame_um, synth_cfg)) is not None}
    t_far = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = synthesize(band_image, scene, [display], synth_cfg, kernels=replace(core, far=far))
    t_apply = time.perf_counter() - t0
    share = float(far[display.name].added.mean()) if display.name in far else 0.0
    return {"images": {display.name: res.captures[display.name].clean_dn.astype(np.float64),
                       "gt": res.gt.astype(np.float64)}, "kernel_s": t_far, "apply_s": t_apply, "far_share": share}


def _errors(run: dict, ref: dict) -> dict:
    out = {}
    for view, y in run["images"].items():
        r = ref["images"][view]
        out[view] = (float(np.linalg.norm(y - r) / np.linalg.norm(r)), float(y.sum() / r.sum() - 1))
    return out


def _label(threshold) -> str:
    return "off" if threshold is None else f"threshold {threshold:g}"


def run_study(out_dir, quick: bool = False, progress: bool = True) -> list[dict]:
    """Write study_far_field.{csv,md,png} into out_dir; returns the rows."""
    cfg = QUICK if quick else FULL
    scene = _scene(cfg)
    band_image = render_scene(scene, progress=False)
    rows = []
    jobs = [("threshold", d, t) for d in ("toled", "poled") for t in cfg["thresholds"]]
    jobs += [("coarse", d, c) for d in ("toled", "poled") for c in cfg["coarse"]]
    refs, cores, base = {}, {}, _base(cfg)
    for study, name, setting in tqdm(jobs, desc="study far_field", unit="run", disable=not progress):
        d = D.preset(name)
        if name not in cores:
            cores[name] = plan_kernels(scene, [d], replace(base, far_field_threshold=None, use_cache=True))
        ref_coarse = DEFAULT_FAR_FIELD_COARSE if study == "threshold" else cfg["ref_coarse"]
        key = (name, ref_coarse)
        if key not in refs:
            refs[key] = _run(scene, band_image, d, replace(base, far_field_threshold=0.0, far_field_coarse=ref_coarse),
                             cores[name])
        synth = (replace(base, far_field_threshold=setting) if study == "threshold"
                 else replace(base, far_field_threshold=0.0, far_field_coarse=setting))
        run = _run(scene, band_image, d, synth, cores[name])
        reference = f"threshold 0, c = {ref_coarse}"
        label = _label(setting) if study == "threshold" else f"c = {setting}"
        for view, (err, light) in _errors(run, refs[key]).items():
            if study == "coarse" and view == "gt":
                continue
            rows.append({"study": study, "display": view if view != "gt" else f"gt ({name} run)", "setting": label,
                         "reference": reference, "rel_error": err, "light_error": light,
                         "far_share": run["far_share"] if view != "gt" else None,
                         "kernel_s": round(run["kernel_s"], 3), "apply_s": round(run["apply_s"], 3)})
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_tables(out, "study_far_field", rows, COLUMNS, markdown(rows, cfg))
    plot(rows, out / "study_far_field.png")
    return rows


def markdown(rows: list[dict], cfg: dict) -> str:
    w, h, p = cfg["sensor"]
    lines = ["# The far field: error against run time", "",
             f"The paper's frame (astronaut, {w} × {h} px of {p} µm, 6 bands of 50 nm, d = 0, noise off). "
             "error: relative L2 of the noise-free RAW (gt: the ground truth's image) against the reference; "
             "light error: the frame's total light against it; far share: the display's mean share of the "
             "transmitted power the far field adds; kernel s: the far kernels (cache off); apply s: synthesize() "
             f"with them. Defaults: threshold {DEFAULT_FAR_FIELD_THRESHOLD:g}, c = {DEFAULT_FAR_FIELD_COARSE}. "
             "Regenerate with `udc-render study far_field --out DIR`.", ""]
    lines += md_table(rows, [("study", "study"), ("display", "view"), ("setting", "setting"),
                             ("reference", "reference"), ("rel_error", "error"), ("light_error", "light error"),
                             ("far_share", "far share"), ("kernel_s", "kernel s"), ("apply_s", "apply s")],
                      {"rel_error": lambda v: f"{v:.2e}", "light_error": lambda v: f"{v:+.2e}",
                       "far_share": lambda v: "" if v is None else f"{v:.2%}",
                       "kernel_s": lambda v: f"{v:.2f}", "apply_s": lambda v: f"{v:.2f}"})
    return "\n".join(lines) + "\n"


def plot(rows: list[dict], path: Path) -> None:
    """study_far_field.png: error against the threshold ('off' at the right), and against far kernel + apply
    seconds for the coarse factor (log-log)."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10.4, 4.0))
    for ax, st in zip(axes, ("threshold", "coarse")):
        for view in dict.fromkeys(r["display"] for r in rows if r["study"] == st):
            rs = [r for r in rows if r["study"] == st and r["display"] == view]
            e = [max(float(r["rel_error"]), 1e-7) for r in rs]
            if st == "threshold":
                x = [0.1 if r["setting"] == "off" else float(r["setting"].split()[-1]) for r in rs]
            else:
                x = [float(r["kernel_s"]) + float(r["apply_s"]) for r in rs]
            ax.loglog(x, e, "o-", label=view)
            if st == "coarse":
                for xi, ei, r in zip(x, e, rs):
                    ax.annotate(r["setting"], (xi, ei), fontsize=7, textcoords="offset points", xytext=(3, 3))
        ax.set_title("far field: threshold (0.1 = off; errors below 1e-7 drawn at it)" if st == "threshold"
                     else "far field: coarse factor c", fontsize=9)
        ax.set_xlabel("threshold (lost share)" if st == "threshold" else "seconds (far kernels + synthesis)")
        ax.set_ylabel("rel. L2 of the RAW")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    save_plot(fig, path)
