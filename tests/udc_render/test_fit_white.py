"""The white-square pair (udc_render/fit/white.py): the square found as a labelled component, whatever else is
bright in the frame; and γ and T(λ) against a closed form: an analytic T(λ) and the camera's and monitor's
spectra integrated here on a 1-nm grid, through a display whose every order falls inside the kernel window
(a cosine grating: γ's gain ratio is its power transmittance, no engine call)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import tifffile
from scipy.special import j1, jn_zeros

from psf import Lens, MicrographLayout
from udc_render.fit import synthetic as S
from udc_render.fit.inputs import FitError, Frame
from udc_render.fit.white import fit_transmission, measure_gamma
from udc_render.optics.displays import SILVER_PLASMA_WAVELENGTH_NM, STACK_INDEX
from udc_render.optics.gamma import panel_white_bands
from udc_render.sensor import photon_weights

CAMERA = "Nikon 5100 (NPL)"
TRUTH = np.array([0.42, 0.5, 0.5, 0.61])


def _frame(name: str, mosaic: np.ndarray) -> Frame:
    return Frame(name, mosaic.astype(np.float64), "cfa", np.array([[0, 1], [1, 2]], np.int8), 64.0, 65535.0, 16)


def _with_stray_light(mosaic: np.ndarray, level_dn: float) -> np.ndarray:
    """A hot pixel at the white level, a bright reflection (20 × 30 px at 0.8 of the square) and a dim ghost
    (40 × 40 px at 0.3) in the square's dark surround."""
    m = mosaic.astype(np.float64)
    m[10, 240] = 65535.0
    m[200:220, 10:40] += 0.8 * level_dn
    m[5:45, 60:100] += 0.3 * level_dn
    return np.clip(m, 0, 65535).astype(np.uint16)


def test_the_square_is_found_whatever_else_is_bright():
    """The 128-px square (rows and columns 64 … 191) and its 66-px central region come back with a hot pixel,
    a reflection and a ghost elsewhere in the glass capture (the bounding box of every bright pixel, the
    old rule, spanned rows 10 … 219), and γ within 3 σ and 1 %."""
    glass, disp = S.white_pair(TRUTH, display_gain=6.0, seed=3)
    level = float(np.median(glass[100:150, 100:150])) - 64.0
    m = measure_gamma(_frame("g", _with_stray_light(glass, level)), _frame("d", disp))
    assert m.square_xy_px == (128, 128) and m.region_xy_px == (66, 66)
    assert np.all(np.abs(m.gamma - TRUTH) < 3 * m.sigma) and np.all(np.abs(m.gamma / TRUTH - 1) < 0.01)


def test_a_bright_region_that_is_not_a_square_is_refused():
    """A disc fills π/4 of its bounding box (80 % on pixels): refused in one line, not measured."""
    y, x = np.mgrid[0:256, 0:256]
    disc = np.where((x - 128) ** 2 + (y - 128) ** 2 < 60 ** 2, 30000, 0) + 64
    f = _frame("disc", disc.astype(np.uint16))
    with pytest.raises(FitError, match=r"fills (79|80)% of its bounding box: expected a white square"):
        measure_gamma(f, f)


# ---------------------------------------------------------------- γ and T(λ) against a closed form

GRID_NM = np.arange(400.0, 701.0, 1.0)  # 1-nm band edges of the truth's integrals
SCALE, EDGE_NM, CATHODE_NM, URBACH_NM = 0.3, 440.0, 10.0, 20.0


def transmission(wl_nm: np.ndarray) -> np.ndarray:
    """The truth's T(λ): a polyimide Urbach edge, 10^(−exp(−(λ − edge)/w)), times a thin silver cathode
    (Tinkham: 1 / (1 + (π d λ / (n λ_p²))²)), times a scale."""
    cathode = 1.0 / (1.0 + (math.pi * CATHODE_NM * wl_nm / (STACK_INDEX * SILVER_PLASMA_WAVELENGTH_NM ** 2)) ** 2)
    return SCALE * 10.0 ** (-np.exp(-(wl_nm - EDGE_NM) / URBACH_NM)) * cathode


