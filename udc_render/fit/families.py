"""The display families: forward models of the orders' powers, from the project's own layouts (psf.layouts,
psf.micrograph: their exact Fourier-series coefficients c_mn per cell, which do not depend on the pitch).

    toled       a stripe cell (psf.layouts.toled): one rectangular opening, width fraction w, height
                fraction h (the slit height); open fraction f = w h;  |c_mn|² = (w h sinc(m w) sinc(n h))²
    poled       a pentile cell (psf.layouts.poled): two large and two small circular openings, open fraction f
                and small-to-large ratio k (its orders with m + n odd vanish: a centred lattice)
    micrograph  a given tile (psf.micrograph): nothing but its orientation (a quarter turn, a mirror) and
                its scale (the pixel size, from the lattice)

The visible orders of a family (the lattice the peaks must form) are those with |c_mn|² ≥ VISIBLE_SHARE
of the zeroth at its default (or given) shape: their integer lattice M Z² (lattice.cell_basis).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from psf import MicrographLayout, layouts
from psf.layouts import Ellipse, PeriodicLayout, Rect
from udc_render.fit.inputs import FitError

FAMILIES = ("toled", "poled", "micrograph")
VISIBLE_SHARE, VISIBLE_RANGE = 1e-3, 6


def toled_layout(pitch_x_um: float, pitch_y_um: float, width: float, height: float) -> PeriodicLayout:
    """psf.layouts.toled's stripe on a p_x × p_y cell: a centred opening w p_x wide and h p_y tall."""
    return PeriodicLayout("toled", pitch_x_um, pitch_y_um,
                          (Rect(pitch_x_um / 2, pitch_y_um / 2, width * pitch_x_um, height * pitch_y_um),))


def poled_layout(pitch_x_um: float, pitch_y_um: float, open_fraction: float, small_to_large: float) -> PeriodicLayout:
    """psf.layouts.poled's pentile cell stretched to p_x × p_y (circles become ellipses when p_x ≠ p_y)."""
    unit = layouts.poled(1.0, open_fraction, small_to_large)
    return PeriodicLayout("poled", pitch_x_um, pitch_y_um,
                          tuple(Ellipse(o.cx_um * pitch_x_um, o.cy_um * pitch_y_um, o.rx_um * pitch_x_um,
                                        o.ry_um * pitch_y_um) for o in unit.openings))


