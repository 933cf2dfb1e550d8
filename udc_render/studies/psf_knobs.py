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
time per knob, log-log). Every file is written to a temporary name beside it and renamed into
place. --quick runs a reduced grid (small kernels and pupils, one repeat) as a smoke test.
"""
from __future__ import annotations

import math
import os
import platform
import statistics
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from psf import Lens, compute_kernels, layouts
from psf.engine import auto_pupil_samples
from psf.spectral import auto_step_nm, band_kernels
from udc_render.io.files import atomic_path, csv_text, save_text

PIXEL_UM = 3.1
SIZE_PX = 255
WAVELENGTHS_NM = (450.0, 520.0, 640.0)
BANDS_NM = ((400.0, 500.0), (500.0, 600.0), (600.0, 700.0))
TOLERANCE_L1 = 1e-3  # "good enough" line used for the recommendation per table

KNOB_TITLES = {
    "pupil_samples": "1. Pupil samples N (mask_raster band_limited vs area)",
    "method": "2. Fraunhofer method (mft / czt / paper)",
    "precision": "3. Precision (float32 vs float64)",
    "band_step_nm": "4. Wavelength samples per band (band_kernels step_nm)",
    "field_phases": "5. Field phases P at d = 1 mm",
    "size_px": "6. Kernel size S",
}

COLUMNS = ["knob", "display", "series", "value", "error_L1", "error_max_rel", "energy_outside", "time_s",
           "time_min_s", "repeats", "is_default", "warning", "pupil_samples_used", "pupil_shape",
           "samples_per_band", "field_kernel_L1_interp", "banding_err_interp", "banding_err_matched",
           "L1_vs_full_ref", "energy_outside_check", "L1_same_N_ref"]


@dataclass
class Config:
    """The grid of one study run (full or quick)."""
    quick: bool
    repeats: int
    size_px: int
    pupil_n: tuple
    pupil_ref_n: int
    method_n: tuple
    default_n: int  # the pupil_samples value that equals the engine's auto choice for this rig
    band_size: int
    band_n: int | None  # None: auto
    band_steps: tuple
    band_ref_step: float  # steps: None is the engine's auto step λ_lo / S (the default)
    field_size: int
    field_n: int
    field_p: tuple
    field_ref_p: int
    default_p: int
    field_distance_mm: float
    field_wavelength_nm: float
    sizes: tuple
    size_ref: int
    size_n: int | None  # None: auto (the engine default) for every size
    default_size: int


FULL = Config(quick=False, repeats=3, size_px=SIZE_PX, pupil_n=(768, 1024, 1536, 2048, 3072), pupil_ref_n=4096,
              method_n=(1024, 2048), default_n=1024, band_size=SIZE_PX, band_n=None, band_steps=(20, 10, 6, 3, 2, None),
              band_ref_step=1.0, field_size=127, field_n=1024, field_p=(1, 2, 3, 4, 6),
              field_ref_p=8, default_p=4, field_distance_mm=1.0, field_wavelength_nm=520.0,
              sizes=(63, 127, 255, 511), size_ref=1023, size_n=None, default_size=255)

QUICK = Config(quick=True, repeats=1, size_px=63, pupil_n=(256, 384), pupil_ref_n=512, method_n=(256,),
               default_n=256, band_size=63, band_n=256, band_steps=(50, None), band_ref_step=10.0,
               field_size=63, field_n=256, field_p=(1, 2), field_ref_p=4, default_p=2, field_distance_mm=1.0,
               field_wavelength_nm=520.0, sizes=(31, 63), size_ref=127, size_n=512, default_size=63)


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


# ----------------------------------------------------------------------------------------------
# Metrics


def kernel_errors(k, k_ref) -> tuple[float, float]:
    """(max over channels of Σ|k − k_ref|, max over channels of max|k − k_ref| / max k_ref)."""
    k = np.asarray(k, dtype=np.float64).reshape(-1, *np.shape(k)[-2:])
    r = np.asarray(k_ref, dtype=np.float64).reshape(-1, *np.shape(k_ref)[-2:])
    d = np.abs(k - r)
    l1 = d.sum(axis=(-2, -1))
    rel = d.max(axis=(-2, -1)) / r.max(axis=(-2, -1))
    return float(l1.max()), float(rel.max())


def crop_centre(k: np.ndarray, size: int) -> np.ndarray:
    """The size² centre of [..., S, S] kernels centred at S // 2 (size odd)."""
    s = k.shape[-1]
    lo = s // 2 - size // 2
    return k[..., lo:lo + size, lo:lo + size]


