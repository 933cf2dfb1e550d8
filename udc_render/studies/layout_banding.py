"""The banding a layout prints at a display-to-lens distance d, for `udc-render study layout` (issue 48).

The exact transmitted power as a function of the mask shift s (psf.banding.PowerSeries, docs/PHYSICS.md §4):
    P(s) = Re Σ_k γ_k w_k e^{−2πi k·s/p},  w_k = b_k(d) Â(k/p),
for the layout repeated plainly (a display tiled with random turns has no period: see below). A pixel at x on
the sensor sees s = x d / z_i, so the harmonic k = h e_x prints bands of period z_i p / (h d) along x. The figures,
per channel (one wavelength each):

- along x and along y, the strongest harmonic h ≥ 1 of the bands averaged along them over a period and its
  amplitude relative to the mean, A = 2 |w_{h e}| / w_0: the banding study's A1 (udc_render.studies.banding: the
  first harmonic of the fitted band period, which is harmonic h of p when the display's bands repeat h times a
  period, as the P-OLED's do);
- the relative peak-to-peak (max P − min P) / mean P over a LATTICE² lattice of shifts across one period (2-D);
- A after the PSF: A × |OTF| of the layout's d = 0 kernel (udc_render.studies.banding_fit.kernel_otf) at the band
  frequency, the flat field's bands (the banding study's 'expected'; the kernel's shape at d is not computed).

The weights are psf.banding.PowerSeries.truncated (|P − P_box| ≤ 1e-5 of the mean at every shift).

A tiling with a random D4 turn per tile has no period and no power series: udc_render.design.tiling_power's
sampled_banding computes P(s) of both tilings in space over every shift the paper's sensor sees (|s_x| ≤ 529 µm,
|s_y| ≤ 265 µm at d = 2 mm), and reports per channel the relative peak-to-peak and standard deviation over that
span and over one period of shifts (what a model that repeats the power of one period, as the engine's field
blend does for a turned tiling, can print); of the repeated tiling also the sd over every registration of its period
(udc_render.design.registration: the figures above are at one, a tile's corner on the axis).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from psf.banding import PowerSeries, power_grid
from psf.micrograph import MicrographLayout
from udc_render.design.tiling_power import DEFAULT_DISTANCE_MM
from udc_render.studies.banding_fit import kernel_otf

__all__ = ["LATTICE", "periodic_layout", "strongest_harmonic", "layout_banding"]

LATTICE = 64


def periodic_layout(layout):
    """The layout repeated plainly: a micrograph with random turns per tile loses them."""
    if isinstance(layout, MicrographLayout) and layout.random_rotation:
        return replace(layout, random_rotation=False)
    return layout


def strongest_harmonic(line: np.ndarray, w0: float) -> tuple[int, float]:
    """(h, 2 |w_h| / w_0) of the largest |w_h| for h ≥ 1 of weights line[h] (h = 0, 1, …); (0, 0.0) if none."""
    if line.size < 2:
        return 0, 0.0
    h = int(np.argmax(np.abs(line[1:]))) + 1
    return h, float(2 * abs(line[h]) / w0)


def _channel(layout, lens, wavelength_nm: float, distance_um: float, lattice: int) -> dict:
    half = PowerSeries(layout, lens, wavelength_nm * 1e-3, distance_um).truncated()
    c = half.shape[0] // 2
    w0 = float(half[c, 0].real)
    px, py = layout.period_um
    power = power_grid(half, (px, py), np.arange(lattice) * px / lattice, np.arange(lattice) * py / lattice)
    hx, ax = strongest_harmonic(half[c], w0)
    hy, ay = strongest_harmonic(half[c:, 0], w0)
    return {"order_x": hx, "amplitude_x": ax, "order_y": hy, "amplitude_y": ay,
            "peak_to_peak": float((power.max() - power.min()) / power.mean()), "mean_power_um2": w0}


def _after_psf(kernel: np.ndarray, pixel_um: float, band_um: tuple, ch: dict) -> float:
    """max over the axes of A × |OTF| of the kernel at the strongest harmonic's band frequency."""
    out = 0.0
    for axis, period, h, a in (("x", band_um[0], ch["order_x"], ch["amplitude_x"]),
                               ("y", band_um[1], ch["order_y"], ch["amplitude_y"])):
        if h:
            otf = abs(kernel_otf(kernel[None], pixel_um, period / h, axis, harmonics=1)[0, 0])
            out = max(out, a * float(otf))
    return out


def layout_banding(layout, lens, wavelengths_nm, distance_mm: float = DEFAULT_DISTANCE_MM,
                   kernels: np.ndarray | None = None, pixel_um: float = 3.1, lattice: int = LATTICE) -> dict:
    """The module doc's figures, per wavelength, of the layout repeated at distance_mm in front of the lens;
    kernels [K, S, S] (centred, at the same wavelengths, d = 0) add A after the PSF."""
    periodic = periodic_layout(layout)
    z_um = lens.image_distance_um
    band_um = tuple(z_um * p / (distance_mm * 1000.0) for p in periodic.period_um)
    chans = [_channel(periodic, lens, wl, distance_mm * 1000.0, lattice) for wl in wavelengths_nm]
    doc = {"distance_mm": float(distance_mm), "wavelengths_nm": [float(w) for w in wavelengths_nm],
           "band_period_um": list(band_um), "lattice": lattice, "tiling": "repeated"}
    for key in chans[0]:
        doc[key] = [c[key] for c in chans]
    doc["strongest"] = [max(c["amplitude_x"], c["amplitude_y"]) for c in chans]
    if kernels is not None:
        doc["after_psf"] = [_after_psf(np.asarray(k, np.float64), pixel_um, band_um, c)
                            for k, c in zip(kernels, chans)]
    return doc
