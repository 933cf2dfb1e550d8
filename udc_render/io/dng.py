"""The RAW capture as a DNG (Adobe DNG 1.4) that RAW tools open (tested: libraw 0.22 through rawpy 0.28).

One IFD, NewSubFileType 0 (the main image), PhotometricInterpretation 32803 (CFA), 16 bits per
sample, uncompressed (see below), CFARepeatPatternDim (2, 2), CFAPattern RGGB (0, 1, 1, 2),
BlackLevel and WhiteLevel of the sensor (DN), ColorMatrix1 (XYZ ──► camera, fitted to the camera's
spectral sensitivities: color_matrix_fit) for CalibrationIlluminant1 21 (D65), AsShotNeutral (the
camera's response to D65, green = 1; the RAW itself is never white balanced), UniqueCameraModel
'udc-render <camera>', Make 'udc-render', Model <camera>. No date, time or software tags: writing
the same mosaic twice gives the same bytes. libraw opens frames of at least 22 × 22 px only (its own
limit; tifffile reads any size).

Compression: none, chosen from `.venv/bin/python benchmarks/bench_raw_files.py --repeats 7` (2048 × 1024
capture with the sensor's noise at gain 6, the T-OLED's; medians, ms, on a loaded 2-core machine;
benchmarks/README.md, "bench_raw_files.py", has the full table and its reading):

    form                                   MB    write   read   read + pack   libraw
    DNG, uncompressed (this module)        4.19   19.3    0.9      1.4        reads it (13.6)
    DNG, deflate (8), level 6              3.88  264.4   32.6     36.1        refuses it
    packed TIFF, zlib level 1              3.86  192.1   35.7     36.9        —
    packed TIFF, zlib level 6 (old)        3.85  260.8   37.5     31.9        —
    packed TIFF, uncompressed              4.19   11.9    0.7      0.9        —
    16-bit PNG, pypng (old raw.png)        3.88  444.2  165.8    171.3        —

Shot noise fills the low bits, so deflate saves 8 % (at gains 1, 6 and 25) for 10–20× the write time
and 30–40 ms of inflate per read. DNG deflate is not an option anyway: libraw 0.22 (the rawpy 0.28
wheel) decodes compression 8 only for floating-point DNGs and refuses a uint16 one ("Corrupted data
or unexpected EOF").
"""
from __future__ import annotations

import functools
from pathlib import Path
from typing import NamedTuple

import numpy as np
import tifffile

from psf import colour_tables
from udc_render.content import spectra
from udc_render.errors import UdcError
from udc_render.io.files import atomic_path
from udc_render.sensor import photon_weights

RATIONAL_DENOMINATOR = 10000  # DNG matrices and neutrals as n / 10000 (4 decimals, as Adobe's converter)
ILLUMINANT_D65 = 21  # EXIF LightSource code of D65
CFA_RGGB = (0, 1, 1, 2)  # CFAPattern: colour (0 R, 1 G, 2 B) of (0, 0), (0, 1), (1, 0), (1, 1)
COMPRESSION = None  # module doc: none (uncompressed); tifffile's code otherwise (8: deflate)


class DngError(UdcError):
    """A mosaic that cannot be written as a DNG, or a file that is not one of ours; one line."""


class DngMosaic(NamedTuple):
    """A DNG's CFA mosaic [H, W] uint16 (RGGB, DN) with its black and white levels (DN)."""
    mosaic_dn: np.ndarray
    black_level_dn: int
    white_level_dn: int


def checker_responses(camera: str) -> tuple[np.ndarray, np.ndarray]:
    """(camera RGB [N + 1, 3], XYZ [N + 1, 3]) of the 24 ColorChecker patches (colour-science 'ColorChecker
    N Ohta') under D65, then of D65 itself (reflectance 1), in 1 nm bands over 360–830 nm:
    c = Σ_k q_k L̄_k Δλ (q: photon_weights, the sensor's quantum efficiency per joule), XYZ = Σ_k x̄_k L̄_k Δλ
    (x̄_k: band means of the CIE 1931 2° CMFs), L = reflectance × D65, L̄ the band means. Units are arbitrary
    (only ratios matter)."""
    patches = colour_tables.names("colourchecker")
    d65 = spectra.illuminant("D65")
    radiance = np.stack([spectra.colourchecker(n) * d65 for n in patches] + [d65])

    def band(s):  # mean over [λ_k, λ_k + 1 nm]
        return 0.5 * (s[..., 1:] + s[..., :-1])
    cam = band(radiance) @ photon_weights(spectra.GRID_NM, camera).T
    xyz = band(radiance) @ band(spectra.cmfs()).T
    return cam, xyz


@functools.lru_cache(maxsize=8)
def _fit(camera: str) -> tuple[tuple[float, ...], float, tuple[float, ...]]:
    cam, xyz = checker_responses(camera)
    m = np.linalg.lstsq(xyz[:-1], cam[:-1], rcond=None)[0].T
    rel_rms = float(np.linalg.norm(cam[:-1] - xyz[:-1] @ m.T) / np.linalg.norm(cam[:-1]))
    m /= (m @ (xyz[-1] / xyz[-1, 1])).max()
    return tuple(m.ravel()), rel_rms, tuple(cam[-1] / cam[-1, 1])


