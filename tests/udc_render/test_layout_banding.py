"""The layout study's banding at d (udc_render.studies.layout_banding) against closed forms and a symmetry."""
from __future__ import annotations

import numpy as np
from scipy.special import j1

from psf.lens import Lens
from psf.micrograph import MicrographLayout
from udc_render.studies.layout_banding import layout_banding

PIXEL_UM = 8.0


def _stripes(columns, size: int = 21, rows=slice(None)) -> MicrographLayout:
    image = np.zeros((size, size))
    for c in columns:
        image[rows, c] = 1.0
    return MicrographLayout("stripes", PIXEL_UM, image=image)


def test_a_slit_grating_near_the_lens_bands_as_its_geometric_shadow():
    """At d → 0, P(s) = ∫ |m(x' − s)|² A(x') dx': harmonic h of a stripe of width w in a period p has amplitude
    2 sinc(h w / p) · 2 J1(q) / q, q = π D h / p (the disc's transform), and none along the stripes. The series
    keeps only the propagating orders (|m| < p / λ), whose dropped tail is ~ 2 / (π² p / λ) ≈ 0.3 % here."""
    layout, lens = _stripes([slice(0, 5)]), Lens()
    p, w = 21 * PIXEL_UM, 5 * PIXEL_UM
    b = layout_banding(layout, lens, (520.0,), distance_mm=1e-3)
    h = np.arange(1, 40)
    q = np.pi * lens.aperture_um * h / p
    expected = np.abs(2 * np.sinc(h * w / p) * 2 * j1(q) / q)
    assert b["order_x"][0] == h[np.argmax(expected)]
    assert abs(b["amplitude_x"][0] / expected.max() - 1) < 1e-2, (b["amplitude_x"], expected.max())
    assert b["amplitude_y"][0] < 1e-12 and b["order_y"][0] in (0, 1)
    # the mean power is the transmitted power: the open area over the disc (Parseval, to the same tail)
    assert abs(b["mean_power_um2"][0] / (np.pi * lens.aperture_um ** 2 / 4) / (w / p) - 1) < 1e-2


def test_a_cell_repeating_at_half_its_period_has_no_bands_at_the_period():
    """A cell made of two equal halves along x has period p / 2: at d = 2 mm its odd harmonics of p vanish (the
    strongest is even), while along y (one stripe per period) harmonic 1 is there."""
    layout = _stripes([slice(1, 4), slice(11, 14)], size=20, rows=slice(2, 15))
    b = layout_banding(layout, Lens(), (640.0, 450.0), distance_mm=2.0)
    assert all(o % 2 == 0 for o in b["order_x"]) and all(a > 1e-4 for a in b["amplitude_x"])
    assert all(o == 1 for o in b["order_y"])
    assert all(p >= max(ax, ay) for p, ax, ay in zip(b["peak_to_peak"], b["amplitude_x"], b["amplitude_y"]))


def test_an_open_display_prints_no_bands():
    b = layout_banding(MicrographLayout("open", PIXEL_UM, image=np.ones((7, 7))), Lens(), (520.0,), 2.0)
    assert b["peak_to_peak"][0] < 1e-12 and b["strongest"][0] < 1e-12
