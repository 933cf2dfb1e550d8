#!/usr/bin/env python
"""Time and accuracy of the PSF engine against hcipy, poppy and the paper's FFT recipe.

Rig (paper, docs/PHYSICS.md §2): f = 6000 µm, D = 3333 µm, sensor pixel ρ = 3.1 µm, 255 × 255 output
centred at index 127, wavelengths 450 / 520 / 640 nm. Every method receives the SAME pupil raster g
(built exactly as psf.engine.compute_kernels builds it: display_grid / lens_grid, tile_mask,
aperture_slices, area-weighted aperture) and returns point samples on the same sensor grid
u_j = (j − 127) ρ, as energy per pixel per unit power through the bare aperture:

    k(u_j) = ρ² |U(u_j)|² / A,   U(u) = 1/(λf) Σ_x g(x) exp(−2πi x·u/(λf)) δxδy,   A = πD²/4.

Cases
  airy   bare circular aperture; reference = analytic ρ² (A/(λf))² (2J₁(v)/v)² / A, v = πD|u|/(λf).
  toled  psf.layouts.toled() × aperture; reference = engine MFT, float64, pupil_samples 4096.
  toled-pixint  compute_kernels at its defaults (pixel-integrated, 3 λ), with method='czt' and with
         method='paper' (2× zero-padded FFT, cubic down-sampling by the printed r: psf.paper), vs hcipy
         sub-sampled and binned; reference = compute_kernels float64 at 4096.
Methods
  engine-mft / engine-czt   fourier.point_kernel: direct MFT (or chirp-z) of g, |U|² ρ², what
                            compute_kernels(pixel_integration=False) runs; de-apodised for the bare lens
  (the paper's recipe runs through compute_kernels, so it is timed in the pixel-integrated case below)
  hcipy                     FraunhoferPropagator(make_pupil_grid, make_uniform_grid) (MFT inside)
  poppy                     matrixDFT.matrix_dft, ADJUSTABLE centring, nlamD = S ρ n δ / (λ f)
Each timed call starts from g and does all the work (peers get fresh objects: no cached matrices).
Errors: max|k − ref| / max ref and Σ|k − ref| / Σ ref over the window (worst wavelength).

    PYTHONPATH=. .venv-bench/bin/python benchmarks/bench_psf.py --out out/bench
"""
from __future__ import annotations

import argparse
import csv
import math
import os
import statistics
import sys
import time
import warnings

import numpy as np
from scipy.special import j1

from psf import fourier, layouts
from psf.engine import compute_kernels
from psf.lens import Lens
from psf.pupil import aperture_slices, display_grid, lens_grid, tile_mask