def color_matrix_fit(camera: str) -> tuple[np.ndarray, float]:
    """DNG ColorMatrix1 of `camera` for D65 and its relative RMS residual over the ColorChecker.

    M = argmin_M Σ_i ‖c_i − M x_i‖² over the 24 patches i under D65 (checker_responses), i.e.
    Mᵀ = (XᵀX)⁻¹ XᵀC, then scaled as DNG requires (DNG 1.4 spec, "Mapping Camera Color Space to CIE XYZ Space"):
    max_c (M x_w)_c = 1 for x_w the XYZ of D65 with Y = 1. Residual (before scaling, so free of
    units): ‖C − XMᵀ‖_F / ‖C‖_F.
    """
    m, rel_rms, _ = _fit(camera)
    return np.reshape(m, (3, 3)), rel_rms


def as_shot_neutral(camera: str) -> np.ndarray:
    """DNG AsShotNeutral: the camera's response to D65 [R, G, B] / G (the inverse of the daylight gains)."""
    return np.asarray(_fit(camera)[2])


def _rationals(values) -> list[int]:
    """Flat (numerator, denominator) pairs: v ≈ round(v · RATIONAL_DENOMINATOR) / RATIONAL_DENOMINATOR."""
    return [n for v in np.ravel(values) for n in (int(round(float(v) * RATIONAL_DENOMINATOR)), RATIONAL_DENOMINATOR)]


def dng_tags(camera: str, black_level_dn: int, white_level_dn: int) -> list[tuple]:
    """tifffile extratags (code, type, count, value, writeonce) of the module doc."""
    matrix, _ = color_matrix_fit(camera)
    name = camera.encode("ascii", "replace").decode()  # TIFF ASCII; a CSV camera's path may not be
    return [(50706, "B", 4, (1, 4, 0, 0), True),  # DNGVersion
            (50707, "B", 4, (1, 1, 0, 0), True),  # DNGBackwardVersion
            (271, "s", 0, "udc-render", True),  # Make
            (272, "s", 0, name, True),  # Model
            (274, "H", 1, 1, True),  # Orientation: top-left
            (33421, "H", 2, (2, 2), True),  # CFARepeatPatternDim
            (33422, "B", 4, CFA_RGGB, True),  # CFAPattern
            (50708, "s", 0, f"udc-render {name}", True),  # UniqueCameraModel
            (50710, "B", 3, (0, 1, 2), True),  # CFAPlaneColor: R, G, B
            (50711, "H", 1, 1, True),  # CFALayout: rectangular
            (50713, "H", 2, (1, 1), True),  # BlackLevelRepeatDim: one level for every site
            (50714, "I", 1, int(black_level_dn), True),  # BlackLevel
            (50717, "I", 1, int(white_level_dn), True),  # WhiteLevel
            (50721, "2i", 9, _rationals(matrix), True),  # ColorMatrix1 (SRATIONAL)
            (50728, "2I", 3, _rationals(as_shot_neutral(camera)), True),  # AsShotNeutral (RATIONAL)
            (50778, "H", 1, ILLUMINANT_D65, True)]  # CalibrationIlluminant1


def _check_mosaic(path: Path, mosaic_dn, black_level_dn: int, white_level_dn: int) -> np.ndarray:
    m = np.asarray(mosaic_dn)
    if m.dtype != np.uint16:
        raise DngError(f"{path}: mosaic dtype {m.dtype}: expected uint16 DN (round and clip before writing)")
    if m.ndim != 2 or min(m.shape) < 2 or m.shape[0] % 2 or m.shape[1] % 2:
        raise DngError(f"{path}: mosaic shape {m.shape}: expected [H, W] with H and W even and ≥ 2 (RGGB cells)")
    if not 0 <= black_level_dn < white_level_dn <= 65535:
        raise DngError(f"{path}: black {black_level_dn}, white {white_level_dn} DN: expected 0 ≤ black < white ≤ 65535")
    return np.ascontiguousarray(m)


def save_dng(path: Path, mosaic_dn: np.ndarray, camera: str, black_level_dn: int, white_level_dn: int,
             compression: int | None = COMPRESSION, compression_level: int | None = None) -> None:
    """Write an RGGB mosaic [H, W] uint16 (DN) as a DNG (module doc), atomically."""
    path = Path(path)
    m = _check_mosaic(path, mosaic_dn, black_level_dn, white_level_dn)
    args = {} if compression is None else {"compression": compression}
    if compression_level is not None:
        args["compressionargs"] = {"level": compression_level}
    with atomic_path(path, ".dng") as tmp:
        tifffile.imwrite(tmp, m, photometric=32803, subfiletype=0, software=False, metadata=None,
                         extratags=dng_tags(camera, black_level_dn, white_level_dn), **args)


def read_dng_mosaic(path: Path) -> DngMosaic:
    """The mosaic and levels of a DNG written by save_dng (read with tifffile)."""
    path = Path(path)
    try:
        with tifffile.TiffFile(path) as tif:
            page = tif.pages[0]
            tags = page.tags
            if page.photometric != 32803 or tags.valueof(33422) != bytes(CFA_RGGB):
                raise DngError(f"{path}: not an RGGB CFA DNG (photometric {int(page.photometric)}): "
                               "expected a file written by udc-render")
            return DngMosaic(page.asarray(), int(tags.valueof(50714, 0)), int(tags.valueof(50717, 65535)))
    except tifffile.TiffFileError as exc:
        raise DngError(f"{path}: not a TIFF/DNG file ({exc})") from None