def periodic_bilinear(samples: np.ndarray, p_ref: int) -> np.ndarray:
    """Resample [P, P, ...] samples at shifts a/P (a = 0…P−1, periodic) onto the p_ref grid b/p_ref.

    Periodic bilinear interpolation between phases: what a renderer holding P phases would use
    at an image position between them. Returns [p_ref, p_ref, ...].
    """
    P = samples.shape[0]
    t = np.arange(p_ref) / p_ref * P
    i0 = np.floor(t).astype(int) % P
    i1 = (i0 + 1) % P
    w = t - np.floor(t)
    out = np.zeros((p_ref, p_ref) + samples.shape[2:])
    for jj in range(p_ref):
        for ii in range(p_ref):
            acc = 0.0
            for jy, wy in ((i0[jj], 1 - w[jj]), (i1[jj], w[jj])):
                for ix, wx in ((i0[ii], 1 - w[ii]), (i1[ii], w[ii])):
                    if wy * wx:
                        acc = acc + wy * wx * samples[jy, ix].astype(np.float64)
            out[jj, ii] = acc
    return out


def _basic(ks, ref_kernels) -> dict:
    l1, rel = kernel_errors(ks.kernels, ref_kernels)
    return {"error_L1": l1, "error_max_rel": rel, "energy_outside": float(np.max(ks.energy_outside))}


# ----------------------------------------------------------------------------------------------
# Study definition


def _displays():
    return {"toled": layouts.toled(), "poled": layouts.poled()}


def _timed(fn, repeats: int, tick) -> tuple[object, list[float], list[str]]:
    """Run fn() `repeats` times; (first result, times, unique warning lines)."""
    times, result, seen = [], None, []
    for r in range(repeats):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            t0 = time.perf_counter()
            out = fn()
            times.append(time.perf_counter() - t0)
        for w in caught:
            line = f"{w.category.__name__}: {w.message}"
            if line not in seen:
                seen.append(line)
        if r == 0:
            result = out
        del out
        tick()
    return result, times, seen


