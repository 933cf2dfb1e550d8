"""Spectra in absolute units: monitor primaries, illuminants, reflectances, band integrals.

Radiance spectra are W·sr⁻¹·m⁻²·nm⁻¹ on a 1 nm grid (360–830 nm, Mitsuba's spectral range).
An emitter of luminance L_v (cd/m²) has spectrum s(λ)·L_v / (683 ∫ s ȳ dλ), ȳ the CIE 1931 2°
photopic luminosity function (683 lm/W at 555 nm).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from psf import colour_tables
from udc_render.errors import UdcError

GRID_NM = np.arange(360.0, 831.0, 1.0)
KM_LM_PER_W = 683.0
_OBSERVER = "CIE 1931 2 Degree Standard Observer"


class SpectrumError(UdcError):
    """A spectrum name or CSV that cannot be used; one line."""


def _on_grid(wavelengths_nm, values) -> np.ndarray:
    """Linear interpolation onto GRID_NM, zero outside the tabulated range."""
    return np.interp(GRID_NM, np.asarray(wavelengths_nm, float), np.asarray(values, float), left=0.0, right=0.0)


def cmfs() -> np.ndarray:
    """CIE 1931 2° x̄, ȳ, z̄ on GRID_NM, shape [3, G]."""
    wavelengths, values = colour_tables.spectrum("cmfs", _OBSERVER)
    return np.stack([_on_grid(wavelengths, values[:, i]) for i in range(3)])


def luminance_cd_m2(radiance: np.ndarray) -> np.ndarray:
    """Luminance of spectra [..., G] in W·sr⁻¹·m⁻²·nm⁻¹ on GRID_NM (1 nm steps)."""
    return KM_LM_PER_W * np.asarray(radiance) @ cmfs()[1]


def scaled_to_luminance(spectrum: np.ndarray, luminance: float) -> np.ndarray:
    """`spectrum` (on GRID_NM) scaled so its luminance is `luminance` cd/m²."""
    y = float(luminance_cd_m2(spectrum))
    if not y > 0:
        raise SpectrumError("a spectrum with no luminance cannot be scaled to a luminance")
    return spectrum * (luminance / y)


def illuminant(name: str) -> np.ndarray:
    """A colour-science illuminant's relative spectral power (e.g. 'D65', 'A') on GRID_NM."""
    key = colour_tables.key("illuminants", name)
    if key is None:
        raise SpectrumError(f"illuminant = {name!r}: expected a colour-science illuminant such as D65, A, D50, FL2")
    return _on_grid(*colour_tables.spectrum("illuminants", key))


def colourchecker(name: str) -> np.ndarray:
    """Reflectance of a ColorChecker patch (colour-science 'ColorChecker N Ohta') on GRID_NM."""
    key = colour_tables.key("colourchecker", name)
    if key is None:
        raise SpectrumError(f"ColorChecker patch {name!r}: expected one of "
                            f"{', '.join(colour_tables.names('colourchecker'))}")
    wavelengths, values = colour_tables.spectrum("colourchecker", key)
    v = _on_grid(wavelengths, values)
    v[GRID_NM < wavelengths[0]], v[GRID_NM > wavelengths[-1]] = values[0], values[-1]  # the end values held outside
    return v