LENS = Lens()                      # f = 6000 µm, D = 3333 µm, in focus
Z_UM = LENS.image_distance_um      # = f
PIXEL_UM = 3.1
SIZE = 255
WL_SET = (450.0, 520.0, 640.0)
WL_ONE = (520.0,)
BARE_POWER = math.pi * LENS.aperture_um ** 2 / 4   # A
U_UM = (np.arange(SIZE) - SIZE // 2) * PIXEL_UM
CDTYPE = {"float32": np.complex64, "float64": np.complex128}
REF_SAMPLES = 4096
ENGINE_BASE = ("engine-mft", "float32")          # ratios are time / this method's time


# ----------------------------------------------------------------------------- pupil and references
class Pupil:
    """The pupil raster g [ny, nx] (complex128) on cells dx × dy, exactly as compute_kernels makes it."""

    def __init__(self, case: str, n: int):
        if case == "airy":
            grid, m = lens_grid(LENS, n), None
        else:
            grid, cell_n, tiles = display_grid(layouts.toled().period_um, LENS, n)
            m = tile_mask(layouts.toled(), cell_n, tiles)[0]   # default raster: band-limited
        sy, sx = aperture_slices(grid, LENS.aperture_um)
        pg = grid.crop(sy, sx)
        aperture = LENS.aperture_area_fraction(pg.x_edges_um, pg.y_edges_um)
        self.g = (aperture if m is None else m[sy, sx] * aperture).astype(np.complex128)
        self.dx, self.dy = pg.dx_um, pg.dy_um
        self.x, self.y = pg.x_um, pg.y_um
        self.case, self.n = case, n

    @property
    def shape(self) -> str:
        return "%d×%d" % self.g.shape


def airy_reference(wavelengths_nm) -> np.ndarray:
    """ρ² I(u)/A with I = (A/(λf))² (2J₁(v)/v)², v = πD|u|/(λf), point-sampled at the pixel centres."""
    out = []
    for lam_nm in wavelengths_nm:
        lam = lam_nm * 1e-3
        r = np.hypot(U_UM[:, None], U_UM[None, :])
        v = math.pi * LENS.aperture_um * r / (lam * Z_UM)
        with np.errstate(invalid="ignore", divide="ignore"):
            a = np.where(v > 0, 2 * j1(v) / v, 1.0)
        out.append(PIXEL_UM ** 2 * BARE_POWER / (lam * Z_UM) ** 2 * a ** 2)
    return np.array(out)


# ----------------------------------------------------------------------------- methods
# Each method: (pupil, wavelengths_nm, precision) -> [K, 255, 255] energy per pixel / A.

def engine_point(p: Pupil, wls, precision, method="mft"):
    """k_j = ρ² |U(u_j)|², U = E_y g E_xᵀ δxδy/(λf) by MFT (or chirp-z): fourier.point_kernel, the
    engine's point-sampled path. De-apodised (/ sinc²(δu/λf) sinc²(δv/λf)) for the bare lens only,
    as compute_kernels does."""
    cd = CDTYPE[precision]
    return np.stack([fourier.point_kernel(p.g, p.x, p.y, p.dx, p.dy, lam * 1e-3, Z_UM, PIXEL_UM, SIZE, method,
                                          cd, deapodize=p.case == "airy")
                     for lam in wls]) / BARE_POWER


def engine_czt(p, wls, precision):
    """As engine_point, the sums by Bluestein chirp-z (scipy.signal.czt)."""
    return engine_point(p, wls, precision, "czt")


def peer_hcipy(p, wls, precision):
    """hcipy FraunhoferPropagator: U = 1/(iλf) Σ g e^{−i (2π/λf) u·x} δxδy; power = |U|² ρ².

    Pupil grid centred (cell centres (i − (n−1)/2) δ), focal grid make_uniform_grid(255, 255 ρ),
    i.e. centres (j − 127) ρ. A fresh propagator per call (its MFT matrices are built each time).
    """
    import hcipy
    ny, nx = p.g.shape
    pgrid = hcipy.make_pupil_grid([nx, ny], [nx * p.dx, ny * p.dy])
    fgrid = hcipy.make_uniform_grid([SIZE, SIZE], [SIZE * PIXEL_UM, SIZE * PIXEL_UM])
    prop = hcipy.FraunhoferPropagator(pgrid, fgrid, focal_length=Z_UM)
    field = hcipy.Field(p.g.astype(CDTYPE[precision]).ravel(), pgrid)
    return np.array([np.asarray(prop.forward(hcipy.Wavefront(field, lam * 1e-3)).power).reshape(SIZE, SIZE)
                     for lam in wls]) / BARE_POWER


def peer_hcipy_binned(p, wls, precision, sub=3):
    """Pixel integration the peer way: hcipy on a sub×sub finer grid (odd sub: sub-pixel centres
    (j − 127)ρ + (k − (sub−1)/2)ρ/sub, the midpoints of sub² cells), power summed per pixel.
    Midpoint rule for K_j = ∫_pixel I; the engine integrates exactly (OTF × sinc)."""
    import hcipy
    ny, nx = p.g.shape
    n = SIZE * sub
    pgrid = hcipy.make_pupil_grid([nx, ny], [nx * p.dx, ny * p.dy])
    fgrid = hcipy.make_uniform_grid([n, n], [SIZE * PIXEL_UM, SIZE * PIXEL_UM])
    prop = hcipy.FraunhoferPropagator(pgrid, fgrid, focal_length=Z_UM)
    field = hcipy.Field(p.g.astype(CDTYPE[precision]).ravel(), pgrid)
    out = [np.asarray(prop.forward(hcipy.Wavefront(field, lam * 1e-3)).power, np.float64)
           .reshape(SIZE, sub, SIZE, sub).sum(axis=(1, 3)) for lam in wls]
    return np.array(out) / BARE_POWER


def peer_poppy(p, wls, precision):
    """poppy matrix_dft (ADJUSTABLE centring: odd output centred on pixel 127), per axis
    nlamD = S ρ n δ / (λ f) so the output pitch is ρ; its unitary normalisation gives
    |F|² δxδy = ρ²|U|². poppy's kernel is e^{+2πi x·u}: a mirror image, the same |U|² for real g."""
    from poppy.matrixDFT import matrix_dft
    ny, nx = p.g.shape
    out = []
    for lam in wls:
        scale = lam * 1e-3 * Z_UM
        nlamd = (SIZE * PIXEL_UM * ny * p.dy / scale, SIZE * PIXEL_UM * nx * p.dx / scale)
        F = matrix_dft(p.g, nlamd, SIZE, centering="ADJUSTABLE")
        out.append((F.real ** 2 + F.imag ** 2) * p.dx * p.dy)
    return np.array(out) / BARE_POWER


def peer_available(name: str) -> bool:
    try:
        __import__(name)
        return True
    except Exception as exc:  # noqa: BLE001 - any import failure means "skip"
        print(f"# {name} not importable ({type(exc).__name__}: {exc}); skipping its rows", file=sys.stderr)
        return False


# ----------------------------------------------------------------------------- timing and errors
def timed(fn, repeats: int):
    """One warm-up call, then the median wall time (perf_counter) of `repeats` calls; returns (s, result)."""
    sec, out = timed_interleaved([fn], repeats)
    return sec[0], out[0]


def timed_interleaved(fns, repeats: int):
    """Warm up every call once, then `repeats` rounds calling each in turn (so load from other
    processes hits all methods alike); returns (median seconds per call, last result per call)."""
    outs = [fn() for fn in fns]
    times = [[] for _ in fns]
    for _ in range(repeats):
        for i, fn in enumerate(fns):
            t0 = time.perf_counter()
            outs[i] = fn()
            times[i].append(time.perf_counter() - t0)
    return [statistics.median(t) for t in times], outs


def errors(k: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """Worst over wavelengths of max|k − ref| / max ref and Σ|k − ref| / Σ|ref|."""
    d = np.abs(np.asarray(k, np.float64) - ref)
    mx = max(float(d[i].max() / ref[i].max()) for i in range(len(ref)))
    l1 = max(float(d[i].sum() / np.abs(ref[i]).sum()) for i in range(len(ref)))
    return mx, l1


def raw_from_kernelset(ks) -> np.ndarray:
    """compute_kernels output back to energy per pixel / A: unit-sum kernels × (1 − outside) × T."""
    return ks.kernels.astype(np.float64) * ((1 - ks.energy_outside) * ks.transmittance)[:, None, None]


# ----------------------------------------------------------------------------- the run
def methods_for(case: str, have_hcipy: bool, have_poppy: bool):
    ms = [("engine-mft", "float32", engine_point), ("engine-mft", "float64", engine_point),
          ("engine-czt", "float64", engine_czt)]
    if have_hcipy:
        ms += [("hcipy", "float32", peer_hcipy), ("hcipy", "float64", peer_hcipy)]
    if have_poppy:
        ms += [("poppy", "float64", peer_poppy)]
    return ms


def run(args) -> list[dict]:
    have_hcipy, have_poppy = peer_available("hcipy"), peer_available("poppy")
    sizes = [1024] if args.quick else args.sizes
    ref_n = 2048 if args.quick else REF_SAMPLES
    rows = []
    for case in ("airy", "toled"):
        t0 = time.perf_counter()
        if case == "airy":
            refs = {wls: airy_reference(wls) for wls in (WL_ONE, WL_SET)}
        else:
            full = engine_point(Pupil(case, ref_n), WL_SET, "float64")
            refs = {WL_SET: full, WL_ONE: full[[WL_SET.index(WL_ONE[0])]]}
            print(f"# toled reference: engine mft float64, pupil_samples {ref_n} "
                  f"({time.perf_counter() - t0:.1f} s)", file=sys.stderr)
        for n in sizes:
            p = Pupil(case, n)
            for wls in (WL_ONE, WL_SET):
                ms = methods_for(case, have_hcipy, have_poppy)
                rows += measure(case, p, wls, ms, refs[wls], args.repeats)
        if case == "airy" and args.engine_4096 and not args.quick:   # the engine alone at N = 4096
            ms = [("engine-mft", "float32", engine_point), ("engine-mft", "float64", engine_point),
                  ("engine-czt", "float64", engine_czt)]
            rows += measure(case, Pupil(case, REF_SAMPLES), WL_SET, ms, refs[WL_SET], args.repeats)
        if case == "toled":
            rows += check_and_time_compute_kernels(args, ref_n)
    add_ratios(rows)
    return rows


def measure(case, p, wls, ms, ref, repeats) -> list[dict]:
    """Time the methods `ms` (interleaved) on pupil p for wavelengths wls; one row each."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")      # AliasingWarning at N = 512 (the window exceeds λf/δ)
        secs, outs = timed_interleaved([lambda fn=fn, prec=prec: fn(p, wls, prec) for _, prec, fn in ms], repeats)
    rows = []
    for (method, prec, _), sec, k in zip(ms, secs, outs):
        mx, l1 = errors(k, ref)
        rows.append(dict(case=case, method=method, N=p.n, pupil=p.shape, precision=prec,
                         wavelengths="/".join("%g" % w for w in wls), time_ms=sec * 1e3, max_err_peak=mx, l1_rel=l1))
        print(f"#   {case} {method:16s} N={p.n:5d} {prec} λ={rows[-1]['wavelengths']:12s} "
              f"{sec * 1e3:9.1f} ms  max {mx:.2e}  L1 {l1:.2e}", file=sys.stderr)
    return rows


def check_and_time_compute_kernels(args, ref_n) -> list[dict]:
    """(a) the raster used above equals compute_kernels' own (float64, N = 1024, point samples);
    (b) compute_kernels at its defaults (float32, mft, auto N, pixel integration) for the 3-λ
    T-OLED set, the same with method='czt', and hcipy on the same raster sub-sampled 3× / 7×
    per axis and binned; error against compute_kernels float64 at pupil_samples ref_n
    (pixel-integrated). Ratios of these rows are to the default."""
    display = layouts.toled()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ks = compute_kernels(display, LENS, WL_SET, PIXEL_UM, SIZE, method="mft", pupil_samples=1024,
                             precision="float64", pixel_integration=False)
    direct = engine_point(Pupil("toled", 1024), WL_SET, "float64")
    diff = np.abs(raw_from_kernelset(ks) - direct).max() / direct.max()
    print(f"# raster check: compute_kernels vs this script's pupil raster, max diff / peak = {diff:.1e}",
          file=sys.stderr)
    if diff > 1e-9:
        print("# WARNING: the benchmark's pupil raster differs from compute_kernels'", file=sys.stderr)
    ref = raw_from_kernelset(compute_kernels(display, LENS, WL_SET, PIXEL_UM, SIZE, pupil_samples=ref_n,
                                             precision="float64"))
    calls = [("compute_kernels (default)", lambda: raw_from_kernelset(
                 compute_kernels(display, LENS, WL_SET, PIXEL_UM, SIZE))),
             ("compute_kernels method=czt", lambda: raw_from_kernelset(
                 compute_kernels(display, LENS, WL_SET, PIXEL_UM, SIZE, method="czt"))),
             ("compute_kernels method=paper", lambda: raw_from_kernelset(
                 compute_kernels(display, LENS, WL_SET, PIXEL_UM, SIZE, method="paper")))]
    n_def = compute_kernels(display, LENS, WL_SET[:1], PIXEL_UM, SIZE).params["pupil_samples"]
    p = Pupil("toled", n_def)
    if peer_available("hcipy"):
        calls += [(f"hcipy {sub}×{sub} sub-samples, binned",
                   lambda sub=sub: peer_hcipy_binned(p, WL_SET, "float32", sub)) for sub in (3, 7)]
    secs, outs = timed_interleaved([c for _, c in calls], args.repeats)
    rows = []
    for (label, _), sec, k in zip(calls, secs, outs):
        mx, l1 = errors(k, ref)
        print(f"# {label} (T-OLED, 3 λ, 255², pixel-integrated, float32): {sec * 1e3:.0f} ms "
              f"(engine target < 2000 ms), N = {n_def}, max {mx:.2e}, L1 {l1:.2e}", file=sys.stderr)
        rows.append(dict(case="toled-pixint", method=label, N=n_def, pupil=p.shape, precision="float32",
                         wavelengths="450/520/640", time_ms=sec * 1e3, max_err_peak=mx, l1_rel=l1))
    return rows


def add_ratios(rows):
    """ratio = time / time of engine-mft float32 at the same case, N and wavelength set."""
    base = {(r["case"], r["N"], r["wavelengths"]): r["time_ms"] for r in rows
            if (r["method"], r["precision"]) == ENGINE_BASE or r["method"] == "compute_kernels (default)"}
    for r in rows:
        b = base.get((r["case"], r["N"], r["wavelengths"]))
        r["ratio"] = r["time_ms"] / b if b else float("nan")


# ----------------------------------------------------------------------------- output
COLUMNS = ("case", "method", "N", "pupil", "precision", "wavelengths", "time_ms", "max_err_peak", "l1_rel", "ratio")
HEADER = ("case", "method", "N", "pupil raster", "precision", "λ (nm)", "time_ms (median)",
          "max_err/peak", "L1 rel err", "time / engine-mft f32")


def markdown(rows) -> str:
    fmt = {"time_ms": "{:.1f}", "max_err_peak": "{:.1e}", "l1_rel": "{:.1e}", "ratio": "{:.2f}"}
    lines = ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    for r in rows:
        lines.append("| " + " | ".join(fmt.get(c, "{}").format(r[c]) for c in COLUMNS) + " |")
    return "\n".join(lines)


def plot(rows, path, ref_n=REF_SAMPLES):
    """Error vs time, log-log, 3-λ set; one marker shape per method/precision, N as label.
    Panels: airy and toled (point samples), toled-pixint (pixel-integrated kernels)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    refs = {"airy": "analytic Airy", "toled": f"engine f64 N={ref_n}", "toled-pixint": f"compute_kernels f64 N={ref_n}"}
    cases = [c for c in refs if any(r["case"] == c for r in rows)]
    fig, axes = plt.subplots(1, len(cases), figsize=(6.5 * len(cases), 5.5), squeeze=False)
    keys = list(dict.fromkeys((r["method"], r["precision"]) for r in rows))
    markers = "os^vDP*Xh<>p"
    for ax, case in zip(axes[0], cases):
        for i, key in enumerate(keys):
            sel = [r for r in rows if r["case"] == case and (r["method"], r["precision"]) == key
                   and r["wavelengths"] == "450/520/640"]
            if not sel:
                continue
            t = [r["time_ms"] for r in sel]
            e = [max(r["max_err_peak"], 1e-16) for r in sel]
            ax.loglog(t, e, markers[i % len(markers)], color=f"C{i % 10}", ms=8, label=f"{key[0]} {key[1]}")
            for r, ti, ei in zip(sel, t, e):
                ax.annotate(str(r["N"]), (ti, ei), textcoords="offset points", xytext=(4, 3), fontsize=7)
        ax.set(title=f"{case}: 450/520/640 nm, 255² at 3.1 µm\n(ref: {refs[case]})",
               xlabel="median time (ms)", ylabel="max |err| / peak")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def environment(load0: float, seconds: float) -> str:
    """One line: versions, cores, load average (other processes inflate times), run time."""
    import scipy
    vers = [f"numpy {np.__version__}", f"scipy {scipy.__version__}"]
    for name in ("hcipy", "poppy"):
        try:
            vers.append(f"{name} {__import__(name).__version__}")
        except Exception:  # noqa: BLE001
            vers.append(f"{name} missing")
    return (f"Python {sys.version.split()[0]}, {', '.join(vers)}; {os.cpu_count()} CPUs; 1-min load average "
            f"{load0:.1f} at start, {os.getloadavg()[0]:.1f} at end; run {seconds:.0f} s. Times: median of the "
            f"repeats after one warm-up, methods interleaved; ratio = time / engine-mft float32 at the same "
            f"case, N and λ set (toled-pixint rows: / compute_kernels default).")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="out/bench", help="output folder (bench_psf.md/.csv/.png)")
    ap.add_argument("--repeats", type=int, default=5, help="timed repeats after one warm-up (median)")
    ap.add_argument("--quick", action="store_true", help="N = 1024 only, reference at 2048 (smoke run)")
    ap.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048], help="pupil_samples sweep")
    ap.add_argument("--engine-4096", action="store_true",
                    help="also time the engine (mft f32/f64, czt f64) on the Airy case at N = 4096 (~2 min)")
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error("--repeats must be ≥ 1")
    os.makedirs(args.out, exist_ok=True)
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    rows = run(args)
    table = markdown(rows)
    info = environment(load0, time.perf_counter() - t0)
    print(info + "\n\n" + table)
    with open(os.path.join(args.out, "bench_psf.md"), "w") as fh:
        fh.write(info + "\n\n" + table + "\n")
    with open(os.path.join(args.out, "bench_psf.csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(rows)
    plot(rows, os.path.join(args.out, "bench_psf.png"), 2048 if args.quick else REF_SAMPLES)
    print(f"# wrote {args.out}/bench_psf.md, .csv, .png in {time.perf_counter() - t0:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
