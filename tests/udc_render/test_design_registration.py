"""The bands of a periodic display over its registrations (udc_render.design.registration): the box sums against
every offset's window, the shift law P_o(s) = P_0(s − o) of the propagated power, one offset is the plain figure, and
the study's registered figure through tiling_power."""
from __future__ import annotations

import numpy as np
import torch

from psf.lens import Lens
from udc_render.design.optimise import RIG_WAVELENGTHS_NM
from udc_render.design.registration import offset_shifts, registered_rsd, widened_span_um
from udc_render.design.tiling_power import registered_rms, registered_variance, shift_span_um, tiling_power


def _binary21(k: int, seed: int) -> np.ndarray:
    flat = np.zeros(441)
    flat[np.random.default_rng(seed).permutation(441)[:k]] = 1.0
    return flat.reshape(21, 21)


def test_the_box_sums_are_every_offsets_window():
    """registered_rsd equals the root mean over every offset of var / mean² of that window, by loops (float64)."""
    rng = np.random.default_rng(0)
    jy, jx, py, px = 3, 5, 4, 6
    region = 100.0 + rng.normal(size=(2 * jy + py, 2 * jx + px))
    rel = [np.var(w) / np.mean(w) ** 2 for w in (region[a:a + 2 * jy + 1, b:b + 2 * jx + 1]
                                                 for a in range(py) for b in range(px))]
    assert abs(float(registered_rsd(torch.from_numpy(region), jy, jx)) / np.sqrt(np.mean(rel)) - 1) < 1e-12


def test_one_offset_is_the_plain_relative_sd_even_in_float32():
    """A period of one sample has one registration: the plain sd / mean, to float32's rounding on a power of small
    contrast (centred sums: no cancellation of the mean's square)."""
    rng = np.random.default_rng(1)
    region = 1e3 * (1 + 1e-3 * rng.normal(size=(9, 13)))
    got = float(registered_rsd(torch.tensor(region, dtype=torch.float32), 4, 6))
    assert abs(got / (region.std() / region.mean()) - 1) < 1e-4


def test_a_shifted_display_prints_the_shifted_power():
    """P_o(s) = P_0(s − o): the cell rolled by (a, b) squares is the display shifted by o = (a, b) × 8 µm, and its
    power at every shift of the span is the unshifted one's at s − o (tiling_power, the same window, 1e-9 of the
    mean): the law the registered figure rests on."""
    cell, (a, b) = _binary21(88, 4), (3, -5)
    span = widened_span_um(shift_span_um(Lens(), 2000.0), 168.0)
    p0, step = tiling_power(cell, 8.0, Lens(), 520.0, 2000.0, span, None, 8.0)
    po, _ = tiling_power(np.roll(cell, (a, b), (0, 1)), 8.0, Lens(), 520.0, 2000.0, span, None, 8.0)
    assert step == 8.0
    inner = (slice(25, -25), slice(25, -25))
    assert np.abs(po[inner] - np.roll(p0, (a, b), (0, 1))[inner]).max() < 1e-9 * p0.mean()


def test_the_studys_registered_figure_spans_its_offsets():
    """tiling_power.registered_rms of a cell repeated lies within the smallest and largest figure of its
    registrations (each the plain sd / mean of the span at offset o, from tiling_power's map), and its offset 0 is
    the plain figure of the study's window."""
    cell, lens = _binary21(88, 5), Lens()
    span = shift_span_um(lens, 2000.0)
    wide = widened_span_um(span, 168.0)
    power, step = tiling_power(cell, 8.0, lens, 640.0, 2000.0, wide, None, 8.0)
    (jx, jy), c = (int(s // step) for s in span), (power.shape[0] // 2, power.shape[1] // 2)
    rows, cols = offset_shifts(jy, 21) + c[0], offset_shifts(jx, 21) + c[1]
    per = [np.std(w) / np.mean(w) for w in (power[rows[a]:rows[a] + 2 * jy + 1, cols[b]:cols[b] + 2 * jx + 1]
                                            for a in range(21) for b in range(21))]
    got = registered_rms(cell, 8.0, lens, 640.0, 2000.0, span, 8.0)
    plain = tiling_power(cell, 8.0, lens, 640.0, 2000.0, span, None, 8.0)[0]
    assert min(per) <= got <= max(per) and max(per) / min(per) > 1.001
    assert abs(got / np.sqrt(np.mean(np.square(per))) - 1) < 1e-10
    assert abs(per[21 * 10 + 10] / (plain.std() / plain.mean()) - 1) < 1e-9


def test_a_period_of_several_cells_averages_their_registrations():
    """A display of one cell's period, registered over a period of two cells (the arranged tiling's window), reads
    the one cell's figure: four copies of its offsets (BandingCeiling, float64, rel 1e-9)."""
    from udc_render.design.bands import BandingCeiling
    cell = torch.tensor(_binary21(88, 6))
    one = BandingCeiling(1.0, 21, 168.0, 0.2, RIG_WAVELENGTHS_NM, 0, False)
    two = BandingCeiling(1.0, 21, 168.0, 0.2, RIG_WAVELENGTHS_NM, 0, False, period_tiles=2)
    with torch.no_grad():
        a = one.bands(cell, "search").numpy()
        b = two.bands(cell, "search", np.zeros((2, 2), int)).numpy()
    assert np.allclose(a, b, rtol=1e-9, atol=0)


def test_the_offset_map_holds_each_registration_and_its_centre_is_the_plain_tiling():
    """tiling_power.registered_variance: one var / mean² per offset of the period ([21, 21] for a 21-square cell on
    its own raster), its root mean is registered_rms, and its centre is the plain tiling's sd / mean over the span
    (rel 1e-9)."""
    cell, lens = _binary21(88, 7), Lens()
    span = shift_span_um(lens, 2000.0)
    var = registered_variance(cell, 8.0, lens, 530.0, 2000.0, span, 8.0)
    plain = tiling_power(cell, 8.0, lens, 530.0, 2000.0, span, None, 8.0)[0]
    assert var.shape == (21, 21) and np.isfinite(var).all()
    assert abs(np.sqrt(var[10, 10]) / (plain.std() / plain.mean()) - 1) < 1e-9
    assert abs(np.sqrt(var.mean()) / registered_rms(cell, 8.0, lens, 530.0, 2000.0, span, 8.0) - 1) < 1e-12
