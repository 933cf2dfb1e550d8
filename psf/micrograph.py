"""A user's measured transmission micrograph as a display layout (PNG, TIFF or EXR).

The image is one tile of the display; it repeats over the plane (optionally each tile randomly
rotated by a multiple of 90°, or 180° for non-square tiles, to break the exact periodicity of a
small crop). Grey values are amplitude or intensity transmittance in [0, 1]: integers are divided
by their type's maximum, floats are taken as they are; colour images are averaged over channels.
Each micrograph pixel is a constant-transmittance square of pixel_um; resampling onto the pupil
grid is exact area weighting of that piecewise-constant picture.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import OpenEXR
from imageio import v3 as iio

from .layouts import LayoutError

__all__ = ["SUFFIXES", "MicrographLayout", "quarter_turns", "read_transmission_image"]

SUFFIXES = {".png", ".tif", ".tiff", ".exr"}


def _read_exr(path: Path) -> np.ndarray:
    with OpenEXR.File(str(path)) as f:
        channels = f.channels()
        if "RGB" in channels:
            return np.asarray(channels["RGB"].pixels, dtype=np.float64)
        if "RGBA" in channels:
            return np.asarray(channels["RGBA"].pixels, dtype=np.float64)[..., :3]
        arrays = [np.asarray(c.pixels, dtype=np.float64) for name, c in sorted(channels.items()) if name != "A"]
        return np.stack(arrays, axis=-1)


def read_transmission_image(path: str | Path) -> np.ndarray:
    """Read a micrograph as a float64 grey image [H, W] with values scaled as described above."""
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise LayoutError(f"micrograph {path}: unsupported suffix '{path.suffix}', allowed: "
                          f"{', '.join(sorted(SUFFIXES))}")
    if not path.is_file():
        raise LayoutError(f"micrograph {path}: no such file")
    try:
        if path.suffix.lower() == ".exr":
            img = _read_exr(path)
        else:
            raw = iio.imread(path, plugin="pillow" if path.suffix.lower() == ".png" else "tifffile")
            img = raw.astype(np.float64)
            if np.issubdtype(raw.dtype, np.integer):
                img /= np.iinfo(raw.dtype).max
            elif raw.dtype == bool:
                img = raw.astype(np.float64)
    except Exception as exc:  # any decoder failure is a user-facing 'cannot read'
        raise LayoutError(f"micrograph {path}: cannot be read as an image ({type(exc).__name__}: "
                          f"{str(exc).splitlines()[0] if str(exc) else 'no detail'})") from None
    if img.ndim == 3:
        img = img[..., :3].mean(axis=-1) if img.shape[-1] >= 3 else img[..., 0]
    if img.ndim != 2 or min(img.shape) < 2:
        raise LayoutError(f"micrograph {path}: expected a 2-D image of at least 2×2 pixels, got shape {img.shape}")
    if not np.all(np.isfinite(img)):
        raise LayoutError(f"micrograph {path}: contains non-finite values")
    lo, hi = float(img.min()), float(img.max())
    if lo < 0 or hi > 1 + 1e-6:
        raise LayoutError(f"micrograph {path}: values must lie in [0, 1] after scaling, got [{lo:.4g}, {hi:.4g}]")
    return np.clip(img, 0.0, 1.0)


def quarter_turns(seed: int, tiles_x: int, tiles_y: int, square: bool = True, flips: bool = False) -> np.ndarray:
    """[tiles_y, tiles_x] D4 elements per tile drawn from seed (k: k mod 4 quarter turns, the tile mirrored left-right
    first when k ≥ 4; psf.pupil.tile_mask): uniform over the quarter turns 0..3 (a square tile) or 0, 2, and with
    flips over those and their mirror images as well."""
    choices = np.array([0, 1, 2, 3]) if square else np.array([0, 2])
    if flips:
        choices = np.concatenate([choices, choices + 4])
    return np.random.default_rng(seed).choice(choices, size=(tiles_y, tiles_x))


def _checked_arrangement(path, arrangement, shape: tuple, random_rotation: bool) -> tuple:
    """arrangement as a tuple of K tuples of K D4 elements (0 … 7), or one line naming what is wrong."""
    try:
        k = np.asarray(arrangement)
    except ValueError:  # ragged rows
        k = np.zeros(0)
    ok = (k.ndim == 2 and k.shape[0] == k.shape[1] >= 1 and k.dtype.kind in "iu" and k.min() >= 0 and k.max() <= 7)
    if not ok or shape[0] != shape[1] or random_rotation:
        raise LayoutError(f"micrograph {path}: tile_arrangement must be a K × K list of D4 elements 0 … 7 for a "
                          f"square tile without tile_rotation; got values of shape {k.shape} for a "
                          f"{shape[0]} × {shape[1]} tile{' with tile_rotation' if random_rotation else ''}")
    return tuple(tuple(int(v) for v in row) for row in k)


def _area_resample_matrix(n_out: int, n_in: int) -> np.ndarray:
    """[n_out, n_in] weights: fraction of output cell i covered by input cell j (same total span)."""
    out_edges = np.linspace(0.0, 1.0, n_out + 1)
    in_edges = np.linspace(0.0, 1.0, n_in + 1)
    lo = np.maximum(out_edges[:-1, None], in_edges[None, :-1])
    hi = np.minimum(out_edges[1:, None], in_edges[None, 1:])
    return np.clip(hi - lo, 0.0, None) * n_out


@dataclass(frozen=True)
class MicrographLayout:
    """A measured display tile; period = image size × pixel_um. random_rotation: each tile turned by a random quarter
    turn; with flip, by a random element of D4 (a quarter turn or its mirror image). arrangement: each tile turned by
    a fixed K × K pattern of D4 elements repeated from the window's first tile (a period of K tiles, rastered tile by
    tile as turned tiles are: its exact power series, which grows as the period squared, is not formed)."""
    path: str
    pixel_um: float
    values: str = "amplitude"
    random_rotation: bool = False
    seed: int = 0
    image: np.ndarray = field(repr=False, compare=False, default=None)
    flip: bool = False
    arrangement: tuple | None = None

    @classmethod
    def load(cls, path, pixel_um: float, values: str = "amplitude", random_rotation: bool = False,
             seed: int = 0, flip: bool = False, arrangement=None) -> "MicrographLayout":
        if not pixel_um > 0:
            raise LayoutError(f"micrograph {path}: pixel_um must be > 0, got {pixel_um}")
        if values not in ("amplitude", "intensity"):
            raise LayoutError(f"micrograph {path}: values must be 'amplitude' or 'intensity', got '{values}'")
        img = read_transmission_image(path)
        amp = np.sqrt(img) if values == "intensity" else img
        if not amp.any():
            raise LayoutError(f"micrograph {path}: fully opaque (every value is 0); nothing is transmitted")
        if flip and not random_rotation:
            raise LayoutError(f"micrograph {path}: flip (--tile-flip) mirrors randomly turned tiles; it needs "
                              "random_rotation (--tile-rotation)")
        if arrangement is not None:
            arrangement = _checked_arrangement(path, arrangement, amp.shape, random_rotation)
        return cls(str(path), float(pixel_um), values, bool(random_rotation), int(seed), amp, bool(flip), arrangement)

    @property
    def name(self) -> str:
        return Path(self.path).stem

    @property
    def period_um(self) -> tuple[float, float]:
        h, w = self.image.shape
        return (w * self.pixel_um, h * self.pixel_um)

    @property
    def open_fraction(self) -> float:
        """Mean intensity transmittance |a|² of the tile (equals the open area for binary masks)."""
        return float(np.mean(self.image ** 2))

    @property
    def power_transmittance(self) -> float:
        return self.open_fraction

    @property
    def periodic(self) -> bool:
        return not self.random_rotation and self.arrangement is None

    def cell_raster(self, nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
        """Area-weighted (amplitude, intensity) of one tile on an nx × ny grid."""
        h, w = self.image.shape
        my, mx = _area_resample_matrix(ny, h), _area_resample_matrix(nx, w)
        return my @ self.image @ mx.T, my @ (self.image ** 2) @ mx.T

    def fourier_coefficients(self, kx: np.ndarray, ky: np.ndarray) -> np.ndarray:
        """Exact Fourier-series coefficients c[ky, kx] of the piecewise-constant tile, any order.

        Pixel j covers [j s, (j+1) s]: c_k = DFT_k(a) / (h w) · sinc(kx/w) sinc(ky/h) · e^{−iπ(kx/w + ky/h)}.
        """
        h, w = self.image.shape
        kx, ky = np.asarray(kx), np.asarray(ky)
        dft = np.fft.fft2(self.image)[np.ix_(ky % h, kx % w)] / (h * w)
        shift = np.exp(-1j * np.pi * (ky[:, None] / h + kx[None, :] / w))
        return dft * np.outer(np.sinc(ky / h), np.sinc(kx / w)) * shift

    def tile_rotations(self, tiles_x: int, tiles_y: int) -> np.ndarray:
        """The D4 element (quarter_turns' numbering: 0..3 turns, 4..7 with flip) of every tile: the arrangement tiled
        from the first tile, else from the recorded seed (all 0 without rotation)."""
        if self.arrangement is not None:
            k = np.asarray(self.arrangement, int)
            return np.tile(k, (-(-tiles_y // k.shape[0]), -(-tiles_x // k.shape[1])))[:tiles_y, :tiles_x]
        if not self.random_rotation:
            return np.zeros((tiles_y, tiles_x), dtype=int)
        h, w = self.image.shape
        return quarter_turns(self.seed, tiles_x, tiles_y, square=h == w, flips=self.flip)

    def describe(self) -> dict:
        digest = hashlib.sha256(np.ascontiguousarray(self.image).tobytes()).hexdigest()[:16]
        return {"kind": "micrograph", "path": self.path, "pixel_um": self.pixel_um, "values": self.values,
                "random_rotation": self.random_rotation, "seed": self.seed,
                "shape": list(self.image.shape), "sha256_16": digest, **({"flip": True} if self.flip else {}),
                **({"arrangement": [list(r) for r in self.arrangement]} if self.arrangement is not None else {})}
