"""Error-versus-run-time study of the capture synthesis's approximations.

    udc-render study capture --out DIR [--quick]

Scene: the default rig (scenes/monitor.toml, astronaut) on a 512 × 256 px sensor of 1.55 µm (the
paper's pitch, so kernels are the real 513 px; the camera is placed to fit the monitor in this
smaller frame). Noise off: every error is the approximation's alone. Error = ‖y − y_ref‖₂ / ‖y_ref‖₂
of the noise-free RAW mosaic (clean_dn) over the frame, for each display; time = seconds of
synthesize() for that display with the kernels computed (cache off: ``kernel_s``) and applied
(``apply_s``: optics + sensor, kernels loaded from the cache; each run has its own empty cache).
Knobs, each against its own reference:

- ``bands``: K bands of step 50, 30, 20, 10 nm vs a 5 nm reference (60 bands), T-OLED and P-OLED,
  d = 0. The render is the same RGB render turned into bands by the primaries matrix (exact), so
  only the wavelength sampling of kernels, T(λ) and the sensitivities differs.
- ``channel``: the paper's per-channel form (3 camera-weighted kernels and the analytic γ of the
  display) vs the per-band reference: the error of collapsing wavelength into 3 channels.
- ``phases``: field phases P = 1, 2, 3, 4, 6 per axis at d = 1 mm (T-OLED, 6 bands of 50 nm) vs P = 8.
- ``field_rank``: the field-dependent convolution with a rank-r basis of each band's phase kernels
  (optics.field.phase_basis), r = 1, 2, 3, 4, against every phase (P = 4), at the physical
  profile's d (T-OLED and P-OLED, 6 bands of 50 nm). apply_s is what the rank saves.
- ``precision``: float32 vs float64 optics FFTs and kernels (T-OLED, 10 nm bands).
- ``supersample``: render.supersample s = 1, 2 vs 3 (T-OLED and glass, 6 bands): the render pixel's
  box and the kernel's pixel integration count the sensor pixel twice at s = 1 (pipeline.py).
- ``layers`` and ``bright`` (studies.capture_depth, their own small scenes): the defocus tolerance of the
  depth layers against a per-pixel reference, and the sun in frame with and without its float64 split.

Outputs: study_capture.csv, study_capture.md (tables and the defaults they justify), study_capture.png.
``quick``: 128 × 64 px of 6.2 µm, fewer settings (a smoke run, 5 min on 2 cores: every kernel is computed with
the cache off).
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
from udc_render.sensor import SensorConfig
from udc_render.studies import capture_depth
from udc_render.studies.report import md_table, pyplot, save_plot, write_tables

COLUMNS = ["study", "display", "setting", "reference", "metric", "rel_error", "frame_error", "kernel_s", "apply_s"]
FULL = {"sensor": (512, 256, 1.55), "steps": (50, 30, 20, 10), "ref_step": 5, "phases": (1, 2, 3, 4, 6),
        "ref_phases": 8, "supersample": (1, 2), "ref_supersample": 3, "ranks": (1, 2, 3, 4)}
QUICK = {"sensor": (128, 64, 6.2), "steps": (100,), "ref_step": 50, "phases": (1, 2), "ref_phases": 3,
         "supersample": (1,), "ref_supersample": 2, "ranks": (1,)}


def _scene(cfg, step_nm: float, supersample: int = 1):
    s = load_scene("monitor")
    w, h, p = cfg["sensor"]
    return replace(s, sensor=replace(s.sensor, width_px=w, height_px=h, pitch_um=p),
                   bands=Bands(range_nm=(400.0, 700.0), step_nm=float(step_nm))).with_render(supersample=supersample)


def _run(scene, band_image, display, synth_cfg):
    """(clean mosaic, kernel seconds, apply seconds) of one display: the kernels computed without a
    cache (timed), then the synthesis with them (timed)."""
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


class _Runs:
    """The renders (one per band step and supersampling) and the references, each made once."""

    def __init__(self, cfg: dict):
        self.cfg = cfg
        # field_rank None (every phase, exact): each knob's error alone
        self.base = SynthConfig(sensor=SensorConfig(noise="none"), exposure_s=0.03, field_rank=None)
        self.renders: dict = {}
        self.refs: dict = {}

    def render(self, step_nm: float, supersample: int = 1):
        """(scene, BandImage) at step_nm bands and render.supersample."""
        if (step_nm, supersample) not in self.renders:
            sc = _scene(self.cfg, step_nm, supersample)
            self.renders[(step_nm, supersample)] = (sc, render_scene(sc, progress=False))
        return self.renders[(step_nm, supersample)]

    def reference(self, key: tuple, label: str, make) -> tuple:
        """(clean mosaic, label) of reference `key`, made by make() → _run(...) the first time."""
        if key not in self.refs:
            self.refs[key] = (make()[0], label)
        return self.refs[key]

    def _bands_reference(self, d: D.Display) -> tuple:
        return self.reference(("bands", d.name), f"{self.cfg['ref_step']} nm bands",
                              lambda: _run(*self.render(self.cfg["ref_step"]), d, self.base))

    def bands(self, d: D.Display, step_nm: float):
        """K bands of step_nm against the ref_step bands."""
        ref = self._bands_reference(d)
        sc, bi = self.render(step_nm)
        return ref, _run(sc, bi, d, self.base), f"{step_nm} nm ({len(bi.centres_nm)} bands)"

    def channel(self, d: D.Display, _setting=None):
        """The per-channel form (3 kernels, the analytic γ) of 10 nm bands against the ref_step bands."""
        ref = self._bands_reference(d)
        sc, bi = self.render(10)
        return (ref, _run(sc, bi, _as_file(d), replace(self.base, form="per_channel")),
                "3 channel kernels, analytic γ")

    def phases(self, d: D.Display, p: int):
        """P field phases per axis at d = 1 mm against ref_phases."""
        sc, bi = self.render(50)
        dd = d.with_distance(1.0)
        ref_p = self.cfg["ref_phases"]
        ref = self.reference(("phases", ref_p), f"P = {ref_p}",
                             lambda: _run(sc, bi, dd, replace(self.base, field_phases=ref_p)))
        return ref, _run(sc, bi, dd, replace(self.base, field_phases=p)), f"P = {p} (d = 1 mm)"

    def field_rank(self, d: D.Display, rank: int):
        """A rank-r basis of the phase kernels at the physical profile's d against every phase (P = 4)."""
        from udc_render.profiles import PHYSICAL_DISTANCE_MM
        sc, bi = self.render(50)
        dd = d.with_distance(PHYSICAL_DISTANCE_MM)
        ref = self.reference(("field_rank", d.name), "every phase (P = 4)", lambda: _run(sc, bi, dd, self.base))
        return (ref, _run(sc, bi, dd, replace(self.base, field_rank=rank)),
                f"rank {rank} (d = {PHYSICAL_DISTANCE_MM:g} mm)")

    def precision(self, d: D.Display, precision: str):
        """Optics FFTs and kernels in `precision` against float64."""
        sc, bi = self.render(10)
        ref = self.reference(("precision",), "float64 kernels and FFTs",
                             lambda: _run(sc, bi, d, replace(self.base, precision="float64",
                                                             kernel_precision="float64")))
        return ref, _run(sc, bi, d, replace(self.base, precision=precision, kernel_precision=precision)), precision

    def supersample(self, d: D.Display, s: int):
        """render.supersample s against ref_supersample (6 bands of 50 nm)."""
        ref_s = self.cfg["ref_supersample"]
        ref = self.reference(("supersample", d.name), f"s = {ref_s}",
                             lambda: _run(*self.render(50, ref_s), d, self.base))
        return ref, _run(*self.render(50, s), d, self.base), f"s = {s}"