def run_study(out_dir: Path, quick: bool = False, progress: bool = True) -> list[dict]:
    """Run every knob's sweep, write study_psf.{csv,md,png} into out_dir and return the rows."""
    from tqdm.auto import tqdm

    cfg = QUICK if quick else FULL
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    lens = Lens()
    disp = _displays()
    t_start = time.perf_counter()
    load_start = os.getloadavg() if hasattr(os, "getloadavg") else None

    # Reference definitions (computed once, single run each, timed for the table headers).
    refs_spec = {
        ("pupil", "toled"): lambda: compute_kernels(disp["toled"], lens, WAVELENGTHS_NM, PIXEL_UM, cfg.size_px,
                                                   pupil_samples=cfg.pupil_ref_n, precision="float64"),
        ("pupil", "poled"): lambda: compute_kernels(disp["poled"], lens, WAVELENGTHS_NM, PIXEL_UM, cfg.size_px,
                                                   pupil_samples=cfg.pupil_ref_n, precision="float64"),
        ("band", "toled"): lambda: band_kernels(disp["toled"], lens, BANDS_NM, step_nm=cfg.band_ref_step,
                                                pixel_um=PIXEL_UM, size_px=cfg.band_size,
                                                pupil_samples=cfg.band_n),
        ("field", "toled"): lambda: compute_kernels(disp["toled"], lens, [cfg.field_wavelength_nm], PIXEL_UM,
                                                   cfg.field_size, distance_mm=cfg.field_distance_mm,
                                                   field_phases=cfg.field_ref_p, pupil_samples=cfg.field_n),
        ("size", "toled"): lambda: compute_kernels(disp["toled"], lens, WAVELENGTHS_NM, PIXEL_UM, cfg.size_ref,
                                                  pupil_samples=cfg.size_n),
    }
    refs: dict = {}
    ref_info: dict = {}

    def ref(key):
        return refs[key]

    jobs: list[Job] = []

    # 1. pupil samples × mask raster, both displays.
    for dname in ("toled", "poled"):
        for raster in ("band_limited", "area"):
            for n in cfg.pupil_n:
                jobs.append(Job("pupil_samples", dname, raster, n,
                                (lambda d=dname, r=raster, n=n: compute_kernels(
                                    disp[d], lens, WAVELENGTHS_NM, PIXEL_UM, cfg.size_px, pupil_samples=n,
                                    mask_raster=r)),
                                n == cfg.default_n and raster == "band_limited",
                                (lambda ks, d=dname: _basic(ks, ref(("pupil", d)).kernels)),
                                share=f"{dname}-{raster}-mft-{n}"))
    # 2. method.
    for method in ("mft", "czt", "paper"):
        for n in cfg.method_n:
            jobs.append(Job("method", "toled", method, n,
                            (lambda m=method, n=n: compute_kernels(disp["toled"], lens, WAVELENGTHS_NM, PIXEL_UM,
                                                                   cfg.size_px, pupil_samples=n, method=m)),
                            method == "mft" and n == cfg.default_n,
                            _compare_with_aux(lambda: ref(("pupil", "toled")).kernels,
                                              (lambda n=n: compute_kernels(
                                                  disp["toled"], lens, WAVELENGTHS_NM, PIXEL_UM, cfg.size_px,
                                                  pupil_samples=n, precision="float64"))
                                              if method == "paper" else None),
                            share=f"toled-band_limited-{method}-{n}"))
    # 3. precision at the default (auto) pupil sampling.
    for prec in ("float32", "float64"):
        jobs.append(Job("precision", "toled", "auto N", prec,
                        (lambda p=prec: compute_kernels(disp["toled"], lens, WAVELENGTHS_NM, PIXEL_UM, cfg.size_px,
                                                        pupil_samples=None if not cfg.quick else cfg.default_n,
                                                        precision=p)),
                        prec == "float32",
                        _compare_with_aux(lambda: ref(("pupil", "toled")).kernels,
                                          lambda: compute_kernels(disp["toled"], lens, WAVELENGTHS_NM, PIXEL_UM,
                                                                  cfg.size_px, pupil_samples=None if not cfg.quick
                                                                  else cfg.default_n, precision="float64"))
                        if prec == "float32" else (lambda ks: _basic(ks, ref(("pupil", "toled")).kernels))))
    # 4. wavelength step per band.
    for step in cfg.band_steps:
        shown = step or auto_step_nm(BANDS_NM[0][0], cfg.band_size)  # auto: λ_lo / S of the first band
        jobs.append(Job("band_step_nm", "toled", "bands", shown,
                        (lambda s=step: band_kernels(disp["toled"], lens, BANDS_NM, step_nm=s, pixel_um=PIXEL_UM,
                                                     size_px=cfg.band_size, pupil_samples=cfg.band_n)),
                        step is None,
                        (lambda ks: _basic(ks, ref(("band", "toled")).kernels))))
    # 5. field phases.
    for p in cfg.field_p:
        jobs.append(Job("field_phases", "toled", "phases", p,
                        (lambda p=p: compute_kernels(disp["toled"], lens, [cfg.field_wavelength_nm], PIXEL_UM,
                                                     cfg.field_size, distance_mm=cfg.field_distance_mm,
                                                     field_phases=p, pupil_samples=cfg.field_n)),
                        p == cfg.default_p, _compare_field(lambda: ref(("field", "toled")), cfg.field_ref_p)))
    # 6. kernel size.
    for s in cfg.sizes:
        jobs.append(Job("size_px", "toled", "size", s,
                        (lambda s=s: compute_kernels(disp["toled"], lens, WAVELENGTHS_NM, PIXEL_UM, s,
                                                     pupil_samples=cfg.size_n)),
                        s == cfg.default_size, _compare_size(lambda: ref(("size", "toled")))))

    total = len(refs_spec) + sum(cfg.repeats for _ in jobs)
    rows: list[dict] = []
    measured: dict = {}
    with tqdm(total=total, disable=not progress, desc="study psf", unit="run", dynamic_ncols=True) as bar:
        tick = lambda: bar.update(1)  # noqa: E731
        for key, fn in refs_spec.items():
            bar.set_postfix_str(f"reference {key[0]} {key[1]}")
            ks, times, warn = _timed(fn, 1, tick)
            refs[key] = ks
            ref_info[key] = {"time_s": times[0], "warning": " | ".join(warn), "params": ks.params,
                             "energy_outside": ks.energy_outside}
        for job in jobs:
            bar.set_postfix_str(f"{job.knob} {job.display} {job.series} {job.value}")
            if job.share in measured:
                ks, times, warn = measured[job.share]
                bar.update(cfg.repeats)
            else:
                ks, times, warn = _timed(job.fn, cfg.repeats, tick)
                if job.share is not None:
                    measured[job.share] = (ks, times, warn)
            row = {"knob": job.knob, "display": job.display, "series": job.series, "value": job.value,
                   "time_s": statistics.median(times), "time_min_s": min(times), "repeats": len(times),
                   "is_default": bool(job.is_default), "warning": " | ".join(warn),
                   "pupil_samples_used": ks.params["pupil_samples"],
                   "pupil_shape": "x".join(str(v) for v in ks.params["pupil_shape"])}
            if job.knob == "band_step_nm":
                row["samples_per_band"] = len(ks.params["sample_wavelengths_nm"]) // len(BANDS_NM)
            row.update(job.compare(ks))
            rows.append(row)
            del ks

    elapsed = time.perf_counter() - t_start
    meta = {"elapsed_s": elapsed, "cfg": cfg, "refs": ref_info, "load_start": load_start,
            "load_end": os.getloadavg() if hasattr(os, "getloadavg") else None,
            "auto_n": auto_pupil_samples(lens, min(WAVELENGTHS_NM), PIXEL_UM, cfg.size_px),
            "banding_ref": _banding_amplitude(refs[("field", "toled")])}
    save_text(out_dir / "study_psf.csv", csv_text(rows, COLUMNS))
    save_text(out_dir / "study_psf.md", _markdown(rows, meta))
    _plot(rows, out_dir / "study_psf.png", cfg)
    return rows


