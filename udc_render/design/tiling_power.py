"""The transmitted power of any tiling of a cell, repeated or turned, at every mask shift the sensor sees (issue 48).

A beam imaged at sensor position x crosses the display at the mask shift s = x d / z_i (docs/PHYSICS.md §4), and
the power the lens passes is
    P(s) = ∫ A(r) |u_d(r + s)|² dr = (A ⋆ |u_d|²)(s),   u_d = F⁻¹[F[m] H_d]
(A: the aperture disc; m: the tiling's amplitude; H_d: the angular-spectrum transfer function over d,
psf.propagation.angular_spectrum_tf; ⋆: correlation). A repeated tiling has the exact power series
psf.banding.PowerSeries; a tiling with a random D4 turn per tile has no period and no series, so here P is
sampled in space: the cell repeated on k × k squares of `sample_um` (a piecewise-constant cell is exact on them),
tiled over the aperture plus the shifts' span plus the lateral spread of the highest angle the raster carries over
d (sin θ = λ / 2δ: the margin keeps the FFT's wrap-around out of every shift used), propagated by one FFT pair and
correlated with the area-weighted disc by another. Orders beyond the raster's band 1/2δ are lost; the error against
the exact series of the repeated tiling is the knob's curve (`sample_um`; tests/udc_render/test_tiling_power.py and
docs/guides/design.md).
"""
from __future__ import annotations

import math

import numpy as np
import scipy.fft as sfft

from psf.plan import PAPER_SENSOR_UM
from psf.propagation import angular_spectrum_tf
from udc_render.errors import UdcError

__all__ = ["SAMPLE_UM", "MAX_SIDE", "DEFAULT_DISTANCE_MM", "DRAW_TILES", "shift_span_um", "tiled_cell", "window_tiles",
           "tiling_power", "registered_variance", "registered_rms", "raster_power", "band_figures", "sampled_banding"]

SAMPLE_UM = 2.0  # the raster's step (the design's 8 µm squares in 4; the T-OLED's 2 µm cell as it is)
DEFAULT_DISTANCE_MM = 2.0  # the display-to-lens distance of the layout study's and the designer's banding
DRAW_TILES = 256  # the turned tiling's D4 draw: one 256² draw, its centre cropped to the window's tiles (so that
# windows of any raster step see the same tiles; a window of more tiles draws its own)
MAX_SIDE = 8192  # raster samples per side (a complex128 array of 1.07 GB, 5 of them at once; the paper's rig at
# d = 2 mm takes 2.9 k at 2 µm and 6.4 k at 1 µm)


def shift_span_um(lens, distance_um: float, sensor_um=PAPER_SENSOR_UM) -> tuple[float, float]:
    """(S_x, S_y): the largest mask shift |s| = (sensor / 2) d / z_i the paper's sensor sees, per axis."""
    return tuple(w / 2 * distance_um / lens.image_distance_um for w in sensor_um)


def tiled_cell(cell: np.ndarray, transforms: np.ndarray, k: int) -> np.ndarray:
    """The amplitude cell [c, c] on k × k squares per pixel, tiled as transforms [R, C] (D4 elements,
    udc_render.design.torch_psf.tile)."""
    import torch  # here: the module is imported by the light study modules

    from udc_render.design.torch_psf import tile
    fine = np.kron(np.asarray(cell, np.float64), np.ones((k, k)))
    return tile(torch.from_numpy(fine), np.asarray(transforms)).numpy()


def _spread_um(distance_um: float, wavelength_um: float, step_um: float) -> float:
    s = min(wavelength_um / (2 * step_um), 0.999)
    return distance_um * s / math.sqrt(1 - s * s)


def _correlation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """C[k] = Σ_x a(x) b(x + k), circular over the window (one FFT correlation)."""
    return sfft.ifft2(np.conj(sfft.fft2(a)) * sfft.fft2(b)).real