def _jobs(cfg: dict) -> list[tuple]:
    """(study, display, setting) in run order."""
    toled, poled, glass = D.preset("toled"), D.preset("poled"), D.preset("glass")
    jobs = [("bands", d, s) for d in (toled, poled) for s in cfg["steps"]]
    jobs += [("channel", d, None) for d in (toled, poled)]
    jobs += [("phases", toled, p) for p in cfg["phases"]] + [("precision", toled, p) for p in ("float32", "float64")]
    jobs += [("field_rank", d, r) for d in (toled, poled) for r in cfg["ranks"]]
    return jobs + [("supersample", d, s) for d in (toled, glass) for s in cfg["supersample"]]


def run_study(out_dir, quick: bool = False, progress: bool = True) -> list[dict]:
    """Run every knob against its reference, write study_capture.{csv,md,png} into out_dir, return the rows."""
    cfg = QUICK if quick else FULL
    out = Path(out_dir)
    runs = _Runs(cfg)
    jobs = _jobs(cfg)
    rows: list[dict] = []
    for study, d, setting in tqdm(jobs, desc="study capture", unit="run", disable=not progress):
        (ref, ref_label), (y, tk, ta), label = getattr(runs, study)(d, setting)
        rows.append({"study": study, "display": d.name, "setting": label, "reference": ref_label,
                     "metric": "rel. L2 of the RAW", "rel_error": _err(y, ref), "kernel_s": round(tk, 3),
                     "apply_s": round(ta, 3)})
    rows += capture_depth.layer_rows(capture_depth.QUICK if quick else capture_depth.FULL)
    rows += capture_depth.bright_rows(capture_depth.QUICK if quick else capture_depth.FULL)
    out.mkdir(parents=True, exist_ok=True)
    write_tables(out, "study_capture", rows, COLUMNS, markdown(rows, cfg))
    plot(rows, out / "study_capture.png")
    return rows