def _banding_amplitude(ks) -> float:
    return float(np.max(np.abs(ks.field_power - 1.0))) if ks.field_power is not None else 0.0


def _compare_with_aux(get_ref_kernels, aux_fn):
    """Error against the shared reference, plus L1_same_N_ref against aux_fn()'s kernels (untimed).

    aux_fn is an isolating reference at the run's own pupil sampling (the float64 MFT run at the
    same N: for the precision knob and for the paper recipe).
    """
    def compare(ks):
        out = _basic(ks, get_ref_kernels())
        if aux_fn is not None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                aux = aux_fn().kernels
            out["L1_same_N_ref"] = kernel_errors(ks.kernels, aux)[0]
        return out
    return compare


def _compare_field(get_ref, p_ref: int):
    def compare(ks):
        r = get_ref()
        out = _basic(ks, r.kernels)
        P = ks.field_kernels.shape[1]
        period = np.asarray(r.params["display"].get("pitch_x_um", np.nan)), \
            np.asarray(r.params["display"].get("pitch_y_um", np.nan))
        expect = lambda q: np.stack(np.meshgrid(np.arange(q) / q * period[0], np.arange(q) / q * period[1]),
                                    axis=-1)  # noqa: E731
        if not (np.allclose(ks.field_shifts_um, expect(P)) and np.allclose(r.field_shifts_um, expect(p_ref))):
            # The engine sampled shifts that are not whole-period fractions (sensor sees < 1 period):
            # the phase grids are not comparable; keep the averaged-kernel error only.
            return out
        fk = periodic_bilinear(ks.field_kernels[0], p_ref)  # [p_ref, p_ref, S, S]
        rk = r.field_kernels[0].astype(np.float64)
        out["field_kernel_L1_interp"] = float(np.abs(fk - rk).sum(axis=(-2, -1)).max())
        fp = periodic_bilinear(ks.field_power[0], p_ref)
        out["banding_err_interp"] = float(np.abs(fp - r.field_power[0]).max())
        if p_ref % P == 0:
            step = p_ref // P
            matched = r.field_power[0][::step, ::step]
            out["banding_err_matched"] = float(np.abs(ks.field_power[0] - matched).max())
        return out
    return compare


