#!/usr/bin/env python
"""Bytes, write and read times of the ground truth's gt.exr under OpenEXR's lossless compressions.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_gt_exr.py [--size-px 2048,1024] [--repeats 5]

The ground truth as `udc-render synth` writes it ([3, H, W] float32, (DN − black) / (g · FW) at gain 1): scikit-image's
astronaut, sRGB-decoded, cropped to 2:1 and resized to the frame, its 99th percentile at 90 % of the full well,
as the paper took it (the mean of 16 frames: sensor.frames.mean_of_frames) and noise-free ('ideal'). Forms: ZIP
(16 scanlines a block), ZIPS (one), PIZ (wavelet), RLE and none; every round trip is checked bit for bit. Times
are CPU medians of `--repeats` rounds, one thread (the page cache is warm: codec cost, not disk).
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from udc_render.io.exr import COMPRESSIONS, read_exr, save_exr
from udc_render.sensor import SensorConfig
from udc_render.sensor.frames import mean_of_frames

FORMS = ("zip", "zips", "piz", "rle", "none")


def ground_truths(width_px: int, height_px: int) -> dict[str, np.ndarray]:
    """{'16 frames': [3, H, W], 'ideal': [3, H, W]} float32 (module doc)."""
    from skimage import data, transform

    from udc_render.content.monitor_image import decode
    img = data.astronaut()
    h = img.shape[1] * height_px // width_px
    img = img[(img.shape[0] - h) // 2:(img.shape[0] + h) // 2]
    lin = np.moveaxis(decode(transform.resize(img, (height_px, width_px), order=1, anti_aliasing=True), "srgb"), -1, 0)
    s = replace(SensorConfig(), gain=1.0)
    electrons = lin * (0.9 * s.full_well_e / np.percentile(lin, 99))
    rng = np.random.default_rng(0)
    scale = s.dn_per_electron * s.full_well_e
    frames = np.stack([(mean_of_frames(e, s, 16, rng)[0] - s.black_level_dn) / scale for e in electrons])
    return {"16 frames": frames.astype(np.float32), "ideal": (electrons / s.full_well_e).astype(np.float32)}


def measure(gt: np.ndarray, folder: Path, repeats: int) -> list[dict]:
    rows = []
    for form in FORMS:
        path = folder / f"{form}.exr"
        writes, reads = [], []
        for _ in range(repeats):
            t0 = time.process_time()
            save_exr(path, {c: gt[i] for i, c in enumerate("RGB")}, compression=form)
            t1 = time.process_time()
            back = read_exr(path)
            reads.append(time.process_time() - t1)
            writes.append(t1 - t0)
            assert all(np.array_equal(back[c], gt[i]) for i, c in enumerate("RGB")), form
        rows.append({"form": form, "mb": path.stat().st_size / 1e6, "write_ms": 1e3 * statistics.median(writes),
                     "read_ms": 1e3 * statistics.median(reads)})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size-px", default="2048,1024", help="frame width,height [2048,1024]")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    w, h = (int(v) for v in args.size_px.split(","))
    assert set(FORMS) <= set(COMPRESSIONS)
    print(f"bench_gt_exr: gt.exr of {w} × {h} × 3 float32 ({12 * w * h / 1e6:.1f} MB in memory); CPU medians of "
          f"{args.repeats}, ms; every round trip bit for bit\n")
    print("| ground truth | compression | MB | write | read |\n|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, gt in ground_truths(w, h).items():
            for r in measure(gt, Path(tmp), args.repeats):
                print(f"| {name} | {r['form']} | {r['mb']:.1f} | {r['write_ms']:.0f} | {r['read_ms']:.0f} |")


if __name__ == "__main__":
    main()