def markdown(rows: list[dict], cfg: dict) -> str:
    """study_capture.md: the set-up and one table row per run."""
    w, h, p = cfg["sensor"]
    lines = ["# Capture synthesis: error against run time", "",
             f"Default rig, astronaut, {w} × {h} px of {p} µm, noise off. Error: relative L2 of the noise-free "
             "RAW against each study's reference; kernel_s: computing the kernels (cache off); apply_s: "
             "optics + sensor with cached kernels. Regenerate with `udc-render study capture --out DIR`.",
             "", "`layers` and `bright` use their own small scenes (udc_render/studies/capture_depth.py): "
             "`layers` is the relative L2 of the electrons within 8 px of a near ramp's outline against the "
             "per-pixel reference (frame error: the whole frame), apply s the layered optics; `bright` is the "
             "largest error over the pixel's own noise √(σ_read² + e) with the sun in frame.", ""]
    lines += md_table(rows, [("study", "study"), ("display", "display"), ("setting", "setting"),
                             ("reference", "reference"), ("metric", "metric"), ("rel_error", "error"),
                             ("frame_error", "frame error"), ("kernel_s", "kernel s"), ("apply_s", "apply s")],
                      {"rel_error": lambda v: f"{v:.2e}", "frame_error": lambda v: "" if v is None else f"{v:.2e}",
                       "kernel_s": lambda v: f"{v:.2f}", "apply_s": lambda v: f"{v:.2f}"})
    return "\n".join(lines) + "\n"


def plot(rows: list[dict], path: Path) -> None:
    """study_capture.png: RAW error vs kernel + apply seconds, one log-log panel per study."""
    plt = pyplot()
    studies = list(dict.fromkeys(r["study"] for r in rows))
    fig, axes = plt.subplots(1, len(studies), figsize=(4.2 * len(studies), 3.8), squeeze=False)
    for ax, st in zip(axes[0], studies):
        for disp in dict.fromkeys(r["display"] for r in rows if r["study"] == st):
            rs = [r for r in rows if r["study"] == st and r["display"] == disp]
            t = [r["kernel_s"] + r["apply_s"] for r in rs]
            e = [max(r["rel_error"], 1e-9) for r in rs]
            ax.loglog(t, e, "o-", label=disp)
            for ti, ei, r in zip(t, e, rs):
                ax.annotate(r["setting"].split(" (")[0], (ti, ei), fontsize=7, textcoords="offset points",
                            xytext=(3, 3))
        ax.set_title(st)
        ax.set_xlabel("seconds (kernels + apply)")
        ax.set_ylabel(rs[0]["metric"])
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    save_plot(fig, path)
