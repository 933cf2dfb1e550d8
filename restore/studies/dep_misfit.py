"""How much DeP loses when its PSF is a little wrong, as the paper's "computed ideal PSF" was.

The paper's DeP "suffers from the inaccuracy of the computed ideal PSF" (l.410): its kernel came from
a model of the panel traced from a micrograph with no published scale (docs/PHYSICS.md §8), while
restore.known hands our DeP the kernel of the very layout that made the captures (up to the `physical`
profile's display distance). The misfit studied here is the one a scale error makes: the micrograph's
pitch off by a fraction ε puts every diffraction order at λf/p off by about −ε, so the kernel is the
true one magnified by 1 / (1 + ε) about its centre (cubic-spline resampling, negative lobes clipped,
renormalised to unit sum; ε = 0 is the known kernel exactly).

Per display: the split's first `items` pairs, cropped to the central `crop_px` square (restore.train's
validation crop), DeP (restore.dep, the known γ) with the misfit kernels, linear PSNR on values clipped
to [0, 1] (restore.train.validation_psnr's measure). The input's PSNR is the row "input".

    python -m restore.studies.dep_misfit DATA [--display toled] [--display poled] [--misfit 0,0.02,0.05,0.1]
        [--split val] [--items 4] [--crop-px 512] [--out out/dep_misfit]

prints a Markdown table and writes <out>/dep_misfit.json and dep_misfit.png.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from restore.dep import dep_restore
from restore.studies.options import parse_options
from udc_render.errors import UdcError
from udc_render.io.files import save_json
from udc_render.io.plots import pyplot, save_plot
from udc_render.metrics import psnr_db
from udc_render.sensor import demosaic_bilinear, unpack_rggb

MISFITS = (0.0, 0.02, 0.05, 0.1, -0.05)


def magnified_kernel(kernel: np.ndarray, scale: float) -> np.ndarray:
    """[k, k] `kernel` (centre at k // 2, unit sum) magnified by `scale` about its centre: K'(x) = K(x / scale),
    cubic spline, negatives clipped, renormalised; scale 1 returns a copy."""
    from scipy.ndimage import map_coordinates
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"scale = {scale!r}: expected a positive number")
    k = np.asarray(kernel, np.float64)
    if scale == 1.0:
        return k.copy()
    c = np.arange(k.shape[-1], dtype=np.float64) - k.shape[-1] // 2
    yy, xx = np.meshgrid(c / scale + k.shape[-2] // 2, c / scale + k.shape[-1] // 2, indexing="ij")
    out = np.clip(map_coordinates(k, [yy, xx], order=3, mode="constant"), 0, None)
    return out / out.sum()


def misfit_psnr(data_dir: Path, display: str, misfits, split: str = "val", items: int = 4,
                crop_px: int = 512) -> dict:
    """{"input": dB, ε: dB, ...}: mean PSNR over the crops (module doc)."""
    from restore.data import list_pairs, load_pair
    from restore.known import known_gamma_rggb, known_kernels_rggb
    from restore.train import centre_crop
    pairs = list_pairs(Path(data_dir), split, [display])[:items]
    crops = [centre_crop(*load_pair(p), crop_px) for p in pairs]
    gamma, kernels = known_gamma_rggb(pairs[0]), known_kernels_rggb(pairs[0], source="exact")
    gts = [np.clip(gt, 0, 1) for _, gt in crops]
    row = {"input": float(np.mean([psnr_db(np.clip(demosaic_bilinear(unpack_rggb(packed)), 0, 1), gt)
                                   for (packed, _), gt in zip(crops, gts)]))}
    for eps in misfits:
        ks = np.stack([magnified_kernel(k, 1.0 / (1.0 + eps)) for k in kernels])
        row[eps] = float(np.mean([psnr_db(np.clip(dep_restore(packed, gamma, ks, rng=np.random.default_rng(p.item)).rgb,
                                                  0, 1), gt) for p, (packed, _), gt in zip(pairs, crops, gts)]))
    return row


def plot(rows: dict, path: Path) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    for display, row in rows.items():
        eps = sorted(k for k in row if k != "input")
        line, = ax.plot([100 * e for e in eps], [row[e] for e in eps], "o-", label=f"DeP, {display}")
        ax.axhline(row["input"], color=line.get_color(), ls=":", lw=1, label=f"input, {display}")
    ax.set_xlabel("pitch error of DeP's layout model ε (%)")
    ax.set_ylabel("PSNR (dB, linear)")
    ax.set_title("DeP with a misfit kernel (val crops)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    save_plot(fig, path)


def main(argv: list[str]) -> None:
    usage = ("python -m restore.studies.dep_misfit DATA [--display D ...] [--misfit 0,0.02,0.05,0.1] "
             "[--split val] [--items 4] [--crop-px 512] [--out out/dep_misfit]")
    pos, o = parse_options(argv, usage, repeated=("display",))
    if len(pos) != 1:
        sys.exit(f"usage: {usage}")
    displays = o["display"] or ["toled", "poled"]
    try:
        misfits = [float(v) for v in o["misfit"].split(",")] if "misfit" in o else list(MISFITS)
        if not all(-0.5 < e < 1.0 for e in misfits):
            raise ValueError(f"--misfit = {o['misfit']!r}: expected fractions between -0.5 and 1")
        out = Path(o.get("out", "out/dep_misfit"))
        out.mkdir(parents=True, exist_ok=True)
        rows = {d: misfit_psnr(Path(pos[0]), d, misfits, o.get("split", "val"), int(o.get("items", 4)),
                               int(o.get("crop_px", 512))) for d in displays}
    except (UdcError, OSError, ValueError) as exc:
        sys.exit(f"error: {exc}")
    save_json(out / "dep_misfit.json", {d: {str(k): v for k, v in r.items()} for d, r in rows.items()})
    plot(rows, out / "dep_misfit.png")
    eps = sorted(misfits)
    print("| display | input | " + " | ".join(f"DeP ε = {100 * e:+g} %" for e in eps) + " |")
    print("|---|---|" + "---|" * len(eps))
    for d, r in rows.items():
        print(f"| {d} | {r['input']:.2f} | " + " | ".join(f"{r[e]:.2f}" for e in eps) + " |")


if __name__ == "__main__":
    main(sys.argv[1:])
