"""How many exposures and what signal does udc-render fit need for a 1 % pitch? (docs/guides/fit.md)

For the T-OLED and P-OLED presets' layouts, laser PSF measurements are made with the project
(udc_render.fit.synthetic.psf_measurement: the paper's lens and 1.55 µm pixels, read noise 4.87 e-, full
well 15 506 e-, 16 bits, black 64 DN, 3 hot pixels, the spot up to 6 px off centre and turned by up to 4°)
at a ladder of signals, the brightest pixel (the zeroth order's core) at a fraction of the full well, in one
exposure, or in 2 or 3 exposures 10× apart (the brightest saturating). Each is fitted with the family
given (udc_render.fit.psf_fit.fit_psf); per setting: the share refused (no orders found), the median and
largest |pitch error| / pitch, the median stated σ / pitch, the median |open-fraction error| / truth.

    .venv/bin/python benchmarks/bench_fit_exposures.py [--trials 6] [--out FILE.csv]
"""
from __future__ import annotations

import argparse
import csv
import sys
import time

import numpy as np

from psf import layouts
from udc_render.fit import FitError, FitSpec, synthetic as S
from udc_render.fit.hdr import merge_psf
from udc_render.fit.inputs import Frame
from udc_render.fit.psf_fit import fit_psf

SETTINGS = [("1 exposure", (f,)) for f in (0.003, 0.03, 0.1, 0.3, 0.5, 0.8)] + \
    [("2 exposures", (0.1, 1.0)), ("2 exposures", (0.8, 8.0)), ("3 exposures", (0.8, 8.0, 80.0))]
DISPLAYS = {"toled": (layouts.toled, 255), "poled": (layouts.poled, 383)}


def one(family: str, peaks, seed: int) -> dict:
    make, size = DISPLAYS[family]
    lay = make()
    rng = np.random.default_rng([seed, 7])
    rot = rng.uniform(-4, 4)
    frames = S.psf_measurement(lay, shape_hw=(size + 17, size + 17), offset_px=tuple(rng.uniform(-6, 6, 2)),
                               rotation_deg=rot, peaks_fw=peaks, hot_pixels=3, seed=seed, window_px=size)
    plane = merge_psf([Frame(f"f{i}", x.astype(float), "mono", None, 64.0, 65535.0, 16) for i, x in enumerate(frames)],
                      650.0, "Nikon 5100 (NPL)")
    try:
        c = fit_psf(plane, FitSpec(psf=("x",)).optics(), family, window_px=size).chosen
    except FitError as exc:
        return {"refused": str(exc)}
    p = lay.pitch_x_um
    x = c.fit.x
    of = x[0] * x[1] if family == "toled" else x[0]
    return {"pitch_err": abs(c.pitch_um[0][0] / p - 1), "pitch_sigma": c.pitch_um[0][1] / p,
            "of_err": abs(of / lay.open_fraction - 1)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=6)
    ap.add_argument("--out", help="also write the table as CSV")
    args = ap.parse_args(argv)
    rows = []
    for family in DISPLAYS:
        for label, peaks in SETTINGS:
            t0 = time.perf_counter()
            res = [one(family, peaks, seed) for seed in range(args.trials)]
            ok = [r for r in res if "refused" not in r]
            row = {"display": family, "exposures": label, "peak_fw": "/".join(f"{p:g}" for p in peaks),
                   "peak_e": f"{peaks[0] * 15506:.0f}", "refused": f"{len(res) - len(ok)}/{len(res)}",
                   "pitch_err_median": np.median([r["pitch_err"] for r in ok]) if ok else np.nan,
                   "pitch_err_max": max([r["pitch_err"] for r in ok]) if ok else np.nan,
                   "pitch_sigma_median": np.median([r["pitch_sigma"] for r in ok]) if ok else np.nan,
                   "open_fraction_err_median": np.median([r["of_err"] for r in ok]) if ok else np.nan,
                   "seconds": round(time.perf_counter() - t0, 1)}
            rows.append(row)
            print(" | ".join(f"{v:.2e}" if isinstance(v, float) else str(v) for v in row.values()), flush=True)
    if args.out:
        with open(args.out, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