def oriented_tiles(image: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """The tile's distinct orientations for the orders' powers (|c_mn|² = |c_-m-n|² for a real tile, so a
    half turn changes nothing): as given and mirrored, and for a square tile both quarter-turned."""
    out = [("as given", image), ("mirrored left-right", image[:, ::-1])]
    if image.shape[0] == image.shape[1]:
        out += [("turned 90°", np.rot90(image)), ("turned 90°, mirrored", np.rot90(image)[:, ::-1])]
    return out


@dataclass(frozen=True)
class Family:
    """A family's forward model: parameter names, bounds and start grid (shape parameters only; the pitch
    comes from the lattice), and the layout at a pitch and parameters."""
    name: str
    names: tuple
    lower: tuple
    upper: tuple
    grid: tuple
    tile: np.ndarray | None = field(default=None, repr=False)
    tile_name: str = ""
    orientation: str = ""

    def layout(self, pitch_x_um: float, pitch_y_um: float, params=()):
        if self.name == "toled":
            return toled_layout(pitch_x_um, pitch_y_um, *params)
        if self.name == "poled":
            return poled_layout(pitch_x_um, pitch_y_um, *params)
        h, w = self.tile.shape  # one pixel size: the mean of the two axes' (psf.MicrographLayout has one)
        return MicrographLayout(self.tile_name, 0.5 * (pitch_x_um / w + pitch_y_um / h), "amplitude", False, 0,
                                self.tile)

    def power(self, params, index: np.ndarray) -> np.ndarray:
        """|c_mn|² of the orders index [N, 2] (m, n) at the shape `params` (pitch-free)."""
        kx, ix = np.unique(index[:, 0], return_inverse=True)
        ky, iy = np.unique(index[:, 1], return_inverse=True)
        return self.power_grid(params, kx, ky)[iy, ix]

    def power_grid(self, params, kx: np.ndarray, ky: np.ndarray) -> np.ndarray:
        """|c_mn|² [len(ky), len(kx)] on the grid of orders m in kx, n in ky."""
        c = self.layout(1.0, 1.0, params).fourier_coefficients(kx, ky) if self.tile is None else \
            self.layout(float(self.tile.shape[1]), float(self.tile.shape[0])).fourier_coefficients(kx, ky)
        return np.abs(c) ** 2

    def twins(self, params) -> list[np.ndarray]:
        """Other shapes whose |c_mn|² equal these at every order with m ≠ 0 and n ≠ 0: the stripe's widths w and
        1 − w, heights h and 1 − h (sin²(π m w) = sin²(π m (1 − w))); only (m, 0), (0, n) and the zeroth tell
        them apart, and those are the orders a long exposure saturates (refine polishes the twins too)."""
        if self.name != "toled":
            return []
        w, h = params
        return [np.clip(np.array(t, float), self.lower, self.upper) for t in ((1 - w, h), (w, 1 - h), (1 - w, 1 - h))]

    def default_params(self) -> tuple:
        """The presets' shapes (psf.layouts.toled / poled defaults): what decides the visible orders."""
        return {"toled": (0.21 / 0.9, 0.9), "poled": (0.23, 0.7)}.get(self.name, ())

    def index_basis(self, params=None) -> np.ndarray:
        """M [2, 2]: the visible orders' integer lattice (module doc), Lagrange–Gauss reduced in the cell's
        metric."""
        r = np.arange(-VISIBLE_RANGE, VISIBLE_RANGE + 1)
        m, n = np.meshgrid(r, r, indexing="ij")
        idx = np.stack([m.ravel(), n.ravel()], axis=1)
        p = self.power(self.default_params() if params is None else params, idx)
        vis = idx[(p >= VISIBLE_SHARE * p[np.all(idx == 0, axis=1)][0]) & np.any(idx != 0, axis=1)]
        basis = integer_basis(vis)
        if basis is None:
            raise FitError(f"--family {self.name}: its orders lie on one line: no two-dimensional lattice to fit")
        h, w = (1, 1) if self.tile is None else self.tile.shape
        return _reduce_int(basis, np.diag([1.0 / w ** 2, 1.0 / h ** 2]))


def integer_basis(vectors: np.ndarray) -> np.ndarray | None:
    """A basis [2, 2] (columns) of the integer lattice the vectors [N, 2] span (Euclid on the first
    coordinate, then the gcd of the second); None when they span a line."""
    cols = [np.array(v, dtype=np.int64) for v in vectors if np.any(v)]
    while sum(1 for c in cols if c[0] != 0) > 1:
        nz = [i for i, c in enumerate(cols) if c[0] != 0]
        p = min(nz, key=lambda i: abs(cols[i][0]))
        cols = [c if (i == p or c[0] == 0) else c - (c[0] // cols[p][0]) * cols[p] for i, c in enumerate(cols)]
    first = [c for c in cols if c[0] != 0]
    g2 = int(np.gcd.reduce([abs(int(c[1])) for c in cols if c[0] == 0] or [0]))
    if not first or g2 == 0:
        return None
    p = first[0]
    return np.array([[p[0], 0], [p[1] % g2, g2]], dtype=np.int64)


def _reduce_int(basis: np.ndarray, metric: np.ndarray) -> np.ndarray:
    """Lagrange–Gauss reduction of an integer basis (columns) under the quadratic form `metric`."""
    a, b = basis[:, 0].copy(), basis[:, 1].copy()

    def dot(u, v):
        return float(u @ metric @ v)
    for _ in range(100):
        if dot(b, b) < dot(a, a):
            a, b = b, a
        mu = round(dot(a, b) / dot(a, a))
        if mu == 0:
            break
        b = b - mu * a
    return np.stack([a, b], axis=1)


def family(name: str, micrograph: Path | None = None, values: str = "amplitude") -> list[Family]:
    """The forward models of a family (a micrograph: one per orientation of its tile)."""
    if name == "toled":
        return [Family("toled", ("width_fraction", "slit_height_fraction"), (0.01, 0.05), (0.99, 1.0),
                       (np.linspace(0.03, 0.97, 48), np.linspace(0.3, 1.0, 15)))]
    if name == "poled":
        return [Family("poled", ("open_fraction", "small_to_large"), (0.005, 0.02), (0.78, 1.0),
                       (np.linspace(0.03, 0.75, 37), np.linspace(0.1, 1.0, 19)))]
    if micrograph is None:
        raise FitError("--family micrograph: no --micrograph FILE: expected the tile's transmission image")
    try:
        tile = MicrographLayout.load(micrograph, 1.0, values).image
    except layouts.LayoutError as exc:
        raise FitError(f"--micrograph: {exc}") from None
    return [Family("micrograph", (), (), (), (), t, Path(micrograph).stem, how) for how, t in oriented_tiles(tile)]
