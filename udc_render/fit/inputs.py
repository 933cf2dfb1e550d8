"""Reading a user's measurement files: PNG or TIFF at 8 or 16 bits (grey or colour) and DNG (its CFA
mosaic, read with tifffile; the black and white levels from its BlackLevel and WhiteLevel tags).

Options win over the file: --black-level (else the DNG's tag, else 0, noted), --saturation (else the DNG's
WhiteLevel, else the integer type's largest value). A pixel at or above the saturation level is clipped: it
is masked, with its 8 neighbours (charge that spills over), never fitted.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import tifffile

from udc_render.errors import UdcError

SUFFIXES = (".png", ".tif", ".tiff", ".dng")
CFA_PHOTOMETRIC, LINEAR_RAW_PHOTOMETRIC = 32803, 34892
TAG_CFA_PATTERN, TAG_BLACK, TAG_WHITE = 33422, 50714, 50717
COLOURS = "RGB"


class FitError(UdcError):
    """What udc-render fit cannot read or fit; one line naming the file or option, the value and what is allowed."""


@dataclass(frozen=True)
class Frame:
    """One measured image, as stored: dn [H, W] (grey or a CFA mosaic) or [H, W, C] (colour), float64 DN.
    kind 'mono', 'cfa' or 'rgb'; sites [2, 2]: the colour (0 R, 1 G, 2 B) of a CFA's 2 × 2 sites;
    black_dn, saturation_dn: the levels; bits: the integer depth; notes: what was assumed."""
    path: str
    dn: np.ndarray
    kind: str
    sites: np.ndarray | None
    black_dn: float
    saturation_dn: float
    bits: int
    notes: tuple = ()

    @property
    def shape(self) -> tuple[int, int]:
        return self.dn.shape[:2]

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


def _pages(tif):
    for page in tif.pages:
        yield page
        yield from (getattr(page, "pages", None) or ())


def _tag(pages, code):
    for p in pages:
        tag = p.tags.get(code)
        if tag is not None:
            return tag
    return None


def _level(tag) -> float | None:
    """A level tag's mean value (one per site, or per channel): RATIONAL (5) and SRATIONAL (10) tags come as
    (numerator, denominator) pairs."""
    if tag is None:
        return None
    a = np.asarray(tag.value, dtype=np.float64).ravel()
    if int(tag.dtype) in (5, 10):
        a = a[0::2] / np.where(a[1::2] == 0, 1.0, a[1::2])
    return float(np.mean(a)) if a.size else None


def _read_dng(path: Path) -> tuple[np.ndarray, str, np.ndarray | None, float | None, float | None]:
    try:
        with tifffile.TiffFile(path) as tif:
            pages = list(_pages(tif))
            raw = next((p for p in pages if int(p.photometric) in (CFA_PHOTOMETRIC, LINEAR_RAW_PHOTOMETRIC)), None)
            if raw is None:
                raise FitError(f"{path}: no CFA or linear raw image in the DNG: expected a raw DNG")
            data = raw.asarray()
            order = [raw] + pages
            black, white = _level(_tag(order, TAG_BLACK)), _level(_tag(order, TAG_WHITE))
            if int(raw.photometric) == LINEAR_RAW_PHOTOMETRIC:
                return data, "rgb", None, black, white
            tag = _tag(order, TAG_CFA_PATTERN)
            pattern = None if tag is None else tag.value
    except tifffile.TiffFileError as exc:
        raise FitError(f"{path}: not a TIFF/DNG file ({exc})") from None
    except (ValueError, NotImplementedError, KeyError, RuntimeError) as exc:  # undecodable compression
        raise FitError(f"{path}: the DNG's raw image cannot be decoded ({type(exc).__name__}: {exc}): expected an "
                       "uncompressed or deflate DNG (convert it with Adobe DNG Converter, uncompressed)") from None
    codes = list(bytes(pattern)) if isinstance(pattern, (bytes, bytearray)) else list(np.ravel(pattern or ()))
    if len(codes) != 4 or any(c not in (0, 1, 2) for c in codes):
        raise FitError(f"{path}: CFAPattern {codes}: expected a 2 × 2 pattern of R, G and B (codes 0, 1, 2)")
    return data, "cfa", np.array(codes, np.int8).reshape(2, 2), black, white


def read_frame(path, black_dn: float | None = None, saturation_dn: float | None = None) -> Frame:
    """One measurement file as a Frame (module doc)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise FitError(f"{path}: unsupported file type {suffix!r}: expected {', '.join(SUFFIXES)}")
    if not path.is_file():
        raise FitError(f"{path}: no such file")
    tag_black = tag_white = sites = None
    if suffix == ".dng":
        data, kind, sites, tag_black, tag_white = _read_dng(path)
    else:
        try:
            data = iio.imread(path, plugin="pillow" if suffix == ".png" else "tifffile")
        except Exception as exc:  # any decoder failure is a one-line 'cannot read'
            raise FitError(f"{path}: cannot be read as an image ({type(exc).__name__})") from None
        kind = "rgb" if data.ndim == 3 else "mono"
    if data.dtype not in (np.uint8, np.uint16):
        raise FitError(f"{path}: pixel type {data.dtype}: expected 8- or 16-bit integers")
    if data.ndim == 3:
        data = data[..., :3] if data.shape[-1] >= 3 else data[..., 0]
        kind = "rgb" if data.ndim == 3 else "mono"
    if data.ndim != 2 and not (data.ndim == 3 and kind == "rgb") or min(data.shape[:2]) < 16:
        raise FitError(f"{path}: image shape {data.shape}: expected a 2-D image of at least 16 × 16 pixels")
    bits = 8 * data.dtype.itemsize
    notes = []
    black = black_dn if black_dn is not None else tag_black
    if black is None:
        black = 0.0
        notes.append(f"{path.name}: black level 0 assumed (no --black-level, no DNG tag)")
    sat = saturation_dn if saturation_dn is not None else (tag_white if tag_white is not None else 2 ** bits - 1)
    if not 0 <= black < sat:
        raise FitError(f"{path}: black level {black:g} and saturation {sat:g} DN: expected 0 ≤ black < saturation")
    return Frame(str(path), data.astype(np.float64), kind, sites, float(black), float(sat), bits, tuple(notes))


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
