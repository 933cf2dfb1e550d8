"""Reading a user's measurement files: PNG (pypng) or TIFF (tifffile) at 8 or 16 bits, grey or colour, every
bit kept; and DNG (fit.dng: decoded by LibRaw, any compression it knows; the ActiveArea, the LinearizationTable,
the black level per CFA site and per row and column, the WhiteLevel and the CFA pattern from the tags).

Options win over the file: --black-level (one level for every pixel; else the DNG's, per pixel; else 0,
noted), --saturation (else the DNG's WhiteLevel, else the integer type's largest value). A pixel at or above
the saturation level is clipped: it is masked, with its 8 neighbours (charge that spills over), never fitted.
What cannot be read is refused in one line naming the file and what is expected.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import png
import tifffile

from udc_render.fit.dng import read_dng
from udc_render.fit.errors import FitError

SUFFIXES = (".png", ".tif", ".tiff", ".dng")
COLOURS = "RGB"


@dataclass(frozen=True)
class Frame:
    """One measured image, as stored (a DNG's linearized): dn [H, W] (grey or a CFA mosaic) or [H, W, C]
    (colour), float64 DN. kind 'mono', 'cfa' or 'rgb'; sites [2, 2]: the colour (0 R, 1 G, 2 B) of a CFA's
    2 × 2 sites; black_dn: the black level (the mean of black_map where the file gives one per pixel);
    saturation_dn: the clip; bits: the integer depth; notes: what was assumed; black_map: the black level of
    every pixel (dn's shape: a DNG's per-site pattern and row and column deltas), None where it is black_dn."""
    path: str
    dn: np.ndarray
    kind: str
    sites: np.ndarray | None
    black_dn: float
    saturation_dn: float
    bits: int
    notes: tuple = ()
    black_map: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.dn.shape[:2]

    def black(self) -> np.ndarray | float:
        """The black level of every pixel (black_map), or the one level."""
        return self.black_dn if self.black_map is None else self.black_map

    def above_black(self) -> np.ndarray:
        """dn − the black level, per pixel."""
        return self.dn - self.black()

    def colour_map(self) -> np.ndarray:
        """[H, W] colour index of every pixel: the CFA's site colours, 0 for grey images."""
        h, w = self.shape
        if self.kind != "cfa":
            return np.zeros((h, w), np.int8)
        return np.tile(self.sites, (h // 2 + 1, w // 2 + 1))[:h, :w]

    def site_map(self) -> np.ndarray:
        """[H, W] site class 0..3 ((row, col) parity: 0 (0,0), 1 (0,1), 2 (1,0), 3 (1,1)); 0 for grey images."""
        h, w = self.shape
        if self.kind != "cfa":
            return np.zeros((h, w), np.int8)
        return np.tile(np.array([[0, 1], [2, 3]], np.int8), (h // 2 + 1, w // 2 + 1))[:h, :w]


def _png(path: Path) -> np.ndarray:
    """A PNG's pixels at their own depth (pypng: 16 bits stay 16; palette expanded; sBIT honoured)."""
    w, h, rows, info = png.Reader(filename=str(path)).asDirect()
    dtype = np.uint16 if info["bitdepth"] > 8 else np.uint8
    data = np.vstack([np.asarray(r, dtype) for r in rows]).reshape(h, w, info["planes"])
    return data[..., 0] if info["planes"] == 1 else data


def _tiff(path: Path) -> np.ndarray:
    """A TIFF's first image, samples last."""
    with tifffile.TiffFile(path) as tif:
        page = tif.pages[0]
        data = page.asarray()
        if data.ndim == 3 and page.planarconfig == 2:
            data = np.moveaxis(data, 0, -1)
    return data


def _read_image(path: Path) -> np.ndarray:
    try:
        return _png(path) if path.suffix.lower() == ".png" else _tiff(path)
    except Exception as exc:  # noqa: BLE001  any decoder failure is one line
        kind = "PNG" if path.suffix.lower() == ".png" else "TIFF"
        raise FitError(f"{path}: cannot be read as a {kind} image ({type(exc).__name__}: {exc}): expected an 8- or "
                       f"16-bit grey or colour {kind}") from None


def _levels(path: Path, black_dn, saturation_dn, tag_black, tag_white, bits) -> tuple[float, float, list]:
    notes = []
    black = black_dn if black_dn is not None else tag_black
    if black is None:
        black = 0.0
        notes.append(f"{path.name}: black level 0 assumed (no --black-level, no DNG tag)")
    sat = saturation_dn if saturation_dn is not None else (tag_white if tag_white is not None else 2 ** bits - 1)
    if not 0 <= black < sat:
        raise FitError(f"{path}: black level {black:g} and saturation {sat:g} DN: expected 0 ≤ black < saturation")
    return float(black), float(sat), notes


def read_frame(path, black_dn: float | None = None, saturation_dn: float | None = None) -> Frame:
    """One measurement file as a Frame (module doc)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise FitError(f"{path}: unsupported file type {suffix!r}: expected {', '.join(SUFFIXES)}")
    if not path.is_file():
        raise FitError(f"{path}: no such file")
    sites = black_map = raw = None
    if suffix == ".dng":
        raw = read_dng(path)
        data, sites, bits = raw.dn, raw.sites, raw.bits
        kind = "cfa" if sites is not None else "rgb"
    else:
        data = _read_image(path)
        if data.dtype not in (np.uint8, np.uint16):
            raise FitError(f"{path}: pixel type {data.dtype}: expected 8- or 16-bit integers")
        bits = 8 * data.dtype.itemsize
        if data.ndim == 3:
            data = data[..., :3] if data.shape[-1] >= 3 else data[..., 0]
        kind = "rgb" if data.ndim == 3 else "mono"
    if data.ndim != 2 and not (data.ndim == 3 and kind == "rgb") or min(data.shape[:2]) < 16:
        raise FitError(f"{path}: image shape {data.shape}: expected a 2-D image of at least 16 × 16 pixels")
    tag_black = None if raw is None else float(np.mean(raw.black_dn))
    black, sat, notes = _levels(path, black_dn, saturation_dn, tag_black, None if raw is None else raw.white_dn, bits)
    if raw is not None:
        notes = list(raw.notes) + notes
        if black_dn is None and np.ptp(raw.black_dn) > 0:
            black_map = raw.black_dn
            notes.append(f"{path.name}: black level per pixel from the DNG (sites, rows, columns): "
                         f"{np.min(black_map):.6g}–{np.max(black_map):.6g} DN")
            if np.max(black_map) >= sat:
                raise FitError(f"{path}: black level up to {np.max(black_map):g} DN and saturation {sat:g} DN: "
                               "expected every pixel's black level below the saturation")
    return Frame(str(path), data.astype(np.float64), kind, sites, black, sat, bits, tuple(notes), black_map)


def read_frames(paths, black_dn=None, saturation_dn=None, what: str = "--psf") -> list[Frame]:
    """Frames of the same spot or scene: one kind and shape."""
    frames = [read_frame(p, black_dn, saturation_dn) for p in paths]
    if not frames:
        raise FitError(f"{what}: no image given: expected one or more of {', '.join(SUFFIXES)}")
    first = frames[0]
    for f in frames[1:]:
        if f.shape != first.shape or f.kind != first.kind:
            raise FitError(f"{what} {f.path}: {f.kind} image of {f.shape[1]} × {f.shape[0]} px, but {first.path} is "
                           f"{first.kind} of {first.shape[1]} × {first.shape[0]}: expected exposures of one camera")
    return frames


def saturated(frame: Frame, plane: np.ndarray) -> np.ndarray:
    """Pixels at or above the saturation level, grown by one pixel (charge spills into the neighbours)."""
    from scipy.ndimage import binary_dilation
    return binary_dilation(plane >= frame.saturation_dn - 0.5, np.ones((3, 3), bool))


def hot_pixels(value: np.ndarray, sigma: np.ndarray, ratio: float = 50.0, snr: float = 10.0) -> np.ndarray:
    """Isolated spikes: above snr σ and above ratio × the largest of their 8 neighbours (an Airy core on a
    1.55 µm pixel at 650 nm holds 17× its brightest neighbour: psf engine, f/1.8)."""
    from scipy.ndimage import maximum_filter
    ring = np.ones((3, 3), bool)
    ring[1, 1] = False
    neigh = maximum_filter(value, footprint=ring, mode="nearest")
    return (value > snr * sigma) & (value > ratio * np.maximum(neigh, sigma))


def border(shape_hw, fraction: float = 0.06) -> np.ndarray:
    """The outer strip of the frame (its dark surround), `fraction` of the shorter side wide."""
    h, w = shape_hw
    b = max(2, int(round(fraction * min(h, w))))
    m = np.zeros(shape_hw, bool)
    m[:b], m[-b:], m[:, :b], m[:, -b:] = True, True, True, True
    return m


def robust_sigma(x: np.ndarray) -> float:
    """1.4826 × the median absolute deviation (the σ of a Gaussian)."""
    x = np.asarray(x, float)
    return float(1.4826 * np.median(np.abs(x - np.median(x)))) if x.size else 0.0