def load_primaries(spec: str, base: Path | None = None) -> tuple[np.ndarray, str]:
    """Relative primary spectra [3, G] (R, G, B) and a description.

    `spec` is a key of colour-science's MSDS_DISPLAY_PRIMARIES (default 'Apple Studio Display', an
    LCD) or a CSV with columns wavelength_nm, r, g, b (header line optional)."""
    key = colour_tables.key("display_primaries", spec)
    if key is not None:
        wavelengths, values = colour_tables.spectrum("display_primaries", key)
        return np.stack([_on_grid(wavelengths, values[:, i]) for i in range(3)]), f"colour-science: {spec}"
    path = Path(spec) if base is None or Path(spec).is_absolute() else base / spec
    if not path.exists():
        raise SpectrumError(f"content.primaries = {spec!r}: expected a colour-science display "
                            f"({', '.join(sorted(colour_tables.names('display_primaries')))}) or a CSV file")
    try:
        table = np.loadtxt(path, delimiter=",", ndmin=2, skiprows=_header_lines(path))
    except ValueError as e:
        raise SpectrumError(f"{path}: not a CSV of wavelength_nm, r, g, b ({e})") from None
    if table.shape[1] != 4 or len(table) < 2 or not np.all(np.isfinite(table)) or np.any(table[:, 1:] < 0):
        raise SpectrumError(f"{path}: expected >= 2 rows of 4 finite columns wavelength_nm, r, g, b (r, g, b >= 0)")
    if np.any(np.diff(table[:, 0]) <= 0):
        raise SpectrumError(f"{path}: wavelength_nm must increase down the file")
    prim = np.stack([_on_grid(table[:, 0], table[:, 1 + i]) for i in range(3)])
    if np.any(luminance_cd_m2(prim) <= 0):
        raise SpectrumError(f"{path}: every primary needs some luminance inside 360–830 nm")
    return prim, f"CSV: {path}"


def _header_lines(path: Path) -> int:
    first = path.read_text().splitlines()[:1]
    try:
        [float(x) for x in first[0].split(",")] if first else None
        return 0
    except ValueError:
        return 1


def monitor_primaries(spec: str, peak_luminance_cd_m2: float, base: Path | None = None,
                      white_point: str = "D65") -> tuple[np.ndarray, str]:
    """Primary radiance spectra [3, G] in W·sr⁻¹·m⁻²·nm⁻¹ at full drive, scaled so that white (all
    three at full drive) has `peak_luminance_cd_m2` and, like a calibrated monitor, the chromaticity
    of `white_point` (a colour-science illuminant, default D65, the sRGB white): the gains a solve
    Σ_c a_c XYZ_c = XYZ_white. `white_point = "native"` keeps the measured primaries' ratios."""
    prim, desc = load_primaries(spec, base)
    if white_point == "native":
        return prim * (peak_luminance_cd_m2 / float(luminance_cd_m2(prim.sum(0)))), desc
    key = colour_tables.key("white_points", white_point)
    if key is None:
        raise SpectrumError(f"content.white_point = {white_point!r}: expected native or a colour-science "
                            "illuminant such as D65, D50")
    x, y = colour_tables.white_point_xy(key)
    target = peak_luminance_cd_m2 * np.array([x / y, 1.0, (1 - x - y) / y])
    xyz = KM_LM_PER_W * cmfs() @ prim.T  # [3 (XYZ), 3 (primaries)]
    gains = np.linalg.solve(xyz, target)
    if not np.all(gains > 0):
        raise SpectrumError(f"content.white_point = {white_point!r}: outside the gamut of the primaries ({desc})")
    return prim * gains[:, None], f"{desc}, white balanced to {white_point}"


def band_means(spectra: np.ndarray, edges_nm) -> np.ndarray:
    """Band-mean of spectra [..., G] (on GRID_NM) over each band [edges[k], edges[k+1]]: [..., K].

    Exact for the piecewise-linear spectrum through the grid samples (trapezoid on a grid refined
    with the band edges)."""
    edges = np.asarray(edges_nm, float)
    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        x = np.unique(np.concatenate([[a, b], GRID_NM[(GRID_NM > a) & (GRID_NM < b)]]))
        y = np.stack([np.interp(x, GRID_NM, s) for s in np.reshape(spectra, (-1, GRID_NM.size))])
        out.append(np.trapezoid(y, x, axis=-1) / (b - a))
    return np.reshape(np.stack(out, -1), np.shape(spectra)[:-1] + (len(edges) - 1,))


def band_xyz(edges_nm) -> np.ndarray:
    """[3, K] weights: XYZ (Y in cd/m²) of a band image = weights @ band means (for previews)."""
    edges = np.asarray(edges_nm, float)
    return KM_LM_PER_W * band_means(cmfs(), edges) * np.diff(edges)
