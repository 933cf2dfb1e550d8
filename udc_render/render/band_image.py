"""BandImage: what the render stage hands on: band-mean radiance at the sensor plane, with its grid."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class BandImage:
    """The render's bands and grid. primaries_image [3, H, W] (float32, set by of_primaries only): the planes r
    with bands = einsum('ck,chw->khw', primaries_matrix, r) exactly, which the optics may convolve in place of the
    bands (optics.primaries); not an init field, so dataclasses.replace (new bands, another matrix) drops it."""
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
        bands = np.einsum("ck,chw->khw", np.asarray(matrix).astype(np.float32), planes)
        out = cls(bands, np.asarray(edges_nm), pitch_um, margin_px, depth_m, meta or {}, np.asarray(matrix))
        object.__setattr__(out, "primaries_image", planes)  # frozen: set once, here
        return out

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
