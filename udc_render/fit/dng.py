"""A camera's DNG as udc-render fit reads it: the raw IFD's pixels decoded by LibRaw (rawpy), its tags read
with tifffile, and the DNG's mapping of stored values to linear ones applied here (DNG 1.4, "Mapping Raw
Values to Linear Reference Values"):

    linear(r, c) = LinearizationTable[stored(r, c)] − BlackLevel[(r − top) mod R, (c − left) mod C]
                   − BlackLevelDeltaH[c − left] − BlackLevelDeltaV[r − top]

over the ActiveArea (top, left, bottom, right) only; the CFA pattern's origin is the ActiveArea's top-left
corner too (the BlackLevel pattern's likewise). WhiteLevel is a linearized value.

What LibRaw 0.22 does with these (measured on files written as cameras write them: lossless JPEG tiles,
tests/udc_render/camera_files.py):
- it decodes uncompressed and lossless-JPEG (LJ92) DNGs, tiled or in strips, and refuses a 16-bit deflate
  one (then tifffile decodes it, and the table is applied here);
- raw_image holds the whole stored image with the LinearizationTable applied (its tone_curve is the table);
- raw_image_visible is not the ActiveArea: LibRaw moves an odd top or left margin to the next even row or
  column, so the crop is made here from the tag;
- black_level_per_channel puts the BlackLevel pattern on the wrong sites when the ActiveArea starts on an
  odd row or column, and adds the mean of BlackLevelDeltaH/V to every site: the levels are read here from
  the tags, per site and per row and column.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rawpy
import tifffile

from udc_render.fit.errors import FitError

CFA, LINEAR_RAW = 32803, 34892
T_PATTERN_DIM, T_PATTERN, T_PLANE_COLOR = 33421, 33422, 50710
T_TABLE, T_BLACK_DIM, T_BLACK, T_DELTA_H, T_DELTA_V, T_WHITE, T_ACTIVE = \
    50712, 50713, 50714, 50715, 50716, 50717, 50829


@dataclass(frozen=True)
class RawDng:
    """A DNG's ActiveArea, linearized: dn [H, W] (CFA) or [H, W, C] (LinearRaw) in DN as stored after the
    LinearizationTable, the black level of every pixel (same shape), the WhiteLevel (None without the tag),
    the CFA's 2 × 2 colours (0 R, 1 G, 2 B; None for LinearRaw), the bit depth of the linear values, and
    what was decoded how."""
    dn: np.ndarray
    black_dn: np.ndarray
    white_dn: float | None
    sites: np.ndarray | None
    bits: int
    notes: tuple


def _pages(tif):
    for page in tif.pages:
        yield page
        yield from (getattr(page, "pages", None) or ())


def _raw_page(pages):
    """The raw IFD: CFA or LinearRaw, the main image (NewSubFileType 0) first, then the largest."""
    raws = [p for p in pages if int(p.photometric) in (CFA, LINEAR_RAW)]
    if not raws:
        return None
    return max(raws, key=lambda p: (int(p.tags.valueof(254, 0)) == 0, p.shape[0] * p.shape[1]))


def _values(page, code) -> np.ndarray | None:
    """A tag's values as float64 (RATIONAL and SRATIONAL pairs divided), None without the tag."""
    tag = page.tags.get(code)
    if tag is None:
        return None
    v = tag.value
    a = np.frombuffer(v, np.uint8).astype(np.float64) if isinstance(v, (bytes, bytearray)) else \
        np.asarray(v, dtype=np.float64).ravel()
    if int(tag.dtype) in (5, 10):
        a = a[0::2] / np.where(a[1::2] == 0, 1.0, a[1::2])
    return a


def _decode_libraw(path: Path, shape_hw, table) -> tuple[np.ndarray, bool, str]:
    """(the stored image as LibRaw decodes it, whether the table is already applied, a note or '')."""
    with rawpy.imread(str(path)) as raw:
        data = np.array(raw.raw_image, copy=True)
        curve = np.array(raw.tone_curve, copy=True)  # a view into LibRaw's memory until copied
    if data.ndim == 3:
        data = data[..., :3]
    if data.shape[:2] != tuple(shape_hw):
        raise ValueError(f"LibRaw decoded a {data.shape[1]} × {data.shape[0]} image, the raw IFD is "
                         f"{shape_hw[1]} × {shape_hw[0]}")
    if table is None:
        return data, True, ""
    n = min(table.size, curve.size)
    if np.array_equal(curve[:n], table[:n]):
        return data, True, ""
    if np.array_equal(curve[:n], np.arange(n)):
        return data, False, "its LinearizationTable applied here (LibRaw did not)"
    raise ValueError("LibRaw's tone curve is neither the file's LinearizationTable nor the identity")


def _decode(path: Path, page, table) -> tuple[np.ndarray, bool, str]:
    """The stored image: LibRaw first (any compression it knows), tifffile where LibRaw refuses it."""
    shape_hw = page.shape[:2] if int(page.photometric) == CFA or page.planarconfig == 1 else page.shape[1:3]
    try:
        return _decode_libraw(path, shape_hw, table)
    except Exception as exc:  # noqa: BLE001  any LibRaw refusal: try tifffile, then say both
        libraw = f"{type(exc).__name__}: {exc}"
    try:
        data = page.asarray()
    except Exception as exc:  # noqa: BLE001
        raise FitError(f"{path}: the raw image cannot be decoded (LibRaw: {libraw}; tifffile: "
                           f"{type(exc).__name__}: {exc}): expected an uncompressed, lossless-JPEG or deflate "
                           "raw DNG") from None
    if data.ndim == 3 and page.planarconfig == 2:
        data = np.moveaxis(data, 0, -1)
    return data, False, f"decoded by tifffile (LibRaw refused it: {libraw})"


