"""The PSF engine against analytic oracles (docs/PHYSICS.md §6) and conservation laws.

Rig: the paper's lens (f = 6 mm, D = 3.333 mm) unless stated. Tolerances are those of docs/PHYSICS.md §6
where it lists one; the value measured on this engine (2-core machine, float64) is noted beside
each assertion as "measured". Heavy variants (N = 4096 pupils) are marked slow.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy.optimize import brentq, minimize_scalar
from scipy.special import j1

from psf import AliasingWarning, Lens, compute_kernels, fourier, layouts
from psf.layouts import PeriodicLayout, Rect
from psf.propagation import propagate
from psf.pupil import cell_raster

LENS = Lens()
Z = LENS.image_distance_um
D = LENS.aperture_um
AREA = math.pi * D ** 2 / 4


# ---------------------------------------------------------------------------------------------
# 1. Airy dark rings
# ---------------------------------------------------------------------------------------------

def _ring_errors(psfkit, n, lam_um):
    pg, g = psfkit.bare_pupil(LENS, n)
    unit = lam_um * Z / D
    # On the x axis the field only depends on the pupil's y-projection (point_field is linear in g):
    # ∫∫ g(x, y) e^{−2πi x u/λz} dx dy = ∫ [∫ g dy] e^{−2πi x u/λz} dx. Checked against the full 2-D g
    # below.
    proj = g.sum(axis=0)[None, :] * pg.dy_um

    def field(u):
        return fourier.point_field(proj, pg.x_um, np.zeros(1), pg.dx_um, 1.0, lam_um, Z,
                                   np.atleast_1d(np.asarray(u, dtype=float)), np.zeros(1))[0]

    u_test = np.array([0.0, 0.7, 1.9, 2.6]) * unit
    full = fourier.point_field(g, pg.x_um, pg.y_um, pg.dx_um, pg.dy_um, lam_um, Z, u_test, np.zeros(1))[0]
    np.testing.assert_allclose(full, field(u_test), rtol=0, atol=1e-12 * abs(full[0]))

    u0 = field(0.0)[0]
    phase = u0 / abs(u0)  # a centred symmetric pupil has a real field up to this constant phase
    samples = field(np.linspace(0, 4 * unit, 41)) / phase
    assert np.max(np.abs(samples.imag)) < 1e-12 * abs(u0)
    errs = []
    for zr in psfkit.j1_zeros / math.pi:
        root = brentq(lambda u: (field(u)[0] / phase).real, (zr - 0.1) * unit, (zr + 0.1) * unit,
                      xtol=1e-13 * unit, rtol=1e-15)
        errs.append(root / unit / zr - 1.0)
    return np.array(errs)


@pytest.mark.parametrize("lam_nm", [450.0, 550.0, 640.0])
def test_airy_dark_rings_at_j1_zeros(psfkit, lam_nm):
    # 1.21967, 2.23313, 3.23832 λf/D (j_{1,k}/π); measured |rel err| ≤ 7.2e-8 at N = 1024 (every λ: the error
    # scales with the ring, not λ), asserted 2e-7 (§6's 1e-6 would let a 10× worse raster through).
    np.testing.assert_allclose(psfkit.j1_zeros / math.pi, [1.21967, 2.23313, 3.23832], atol=5e-6)
    errs = _ring_errors(psfkit, 1024, lam_nm * 1e-3)
    assert np.max(np.abs(errs)) < 2e-7, errs


@pytest.mark.slow
def test_airy_dark_rings_fine_pupil(psfkit):
    # measured 2.2e-9 at N = 4096 (error ∝ 1/N² from the grey edge cells).
    errs = _ring_errors(psfkit, 4096, 0.55)
    assert np.max(np.abs(errs)) < 1e-8, errs


# ---------------------------------------------------------------------------------------------
# 2. Airy intensity, point samples
# ---------------------------------------------------------------------------------------------

def test_airy_intensity_point_field(psfkit):
    # |U|² from point_field on the N = 1024 raster vs I0 (2J1(v)/v)², absolute (I0 = (A/λz)²),
    # on an off-grid 129² patch out to ~80 µm. §6: 2e-6 of peak at N = 1024; measured 2.2e-7, asserted 5e-7.
    lam = 0.55
    pg, g = psfkit.bare_pupil(LENS, 1024)
    u = (np.arange(129) - 64) * 1.147 + 0.123
    v = (np.arange(129) - 64) * 1.271 - 0.27
    U = fourier.point_field(g, pg.x_um, pg.y_um, pg.dx_um, pg.dy_um, lam, Z, u, v)
    i0 = psfkit.airy_peak(LENS, lam)
    ref = i0 * psfkit.airy_norm(np.hypot(u[None, :], v[:, None]), LENS, lam)
    assert np.max(np.abs(np.abs(U) ** 2 - ref)) < 5e-7 * i0


def _engine_point_error(psfkit, n):
    lam, rho, size = 0.55, 3.1, 255
    ks = compute_kernels(None, LENS, [550.0], pixel_um=rho, size_px=size, pupil_samples=n,
                         precision="float64", pixel_integration=False)
    u = (np.arange(size) - size // 2) * rho
    ref = rho ** 2 * psfkit.airy_peak(LENS, lam) * psfkit.airy_norm(np.hypot(u[None, :], u[:, None]), LENS, lam) / AREA
    got = ks.kernels[0] * (1 - ks.energy_outside[0])  # energy per point sample / transmitted power
    return np.max(np.abs(got - ref)) / ref.max()


def test_airy_intensity_engine_point_samples(psfkit):
    # Engine MFT, ρ² I(u_j) on the 255² grid of 3.1 µm, absolute. Measured 3.6e-9 at N = 1024
    # (the de-apodisation of the bare raster removes the grey-edge error seen by point_field); asserted 1e-8.
    assert _engine_point_error(psfkit, 1024) < 1e-8


@pytest.mark.slow
def test_airy_intensity_engine_point_samples_fine(psfkit):
    # §6: 3e-9 of peak at N = 4096; measured 1.0e-10, asserted 3e-10.
    assert _engine_point_error(psfkit, 4096) < 3e-10


# ---------------------------------------------------------------------------------------------
# 3. Encircled energy
# ---------------------------------------------------------------------------------------------

def test_encircled_energy_at_dark_rings(psfkit):
    # 1 − J0² − J1² at the first three rings: 0.83778, 0.90993, 0.93765. Pixel-integrated kernel
    # on 0.1 λf/D pixels, absolute energy = kernel × (1 − energy_outside), summed over the pixels
    # whose centres lie within the ring. §6: 1e-4; measured ≤ 6.7e-6, asserted 2e-5.
    lam = 0.55
    unit = lam * Z / D
    rho, size = 0.1 * unit, 85
    ks = compute_kernels(None, LENS, [550.0], pixel_um=rho, size_px=size, pupil_samples=1024, precision="float64")
    absolute = ks.kernels[0] * (1 - ks.energy_outside[0])
    c = (np.arange(size) - size // 2) * rho
    r = np.hypot(c[None, :], c[:, None])
    zeros = psfkit.j1_zeros
    expected = psfkit.encircled_energy(zeros)
    np.testing.assert_allclose(expected, [0.83778, 0.90993, 0.93765], atol=5e-6)
    got = np.array([absolute[r <= z / math.pi * unit].sum() for z in zeros])
    np.testing.assert_allclose(got, expected, rtol=0, atol=2e-5)


# ---------------------------------------------------------------------------------------------
# 4. Pixel-integrated Airy
# ---------------------------------------------------------------------------------------------

def _pixel_integrated_error(psfkit, n):
    lam, rho, size, m = 0.55, 3.1, 255, 41
    ks = compute_kernels(None, LENS, [550.0], pixel_um=rho, size_px=size, pupil_samples=n, precision="float64")
    got = ks.kernels[0] * (1 - ks.energy_outside[0])
    h = size // 2
    got = got[h - m // 2:h + m // 2 + 1, h - m // 2:h + m // 2 + 1]
    ref = psfkit.airy_pixel_energy((np.arange(m) - m // 2) * rho, rho, LENS, lam, nodes=32)
    return np.max(np.abs(got - ref)) / ref.max()


def test_pixel_integrated_airy_matches_gauss_legendre(psfkit):
    # Engine OTF × pixel-sinc vs 32×32-point Gauss-Legendre integral of the Airy pattern over
    # each 3.1 µm pixel (41×41 about the centre; GL converged to 4e-15). Measured 1.2e-6 at N = 1024.
    assert _pixel_integrated_error(psfkit, 1024) < 2e-6


@pytest.mark.slow
def test_pixel_integrated_airy_fine_pupil(psfkit):
    # Measured 7.7e-8 at N = 4096 (∝ 1/N²).
    assert _pixel_integrated_error(psfkit, 4096) < 2e-7


def test_pixel_integration_matters_at_the_papers_pixel():
    # PHYSICS §3: point sampling vs pixel integration differ by 0.23 in L1 at 3.1 µm (measured 0.2253: the
    # two digits PHYSICS prints).
    kw = dict(wavelengths_nm=[550.0], pixel_um=3.1, size_px=127, pupil_samples=512, precision="float64")
    a = compute_kernels(None, LENS, pixel_integration=True, **kw).kernels[0]
    b = compute_kernels(None, LENS, pixel_integration=False, **kw).kernels[0]
    assert 0.225 <= np.abs(a - b).sum() < 0.235


# ---------------------------------------------------------------------------------------------
# 5. Slit grating orders
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("pitch, opening", [(60.0, 14.0), (50.0, 20.0)])
def test_slit_grating_orders(psfkit, pitch, opening):
    # Orders at m λ z / p with P_m / P_0 = sinc²(m a / p). |U|² maximised near each order along the
    # x axis (y-projection of the raster, exact on v = 0). §6: positions 1e-3 of the spacing,
    # ratios 0.5 %; measured ≤ 3.3e-5 of the spacing and ≤ 6.3e-4 relative (m ≤ 3), asserted 1e-4 and 1.5e-3.
    lam = 0.55
    lay = layouts.slit_grating(pitch, opening)
    pg, g, _ = psfkit.display_pupil(lay, LENS, 1024)
    proj = g.sum(axis=0)[None, :] * pg.dy_um

    def intensity(u):
        U = fourier.point_field(proj, pg.x_um, np.zeros(1), pg.dx_um, 1.0, lam, Z, np.atleast_1d(u), np.zeros(1))
        return float(np.abs(U[0, 0]) ** 2)

    spacing, width = lam * Z / pitch, lam * Z / D
    orders = np.arange(4)
    pos, peak = [], []
    for m in orders:
        res = minimize_scalar(lambda u: -intensity(u), bounds=(m * spacing - 0.5 * width, m * spacing + 0.5 * width),
                              method="bounded", options={"xatol": 1e-7 * spacing})
        pos.append(res.x)
        peak.append(-res.fun)
    pos, peak = np.array(pos), np.array(peak)
    assert np.max(np.abs(pos - orders * spacing)) < 1e-4 * spacing
    np.testing.assert_allclose(peak / peak[0], np.sinc(orders * opening / pitch) ** 2, rtol=1.5e-3)


# ---------------------------------------------------------------------------------------------
# 6. Zero-order energy of a binary mask
# ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def bare_centre_energy():
    ks = compute_kernels(None, LENS, [550.0], size_px=63, pupil_samples=1024, precision="float64")
    return ks.kernels[0, 31, 31] * (1 - ks.energy_outside[0])


@pytest.mark.parametrize("layout", [layouts.toled(pitch_um=60.0), layouts.poled(), layouts.slit_grating(20.0, 6.0)],
                         ids=["toled", "poled", "slits20"])
def test_zero_order_energy_equals_open_fraction(bare_centre_energy, layout):
    # A binary mask of open fraction F has zero-order amplitude c0 = F, so its zero order carries
    # F² A = F × (F A): the fraction F of the geometric transmitted power F A. The zero order is the
    # undiffracted Airy core: its energy on the central pixel, per unit bare-aperture power
    # (kernel × (1 − energy_outside) × transmittance), over the bare lens's, is F² up to the wings
    # of the other orders there (≲ 1e-3 of F). §6: 1e-3; measured |ratio/F − F|: T-OLED 3.2e-4,
    # P-OLED 5.3e-5, 20-µm slits 8.3e-5.
    # (Per unit of the engine's transmitted power the ratio is F·F/T: T excludes evanescent orders,
    # ~1e-3 below F, see test_transmittance_is_the_propagating_order_series.)
    ks = compute_kernels(layout, LENS, [550.0], size_px=63, pupil_samples=1024, precision="float64")
    centre = ks.kernels[0, 31, 31] * (1 - ks.energy_outside[0]) * ks.transmittance[0]
    ratio = centre / bare_centre_energy
    f = layout.open_fraction
    assert abs(ratio / f - f) < 1e-3


# ---------------------------------------------------------------------------------------------
# 7. Parseval / energy
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("precision, tol", [("float64", 1e-12), ("float32", 1e-6)])
def test_kernels_have_unit_sum(precision, tol):
    ks = compute_kernels(layouts.poled(), LENS, [450.0, 520.0, 640.0], size_px=63, pupil_samples=256,
                         precision=precision)
    assert ks.kernels.dtype == (np.float64 if precision == "float64" else np.float32)
    np.testing.assert_allclose(ks.kernels.astype(np.float64).sum(axis=(1, 2)), 1.0, rtol=0, atol=tol)
    assert np.all(ks.kernels >= -1e-6 * ks.kernels.max())  # intensities (float noise only)


def test_full_alias_period_carries_the_pupil_energy(psfkit):
    # Discrete Parseval: a kernel window that spans exactly one alias period λz/δ with S ≥ 2N − 1
    # pixels sums to R(0) = Σ|g|² δx δy (only lag 0 survives Σ_j e^{−2πi m j / S}). Bare raster,
    # no de-apodisation (that is a deliberate change of spectrum). Measured ≤ 9e-14 relative.
    lam = 0.52
    pg, g = psfkit.bare_pupil(LENS, 96)
    R = fourier.autocorrelation_half(g, pg.dx_um, pg.dy_um)
    size = 2 * max(pg.nx, pg.ny) + 1
    rho = lam * Z / (pg.dx_um * size)
    energy = float(np.sum(np.abs(g) ** 2)) * pg.dx_um * pg.dy_um
    for method in ("mft", "czt"):
        for integ in (True, False):
            k = fourier.pixel_kernel(R, pg.dx_um, pg.dy_um, lam, Z, rho, size, method, integ, np.complex128,
                                     deapodize=False)
            assert abs(k.sum() / energy - 1) < 1e-12, (method, integ)


def test_engine_energy_bookkeeping_over_full_alias_period(psfkit):
    # Same identity through compute_kernels with a display (band-limited raster, no de-apodisation):
    # window energy = (1 − energy_outside) × transmittance × A must equal Σ|g|² δ² of the engine's
    # pupil. Measured 5e-15 relative.
    lam, n = 0.52, 48
    lay = layouts.toled(pitch_um=60.0)
    pg, g, _ = psfkit.display_pupil(lay, LENS, n)
    assert pg.dx_um == pg.dy_um
    size = 2 * max(pg.nx, pg.ny) + 1
    rho = lam * Z / (pg.dx_um * size)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", AliasingWarning)  # the window is exactly the alias-free field
        ks = compute_kernels(lay, LENS, [520.0], pixel_um=rho, size_px=size, pupil_samples=n, precision="float64")
    assert ks.params["pupil_shape"] == [pg.ny, pg.nx]
    window = (1 - ks.energy_outside[0]) * ks.transmittance[0] * AREA
    energy = float(np.sum(np.abs(g) ** 2)) * pg.dx_um * pg.dy_um
    assert abs(window / energy - 1) < 1e-12


@pytest.mark.parametrize("layout", [layouts.toled(pitch_um=60.0), layouts.poled()], ids=["toled", "poled"])
def test_transmittance_is_the_propagating_order_series(psfkit, layout):
    # d = 0: power through the aperture = Σ_k b_k Â(k/p) over the propagating orders (independent
    # re-implementation in conftest). The open fraction (0.21 / 0.23) is the same sum over all orders
    # without the aperture edge; the difference is the evanescent orders' power (|ν| > 1/λ), about
    # 1e-3 for these 10-µm features, plus the edge term Σ_{k≠0} ≲ 3e-4. Measured T − F:
    # T-OLED −6.2e-4/−8.0e-4/−9.7e-4, P-OLED −1.16e-3/−1.43e-3/−1.66e-3 at 450/550/640 nm; series
    # agreement ≤ 4e-15 relative.
    # NOTE: §6 asks "≈ open fraction within ~1e-3"; the engine's choice to drop evanescent orders puts
    # the P-OLED at 1.66e-3, so that check is 2e-3 here (the exact series check is the tight one).
    ks = compute_kernels(layout, LENS, [450.0, 550.0, 640.0], size_px=15, pupil_samples=256, precision="float64")
    for k, lam_nm in enumerate(ks.wavelengths_nm):
        expected = psfkit.series_power(layout, LENS, lam_nm * 1e-3, 0.0, np.zeros(2)).real / AREA
        assert abs(ks.transmittance[k] / expected - 1) < 1e-10
        assert abs(ks.transmittance[k] - layout.open_fraction) < 2e-3


# ---------------------------------------------------------------------------------------------
# 8. Talbot self-imaging (Fresnel transfer function)
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("n, periods, raster", [(24, 4, "area"), (25, 3, "band_limited")])
def test_talbot_self_imaging(n, periods, raster):
    # The window holds `periods` whole periods of n samples (δ = p/n, N = n·periods), so the DFT of
    # the raster is non-zero only on the lines ν = j/p (index multiples of `periods`), and fftfreq puts
    # those lines exactly at integer j/p. There exp(−iπλz ν²) at z_T = 2p²/λ is exp(−2πi j²) = 1, and
    # at z_T/2 it is exp(−iπ j²) = (−1)^j = exp(−2πi j (p/2)/p): the mask shifted by p/2 — exactly,
    # for every line including the Nyquist one (sign-symmetric). Only rounding remains (phases up to
    # 2π j² ~ 1e3 rad: ~1e-13). Measured ≤ 7e-14.
    lam, p = 0.55, 60.0
    amp, _ = cell_raster(layouts.toled(pitch_um=60.0), n, n, raster)
    field = np.tile(amp, (periods, periods)).astype(complex)
    d = p / n
    zt = 2 * p ** 2 / lam
    full = propagate(field, d, d, lam, zt, transfer="fresnel")
    assert np.max(np.abs(full - field)) < 1e-12
    half = propagate(field, d, d, lam, zt / 2, transfer="fresnel")
    shifted = propagate(field, d, d, lam, 0.0, transfer="fresnel", shift_um=(p / 2, p / 2))
    assert np.max(np.abs(half - shifted)) < 1e-12
    if n % 2 == 0:  # p/2 is a whole number of samples: compare with a plain roll
        assert np.max(np.abs(half - np.roll(field, (n // 2, n // 2), axis=(0, 1)))) < 1e-12
    # Not trivially true: a quarter Talbot length changes the field, and the exact angular spectrum
    # (non-paraxial) does not self-image exactly.
    assert np.max(np.abs(propagate(field, d, d, lam, zt / 4, transfer="fresnel") - field)) > 0.5
    assert np.max(np.abs(propagate(field, d, d, lam, zt) - field)) > 1e-2


def test_talbot_needs_whole_periods_in_the_window():
    # The same mask on a window that is 3 samples short of whole periods: spectral lines fall between
    # DFT samples and the self-image is lost — the exactness above is a property of the sampling.
    lam, p, n = 0.55, 60.0, 24
    amp, _ = cell_raster(layouts.toled(pitch_um=60.0), n, n, "area")
    field = np.tile(amp, (4, 4))[:-3, :-3].astype(complex)
    out = propagate(field, p / n, p / n, lam, 2 * p ** 2 / lam, transfer="fresnel")
    assert np.max(np.abs(out - field)) > 1e-2


# ---------------------------------------------------------------------------------------------
# 9. Banding at d > 0
# ---------------------------------------------------------------------------------------------

TWO_SLITS = PeriodicLayout("two-slits", 200.0, 200.0, (Rect(50.0, 100.0, 40.0, 200.0), Rect(130.0, 100.0, 20.0, 200.0)))
SMALL_LENS = Lens(aperture_um=600.0)


@pytest.mark.parametrize("layout, distance_mm, phases",
                         [(layouts.slit_grating(200.0, 60.0), 20.0, 6), (TWO_SLITS, 5.0, 4)],
                         ids=["slits-200-60", "two-slits"])
def test_banding_follows_the_power_series(psfkit, layout, distance_mm, phases):
    # Coarse grating (p = 200 µm) and a 600 µm aperture: banding of a few % (D/p = 3).
    # Convention: phase (j, i) shifts the mask by +s = field_shifts_um[j, i] (the field becomes
    # m(x − s)); the aperture stays; P(s) = ∫ A(x)|m_d(x − s)|² dx = Σ_k b_k(d) Â(k/p) e^{−2πiks/p}.
    # The two-slit cell is asymmetric, so the sign of the exponent is tested too.
    # §6: 1 % of the banding amplitude. Measured ≤ 1.5e-11 of the amplitude vs the series and vs the
    # brute-force quadrature (sampled amplitudes 0.76 % and 2.6 %).
    lam = 0.55
    d_um = distance_mm * 1000
    ks = compute_kernels(layout, SMALL_LENS, [550.0], size_px=31, distance_mm=distance_mm, field_phases=phases,
                         pupil_samples=128, precision="float64")
    fp = ks.field_power[0]
    shifts = ks.field_shifts_um  # the engine's choice of shifts is used as it is
    # invariant along y: every row of phases is the same
    assert np.ptp(fp, axis=0).max() < 1e-12
    series = psfkit.series_power(layout, SMALL_LENS, lam, d_um, shifts[0])
    assert np.max(np.abs(series.imag)) < 1e-9 * np.abs(series).max()
    series = series.real / series.real.mean()
    amp = np.ptp(series) / 2
    assert amp > 5e-3  # banding worth testing
    assert np.max(np.abs(fp[0] - series)) < 0.01 * amp
    brute = psfkit.slit_power_quadrature(layout, SMALL_LENS, lam, d_um, shifts[0, :, 0])
    brute /= brute.mean()
    assert np.max(np.abs(fp[0] - brute)) < 0.01 * amp
    # the propagation over d matters here (d = 0 prediction is off by ≫ 1 % of the amplitude)
    flat = psfkit.series_power(layout, SMALL_LENS, lam, 0.0, shifts[0]).real
    assert np.max(np.abs(flat / flat.mean() - series)) > 0.1 * amp
    if layout is TWO_SLITS:  # the opposite sign convention would be caught
        mirrored = psfkit.series_power(layout, SMALL_LENS, lam, d_um, -shifts[0]).real
        assert np.max(np.abs(mirrored / mirrored.mean() - series)) > 0.3 * amp


def test_field_phase_is_the_mask_shifted_by_plus_s():
    # Phase (j, i) at d > 0 must be the d-propagated PSF of the layout moved by +field_shifts_um[j, i]
    # (propagation and shift commute; both rasters carry the same orders): measured 4e-16 of peak,
    # power identical. The mask moved by −s gives a different kernel (3e-4 and 1.7e-5 of peak): the direction
    # is tested.
    base = layouts.toled(pitch_um=60.0)
    o = base.openings[0]
    kw = dict(wavelengths_nm=[520.0], size_px=31, distance_mm=1.0, field_phases=4, pupil_samples=128,
              precision="float64")
    ks = compute_kernels(base, LENS, **kw)
    peak = ks.kernels.max()
    for j, i in ((0, 1), (1, 2)):
        sx, sy = ks.field_shifts_um[j, i]  # (15, 0) and (30, 15) µm with the current phase grid
        moved = {}
        for sign in (1, -1):
            opening = Rect(o.cx_um + sign * sx, o.cy_um + sign * sy, o.width_um, o.height_um)
            lay = PeriodicLayout("moved", 60.0, 60.0, (opening,))
            moved[sign] = compute_kernels(lay, LENS, **kw)
        assert np.max(np.abs(ks.field_kernels[0, j, i] - moved[1].field_kernels[0, 0, 0])) < 1e-12 * peak
        assert abs(ks.field_power[0, j, i] - moved[1].field_power[0, 0, 0]) < 1e-12
        assert np.max(np.abs(ks.field_kernels[0, j, i] - moved[-1].field_kernels[0, 0, 0])) > 3e-6 * peak


def test_banding_amplitude_small_for_fine_display(psfkit):
    # PHYSICS §4: first harmonic ≈ 2|c1/c0| |2J1(πD/p)/(πD/p)|, of order 1e-3 for D/p ≈ 55: 1.02e-3 for the
    # 14-µm slit (c1/c0 = sinc(14/60)); the largest excursion of the 4 × 4 phases is measured 8.2e-4, asserted
    # within a factor 2 of the estimate either way.
    ks = compute_kernels(layouts.toled(pitch_um=60.0), LENS, [520.0], size_px=15, distance_mm=1.0, field_phases=4,
                         pupil_samples=128, precision="float64")
    fp = ks.field_power[0]
    series = psfkit.series_power(layouts.toled(pitch_um=60.0), LENS, 0.52, 1000.0, ks.field_shifts_um).real
    np.testing.assert_allclose(fp, series / series.mean(), rtol=0, atol=1e-10)
    x = math.pi * D / 60.0
    estimate = 2 * np.sinc(14.0 / 60.0) * abs(2 * j1(x) / x)
    assert 0.5 * estimate < np.max(np.abs(fp - 1)) < 2 * estimate


# ---------------------------------------------------------------------------------------------
# 10. d → 0
# ---------------------------------------------------------------------------------------------

D0_KW = dict(wavelengths_nm=[450.0, 640.0], size_px=63, pupil_samples=256, precision="float64")


@pytest.fixture(scope="module")
def principal_plane():
    return compute_kernels(layouts.toled(pitch_um=60.0), LENS, **D0_KW)


def test_d_to_zero_single_phase_equals_principal_plane(principal_plane):
    # With one field phase (s = 0), d = 1e-6 mm must reproduce the d = 0 model: the angular-spectrum
    # phase at d = 1 nm is ≤ 1e-4 rad. Measured 5e-16 of the peak; 5e-13 in energy_outside.
    ks = compute_kernels(layouts.toled(pitch_um=60.0), LENS, distance_mm=1e-6, field_phases=1, **D0_KW)
    peak = principal_plane.kernels.max()
    assert np.max(np.abs(ks.kernels - principal_plane.kernels)) < 1e-10 * peak
    np.testing.assert_allclose(ks.energy_outside, principal_plane.energy_outside, rtol=0, atol=1e-10)
    np.testing.assert_allclose(ks.transmittance, principal_plane.transmittance, rtol=1e-10)
    np.testing.assert_allclose(ks.field_power, 1.0, rtol=0, atol=1e-12)


def test_d_to_zero_phase_kernels_follow_the_d0_model(psfkit, principal_plane):
    # Each field kernel at d → 0 is the d = 0 PSF of the shifted mask; the s = 0 one is the
    # principal-plane kernel (measured 4e-15 of peak). The per-phase powers tend to the d = 0 series
    # P0(s) = Σ c_k Â(k/p) e^{−2πiks/p} (measured 5.5e-13), which is NOT flat: ~1e-3 for the T-OLED.
    ks = compute_kernels(layouts.toled(pitch_um=60.0), LENS, distance_mm=1e-6, field_phases=2, **D0_KW)
    peak = principal_plane.kernels.max()
    assert np.max(np.abs(ks.field_kernels[:, 0, 0] - principal_plane.kernels)) < 1e-10 * peak
    for k, lam_nm in enumerate(ks.wavelengths_nm):
        p0 = psfkit.series_power(layouts.toled(pitch_um=60.0), LENS, lam_nm * 1e-3, 0.0, ks.field_shifts_um).real
        np.testing.assert_allclose(ks.field_power[k], p0 / p0.mean(), rtol=0, atol=1e-9)


def test_d_to_zero_field_average_equals_principal_plane(principal_plane):
    ks = compute_kernels(layouts.toled(pitch_um=60.0), LENS, distance_mm=1e-6, field_phases=2, **D0_KW)
    peak = principal_plane.kernels.max()
    assert np.max(np.abs(ks.kernels - principal_plane.kernels)) < 1e-9 * peak
    np.testing.assert_allclose(ks.transmittance, principal_plane.transmittance, rtol=1e-9)
    np.testing.assert_allclose(ks.field_power, 1.0, rtol=0, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# 11. Wavelength scaling at d = 0
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("layout", [None, layouts.toled(pitch_um=60.0)], ids=["bare", "toled"])
def test_psf_dilates_with_wavelength_point_field(psfkit, layout):
    # d = 0, in focus: the pupil does not depend on λ and U_λ(u) = (1/λz) ∫ g e^{−2πi x·u/(λz)}, so
    # U_λ2(u λ2/λ1) = (λ1/λ2) U_λ1(u) exactly. Measured ≤ 4e-15 of peak.
    if layout is None:
        pg, g = psfkit.bare_pupil(LENS, 256)
    else:
        pg, g, _ = psfkit.display_pupil(layout, LENS, 256)
    l1, l2 = 0.45, 0.64
    u = np.linspace(-60, 60, 37) + 0.31
    v = np.linspace(-50, 50, 29) - 0.17
    U1 = fourier.point_field(g, pg.x_um, pg.y_um, pg.dx_um, pg.dy_um, l1, Z, u, v)
    U2 = fourier.point_field(g, pg.x_um, pg.y_um, pg.dx_um, pg.dy_um, l2, Z, u * l2 / l1, v * l2 / l1)
    assert np.max(np.abs(U2 * (l2 / l1) - U1)) < 1e-12 * np.abs(U1).max()


def test_psf_dilates_with_wavelength_engine():
    # Engine kernels at (λ1, ρ1) and (λ2, ρ1 λ2/λ1) are the same array: the pixel grid, the pixel
    # integration and the de-apodisation all dilate together. Window energy per bare power
    # (1 − energy_outside) × transmittance is also the same (the transmittance alone is not: its
    # evanescent cut-off |ν| < 1/λ does not dilate). Measured ≤ 1.6e-14 of peak.
    l1, l2, rho = 450.0, 640.0, 3.1
    for layout in (None, layouts.toled(pitch_um=60.0)):
        kw = dict(size_px=63, pupil_samples=512, precision="float64")
        a = compute_kernels(layout, LENS, [l1], pixel_um=rho, **kw)
        b = compute_kernels(layout, LENS, [l2], pixel_um=rho * l2 / l1, **kw)
        assert np.max(np.abs(a.kernels - b.kernels)) < 1e-12 * a.kernels.max()
        wa = (1 - a.energy_outside) * a.transmittance
        wb = (1 - b.energy_outside) * b.transmittance
        np.testing.assert_allclose(wa, wb, rtol=1e-12)


# ---------------------------------------------------------------------------------------------
# 12. T-OLED MTF nulls
# ---------------------------------------------------------------------------------------------

def _otf_row(g, pg):
    R = fourier.autocorrelation_half(g, pg.dx_um, pg.dy_um)
    row = R[(R.shape[0] - 1) // 2]  # Δy = 0
    return row / row[0].real, np.arange(R.shape[1]) * pg.dx_um


def test_toled_otf_has_true_nulls_along_x(psfkit):
    # The T-OLED opening is a = 14 µm wide in a 60 µm cell: for Δx mod p in (a, p − a) shifted
    # openings never overlap, so the OTF R(Δx, 0) = ∫ g(x + Δx) g*(x) dx is exactly 0 there (the
    # "MTF nulls along x" of the paper). The bare lens's OTF (disc overlap) has none.
    lay = layouts.toled(pitch_um=60.0)
    p, a = lay.pitch_x_um, lay.openings[0].width_um
    # Area raster: compact support → zeros to rounding. Measured 1.4e-16.
    pg, g, _ = psfkit.display_pupil(lay, LENS, 1024, "area")
    row, lag = _otf_row(g, pg)
    ph = np.mod(lag, p)
    band = (ph > a) & (ph < p - a) & (lag < 0.9 * D)
    core = ((ph < a / 2) | (ph > p - a / 2)) & (lag < D / 2)
    assert np.max(np.abs(row[band])) < 1e-12
    assert row[core].real.min() > 0.15  # large OTF between the nulls (measured ≥ 0.245)
    # Default band-limited raster: orders beyond the raster's band (their light falls outside the
    # alias-free field) are missing, so the nulls carry a small Gibbs residue. Measured 6.7e-3.
    pg, g, _ = psfkit.display_pupil(lay, LENS, 1024)
    row_bl, lag_bl = _otf_row(g, pg)
    ph = np.mod(lag_bl, p)
    band = (ph > a) & (ph < p - a) & (lag_bl < 0.9 * D)
    assert np.max(np.abs(row_bl[band])) < 1e-2
    # Bare lens: (2/π)(arccos s − s sqrt(1 − s²)), s = Δ/D, ≥ 0.39 for Δ < D/2; no nulls.
    # Measured 6.3e-4 from the analytic (grey edge cells).
    pg, g = psfkit.bare_pupil(LENS, 1024)
    row, lag = _otf_row(g, pg)
    inside = lag < D
    s = lag[inside] / D
    np.testing.assert_allclose(row[inside].real, (2 / np.pi) * (np.arccos(s) - s * np.sqrt(1 - s * s)), atol=1e-3)
    assert row[lag < D / 2].real.min() > 0.39


# ---------------------------------------------------------------------------------------------
# 13. Method agreement
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("layout", [None, layouts.toled(pitch_um=60.0)], ids=["bare", "toled"])
def test_mft_and_chirp_z_agree(layout):
    # Same sums, two algorithms: measured 1.1e-12 (bare) and 2.6e-12 (T-OLED) of peak at float64
    # (PHYSICS asks ~1e-6); energy_outside within 1.6e-12.
    kw = dict(wavelengths_nm=[450.0, 640.0], size_px=127, pupil_samples=512, precision="float64")
    a = compute_kernels(layout, LENS, method="mft", **kw)
    b = compute_kernels(layout, LENS, method="czt", **kw)
    assert np.max(np.abs(a.kernels - b.kernels)) < 1e-9 * a.kernels.max()
    np.testing.assert_allclose(a.energy_outside, b.energy_outside, rtol=0, atol=1e-10)


def test_paper_recipe_is_off_by_about_0_12(psfkit):
    # The paper's recipe as printed (psf.paper: 2× zero pad, FFT, |·|², cubic down-sampling by the printed r)
    # vs the Gauss-Legendre pixel-integrated Airy pattern, absolute, 41×41 about the centre. It is stuck at a
    # fixed error whatever N: measured 0.115, 0.116, 0.116 of peak at N = 512, 1024, 2048, from its point
    # samples at (printed / formula) · ρ = 0.90 ρ (tests/psf/test_paper_recipe.py). The earlier recipe (area
    # down-sampling by the formula's r) was at 4.1e-4. The MFT on the same pupil: 1.2e-6.
    lam, rho, size, m = 0.55, 3.1, 255, 41
    ref = psfkit.airy_pixel_energy((np.arange(m) - m // 2) * rho, rho, LENS, lam, nodes=32)
    h = size // 2
    errs = {}
    for method in ("paper", "mft"):
        ks = compute_kernels(None, LENS, [550.0], pixel_um=rho, size_px=size, pupil_samples=1024, precision="float64",
                             method=method)
        got = (ks.kernels[0] * (1 - ks.energy_outside[0]))[h - m // 2:h + m // 2 + 1, h - m // 2:h + m // 2 + 1]
        errs[method] = np.max(np.abs(got - ref)) / ref.max()
    assert 0.1 < errs["paper"] < 0.13
    assert errs["mft"] < 2e-6


def test_ratio_r_is_the_papers_formula():
    # r = D ρ / (λ f) with N δ_N = D = 3333 µm: 2.69, 3.31, 3.83 at 640, 520, 450 nm (PHYSICS §2), reported by
    # the exact methods; the paper's table 2.41, 2.98, 3.44 (a ≈ 3.0 mm window) is what method 'paper' uses
    # (tests/psf/test_paper_recipe.py).
    ks = compute_kernels(None, LENS, [640.0, 520.0, 450.0], size_px=15, pupil_samples=64)
    np.testing.assert_allclose(ks.ratio_r, D * 3.1 / (np.array([0.64, 0.52, 0.45]) * 6000.0), rtol=1e-12)
    np.testing.assert_allclose(ks.ratio_r, [2.69, 3.31, 3.83], atol=0.006)
