"""BandImage: what the render stage hands on: band-mean radiance at the sensor plane, with its grid."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class BandImage:
    bands: np.ndarray  # [K, H, W] float32, band-mean radiance W·sr⁻¹·m⁻²·nm⁻¹
    edges_nm: np.ndarray  # [K + 1]
    pitch_um: float  # render pixel pitch on the sensor
    margin_px: int  # frame = bands[:, m:H-m, m:W-m]
    depth_m: np.ndarray | None  # [H, W] axial distance (m); inf where the ray leaves the scene
    meta: dict = field(default_factory=dict)  # every render parameter, as recorded in render.json
    primaries_matrix: np.ndarray | None = None  # [3, K] band-mean radiance of the monitor's R, G, B at full drive

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
