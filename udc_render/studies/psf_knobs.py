"""Error-versus-run-time study of every approximation knob of the PSF engine.

    udc-render study psf --out DIR [--quick]

Each knob is varied with everything else at the paper's rig defaults (Lens(): f = 6 mm, f/1.8;
3.1 µm pixels; 255² kernels; T-OLED display, and P-OLED for the pupil knob). For every setting
the study records the error against a converged reference and the run time (median of repeated
runs timed with time.perf_counter), one row per setting:

    knob, display, value, error_L1, error_max_rel, energy_outside, time_s, is_default, ...

error_L1 = Σ|k − k_ref| over unit-sum kernels (maximum over the wavelengths or bands of a run),
error_max_rel = max|k − k_ref| / max k_ref (maximum over the wavelengths or bands),
energy_outside = the engine's fraction of the transmitted power outside the window (maximum).

Outputs in DIR: study_psf.csv, study_psf.md (one table per knob) and study_psf.png (error vs
time per knob, log-log; psf_report.py). Every file is written to a temporary name beside it and
renamed into place. --quick runs a reduced grid (small kernels and pupils, one repeat) as a smoke
test. The grids and the rig: psf_config.py; the error metrics: psf_metrics.py.
"""
from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from tqdm.auto import tqdm

from psf import Lens, compute_kernels, layouts
from psf.engine import auto_pupil_samples
from psf.spectral import auto_step_nm, band_kernels
from udc_render.studies.psf_config import BANDS_NM, FULL, PIXEL_UM, QUICK, WAVELENGTHS_NM, Config
from udc_render.studies.psf_metrics import (
    banding_amplitude,
    basic_errors,
    compare_field,
    compare_size,
    compare_with_aux,
)
from udc_render.studies.psf_report import write_report
from udc_render.studies.report import Timed, load_average, timed


@dataclass
class Job:
    """One timed setting: fn() returns a KernelSet; compare(ks) returns the error columns."""
    knob: str
    display: str
    series: str
    value: object
    fn: Callable
    is_default: bool
    compare: Callable
    share: str | None = None  # jobs with the same key make the identical call: measured once, reused


@dataclass
class Sweep:
    """What the jobs share: the grid, the lens, the displays and the references (filled before any job runs)."""
    cfg: Config
    lens: Lens
    displays: dict
    refs: dict = field(default_factory=dict)

    def kernels(self, display: str, wavelengths_nm, size_px: int, **kw):
        """compute_kernels of `display` at PIXEL_UM with the study's lens."""
        return compute_kernels(self.displays[display], self.lens, wavelengths_nm, PIXEL_UM, size_px, **kw)

    def bands(self, step_nm: float | None):
        """T-OLED band_kernels of BANDS_NM sampled every step_nm (None: the engine's auto step)."""
        return band_kernels(self.displays["toled"], self.lens, BANDS_NM, step_nm=step_nm, pixel_um=PIXEL_UM,
                            size_px=self.cfg.band_size, pupil_samples=self.cfg.band_n)

    def field_kernels(self, phases: int):
        """T-OLED kernels at d = field_distance_mm with `phases` field phases per axis."""
        c = self.cfg
        return self.kernels("toled", [c.field_wavelength_nm], c.field_size, distance_mm=c.field_distance_mm,
                            field_phases=phases, pupil_samples=c.field_n)

    def ref_kernels(self, key: tuple):
        """A callable returning the reference `key`'s kernels (looked up when a job compares)."""
        return lambda: self.refs[key].kernels


# ----------------------------------------------------------------------------------------------
# The references and the sweeps, one function per knob


def reference_specs(sw: Sweep) -> dict:
    """(knob, display) → the converged reference call (run once, timed for the table headers)."""
    c = sw.cfg
    return {
        ("pupil", "toled"): lambda: sw.kernels("toled", WAVELENGTHS_NM, c.size_px, pupil_samples=c.pupil_ref_n,
                                               precision="float64"),
        ("pupil", "poled"): lambda: sw.kernels("poled", WAVELENGTHS_NM, c.size_px, pupil_samples=c.pupil_ref_n,
                                               precision="float64"),
        ("band", "toled"): lambda: sw.bands(c.band_ref_step),
        ("field", "toled"): lambda: sw.field_kernels(c.field_ref_p),
        ("size", "toled"): lambda: sw.kernels("toled", WAVELENGTHS_NM, c.size_ref, pupil_samples=c.size_n),
    }


def pupil_jobs(sw: Sweep) -> list[Job]:
    """1. pupil samples N × mask raster, both displays."""
    c = sw.cfg
    return [Job("pupil_samples", d, raster, n,
                lambda d=d, r=raster, n=n: sw.kernels(d, WAVELENGTHS_NM, c.size_px, pupil_samples=n, mask_raster=r),
                n == c.default_n and raster == "band_limited",
                lambda ks, d=d: basic_errors(ks, sw.refs[("pupil", d)].kernels),
                share=f"{d}-{raster}-mft-{n}")
            for d in ("toled", "poled") for raster in ("band_limited", "area") for n in c.pupil_n]


def method_jobs(sw: Sweep) -> list[Job]:
    """2. Fraunhofer method; the paper recipe also against the float64 MFT at its own N."""
    c = sw.cfg
    return [Job("method", "toled", method, n,
                lambda m=method, n=n: sw.kernels("toled", WAVELENGTHS_NM, c.size_px, pupil_samples=n, method=m),
                method == "mft" and n == c.default_n,
                compare_with_aux(sw.ref_kernels(("pupil", "toled")),
                                 (lambda n=n: sw.kernels("toled", WAVELENGTHS_NM, c.size_px, pupil_samples=n,
                                                         precision="float64")) if method == "paper" else None),
                share=f"toled-band_limited-{method}-{n}")
            for method in ("mft", "czt", "paper") for n in c.method_n]