A, B = 0.5, 0.4  # the grating's amplitude a + b cos(2π x / p)


def _cosine_grating(path, lens: Lens) -> tuple[MicrographLayout, float]:
    """(the grating a + b cos(2π x / p), constant along y; its power transmittance over the lens's pupil).
    Orders 0 and ±1 only (about 8.5 px apart at 650 nm on the paper's lens): the window holds all its light.
    Over a pupil of radius R centred on a crest, the mean of |t|² is a² + b²/2 + 2ab 2J₁(kR)/(kR)
    + (b²/2) 2J₁(2kR)/(2kR), k = 2π/p; p puts kR on the 11th zero of J₁, so the cross term vanishes wherever
    the crest lies, and τ is 0.33 within 1e-4."""
    radius_um = lens.aperture_um / 2
    k = jn_zeros(1, 11)[-1] / radius_um
    x = np.arange(64)
    tile = np.tile(A + B * np.cos(2 * np.pi * x / 64), (8, 1)).astype(np.float32)
    tifffile.imwrite(path, tile)
    tau = A * A + B * B / 2 + B * B / 2 * 2 * j1(2 * k * radius_um) / (2 * k * radius_um)
    return MicrographLayout.load(path, 2 * np.pi / k / 64, "amplitude"), float(tau)


def _closed_form_pair(tmp_path, gain: float = 4.0):
    """(the grating, the truth's γ (R, Gr, Gb, B), the white square measured on the pair made with it)."""
    layout, tau = _cosine_grating(tmp_path / "grating.tif", Lens())
    q = photon_weights(GRID_NM, CAMERA) * panel_white_bands(GRID_NM)[None, :]
    rgb = gain * tau * (q @ transmission(0.5 * (GRID_NM[1:] + GRID_NM[:-1]))) / q.sum(axis=1)
    truth = np.array([rgb[0], rgb[1], rgb[1], rgb[2]])
    glass, disp = S.white_pair(truth, display_gain=gain, seed=5)
    return layout, truth, measure_gamma(_frame("g", glass), _frame("d", disp))


def test_gamma_from_an_analytic_spectrum(tmp_path):
    """γ_c = G τ Σ q_c(λ) L(λ) T(λ) / Σ q_c L (the camera's photon weights q and the monitor's white L in 1-nm
    bands, the closed-form T above, τ the grating's power transmittance): the white pair made with it
    measures γ within 1 % and 3 σ, and the fit on 100-nm bands (three: an exact solve) gives it back within
    1 %."""
    layout, truth, square = _closed_form_pair(tmp_path)
    assert np.all(np.abs(square.gamma / truth - 1) < 0.01) and np.all(np.abs(square.gamma - truth) < 3 * square.sigma)
    _, _, model = fit_transmission(square, layout, Lens(), np.array([400.0, 500.0, 600.0, 700.0]), 1.55, CAMERA, 4.0)
    assert np.all(np.abs(model / truth - 1) < 0.01)


@pytest.mark.slow
def test_t_from_an_analytic_spectrum(tmp_path):
    """The fit on the presets' 10-nm bands gives the closed-form T(λ) back: γ within 1 %, T within 1 % over
    460–700 nm (measured 0.8 %; below, the absorption edge falls 10× in 40 nm), each parameter within 3 σ
    (measured ≤ 2.1 σ). ~30 s with a cold kernel cache."""
    layout, truth, square = _closed_form_pair(tmp_path)
    trans, params, model = fit_transmission(square, layout, Lens(), np.arange(400.0, 701.0, 10.0), 1.55, CAMERA, 4.0)
    assert trans.kind == "polyimide" and np.all(np.abs(model / truth - 1) < 0.01)
    wl = np.arange(460.0, 701.0, 5.0)
    assert np.max(np.abs(trans(wl) / transmission(wl) - 1)) < 0.01
    for name, truth_value in (("scale", SCALE), ("edge_nm", EDGE_NM), ("cathode_nm", CATHODE_NM)):
        value, sigma = params[name]
        assert abs(value - truth_value) < 3 * sigma, name
