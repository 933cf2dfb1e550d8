"""Display pixel layouts as amplitude-transmittance masks in physical units (µm).

A layout is periodic: one unit cell of size pitch_x_um × pitch_y_um, repeated over the plane.
`cell_raster(nx, ny)` gives the exactly area-weighted amplitude and intensity transmittance of
one cell on an nx × ny grid; the PSF engine tiles it (and shifts it by Fourier phase ramps,
never by re-rasterising). Transparent openings sit on an opaque background.

Defaults reproduce the paper's open areas (Zhou et al. 2021, §3): T-OLED 21 %, P-OLED 23 %.
The pitches are not given in the paper (no micrograph scale is public); the defaults are chosen by
`udc-render study realism` against the paper's observables (docs/PHYSICS.md §8): a 317 µm T-OLED
cell (a 55-inch 4K panel, 3840 columns over 1.21 m; the paper's T-OLED is "4K", and coarser than the
P-OLED, l.116) and a 64 µm RGBG pentile cell (a square cell holding two logical pixels has side
√2 × the pixel pitch: 64 µm is a ≈ 560 ppi phone panel).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.special import j1

from .geometry import ellipse_areas, rect_areas
from .propagation import ramp

__all__ = ["LayoutError", "Rect", "Ellipse", "PeriodicLayout", "toled", "poled", "slit_grating", "disordered",
           "BUILTIN"]


class LayoutError(ValueError):
    """A display layout that cannot be built or read (message is one line for the user)."""


@dataclass(frozen=True)
class Rect:
    """Axis-aligned rectangular opening, centre and size in µm (cell coordinates)."""
    cx_um: float
    cy_um: float
    width_um: float
    height_um: float

    @property
    def area_um2(self) -> float:
        return self.width_um * self.height_um

    @property
    def left_um(self) -> float:
        return self.cx_um - self.width_um / 2

    def areas(self, x_edges, y_edges, dx_um=0.0, dy_um=0.0):
        return rect_areas(x_edges, y_edges, self.cx_um + dx_um, self.cy_um + dy_um,
                          self.width_um, self.height_um)

    def spectrum(self, nu_x, nu_y):
        """∫ rect · exp(−2πi ν·x) dx (µm²) at frequencies nu_y[:, None], nu_x[None, :] (1/µm)."""
        return self.area_um2 * np.outer(np.sinc(nu_y * self.height_um) * ramp(nu_y, self.cy_um),
                                        np.sinc(nu_x * self.width_um) * ramp(nu_x, self.cx_um))


@dataclass(frozen=True)
class Ellipse:
    """Axis-aligned elliptical opening, centre and semi-axes in µm (cell coordinates)."""
    cx_um: float
    cy_um: float
    rx_um: float
    ry_um: float

    @property
    def area_um2(self) -> float:
        return math.pi * self.rx_um * self.ry_um

    @property
    def left_um(self) -> float:
        return self.cx_um - self.rx_um

    def areas(self, x_edges, y_edges, dx_um=0.0, dy_um=0.0):
        return ellipse_areas(x_edges, y_edges, self.cx_um + dx_um, self.cy_um + dy_um,
                             self.rx_um, self.ry_um)

    def spectrum(self, nu_x, nu_y):
        """∫ ellipse · exp(−2πi ν·x) dx = π rx ry · 2 J1(2πq)/(2πq), q = |(rx νx, ry νy)|."""
        q = 2 * np.pi * np.hypot(nu_y[:, None] * self.ry_um, nu_x[None, :] * self.rx_um)
        jinc = np.where(q > 0, 2 * j1(q) / np.where(q > 0, q, 1.0), 1.0)
        return self.area_um2 * jinc * np.outer(ramp(nu_y, self.cy_um), ramp(nu_x, self.cx_um))


@dataclass(frozen=True)
class PeriodicLayout:
    """Disjoint transparent openings in a unit cell, amplitude `amplitude` inside, 0 outside."""
    name: str
    pitch_x_um: float
    pitch_y_um: float
    openings: tuple = field(default_factory=tuple)
    amplitude: float = 1.0

    def __post_init__(self):
        if not (self.pitch_x_um > 0 and self.pitch_y_um > 0):
            raise LayoutError(f"layout {self.name}: pitch must be > 0 µm, got "
                              f"{self.pitch_x_um} × {self.pitch_y_um}")
        if not 0.0 <= self.amplitude <= 1.0:
            raise LayoutError(f"layout {self.name}: amplitude must be in [0, 1], got {self.amplitude}")

    @property
    def period_um(self) -> tuple[float, float]:
        return (self.pitch_x_um, self.pitch_y_um)

    @property
    def open_fraction(self) -> float:
        """Exact open area / cell area (openings are disjoint)."""
        return sum(o.area_um2 for o in self.openings) / (self.pitch_x_um * self.pitch_y_um)

    @property
    def power_transmittance(self) -> float:
        """Mean intensity transmittance over a cell: amplitude² × open fraction."""
        return self.amplitude ** 2 * self.open_fraction

    def cell_raster(self, nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
        """Area-weighted (amplitude, intensity) transmittance of one cell, arrays [ny, nx].

        Openings that cross the cell border wrap around (their 8 periodic images are added).
        """
        xe = np.linspace(0.0, self.pitch_x_um, nx + 1)
        ye = np.linspace(0.0, self.pitch_y_um, ny + 1)
        area = np.zeros((ny, nx))
        for o in self.openings:
            for kx in (-1, 0, 1):
                for ky in (-1, 0, 1):
                    area += o.areas(xe, ye, kx * self.pitch_x_um, ky * self.pitch_y_um)
        frac = np.clip(area / ((xe[1] - xe[0]) * (ye[1] - ye[0])), 0.0, 1.0)
        return self.amplitude * frac, self.amplitude ** 2 * frac

    def fourier_coefficients(self, kx: np.ndarray, ky: np.ndarray) -> np.ndarray:
        """Fourier-series coefficients c[ky, kx] of the amplitude over one cell (exact, any order)."""
        nu_x, nu_y = np.asarray(kx) / self.pitch_x_um, np.asarray(ky) / self.pitch_y_um
        c = sum(o.spectrum(nu_x, nu_y) for o in self.openings)
        return self.amplitude * c / (self.pitch_x_um * self.pitch_y_um)

    def describe(self) -> dict:
        """Every parameter, for cache keys and output metadata."""
        return {"kind": "periodic", "name": self.name, "pitch_x_um": self.pitch_x_um,
                "pitch_y_um": self.pitch_y_um, "amplitude": self.amplitude,
                "openings": [{"shape": type(o).__name__, **o.__dict__} for o in self.openings]}


def _solve_fraction(name: str, open_fraction: float, lo: float, hi: float) -> None:
    if not lo <= open_fraction <= hi:
        raise LayoutError(f"layout {name}: open_fraction must be in [{lo}, {hi}], got {open_fraction}")


def toled(pitch_um: float = 317.0, open_fraction: float = 0.21, slit_height_fraction: float = 0.9,
          amplitude: float = 1.0) -> PeriodicLayout:
    """T-OLED stripe layout (grating-like): one tall narrow opening per square cell.

    The opening spans `slit_height_fraction` of the cell height (thin opaque row lines between
    cells) and is as wide as needed for `open_fraction`: width = open_fraction / height_fraction
    × pitch. Light is diffracted mostly along x (the paper's horizontal smear, MTF nulls along x).
    """
    _solve_fraction("toled", open_fraction, 0.0, slit_height_fraction)
    width = open_fraction / slit_height_fraction * pitch_um
    return PeriodicLayout("toled", pitch_um, pitch_um,
                          (Rect(pitch_um / 2, pitch_um / 2, width, slit_height_fraction * pitch_um),),
                          amplitude)


def poled(pitch_um: float = 64.0, open_fraction: float = 0.23, small_to_large: float = 0.7,
          amplitude: float = 1.0) -> PeriodicLayout:
    """P-OLED pentile (RGBG diamond) layout: circular openings between the sub-pixels.

    The RGBG unit cell (pitch_um square, two sub-pixel pitches wide) holds four openings on the
    diamond lattice of the pentile arrangement, at (¼,¼), (¾,¾) (large, radius r) and (¾,¼), (¼,¾)
    (small, radius small_to_large · r), the gaps between the R/B diamonds and the G sub-pixels.
    r is solved from open_fraction: 2πr²(1 + k²) = open_fraction · pitch².
    """
    # Neighbouring large and small openings are p/2 apart: r (1 + k) < p / 2 keeps them disjoint.
    limit = math.pi * (1 + small_to_large ** 2) / (2 * (1 + small_to_large) ** 2)
    _solve_fraction("poled", open_fraction, 0.0, round(limit, 4))
    r = pitch_um * math.sqrt(open_fraction / (2 * math.pi * (1 + small_to_large ** 2)))
    q, t = pitch_um / 4, 3 * pitch_um / 4
    rs = small_to_large * r
    return PeriodicLayout("poled", pitch_um, pitch_um,
                          (Ellipse(q, q, r, r), Ellipse(t, t, r, r), Ellipse(t, q, rs, rs), Ellipse(q, t, rs, rs)),
                          amplitude)


def slit_grating(pitch_um: float, opening_um: float, height_um: float | None = None) -> PeriodicLayout:
    """1-D slit grating (the analytic oracle of docs/PHYSICS.md §6): openings of width opening_um along x.

    With height_um None the slits are unbroken along y (a cell as tall as it is wide, fully open in y).
    """
    if not 0 < opening_um < pitch_um:
        raise LayoutError(f"slit grating: opening must be in (0, {pitch_um}) µm, got {opening_um}")
    h = pitch_um if height_um is None else height_um
    return PeriodicLayout("slits", pitch_um, pitch_um, (Rect(pitch_um / 2, pitch_um / 2, opening_um, h),))


def disordered(layout: PeriodicLayout, cells: int, position_sd_um: float, size_sd: float,
               seed: int = 0) -> PeriodicLayout:
    """A supercell of cells × cells copies of `layout` whose openings are moved by N(0, position_sd_um)
    along x and y and scaled by 1 + N(0, size_sd): the fabrication disorder of a real panel, periodic
    at cells × the pitch (so the engine's periodic tiling still holds). Scales are clipped to
    [0.5, 1.5]; openings must stay disjoint, so keep position_sd_um well below the gaps."""
    if cells < 1 or position_sd_um < 0 or size_sd < 0:
        raise LayoutError(f"disordered: cells ≥ 1, position_sd_um ≥ 0 and size_sd ≥ 0 expected, got "
                          f"{cells}, {position_sd_um}, {size_sd}")
    rng = np.random.default_rng(seed)
    out = []
    for j in range(cells):
        for i in range(cells):
            for o in layout.openings:
                dx, dy = rng.normal(0.0, position_sd_um, 2) if position_sd_um else (0.0, 0.0)
                k = float(np.clip(1 + rng.normal(0.0, size_sd), 0.5, 1.5)) if size_sd else 1.0
                cx, cy = o.cx_um + i * layout.pitch_x_um + dx, o.cy_um + j * layout.pitch_y_um + dy
                out.append(Rect(cx, cy, o.width_um * k, o.height_um * k) if isinstance(o, Rect)
                           else Ellipse(cx, cy, o.rx_um * k, o.ry_um * k))
    return PeriodicLayout(f"{layout.name}-disordered", cells * layout.pitch_x_um, cells * layout.pitch_y_um,
                          tuple(out), layout.amplitude)


BUILTIN = {"toled": toled, "poled": poled}
