"""BandImage: what the render stage hands on: band-mean radiance at the sensor plane, with its grid."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class BandImage:
    """The render's bands and grid. primaries_image [3, H, W] (float32, set by of_primaries only): the planes r
    with bands = einsum('ck,chw->khw', primaries_matrix, r) exactly, which the optics may convolve in place of the
    bands (optics.primaries); not an init field, so dataclasses.replace (new bands, another matrix) drops it.
    An image of_primaries makes its bands on their first use (K frame-sized planes: 0.47 GB at the paper's frame
    and 30 bands), which the optics through the planes never make: `shape` and `band_peaks` need no bands."""
    bands: np.ndarray  # [K, H, W] float32, band-mean radiance W·sr⁻¹·m⁻²·nm⁻¹
    edges_nm: np.ndarray  # [K + 1]
    pitch_um: float  # render pixel pitch on the sensor
    margin_px: int  # frame = bands[:, m:H-m, m:W-m]
    depth_m: np.ndarray | None  # [H, W] axial distance (m); inf where the ray leaves the scene
    meta: dict = field(default_factory=dict)  # every render parameter, as recorded in render.json
    primaries_matrix: np.ndarray | None = None  # [3, K] band-mean radiance of the monitor's R, G, B at full drive
    primaries_image: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    @classmethod
    def of_primaries(cls, planes: np.ndarray, matrix: np.ndarray, edges_nm, pitch_um: float, margin_px: int,
                     depth_m=None, meta: dict | None = None) -> "BandImage":
        """The band image of planes [3, H, W] float32 through matrix [3, K] (bands x_k = Σ_c M_ck r_c, float32),
        keeping the planes (primaries_image)."""
        planes = np.ascontiguousarray(planes, np.float32)
        out = cls(None, np.asarray(edges_nm), pitch_um, margin_px, depth_m, meta or {}, np.asarray(matrix))
        object.__setattr__(out, "primaries_image", planes)  # frozen: set once, here; the bands on first use
        return out

    @property
    def shape(self) -> tuple[int, int, int]:
        """(K, H, W) of the bands, made or not."""
        bands = self.__dict__["_bands"]
        if bands is not None:
            return tuple(bands.shape)
        return (np.shape(self.primaries_matrix)[1], *self.primaries_image.shape[1:])

    def band_peaks(self) -> np.ndarray:
        """[K] each band's largest value (float32), the bands' own max; of planes not made into bands, the same
        values from blocks of BLOCK_ROWS rows (each band value is the einsum's, bit for bit)."""
        bands = self.__dict__["_bands"]
        if bands is not None:
            return bands.max(axis=(1, 2))
        peaks = self.__dict__.get("_peaks")
        if peaks is None:
            m, r = _matrix32(self.primaries_matrix), self.primaries_image
            blocks = (_bands_of(m, r[:, h:h + BLOCK_ROWS]).max(axis=(1, 2)) for h in range(0, r.shape[1], BLOCK_ROWS))
            peaks = self.__dict__["_peaks"] = np.max(np.stack(list(blocks)), axis=0)
        return peaks

    @property
    def centres_nm(self) -> np.ndarray:
        return (self.edges_nm[:-1] + self.edges_nm[1:]) / 2

    def white_bands(self) -> np.ndarray | None:
        """[K] band radiance of the monitor's full white, or None for content without a monitor."""
        m = self.primaries_matrix
        return None if m is None else np.asarray(m, float).sum(axis=0)

    def frame(self, a: np.ndarray) -> np.ndarray:
        m = self.margin_px
        return a[..., m:a.shape[-2] - m, m:a.shape[-1] - m]


def band_names(edges_nm) -> list[str]:
    """Zero-padded channel names by band centre, e.g. 'band_0405nm' or 'band_0412p5nm' (EXR
    channels sort alphabetically; a dot would start an EXR layer)."""
    c = (np.asarray(edges_nm[:-1], float) + np.asarray(edges_nm[1:], float)) / 2
    return [f"band_{int(x):04d}nm" if float(x).is_integer() else f"band_{x:06.1f}nm".replace(".", "p") for x in c]


BLOCK_ROWS = 64  # rows of planes a block of BandImage.band_peaks (30 bands × 64 rows of 2.4 k: 18 MB)


def _matrix32(matrix) -> np.ndarray:
    return np.asarray(matrix).astype(np.float32)


def _bands_of(matrix32: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """x_k = Σ_c M_ck r_c, float32 (BandImage.of_primaries)."""
    return np.einsum("ck,chw->khw", matrix32, planes)


def _bands(image: BandImage) -> np.ndarray:
    """BandImage.bands: as given, or made from the planes on first use (of_primaries) and kept."""
    bands = image.__dict__["_bands"]
    if bands is None:
        bands = image.__dict__["_bands"] = _bands_of(_matrix32(image.primaries_matrix), image.primaries_image)
    return bands


def _set_bands(image: BandImage, bands) -> None:
    image.__dict__["_bands"] = bands


# `bands` is the dataclass's first field (its __init__, replace and repr use it) and a property that makes an
# of_primaries image's bands on first use: set after the class, so the field has no default.
BandImage.bands = property(_bands, _set_bands, doc="[K, H, W] float32, band-mean radiance W·sr⁻¹·m⁻²·nm⁻¹")