def _active(page, path: Path, shape_hw) -> tuple[int, int, int, int]:
    a = _values(page, T_ACTIVE)
    h, w = shape_hw
    if a is None:
        return 0, 0, h, w
    top, left, bottom, right = (int(v) for v in a[:4])
    if not (0 <= top < bottom <= h and 0 <= left < right <= w):
        raise FitError(f"{path}: ActiveArea {top, left, bottom, right} outside the {w} × {h} raw image: "
                           "expected top < bottom ≤ height, left < right ≤ width")
    return top, left, bottom, right


def _black(page, path: Path, shape: tuple) -> np.ndarray:
    """The black level of every pixel of the ActiveArea [H, W] or [H, W, C] (module doc)."""
    h, w = shape[:2]
    spp = shape[2] if len(shape) == 3 else 1
    dim = _values(page, T_BLACK_DIM)
    rows, cols = (1, 1) if dim is None else (int(dim[0]), int(dim[1]))
    level = _values(page, T_BLACK)
    level = np.zeros(1) if level is None else level
    if level.size == 1:
        level = np.full(rows * cols * spp, level[0])
    if rows < 1 or cols < 1 or level.size != rows * cols * spp:
        raise FitError(f"{path}: BlackLevel holds {level.size} values for BlackLevelRepeatDim {rows} × {cols} "
                           f"and {spp} sample(s): expected rows × cols × samples values")
    pattern = level.reshape(rows, cols, spp)
    black = np.tile(pattern, (h // rows + 1, w // cols + 1, 1))[:h, :w]
    for code, n, axis in ((T_DELTA_H, w, 1), (T_DELTA_V, h, 0)):
        delta = _values(page, code)
        if delta is None:
            continue
        if delta.size != n:
            name = "BlackLevelDeltaH" if axis == 1 else "BlackLevelDeltaV"
            raise FitError(f"{path}: {name} holds {delta.size} values: expected one per ActiveArea "
                               f"{'column' if axis == 1 else 'row'} ({n})")
        black = black + (delta[None, :, None] if axis == 1 else delta[:, None, None])
    return black if spp > 1 else black[..., 0]


def _sites(page, path: Path) -> np.ndarray:
    dim = _values(page, T_PATTERN_DIM)
    codes = _values(page, T_PATTERN)
    planes = _values(page, T_PLANE_COLOR)
    planes = np.array([0, 1, 2]) if planes is None else planes
    if codes is None or (dim is not None and tuple(int(v) for v in dim) != (2, 2)) or codes.size != 4:
        raise FitError(f"{path}: CFA pattern {None if codes is None else codes.astype(int).tolist()} of "
                           f"{None if dim is None else dim.astype(int).tolist()}: expected a 2 × 2 pattern")
    try:
        colours = [int(planes[int(c)]) for c in codes]
    except IndexError:
        colours = [-1]
    if sorted(set(colours)) != [0, 1, 2]:
        raise FitError(f"{path}: CFA pattern {codes.astype(int).tolist()} (CFAPlaneColor "
                           f"{planes.astype(int).tolist()}): expected red, green and blue sites (0, 1, 2)")
    return np.array(colours, np.int8).reshape(2, 2)


def read_dng(path) -> RawDng:
    """The DNG's ActiveArea linearized, its per-pixel black level, white level and CFA (module doc)."""
    path = Path(path)
    try:
        with tifffile.TiffFile(path) as tif:
            page = _raw_page(list(_pages(tif)))
            if page is None:
                raise FitError(f"{path}: no CFA or LinearRaw image in the DNG: expected a raw DNG")
            table = _values(page, T_TABLE)
            data, linear, how = _decode(path, page, table)
            top, left, bottom, right = _active(page, path, data.shape[:2])
            white = _values(page, T_WHITE)
            kind_cfa = int(page.photometric) == CFA
            sites = _sites(page, path) if kind_cfa else None
            bits = int(np.max(np.atleast_1d(page.bitspersample)))
            crop = data[top:bottom, left:right]
            black = _black(page, path, crop.shape)
    except tifffile.TiffFileError as exc:
        raise FitError(f"{path}: not a TIFF/DNG file ({exc}): expected a raw DNG") from None
    if data.dtype.kind not in "ui":
        raise FitError(f"{path}: raw samples of type {data.dtype}: expected integers (a floating-point DNG "
                           "is not read)")
    crop = crop.astype(np.int64)
    if table is not None:
        if not linear:
            crop = table.astype(np.int64)[np.clip(crop, 0, table.size - 1)]
        bits = max(bits, int(np.ceil(np.log2(float(table.max()) + 1.0))))
    notes = [f"{path.name}: {how}"] if how else []
    if (top, left, bottom, right) != (0, 0) + data.shape[:2]:
        notes.append(f"{path.name}: ActiveArea rows {top}–{bottom}, columns {left}–{right}")
    w = None if white is None else float(np.min(white))
    return RawDng(crop.astype(np.float64), black, w, sites, bits, tuple(notes))