def window_tiles(cell_px: int, cell_um: float, lens, wavelength_nm: float, distance_um: float,
                 span_um: tuple[float, float], sample_um: float = SAMPLE_UM) -> tuple[int, int, float]:
    """(tiles per side, even; k squares per cell pixel; δ) of tiling_power's window (module doc): the disc, the
    shifts, the spread over d at δ, and a period; refused in one line beyond MAX_SIDE samples a side."""
    k = max(1, round(cell_um / sample_um))
    step = cell_um / k
    period = cell_px * cell_um
    half = lens.aperture_um / 2 + max(span_um) + _spread_um(distance_um, wavelength_nm * 1e-3, step) + period
    tiles = 2 * math.ceil(half / period)
    if tiles * cell_px * k > MAX_SIDE:
        raise UdcError(f"--distance-mm {distance_um / 1000:g}: the sampled banding needs {tiles * cell_px * k}² "
                       f"samples of {step:g} µm (aperture, shifts and spread over d); allowed ≤ {MAX_SIDE}²: use a "
                       "smaller distance or a coarser raster")
    return tiles, k, step


def tiling_power(cell: np.ndarray, cell_um: float, lens, wavelength_nm: float, distance_um: float,
                 span_um: tuple[float, float], transforms=None, sample_um: float = SAMPLE_UM
                 ) -> tuple[np.ndarray, float]:
    """(P [2 J_y + 1, 2 J_x + 1] in µm², δ): the module doc's P(s) at the shifts s = (i δ, j δ), |s| ≤ span_um per
    axis, of the cell (amplitude on cell_um squares) tiled plainly (transforms None) or as transforms(tiles) →
    [tiles, tiles] D4 elements, over window_tiles' window centred on the optical axis."""
    tiles, k, step = window_tiles(cell.shape[0], cell_um, lens, wavelength_nm, distance_um, span_um, sample_um)
    lam = wavelength_nm * 1e-3
    plan = np.zeros((tiles, tiles), int) if transforms is None else np.asarray(transforms(tiles))
    mask = tiled_cell(cell, plan, k)
    n = mask.shape[0]
    f = sfft.fftfreq(n, step)
    field = sfft.ifft2(sfft.fft2(mask) * angular_spectrum_tf(f, f, lam, distance_um))
    edges = (np.arange(n + 1) - n / 2) * step
    disc = lens.aperture_area_fraction(edges, edges)
    power = _correlation(disc, np.abs(field) ** 2) * step ** 2
    jx, jy = (int(s // step) for s in span_um)
    rows, cols = np.arange(-jy, jy + 1) % n, np.arange(-jx, jx + 1) % n
    return power[np.ix_(rows, cols)], step


def registered_variance(cell: np.ndarray, cell_um: float, lens, wavelength_nm: float, distance_um: float,
                        span_um: tuple[float, float], sample_um: float = SAMPLE_UM) -> np.ndarray:
    """[p, p]: var / mean² of P over the span at every registration of the cell repeated (one period of offsets on
    the raster: udc_render.design.registration.offset_variance; [p // 2, p // 2] is the cell's corner on the axis,
    the plain tiling's registration), from one tiling_power map over the widened span."""
    import torch  # here: the module is imported by the light study modules

    from udc_render.design.registration import offset_shifts, offset_variance, widened_span_um
    wide = widened_span_um(span_um, cell.shape[0] * cell_um)
    power, step = tiling_power(cell, cell_um, lens, wavelength_nm, distance_um, wide, None, sample_um)
    p = round(cell.shape[0] * cell_um / step)
    (jx, jy), (cy, cx) = (int(s // step) for s in span_um), (power.shape[0] // 2, power.shape[1] // 2)
    region = power[np.ix_(offset_shifts(jy, p) + cy, offset_shifts(jx, p) + cx)]
    return offset_variance(torch.from_numpy(region), jy, jx).numpy()


def registered_rms(cell: np.ndarray, cell_um: float, lens, wavelength_nm: float, distance_um: float,
                   span_um: tuple[float, float], sample_um: float = SAMPLE_UM) -> float:
    """The relative sd of P over the span, root mean over every registration of the cell repeated
    (registered_variance)."""
    return float(np.sqrt(registered_variance(cell, cell_um, lens, wavelength_nm, distance_um, span_um,
                                             sample_um).mean()))


def raster_power(plan, wavelength_nm: float) -> np.ndarray:
    """P(s) [ny, nx] in µm² of the psf engine's own window (a psf.plan.Plan of an aperiodic display at d > 0) at the
    whole-sample shifts s = (i δx, j δy), indices modulo the window: κ δx δy Σ_r A(r) |u_d(r − s)|², the power of
    the engine's field phase at s (psf.engine._wavelength), for every s by one correlation of the propagated
    intensity with the aperture. Circular over the window: P is the engine's where |s| ≤ the window's margin less
    the spread over d (psf.plan._window)."""
    if plan.field_raster is None or plan.field_raster.shape != plan.mask.shape:
        raise UdcError("raster_power needs the plan of an aperiodic display at d > 0 (its field raster is the window)")
    lam = wavelength_nm * 1e-3
    field = sfft.ifft2(plan.mask_spec * angular_spectrum_tf(plan.fx, plan.fy, lam, plan.d_um))
    aperture = np.zeros(field.shape)
    aperture[plan.sy, plan.sx] = plan.aperture
    return plan.kappa * plan.grid.dx_um * plan.grid.dy_um * _correlation(np.abs(field) ** 2, aperture)


def band_figures(power: np.ndarray) -> dict:
    """Relative figures of P over the shifts: peak-to-peak (max − min) / mean and the standard deviation / mean."""
    mean = float(power.mean())
    return {"peak_to_peak": float((power.max() - power.min()) / mean), "rms": float(power.std() / mean),
            "mean_power_um2": mean}


def _sampled_channel(cell, cell_um, lens, wavelength_nm, distance_um, span_um, transforms, sample_um) -> dict:
    power, step = tiling_power(cell, cell_um, lens, wavelength_nm, distance_um, span_um, transforms, sample_um)
    n = round(cell.shape[0] * cell_um / step)  # one period of shifts from s = 0 (the span, if shorter)
    cy, cx = power.shape[0] // 2, power.shape[1] // 2
    period = band_figures(power[cy:cy + n, cx:cx + n])
    return {**band_figures(power), "peak_to_peak_one_period": period["peak_to_peak"],
            "rms_one_period": period["rms"], "mean_power_one_period_um2": period["mean_power_um2"]}


def sampled_banding(cell: np.ndarray, cell_um: float, lens, wavelengths_nm, distance_mm: float = DEFAULT_DISTANCE_MM,
                    seed: int = 0, sample_um: float = SAMPLE_UM, tilings=("repeated", "turned"),
                    registered: bool = False) -> dict:
    """The sampled figures of udc_render.studies.layout_banding's doc (band_figures of P(s) over the sensor's shifts
    and over one period of them) of the cell (amplitude on cell_um squares, framed as the study takes it) repeated
    and turned (the centre of tile_transforms(DRAW_TILES, seed, keys=('banding',))), per wavelength, at distance_mm
    in front of the lens; tilings: the ones computed; registered: the repeated tiling's 'rms_registered' too
    (registered_rms: over every registration)."""
    from udc_render.design.torch_psf import tile_transforms  # torch: not at this module's import
    d_um = distance_mm * 1000.0
    span = shift_span_um(lens, d_um)
    doc = {"span_um": list(span), "sample_um": float(sample_um), "seed": int(seed),
           "sensor": "the paper's, 2048 × 1024 px of 1.55 µm (psf.plan.PAPER_SENSOR_UM)"}
    def turned(tiles: int) -> np.ndarray:
        n = max(tiles, DRAW_TILES)
        o = (n - tiles) // 2
        return tile_transforms(n, seed, keys=("banding",))[o:o + tiles, o:o + tiles]

    plans = {"repeated": None, "turned": turned}
    for tiling in tilings:
        plan = plans[tiling]
        chans = [_sampled_channel(cell, cell_um, lens, wl, d_um, span, plan, sample_um) for wl in wavelengths_nm]
        doc[tiling] = {key: [c[key] for c in chans] for key in chans[0]}
        if registered and tiling == "repeated":
            doc[tiling]["rms_registered"] = [registered_rms(cell, cell_um, lens, wl, d_um, span, sample_um)
                                             for wl in wavelengths_nm]
    doc["wavelengths_nm"] = [float(w) for w in wavelengths_nm]
    return doc
