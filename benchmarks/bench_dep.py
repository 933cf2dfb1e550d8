#!/usr/bin/env python
"""DeP on a T-OLED pair: PSNR and median run time for each denoiser and each boundary treatment
(the measured justification of restore.dep's defaults).

The pair: the psf engine's T-OLED kernels at the packed planes' pitch (3.1 µm; 640, 520, 520,
450 nm for R, Gr, Gb, B; --kernel-px, default 129), a linear-RGB scene in [0, 0.8]
(skimage.data.astronaut, sRGB^2.2, mirror-tiled at its native resolution where the frame is larger
than 512 px; the frame's edges are not on a mirror seam), blurred per packed channel by linear
(non-wrapping) convolution on a frame larger by the kernel's half-width, then cropped; × γ = 0.97;
Poisson-Gaussian noise of variance λ_shot·x + λ_read (1e-3, 1e-6). PSNR (peak 1) of the camera-RGB
output against the ground truth, over the whole frame; 'naive' is the bilinear-demosaiced input / γ.

Rows: every denoiser at the default boundary treatment, then every boundary treatment with
denoiser 'none' (the denoiser runs before the padding, so the two do not interact). 'wavelet' needs
PyWavelets and 'bm3d' the bm3d package (non-commercial licence); a missing one is reported and skipped.
Times: median of --repeats runs of dep_restore (2 cores, shared machine: compare ratios).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_dep.py --out out/bench_dep
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import scipy.signal

from restore.dep import DENOISERS, DePError, dep_restore
from udc_render.io.files import csv_text, save_figure, save_text
from udc_render.metrics import psnr_db
from udc_render.sensor import demosaic_bilinear, mosaic_of, pack_rggb, unpack_rggb

GAMMA, SHOT, READ = 0.97, 1e-3, 1e-6


def toled_pair(h: int, w: int, kernel_px: int, seed: int = 0):
    """(noisy packed [4, h, w], ground truth [3, 2h, 2w], kernels [4, k, k]); see the module doc."""
    import skimage.data

    from psf import Lens, compute_kernels, layouts
    k3 = compute_kernels(layouts.toled(), Lens(), wavelengths_nm=[640, 520, 450], pixel_um=3.1,
                         size_px=kernel_px).kernels
    k4 = k3[[0, 1, 1, 2]].astype(np.float64)
    m = kernel_px // 2
    fh, fw, off = 2 * (h + 2 * m), 2 * (w + 2 * m), (40, 24)
    img = (skimage.data.astronaut() / 255.0) ** 2.2 * 0.8
    tiles = [(n + o) // 512 for n, o in zip((fh, fw), off)]
    img = np.pad(img, ((0, 512 * tiles[0]), (0, 512 * tiles[1]), (0, 0)), mode="symmetric")
    frame = np.moveaxis(img[off[0]:off[0] + fh, off[1]:off[1] + fw], -1, 0)
    big = pack_rggb(mosaic_of(frame))
    blur = GAMMA * np.stack([scipy.signal.fftconvolve(big[c], k4[c], mode="valid") for c in range(4)])
    rng = np.random.default_rng(seed)
    noisy = SHOT * rng.poisson(np.clip(blur, 0, None) / SHOT) + np.sqrt(READ) * rng.standard_normal(blur.shape)
    return noisy, frame[:, 2 * m:-2 * m, 2 * m:-2 * m], k4


def cases(k: int) -> list[tuple[str, dict]]:
    out = [(f"denoiser {d}", {"denoiser": d}) for d in DENOISERS]
    half = k // 2
    for label, kw in [("no padding", {"pad_px": 0, "fill_iterations": 0}),
                      ("symmetric k/2", {"boundary": "symmetric", "fill_iterations": 0}),
                      ("reflect k/2", {"boundary": "reflect", "fill_iterations": 0}),
                      ("edge k/2", {"boundary": "edge", "fill_iterations": 0}),
                      ("taper k/2", {"boundary": "taper", "fill_iterations": 0}),
                      ("edge k/2 + fill 10", {"fill_iterations": 10}),
                      ("edge k/2 + fill 30 (default)", {}),
                      ("edge k + fill 30", {"pad_px": min(k, 128)}),
                      ("symmetric k/2 + fill 30", {"boundary": "symmetric"}),
                      ("taper k/2 + fill 30", {"boundary": "taper"}),
                      ("edge k/2 + fill 30, laplacian prior", {"prior": "laplacian"})]:
        out.append((f"padding: {label}" + (f" ({half} px)" if "k/2" in label else ""), {"denoiser": "none", **kw}))
    return out


def run(h: int, w: int, kernel_px: int, repeats: int) -> list[dict]:
    noisy, gt, k4 = toled_pair(h, w, kernel_px)
    naive = psnr_db(demosaic_bilinear(unpack_rggb(noisy)) / GAMMA, gt)
    rows = [{"case": "naive (bilinear demosaic / gamma)", "psnr_db": round(naive, 2), "ms": 0.0}]
    print(f"{'naive':<52} {naive:6.2f} dB", flush=True)
    for name, kw in cases(kernel_px):
        times, res = [], None
        try:
            for _ in range(repeats):
                t0 = time.perf_counter()
                res = dep_restore(noisy, GAMMA, k4, rng=0, **kw)
                times.append(time.perf_counter() - t0)
        except DePError as e:
            print(f"{name:<52} skipped: {e}", flush=True)
            continue
        p = psnr_db(res.rgb, gt)
        ms = 1000 * statistics.median(times)
        step = {s: round(1000 * v, 1) for s, v in res.timings_s.items()}
        rows.append({"case": name, "psnr_db": round(p, 2), "ms": round(ms, 1), "denoise_ms": step["denoise_s"],
                     "wiener_ms": step["wiener_s"], "repeats": repeats})
        print(f"{name:<52} {p:6.2f} dB {ms:9.1f} ms (denoise {step['denoise_s']} ms, wiener {step['wiener_s']} ms)",
              flush=True)
    return rows


def plot(rows: list[dict], title: str, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 5))
    for r in rows[1:]:
        ax.scatter(r["ms"], r["psnr_db"], color="C0" if r["case"].startswith("denoiser") else "C1")
        ax.annotate(r["case"].replace("padding: ", ""), (r["ms"], r["psnr_db"]), fontsize=7,
                    xytext=(3, 2), textcoords="offset points")
    ax.axhline(rows[0]["psnr_db"], color="grey", ls="--", label="naive input")
    ax.set_xscale("log")
    ax.set_xlabel("median run time of dep_restore (ms)")
    ax.set_ylabel("PSNR vs ground truth (dB)")
    ax.set_title(title, fontsize=9)
    ax.legend()
    save_figure(fig, path)
    plt.close(fig)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/bench_dep"))
    ap.add_argument("--size", default="256x512", help="packed plane size HxW (the paper's: 512x1024)")
    ap.add_argument("--kernel-px", type=int, default=129)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    h, w = (int(v) for v in args.size.lower().split("x"))
    rows = run(h, w, args.kernel_px, args.repeats)
    cols = ["case", "psnr_db", "ms", "denoise_ms", "wiener_ms", "repeats"]
    save_text(args.out / "bench_dep.csv", csv_text(rows, cols))
    md = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    md += ["| " + " | ".join("" if r.get(c) is None else str(r.get(c)) for c in cols) + " |" for r in rows]
    save_text(args.out / "bench_dep.md", "\n".join(md) + "\n")
    print("\n".join(md))
    try:
        plot(rows, f"DeP on a T-OLED pair: planes {h}x{w}, kernel {args.kernel_px} px", args.out / "bench_dep.png")
    except ImportError:
        print("matplotlib not installed: no PNG")
    return 0


if __name__ == "__main__":
    sys.exit(main())