def _compare_size(get_ref):
    def compare(ks):
        r = get_ref()
        S = ks.size_px
        crop = crop_centre(r.kernels.astype(np.float64), S)
        inside = crop.sum(axis=(-2, -1))
        l1, rel = kernel_errors(ks.kernels, crop / inside[:, None, None])
        full = np.zeros(r.kernels.shape)
        lo = r.size_px // 2 - S // 2
        full[:, lo:lo + S, lo:lo + S] = ks.kernels
        l1_full, _ = kernel_errors(full, r.kernels)
        # The energy outside the S window according to the reference: 1 − (1 − e_ref) Σ crop.
        check = 1.0 - (1.0 - r.energy_outside) * inside
        return {"error_L1": l1, "error_max_rel": rel, "energy_outside": float(np.max(ks.energy_outside)),
                "L1_vs_full_ref": l1_full, "energy_outside_check": float(np.max(check))}
    return compare


# ----------------------------------------------------------------------------------------------
# Output


def _g(v, digits=3) -> str:
    if v is None or v == "":
        return ""
    if isinstance(v, (bool, np.bool_)):
        return "**yes**" if v else ""
    if isinstance(v, (float, np.floating)):
        return f"{v:.{digits}g}"
    return str(v)


def _short_warning(text: str) -> str:
    if not text:
        return ""
    return ", ".join(dict.fromkeys(part.split(":")[0].strip() for part in text.split(" | ")))


def _table(rows: list[dict], cols: list[tuple[str, str]]) -> list[str]:
    out = ["| " + " | ".join(h for _, h in cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for r in rows:
        cells = []
        for key, _ in cols:
            v = r.get(key)
            cells.append(_short_warning(v) if key == "warning" else _g(v))
        out.append("| " + " | ".join(cells) + " |")
    return out


def _fmt(value) -> str:
    """A knob value for labels: floats to 3 significant figures, anything else as it is."""
    return f"{value:.3g}" if isinstance(value, float) else str(value)


def _recommend(rows: list[dict], tol: float = TOLERANCE_L1, key: str = "error_L1") -> str:
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["display"], r["series"]), []).append(r)
    parts = []
    for (d, s), rs in groups.items():
        ok = [r for r in rs if r.get(key) is not None and r[key] <= tol]
        if ok:
            best = min(ok, key=lambda r: r["time_s"])
            parts.append(f"{d}/{s}: {_fmt(best['value'])} ({key} {best[key]:.2g}, {best['time_s']:.2g} s)")
        else:
            parts.append(f"{d}/{s}: none within {tol:g}")
    return f"Cheapest setting with {key} ≤ {tol:g}: " + "; ".join(parts) + "."


def _ref_line(meta, key, what: str) -> str:
    info = meta["refs"][key]
    eo = ", ".join(f"{v:.3g}" for v in np.atleast_1d(info["energy_outside"]))
    w = f"; warning: {info['warning']}" if info["warning"] else ""
    return (f"Reference: {what} (pupil {info['params']['pupil_shape'][1]}² samples across the window crop, "
            f"single run {info['time_s']:.1f} s, its energy_outside {eo}{w}).")


