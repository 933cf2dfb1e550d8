"""Wavefront aberrations of the lens (psf.zernike, psf.lens.Lens.zernike_waves): the polynomials, the pupil
phase, the Strehl ratio against Maréchal and an exact quadrature, the cache key, extremes and bad values."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from psf import Lens, compute_kernels, layouts, zernike
from psf.cache import cache_key
from psf.engine import AliasingWarning
from psf.lens import LensError
from psf.plan import _mirror_symmetries, make_plan, validate_request
from psf.pupil import lens_grid

TERMS_TO_6 = [(n, m) for n in range(2, 7) for m in range(-n, n + 1, 2)]


def _disc_quadrature(nodes: int = 64):
    """(ρ, θ, weights) of a product rule on the unit disc, weights summing to 1 (the mean over the disc):
    Gauss–Legendre in ρ² (exact for polynomials in ρ² of degree < nodes), uniform in θ (4 nodes per order)."""
    u, w = np.polynomial.legendre.leggauss(nodes)
    rho = np.sqrt((u + 1) / 2)
    theta = np.arange(4 * nodes) * 2 * math.pi / (4 * nodes)
    return rho[:, None], theta[None, :], (w / 2)[:, None] * np.full((1, theta.size), 1 / theta.size)


def test_zernike_terms_are_orthonormal_over_the_disc():
    """(1/π) ∫ Z_j Z_k dA = δ_jk for every term up to n = 6 (OSA/ANSI normalisation: each has RMS 1)."""
    rho, theta, w = _disc_quadrature()
    z = np.stack([zernike.zernike(n, m, rho, theta) for n, m in TERMS_TO_6])
    gram = np.einsum("jab,kab,ab->jk", z, z, w)
    np.testing.assert_allclose(gram, np.eye(len(TERMS_TO_6)), atol=1e-10)
    np.testing.assert_allclose(np.einsum("jab,ab->j", z, w), 0, atol=1e-12)  # n ≥ 1: zero mean


@pytest.mark.parametrize("terms", [((4, 0, 0.05),), ((3, -1, 0.02),), ((2, 2, 0.03), (4, 0, 0.04), (6, 0, 0.01))])
def test_pupil_phase_rms_equals_the_coefficients(terms):
    """The lens's optical path over the engine's pupil grid (area-weighted aperture) has RMS λ_ref √Σa²,
    and the pupil phase is exp(2πi W / λ)."""
    lens = Lens(zernike_waves=terms)
    g = lens_grid(lens, 1024)
    area = lens.aperture_area_fraction(g.x_edges_um, g.y_edges_um)
    w_um = lens.wavefront_um(g.x_um, g.y_um)
    mean = np.sum(area * w_um) / area.sum()
    rms_waves = math.sqrt(np.sum(area * (w_um - mean) ** 2) / area.sum()) / (zernike.REFERENCE_NM * 1e-3)
    assert rms_waves == pytest.approx(zernike.rms_waves(terms), rel=1e-4)  # measured ≤ 2.4e-5 (the grey edge)
    lam_um = 0.45
    np.testing.assert_allclose(lens.pupil_phase(g.x_um, g.y_um, lam_um), np.exp(2j * math.pi * w_um / lam_um),
                               atol=1e-12)


def _strehl_engine(terms, lam_nm=550.0):
    """The centre value of the point-sampled kernel (× the window's share of the power) over the
    diffraction-limited one's."""
    def centre(lens):
        k = compute_kernels(None, lens, [lam_nm], pixel_um=0.5, size_px=63, pixel_integration=False,
                            precision="float64")
        return k.kernels[0, 31, 31] * (1 - k.energy_outside[0])
    return centre(Lens(zernike_waves=terms)) / centre(Lens())


def _strehl_exact(terms, lam_nm=550.0):
    """|mean over the disc of exp(2πi W / λ)|² by quadrature (the on-axis intensity ratio, Born & Wolf §9.1)."""
    rho, theta, w = _disc_quadrature(96)
    phase = 2 * math.pi * zernike.wavefront(terms, rho, theta) * zernike.REFERENCE_NM / lam_nm
    return abs(np.sum(w * np.exp(1j * phase))) ** 2


@pytest.mark.parametrize("terms", [((4, 0, 0.03),), ((4, 0, 0.05),), ((3, 1, 0.05),), ((2, -2, 0.04),),
                                   ((4, 0, 0.2),)])
def test_strehl_against_quadrature_and_marechal(terms):
    """The engine's Strehl equals the exact |⟨e^{iφ}⟩|² to 2e-5 (measured ≤ 5.2e-6; it was 0.2 %) and, for
    σ ≤ 0.05 wave, Maréchal's exp(−(2πσ)²) to 0.2 % (the approximation's own error: measured ≤ 0.07 %; it was
    1 %); at 450 nm the same path is 550/450 of the waves."""
    sigma = zernike.rms_waves(terms)
    s = _strehl_engine(terms)
    assert s == pytest.approx(_strehl_exact(terms), rel=2e-5)
    if sigma <= 0.05:
        assert s == pytest.approx(math.exp(-(2 * math.pi * sigma) ** 2), rel=2e-3)
    else:
        assert s < math.exp(-(2 * math.pi * 0.05) ** 2)
    if terms == ((4, 0, 0.05),):
        assert _strehl_engine(terms, 450.0) == pytest.approx(_strehl_exact(terms, 450.0), rel=2e-5)
        assert _strehl_engine(terms, 450.0) < s


def test_no_aberration_is_bit_identical_and_keeps_the_cache_key():
    """() and zero coefficients are the diffraction-limited lens: the same kernels, bit for bit (defocused
    and at d > 0 too), the same description and cache key; an aberration changes the key."""
    kw = dict(pixel_um=3.1, size_px=31, pupil_samples=256)
    for lens, display, d in ((Lens(), None, 0.0), (Lens(focus_distance_mm=500, object_distance_mm=300), None, 0.0),
                             (Lens(), layouts.toled(), 2.0)):
        zero = Lens(lens.focal_length_um, lens.aperture_um, lens.focus_distance_mm, lens.object_distance_mm,
                    ((4, 0, 0.0), (3, 1, 0)))
        assert zero == lens and zero.describe() == lens.describe()
        a = compute_kernels(display, lens, [550.0], distance_mm=d, field_phases=2, **kw)
        b = compute_kernels(display, zero, [550.0], distance_mm=d, field_phases=2, **kw)
        np.testing.assert_array_equal(a.kernels, b.kernels)
        assert cache_key("mono", display, lens, size_px=31) == cache_key("mono", display, zero, size_px=31)
    ab = Lens(zernike_waves=((4, 0, 0.05),))
    assert cache_key("mono", None, ab, size_px=31) != cache_key("mono", None, Lens(), size_px=31)
    assert Lens(**ab.describe()) == ab and ab.describe()["zernike_waves"] == [[4, 0, 0.05]]


def test_asymmetric_aberrations_drop_the_mirror_shortcut():
    """Field phases are reflected copies only under mirrors the pupil keeps: coma along x is odd in x, so
    x → −x is no longer a symmetry; spherical aberration keeps every mirror."""
    def mirrors(terms):
        wl = validate_request([550.0], 3.1, 31, 2.0, 2, "mft", "float32", 256, "band_limited")
        plan = make_plan(layouts.toled(), Lens(zernike_waves=terms), wl, 3.1, 31, 2.0, 2, "mft", 256, "float32", True,
                         "band_limited", (3174.4, 1587.2), [])
        return set(_mirror_symmetries(plan))
    assert (False, True) in mirrors(()) and (False, True) in mirrors(((4, 0, 0.05),))
    assert (False, True) not in mirrors(((3, 1, 0.05),)) and (True, False) in mirrors(((3, 1, 0.05),))


def test_extreme_aberrations_stay_finite_and_sample_the_phase():
    """The largest allowed wavefront (1 wave RMS, n up to 10) gives finite unit-sum kernels; the automatic
    pupil sampling keeps the phase step below π; too few samples given are warned about."""
    for terms in (((4, 0, 1.0),), ((10, 0, 0.7), (9, 3, 0.7))):
        lens = Lens(zernike_waves=terms)
        with warnings.catch_warnings():
            warnings.simplefilter("error", AliasingWarning)
            k = compute_kernels(None, lens, [450.0], pixel_um=3.1, size_px=63)
        assert np.all(np.isfinite(k.kernels)) and k.kernels.sum() == pytest.approx(1, abs=1e-5)
        assert 0 <= k.energy_outside[0] < 1
        step = lens.aperture_um / k.params["pupil_samples"]
        assert lens.max_phase_slope() * step <= 0.45 / 2
    with pytest.warns(AliasingWarning, match="aberrations"):
        compute_kernels(None, Lens(zernike_waves=((10, 0, 1.0),)), [450.0], pixel_um=3.1, size_px=31, pupil_samples=64)


@pytest.mark.parametrize("bad", [((1, 1, 0.1),), ((4, 1, 0.1),), ((4, 6, 0.1),), ((12, 0, 0.1),), ((4, 0, math.nan),),
                                 ((4, 0, 1.5),), ((4, 0, 0.1), (4, 0, 0.2)), ((4, 0),), "4,0,0.1", ((4.0, 0, 0.1),)])
def test_bad_terms_are_one_line_errors(bad):
    with pytest.raises(LensError, match=r"zernike_waves = .*: expected a list of \[n, m, waves") as e:
        Lens(zernike_waves=bad)
    assert "\n" not in str(e.value)