def precision_jobs(sw: Sweep) -> list[Job]:
    """3. float32 vs float64 at the default (auto) pupil sampling; float32 also against float64 at the same N."""
    c = sw.cfg
    n = None if not c.quick else c.default_n

    def run(precision):
        return lambda: sw.kernels("toled", WAVELENGTHS_NM, c.size_px, pupil_samples=n, precision=precision)
    ref = sw.ref_kernels(("pupil", "toled"))
    return [Job("precision", "toled", "auto N", "float32", run("float32"), True,
                compare_with_aux(ref, run("float64"))),
            Job("precision", "toled", "auto N", "float64", run("float64"), False,
                lambda ks: basic_errors(ks, ref()))]


def band_jobs(sw: Sweep) -> list[Job]:
    """4. wavelength step per band (None: the engine's auto step λ_lo / S, shown for the first band)."""
    c = sw.cfg
    return [Job("band_step_nm", "toled", "bands", step or auto_step_nm(BANDS_NM[0][0], c.band_size),
                lambda s=step: sw.bands(s), step is None,
                lambda ks: basic_errors(ks, sw.refs[("band", "toled")].kernels))
            for step in c.band_steps]


def field_jobs(sw: Sweep) -> list[Job]:
    """5. field phases P per axis at d = field_distance_mm."""
    c = sw.cfg
    return [Job("field_phases", "toled", "phases", p, lambda p=p: sw.field_kernels(p), p == c.default_p,
                compare_field(lambda: sw.refs[("field", "toled")], c.field_ref_p))
            for p in c.field_p]


def size_jobs(sw: Sweep) -> list[Job]:
    """6. kernel size S."""
    c = sw.cfg
    return [Job("size_px", "toled", "size", s,
                lambda s=s: sw.kernels("toled", WAVELENGTHS_NM, s, pupil_samples=c.size_n), s == c.default_size,
                compare_size(lambda: sw.refs[("size", "toled")]))
            for s in c.sizes]


# ----------------------------------------------------------------------------------------------
# Measuring


def measure_references(sw: Sweep, specs: dict, bar) -> dict:
    """Run each reference once into sw.refs; returns (knob, display) → time, warnings, params, energy_outside."""
    info = {}
    for key, fn in specs.items():
        bar.set_postfix_str(f"reference {key[0]} {key[1]}")
        t = timed(fn, 1, record_warnings=True, tick=lambda: bar.update(1))
        sw.refs[key] = ks = t.result
        info[key] = {"time_s": t.seconds[0], "warning": " | ".join(t.warnings), "params": ks.params,
                     "energy_outside": ks.energy_outside}
    return info


def measure_jobs(jobs: list[Job], repeats: int, bar) -> list[dict]:
    """One row per job: median and fastest of `repeats` timed runs, warnings, the job's errors."""
    rows: list[dict] = []
    measured: dict[str, Timed] = {}
    for job in jobs:
        bar.set_postfix_str(f"{job.knob} {job.display} {job.series} {job.value}")
        if job.share in measured:
            t = measured[job.share]
            bar.update(repeats)
        else:
            t = timed(job.fn, repeats, record_warnings=True, tick=lambda: bar.update(1))
            if job.share is not None:
                measured[job.share] = t
        rows.append(_row(job, t))
    return rows


def _row(job: Job, t: Timed) -> dict:
    ks = t.result
    row = {"knob": job.knob, "display": job.display, "series": job.series, "value": job.value,
           "time_s": statistics.median(t.seconds), "time_min_s": min(t.seconds), "repeats": len(t.seconds),
           "is_default": bool(job.is_default), "warning": " | ".join(t.warnings),
           "pupil_samples_used": ks.params["pupil_samples"],
           "pupil_shape": "x".join(str(v) for v in ks.params["pupil_shape"])}
    if job.knob == "band_step_nm":
        row["samples_per_band"] = len(ks.params["sample_wavelengths_nm"]) // len(BANDS_NM)
    row.update(job.compare(ks))
    return row


def run_study(out_dir: Path, quick: bool = False, progress: bool = True) -> list[dict]:
    """Run every knob's sweep, write study_psf.{csv,md,png} into out_dir and return the rows."""

    cfg = QUICK if quick else FULL
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    sw = Sweep(cfg, Lens(), {"toled": layouts.toled(), "poled": layouts.poled()})
    t_start = time.perf_counter()
    load_start = load_average()
    specs = reference_specs(sw)
    jobs = pupil_jobs(sw) + method_jobs(sw) + precision_jobs(sw) + band_jobs(sw) + field_jobs(sw) + size_jobs(sw)
    with tqdm(total=len(specs) + cfg.repeats * len(jobs), disable=not progress, desc="study psf", unit="run",
              dynamic_ncols=True) as bar:
        ref_info = measure_references(sw, specs, bar)
        rows = measure_jobs(jobs, cfg.repeats, bar)
    meta = {"elapsed_s": time.perf_counter() - t_start, "cfg": cfg, "refs": ref_info, "load_start": load_start,
            "load_end": load_average(),
            "auto_n": auto_pupil_samples(sw.lens, min(WAVELENGTHS_NM), PIXEL_UM, cfg.size_px),
            "banding_ref": banding_amplitude(sw.refs[("field", "toled")])}
    write_report(out_dir, rows, meta)
    return rows