def _markdown(rows: list[dict], meta: dict) -> str:
    cfg: Config = meta["cfg"]
    by = lambda knob: [r for r in rows if r["knob"] == knob]  # noqa: E731
    la, lb = meta["load_start"], meta["load_end"]
    lines = [
        "# PSF approximation knobs: error versus run time",
        "",
        f"{'QUICK smoke-test grid (not for decisions). ' if cfg.quick else ''}"
        f"Total study time {meta['elapsed_s']:.0f} s on {os.cpu_count()} CPU cores "
        f"({platform.processor() or platform.machine()}); load average {la[0]:.1f} at start, "
        f"{lb[0]:.1f} at end (the machine is shared: timings are noisy)." if la else
        f"Total study time {meta['elapsed_s']:.0f} s.",
        "",
        f"Rig defaults: Lens() (f = 6 mm, D = 3.333 mm), {PIXEL_UM} µm pixels, T-OLED toled() "
        f"(P-OLED poled() for the pupil knob), d = 0 unless stated. time_s = median of {cfg.repeats} "
        f"run(s) (time.perf_counter, whole compute_kernels / band_kernels call, scipy.fft on all cores); "
        f"time_min_s = fastest.",
        "",
        "Metrics: **error_L1 = Σ|k − k_ref| over the unit-sum kernels** (each kernel sums to 1 inside its "
        "window), maximum over the wavelengths (or bands) of the run; error_max_rel = max|k − k_ref| / "
        "max k_ref, maximum over wavelengths; energy_outside = the engine's fraction of the transmitted "
        "power outside the window (maximum over wavelengths). **default** marks the engine's current "
        "default. Warnings are recorded, not printed (full text in study_psf.csv).",
        "",
    ]

    base_cols = [("value", "value"), ("error_L1", "error_L1 (Σ|Δk|)"), ("error_max_rel", "error_max_rel"),
                 ("energy_outside", "energy_outside"), ("time_s", "time_s"), ("time_min_s", "time_min_s"),
                 ("is_default", "default"), ("warning", "warning")]

    # 1
    lines += [f"## {KNOB_TITLES['pupil_samples']}", "",
              f"Wavelengths {', '.join(f'{w:g}' for w in WAVELENGTHS_NM)} nm, S = {cfg.size_px}, mft, float32. "
              + _ref_line(meta, ("pupil", "toled"), f"N = {cfg.pupil_ref_n}, band_limited, mft, float64 "
                          f"(T-OLED)") + " P-OLED: " + _ref_line(meta, ("pupil", "poled"), "same settings")
              + f" The engine's auto N for this rig is {meta['auto_n']} (the display grid then equals "
              f"N = {cfg.default_n}'s: same samples per period). pupil_shape = samples over the aperture crop.",
              ""]
    lines += _table(by("pupil_samples"), [("display", "display"), ("series", "mask_raster")] + base_cols
                    + [("pupil_shape", "pupil_shape")])
    lines += ["", _recommend(by("pupil_samples")), ""]
    # 2
    lines += [f"## {KNOB_TITLES['method']}", "",
              "T-OLED, band_limited, float32, S = {0}. Same reference as knob 1 (N = {1} mft float64); the mft "
              "rows are the very runs of knob 1 (same call, measured once). "
              "'paper' = the paper's recipe as psf.fourier.paper_kernel implements it (2× zero-padded FFT of the "
              "pupil, |·|², down-sampled to the pixels). L1_same_N_ref (paper only): against the float64 MFT "
              "at the same N, i.e. the recipe's own error with the pupil sampling error taken out."
              .format(cfg.size_px, cfg.pupil_ref_n), ""]
    lines += _table(by("method"), [("series", "method"), ("value", "N")] + base_cols[1:3]
                    + [("L1_same_N_ref", "L1_same_N_ref")] + base_cols[3:])
    lines += ["", _recommend(by("method")), ""]
    # 3
    lines += [f"## {KNOB_TITLES['precision']}", "",
              f"T-OLED, auto N ({meta['auto_n']}), band_limited, mft, S = {cfg.size_px}. Same reference as "
              "knob 1 (so error_L1 is dominated by the pupil sampling). L1_same_N_ref (float32 row): against "
              "the float64 run at the same N, i.e. the precision error alone.", ""]
    lines += _table(by("precision"), base_cols[:3] + [("L1_same_N_ref", "L1_same_N_ref")] + base_cols[3:]
                    + [("pupil_shape", "pupil_shape")])
    lines += [""]
    # 4
    lines += [f"## {KNOB_TITLES['band_step_nm']}", "",
              f"Bands {', '.join(f'{lo:g}-{hi:g}' for lo, hi in BANDS_NM)} nm, flat weight; "
              f"**S = {cfg.band_size} and N = {cfg.band_n or 'auto'} for every run and the reference** "
              "(float32), so only the wavelength sampling differs. "
              + _ref_line(meta, ("band", "toled"), f"step {cfg.band_ref_step:g} nm "
                          f"({int(100 / cfg.band_ref_step)} samples per band), same S, N, float32")
              + " error_L1 is the worst of the three bands. The default row is the engine's auto step "
              "λ_lo / S per band (shown: the first band's); the needed step shrinks as S grows.", ""]
    lines += _table(by("band_step_nm"), [("value", "step_nm"), ("samples_per_band", "samples/band")]
                    + base_cols[1:])
    lines += ["", _recommend(by("band_step_nm")), ""]
    # 5
    lines += [f"## {KNOB_TITLES['field_phases']}", "",
              f"T-OLED, λ = {cfg.field_wavelength_nm:g} nm, d = {cfg.field_distance_mm:g} mm, N = {cfg.field_n}, "
              f"S = {cfg.field_size}, float32. "
              + _ref_line(meta, ("field", "toled"), f"P = {cfg.field_ref_p} (same λ, d, N, S, float32)")
              + f" Reference banding amplitude max|field_power − 1| = {meta['banding_ref']:.3g}. "
              "error_L1 compares the phase-averaged (power-weighted) `kernels`. "
              f"field_kernel_L1_interp: max over the reference's {cfg.field_ref_p}² phases of Σ|k_field − "
              "k_field,ref| when the P-phase field kernels are interpolated periodically-bilinearly to the "
              "reference's shifts (what a renderer holding P phases would use between them). "
              "banding_err_interp: the same for field_power (max abs). banding_err_matched: max "
              "|field_power − reference| at the reference's coinciding phases (P dividing "
              f"{cfg.field_ref_p}; identical kernels there, differences only from the mean normalisation).",
              ""]
    lines += _table(by("field_phases"), [("value", "P")] + base_cols[1:3] + [
        ("field_kernel_L1_interp", "field_kernel_L1_interp"), ("banding_err_interp", "banding_err_interp"),
        ("banding_err_matched", "banding_err_matched")] + base_cols[3:])
    lines += ["", _recommend(by("field_phases")), ""]
    # 6
    size_n = "auto N (the engine default: N grows with S to stay alias-free)" if cfg.size_n is None else \
        f"N = {cfg.size_n}"
    lines += [f"## {KNOB_TITLES['size_px']}", "",
              f"T-OLED, {', '.join(f'{w:g}' for w in WAVELENGTHS_NM)} nm, {size_n}, float32. "
              + _ref_line(meta, ("size", "toled"), f"S = {cfg.size_ref}, {size_n}, float32")
              + " **The window's error is energy_outside** (the power the S² kernel loses; the renderer "
              "renormalises it into the window). error_L1: the S kernel against the reference's S² centre "
              "crop renormalised to unit sum (values inside the window do not depend on S, so this measures "
              "only the different auto N). L1_vs_full_ref: the S kernel zero-padded to "
              f"{cfg.size_ref}² against the unit-sum reference (≈ 2 × the power between the windows). "
              "energy_outside_check = 1 − (1 − e_ref) · Σ(reference crop): should equal energy_outside.",
              ""]
    lines += _table(by("size_px"), [("value", "S")] + base_cols[1:3] + [
        ("L1_vs_full_ref", "L1_vs_full_ref"), ("energy_outside", "energy_outside"),
        ("energy_outside_check", "energy_outside_check"), ("time_s", "time_s"), ("time_min_s", "time_min_s"),
        ("is_default", "default"), ("pupil_samples_used", "N used"), ("warning", "warning")])
    lines += ["", _recommend(by("size_px"), key="energy_outside", tol=0.05), ""]
    return "\n".join(lines)


