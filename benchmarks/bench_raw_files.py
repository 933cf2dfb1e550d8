#!/usr/bin/env python
"""Bytes, write and read times of the RAW file forms of a capture (benchmarks/README.md, "bench_raw_files.py").

The capture: scikit-image's astronaut, sRGB-decoded, cropped to 2:1 and resized to the frame
(default 2048 × 1024), mosaicked RGGB and exposed by the sensor (udc_render.sensor.capture_electrons:
Poisson + read noise, 16-bit quantisation) at `--gain` (6: the T-OLED's) with the image's 99th
percentile at 90 % of the white level, as `udc-render synth` exposes.

Forms: the DNG of udc_render.io.dng uncompressed and deflated (compression 8), the packed TIFF
[4, H/2, W/2] (the old packed.tiff) with zlib at levels 1 and 6 and uncompressed, and the old
16-bit PNG (pypng, as the old raw.png). Times are medians of `--repeats` rounds, forms interleaved in
each round, files in `--dir` (the page cache is warm: decode cost, not disk):

    write      the array ──► file (atomic rename included for the DNG)
    read       file ──► the stored array with tifffile (pypng for the PNG)
    rawpy      file ──► rawpy.imread(...).raw_image_visible (libraw), or why libraw refuses it
    packed     file ──► [4, H/2, W/2] uint16 for training (read, then sensor.pack_rggb if stored as a mosaic)

    .venv/bin/python benchmarks/bench_raw_files.py --out out/bench/raw_files.md
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from udc_render.io.dng import read_dng_mosaic, save_dng
from udc_render.sensor import SensorConfig, capture_electrons, mosaic_of, pack_rggb

CAMERA = "Nikon 5100 (NPL)"


def test_capture(width_px: int, height_px: int, gain: float, seed: int = 0) -> tuple[np.ndarray, SensorConfig]:
    """(mosaic [H, W] uint16, sensor) of the module doc's capture."""
    import colour
    from skimage import data, transform
    img = data.astronaut()
    h = img.shape[1] * height_px // width_px
    img = img[(img.shape[0] - h) // 2:(img.shape[0] + h) // 2]
    lin = colour.cctf_decoding(transform.resize(img, (height_px, width_px), order=1, anti_aliasing=True), "sRGB")
    sensor = SensorConfig(gain=gain, camera=CAMERA, form="per_channel")  # the electrons are given: no spectra
    rgb = np.moveaxis(lin, -1, 0)
    electrons = mosaic_of(rgb) * (0.9 * sensor.full_well_e / gain / np.percentile(rgb, 99))
    return capture_electrons(electrons, sensor, np.random.default_rng(seed)).mosaic_dn, sensor


def _png_write(path: Path, mosaic: np.ndarray) -> None:
    """The old raw.png writer (16-bit grey, pypng)."""
    import png
    with open(path, "wb") as f:
        png.Writer(mosaic.shape[1], mosaic.shape[0], greyscale=True, bitdepth=16).write(f, mosaic)


def _png_read(path: Path) -> np.ndarray:
    import png
    w, h, rows, _ = png.Reader(filename=str(path)).read()
    return np.vstack([np.asarray(r, dtype=np.uint16) for r in rows]).reshape(h, w)


def _tiff_write(path: Path, packed: np.ndarray, level: int | None) -> None:
    """The old packed.tiff writer, at a zlib level (None: uncompressed)."""
    import tifffile
    args = {} if level is None else {"compression": "zlib", "compressionargs": {"level": level}}
    tifffile.imwrite(path, packed, photometric="minisblack", planarconfig="separate", metadata={"axes": "CYX"},
                     software=False, **args)


def _tiff_read(path: Path) -> np.ndarray:
    import tifffile
    return tifffile.imread(path)


def _rawpy_read(path: Path) -> np.ndarray:
    import rawpy
    with rawpy.imread(str(path)) as r:
        return r.raw_image_visible.copy()


def forms(sensor: SensorConfig) -> dict:
    """name ──► (suffix, write(path, mosaic), read(path) ──► stored array, stored as mosaic?, rawpy?)."""
    levels = (sensor.black_level_dn, sensor.white_level_dn)

    def dng(compression, level):
        return lambda p, m: save_dng(p, m, CAMERA, *levels, compression=compression, compression_level=level)

    def tiff(level):
        return lambda p, m: _tiff_write(p, pack_rggb(m), level)
    return {"DNG, uncompressed": (".dng", dng(None, None), lambda p: read_dng_mosaic(p).mosaic_dn, True, True),
            "DNG, deflate (8), level 6": (".dng", dng(8, 6), lambda p: read_dng_mosaic(p).mosaic_dn, True, True),
            "packed TIFF, zlib level 1": (".tiff", tiff(1), _tiff_read, False, False),
            "packed TIFF, zlib level 6 (old packed.tiff)": (".tiff", tiff(6), _tiff_read, False, False),
            "packed TIFF, uncompressed": (".tiff", tiff(None), _tiff_read, False, False),
            "16-bit PNG, pypng (old raw.png)": (".png", _png_write, _png_read, True, False)}


def _timed(fn, *args) -> tuple[float, object]:
    t0 = time.perf_counter()
    out = fn(*args)
    return time.perf_counter() - t0, out


def _rawpy_check(path: Path, mosaic: np.ndarray) -> str | None:
    """None when libraw reads the file back exactly, else why not (one line)."""
    try:
        ok = np.array_equal(_rawpy_read(path), mosaic)
    except Exception as exc:  # noqa: BLE001  libraw's refusal is the result
        return f"{type(exc).__name__}: {exc}"
    return None if ok else "reads, but not the same mosaic"


def measure(mosaic: np.ndarray, sensor: SensorConfig, folder: Path, repeats: int) -> list[dict]:
    """One row per form: median times (ms), bytes, exact round trips."""
    table = forms(sensor)
    paths = {n: folder / f"form{i}{suffix}" for i, (n, (suffix, *_)) in enumerate(table.items())}
    times = {n: {"write": [], "read": [], "rawpy": [], "packed": []} for n in table}
    rawpy_note = {}
    for r in range(repeats):
        for n, (_, write, read, is_mosaic, try_rawpy) in table.items():
            path = paths[n]
            times[n]["write"].append(_timed(write, path, mosaic)[0])
            dt, stored = _timed(read, path)
            times[n]["read"].append(dt)
            assert np.array_equal(stored, mosaic if is_mosaic else pack_rggb(mosaic)), n
            times[n]["packed"].append(_timed(lambda: pack_rggb(read(path)) if is_mosaic else read(path))[0])
            if try_rawpy:
                if r == 0:
                    rawpy_note[n] = _rawpy_check(path, mosaic)
                if rawpy_note[n] is None:
                    times[n]["rawpy"].append(_timed(_rawpy_read, path)[0])
    rows = []
    for n in table:
        med = {k: statistics.median(v) * 1e3 if v else None for k, v in times[n].items()}
        rows.append({"form": n, "bytes": paths[n].stat().st_size, **med,
                     "rawpy_note": rawpy_note.get(n, "not a RAW file")})
    return rows


def markdown(rows: list[dict], mosaic: np.ndarray, gain: float, repeats: int) -> str:
    raw_bytes = mosaic.nbytes
    lines = [f"Capture {mosaic.shape[1]} × {mosaic.shape[0]} uint16 ({raw_bytes / 1e6:.2f} MB in memory), "
             f"gain {gain:g}; "
             f"medians of {repeats} repeats, ms.", "",
             "| form | MB | of raw | write | read (tifffile) | read (rawpy) | to packed [4, H/2, W/2] |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        rawpy = f"{r['rawpy']:.1f}" if r["rawpy"] is not None else f"— ({r['rawpy_note']})"
        lines.append(f"| {r['form']} | {r['bytes'] / 1e6:.2f} | {r['bytes'] / raw_bytes:.0%} | {r['write']:.1f} | "
                     f"{r['read']:.1f} | {rawpy} | {r['packed']:.1f} |")
    lines.append("")
    lines.append("read (tifffile): pypng for the PNG; to packed: read, then pack_rggb when stored as a mosaic.")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size-px", default="2048,1024", help="frame width,height [2048,1024]")
    ap.add_argument("--gain", type=float, default=6.0, help="sensor gain (1 glass, 6 T-OLED, 25 P-OLED) [6]")
    ap.add_argument("--repeats", type=int, default=5, choices=range(3, 101), metavar="N",
                    help="rounds (3–100); medians reported [5]")
    ap.add_argument("--dir", type=Path, default=None, help="folder for the files [a temporary folder]")
    ap.add_argument("--out", type=Path, default=None, help="also write the markdown table here")
    args = ap.parse_args()
    w, h = (int(v) for v in args.size_px.split(","))
    mosaic, sensor = test_capture(w, h, args.gain)
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        text = markdown(measure(mosaic, sensor, Path(tmp), args.repeats), mosaic, args.gain, args.repeats)
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)


if __name__ == "__main__":
    main()
