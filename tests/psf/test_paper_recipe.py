"""The paper's PSF recipe as printed (psf.paper: printed r, cubic down-sampling), `psf --method paper`.

Measured values (2-core machine, float64) are noted beside each assertion.
"""
from __future__ import annotations

import numpy as np
import pytest

from psf import Lens, compute_kernels, layouts
from psf.paper import PRINTED_R, _cubic_samples, formula_ratio_r, paper_ratio_r

LENS = Lens()
WAVELENGTHS_NM = [640.0, 520.0, 450.0]  # R, G, B (l.263)
S, H = 127, 63


def _paper(layout):
    return compute_kernels(layout, LENS, WAVELENGTHS_NM, method="paper", precision="float64", size_px=S)


def _points(layout, lam_nm: float, pixel_um: float) -> np.ndarray:
    """ρ² I(u_j) by the exact MFT, unit sum on the window."""
    return compute_kernels(layout, LENS, [lam_nm], pixel_um=pixel_um, method="mft", pixel_integration=False,
                           precision="float64", size_px=S).kernels[0]


def test_r_is_the_printed_one_on_the_papers_rig():
    # The formula's r = D ρ / (λ f) from the rig's numbers written out (D 3333 µm, f 6000 µm, ρ 3.1 µm):
    # 2.69, 3.31, 3.83 (docs/PHYSICS.md §2).
    formula = [3333.0 * 3.1 / (lam * 1e-3 * 6000.0) for lam in WAVELENGTHS_NM]
    np.testing.assert_allclose([formula_ratio_r(lam, LENS, 3.1) for lam in WAVELENGTHS_NM], formula, rtol=1e-12)
    np.testing.assert_allclose(formula, [2.69, 3.31, 3.83], atol=0.006)
    # The printed r are one window of ≈ 3.0 mm, not the aperture's 3333 µm: r λ f / ρ = 2985, 2999, 2996 µm
    # (the module's "as if the sampled window were ≈ 3.0 mm"; printed / formula = 0.896, 0.900, 0.899).
    printed = [2.41, 2.98, 3.44]
    assert sorted(PRINTED_R.items()) == [(450.0, 3.44), (520.0, 2.98), (640.0, 2.41)]
    window_um = [r * lam * 1e-3 * 6000.0 / 3.1 for r, lam in zip(printed, WAVELENGTHS_NM)]
    np.testing.assert_allclose(window_um, 3000.0, rtol=5e-3)
    ks = compute_kernels(None, LENS, WAVELENGTHS_NM, method="paper", size_px=15, pupil_samples=64)
    np.testing.assert_allclose(ks.ratio_r, printed, rtol=1e-12)
    # Between the printed wavelengths the ratio printed / formula is linear in λ: at 580 nm, midway between
    # 520 and 640, r = (2.98 · 520 + 2.41 · 640) / (2 · 580) = 2.66552; beyond them the nearest ratio is kept,
    # r ∝ 1/λ: 3.44 · 450 / 400 = 3.87 and 2.41 · 640 / 700 = 2.20343.
    assert paper_ratio_r(580.0, LENS, 3.1) == pytest.approx((2.98 * 520 + 2.41 * 640) / (2 * 580), rel=1e-12)
    assert paper_ratio_r(400.0, LENS, 3.1) == pytest.approx(3.44 * 450 / 400, rel=1e-12)
    assert paper_ratio_r(700.0, LENS, 3.1) == pytest.approx(2.41 * 640 / 700, rel=1e-12)
    # Another rig keeps the ratio: r scales as D ρ / f (here 2000 µm, 1.55 µm, 4000 µm: × 0.45005)
    other = Lens(focal_length_um=4000.0, aperture_um=2000.0)
    want = (2.98 * 520 + 2.41 * 640) / (2 * 580) * (2000.0 / 3333.0) * (1.55 / 3.1) * (6000.0 / 4000.0)
    assert paper_ratio_r(580.0, other, 1.55) == pytest.approx(want, rel=1e-12)


@pytest.mark.parametrize("layout,tol,off", [(None, 2.5e-3, None), (layouts.toled(), 1.5e-2, 0.3)],
                         ids=["bare", "toled"])
def test_kernel_is_the_pattern_sampled_at_printed_over_formula_pitch(layout, tol, off):
    # Down-sampling by the printed r = sampling the true pattern at (printed / formula) · ρ. Against the MFT's
    # point samples there, max error of peak: bare 1.9e-3, 7.9e-4, 5.7e-4; T-OLED 1.3e-2, 2.8e-3, 6.2e-3 (the
    # cubic spline on the 2×-padded DFT, which samples the intensity at its Nyquist rate). At ρ itself (the
    # formula's r) the T-OLED's orders land elsewhere: 0.56, 0.40, 0.65.
    ks = _paper(layout)
    c = slice(H - 20, H + 21)
    for k, lam, r in zip(ks.kernels, WAVELENGTHS_NM, ks.ratio_r):
        s = r / formula_ratio_r(lam, LENS, 3.1)
        at_s = _points(layout, lam, 3.1 * s)
        assert np.max(np.abs(k[c, c] - at_s[c, c])) < tol * at_s.max()
        if off is not None:
            at_rho = _points(layout, lam, 3.1)
            assert np.max(np.abs(k[c, c] - at_rho[c, c])) > off * at_rho.max()


def test_kernels_are_wider_by_formula_over_printed():
    # Second moment Σ k |j|² (pixels²) of the bare lens against the MFT's point samples at ρ: the square root of
    # the ratio is 1.156, 1.137, 1.134 (formula / printed = 1.116, 1.111, 1.112; the window truncates the
    # Airy tails, whose second moment diverges: the MFT at (printed / formula)·ρ against ρ gives 1.176, 1.170,
    # 1.172). Narrower kernels (r > formula) or the formula's r would give ≤ 1.
    ks = _paper(None)
    y, x = np.mgrid[-H:H + 1, -H:H + 1]
    r2 = x ** 2 + y ** 2
    for k, lam, r in zip(ks.kernels, WAVELENGTHS_NM, ks.ratio_r):
        ref = _points(None, lam, 3.1)
        ratio = np.sqrt((k * r2).sum() / (ref * r2).sum())
        assert formula_ratio_r(lam, LENS, 3.1) / r < ratio < 1.2


def test_kernels_are_unit_sum_finite_and_non_negative():
    ks = _paper(layouts.toled())
    assert np.all(np.isfinite(ks.kernels)) and ks.kernels.min() >= 0
    np.testing.assert_allclose(ks.kernels.sum(axis=(1, 2)), 1.0, rtol=1e-12)
    assert np.all((ks.energy_outside > 0) & (ks.energy_outside < 0.05))  # the power on the window's DFT cells
    assert ks.params["method"] == "paper"


def test_the_cubic_is_skimages_order_3():
    # _cubic_samples = skimage.transform.warp(order=3, clip=True) at the same coordinates (the interpolant of
    # skimage's resize and rescale at order 3), to rounding.
    transform = pytest.importorskip("skimage.transform")
    rng = np.random.default_rng(0)
    image = rng.random((64, 64)) ** 4
    got = _cubic_samples(image, 2.41, 2.98, 9)
    j = np.arange(9) - 4
    coords = np.stack(np.meshgrid(32 + j * 2.41, 32 + j * 2.98, indexing="ij"))
    want = transform.warp(image, coords, order=3, mode="wrap", clip=True, preserve_range=True)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