def _plot(rows: list[dict], path: Path, cfg: Config) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    knobs = list(KNOB_TITLES)
    fig, axes = plt.subplots(2, 3, figsize=(17, 10.5))
    floor = 1e-12
    for ax, knob in zip(axes.ravel(), knobs):
        rs = [r for r in rows if r["knob"] == knob]
        series: dict = {}
        if knob == "field_phases":
            for r in rs:
                series.setdefault("averaged kernel L1", []).append((r, r["error_L1"]))
                series.setdefault("field kernel L1 (interp.)", []).append((r, r.get("field_kernel_L1_interp")))
                series.setdefault("banding abs err (interp.)", []).append((r, r.get("banding_err_interp")))
        elif knob == "size_px":
            for r in rs:
                series.setdefault("energy_outside", []).append((r, r["energy_outside"]))
                series.setdefault("L1 vs full reference", []).append((r, r.get("L1_vs_full_ref")))
                series.setdefault("L1 vs renormalised crop", []).append((r, r["error_L1"]))
        elif knob == "precision":
            for r in rs:
                series.setdefault("vs N=%d float64 reference" % cfg.pupil_ref_n, []).append((r, r["error_L1"]))
                if r.get("L1_same_N_ref") is not None:
                    series.setdefault("float32 vs float64 at the same N", []).append((r, r["L1_same_N_ref"]))
        else:
            for r in rs:
                label = r["series"] if knob != "pupil_samples" else f"{r['display']} {r['series']}"
                series.setdefault(label, []).append((r, r["error_L1"]))
        default_done = False
        for label, pts in series.items():
            pts = [(r, e) for r, e in pts if e is not None]
            if not pts:
                continue
            t = [r["time_s"] for r, _ in pts]
            e = [max(e, floor) for _, e in pts]
            line, = ax.loglog(t, e, marker="o", ms=5, lw=1, label=label)
            for (r, _), ti, ei in zip(pts, t, e):
                ax.annotate(_fmt(r["value"]), (ti, ei), textcoords="offset points", xytext=(4, 3), fontsize=7,
                            color=line.get_color())
                if r["is_default"]:
                    ax.scatter([ti], [ei], s=160, facecolors="none", edgecolors="red", linewidths=2, zorder=5,
                               label=None if default_done else "default")
                    default_done = True
        ax.axhline(TOLERANCE_L1, color="grey", ls=":", lw=0.8)
        lo, hi = ax.get_xlim()
        if hi / lo < 4:  # a narrow time range: widen it so the log axis keeps readable major ticks
            mid = math.sqrt(lo * hi)
            ax.set_xlim(mid / 2.5, mid * 2.5)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_title(KNOB_TITLES[knob], fontsize=10)
        ax.set_xlabel("run time (s, median)")
        ax.set_ylabel("energy lost / L1" if knob == "size_px" else "error (L1 = Σ|k − k_ref|)")
        ax.grid(True, which="both", alpha=0.25)
        ax.legend(fontsize=7, loc="best")
    fig.suptitle(("QUICK grid — " if cfg.quick else "") + "PSF knobs: error vs run time (dotted: L1 = 1e-3; "
                 "red ring: engine default)", fontsize=12)
    fig.tight_layout()
    try:
        with atomic_path(path, ".png") as tmp:
            fig.savefig(tmp, dpi=110, format="png")
    finally:
        plt.close(fig)
