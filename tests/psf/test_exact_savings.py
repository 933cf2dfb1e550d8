"""The kernel-set speed-ups of issue 13 are exact: shared per-wavelength work, the folded MFT, the field
phases shared by the display's symmetries and the half-plane power series reproduce the engine before them.
Measured values (2-core machine) are noted beside the assertions."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from psf import Lens, MicrographLayout, compute_kernels, fourier, layouts
from psf.banding import even_order_autocorrelation, order_autocorrelation
from psf.engine import PAPER_SENSOR_UM
from psf.plan import make_plan

GOLDEN = Path(__file__).parent / "golden" / "kernels_v1.npz"
WL = (450.0, 640.0)


def _micrograph():
    img = np.zeros((20, 30))
    img[3:17, 5:12] = 1.0
    img[8:12, 18:27] = 0.6
    return MicrographLayout("tile.png", 2.0, "amplitude", True, 3, img)


# Each case: (display, lens, compute_kernels arguments) at WL, 1.55 µm pixels, 21 px. GOLDEN holds their
# results from compute_kernels at commit 831aa6e, before the exact savings (per-phase complex MFT with its
# matrices rebuilt, 2-D shift ramps and ifft2, the einsum power series). The rotated micrograph's entries were
# re-made at 831aa6e with the sensor (600, 300) µm, whose shifts (20 × 10 µm at d = 0.2 mm) lie within one tile:
# there 831aa6e already spanned the sensor, as the engine now does for every aperiodic display (psf-5).
CASES = {
    "toled-d2": lambda: (layouts.toled(), Lens(), dict(distance_mm=2.0, pupil_samples=64)),
    "poled-d2": lambda: (layouts.poled(), Lens(), dict(distance_mm=2.0, pupil_samples=160)),
    "toled-defocus-area-f64": lambda: (layouts.toled(), Lens(focus_distance_mm=500.0, object_distance_mm=300.0),
                                       dict(distance_mm=1.0, field_phases=2, pupil_samples=64, mask_raster="area",
                                            precision="float64")),
    "micrograph-rotated": lambda: (_micrograph(), Lens(), dict(distance_mm=0.2, field_phases=2, pupil_samples=64,
                                                               sensor_um=(600.0, 300.0))),
    "toled-d0": lambda: (layouts.toled(), Lens(), dict(distance_mm=0.0, pupil_samples=64)),
    "toled-sensor-span": lambda: (layouts.toled(), Lens(), dict(distance_mm=2.0, field_phases=2, pupil_samples=64,
                                                                sensor_um=(200.0, 100.0))),
    "toled-czt-point": lambda: (layouts.toled(), Lens(), dict(distance_mm=2.0, field_phases=2, pupil_samples=64,
                                                              method="czt", pixel_integration=False)),
}


def _kernels(display, lens, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # aliasing warnings of the deliberately coarse pupils
        return compute_kernels(display, lens, kw.pop("wavelengths_nm", WL), pixel_um=kw.pop("pixel_um", 1.55),
                               size_px=kw.pop("size_px", 21), **kw)


@pytest.mark.parametrize("case", list(CASES))
def test_exact_savings_reproduce_the_engine_before_them(case):
    # Measured: float32 cases within 6e-7 of the peak (kernels), float64 within 1.2e-15; the power series
    # to 6e-15 relative (the rotated micrograph's raster power is float32: 4e-8).
    display, lens, kw = CASES[case]()
    ks = _kernels(display, lens, **kw)
    gold = np.load(GOLDEN)
    f64 = kw.get("precision") == "float64"
    for key in ("kernels", "field_kernels", "field_power", "transmittance", "energy_outside"):
        if f"{case}/{key}" not in gold:
            assert key.startswith("field") and getattr(ks, key) is None
            continue
        ref, got = gold[f"{case}/{key}"], getattr(ks, key).astype(np.float64)
        tol = 1e-13 if f64 else (2e-6 if key.endswith("kernels") or key == "energy_outside" else 1e-6)
        np.testing.assert_allclose(got, ref, rtol=0, atol=tol * np.abs(ref).max(), err_msg=key)


@pytest.mark.parametrize("size", [3, 21])
@pytest.mark.parametrize("integrate, deapodize", [(True, False), (False, True)])
def test_folded_pixel_mft_equals_the_complex_mft(size, integrate, deapodize):
    # The complex MFT written out: F = E_y c E_xᵀ, E = exp(−2πi u ⊗ lag δ / λz), K = 2 Re F ρ²δxδy/(λz)².
    rng = np.random.default_rng(3)
    R = rng.standard_normal((2 * 9 - 1, 7)) + 1j * rng.standard_normal((2 * 9 - 1, 7))
    dx, dy, lam, z, rho = 0.9, 1.1, 0.5, 6000.0, 1.55
    scale = lam * z
    u = (np.arange(size) - size // 2) * rho
    ly, lx = np.arange(-8, 9), np.arange(7)
    c = R.copy()
    if integrate:
        c *= np.outer(np.sinc(rho * ly * dy / scale), np.sinc(rho * lx * dx / scale))
    c[:, 0] *= 0.5
    ey, ex = np.exp(-2j * np.pi * np.outer(u, ly * dy) / scale), np.exp(-2j * np.pi * np.outer(u, lx * dx) / scale)
    ref = 2 * (ey @ c @ ex.T).real * (rho / scale) ** 2 * dx * dy
    if deapodize:
        ref /= np.outer(np.maximum(np.sinc(dy * u / scale) ** 2, np.sinc(0.5) ** 2),
                        np.maximum(np.sinc(dx * u / scale) ** 2, np.sinc(0.5) ** 2))
    got = fourier.PixelMFT(R.shape, dx, dy, lam, z, rho, size, integrate, np.complex128, deapodize)(R)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-14 * np.abs(ref).max())


def test_order_autocorrelation_is_the_direct_sum():
    rng = np.random.default_rng(5)
    c = rng.standard_normal((5, 7)) + 1j * rng.standard_normal((5, 7))
    b = order_autocorrelation(c)  # k_y = −4…4, k_x = 0…6
    assert b.shape == (9, 7)
    for ky in range(-4, 5):
        for kx in range(7):
            direct = sum(c[my + ky, mx + kx] * np.conj(c[my, mx]) for my in range(5) for mx in range(7)
                         if 0 <= my + ky < 5 and 0 <= mx + kx < 7)
            assert abs(b[ky + 4, kx] - direct) < 1e-13


def test_even_order_autocorrelation_is_the_general_one():
    # Orders even in each axis (a display symmetric about its cell's centre lines): the DCT-I route gives
    # the general FFT route's b on the quadrant, real.
    rng = np.random.default_rng(6)
    q = rng.standard_normal((4, 6)) + 1j * rng.standard_normal((4, 6))
    c = np.concatenate([q[:0:-1], q])                 # even in y: rows −3…3
    c = np.concatenate([c[:, :0:-1], c], axis=1)      # even in x: columns −5…5
    general = order_autocorrelation(c)                # k_y = −6…6, k_x = 0…10
    even = even_order_autocorrelation(c)              # k_y = 0…6, k_x = 0…10
    np.testing.assert_allclose(even, general[6:].real, rtol=0, atol=1e-12 * np.abs(general).max())
    assert np.abs(general.imag).max() < 1e-12 * np.abs(general).max()


# ---------------------------------------------------------------------------------------------
# field phases shared by the display's symmetries
# ---------------------------------------------------------------------------------------------

def _sources(display, **kw):
    args = dict(wavelengths_nm=[405.0], size_px=63, distance_mm=2.0, sensor_um=PAPER_SENSOR_UM) | kw
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return make_plan(display, Lens(), np.asarray(args.pop("wavelengths_nm")), 1.55,
                                                    args.pop("size_px"), args.pop("distance_mm"), None, "mft", 256,
                                                    "float32", True, "band_limited", args.pop("sensor_um"), []).sources


def test_phase_sources_of_the_presets():
    # T-OLED: mirror symmetric in x and y, phases i ↔ P − i per axis: 3 × 3 computed. P-OLED: the pentile's
    # inner translation (p/2, p/2) and the point reflection: 6 computed. Disorder breaks both.
    assert sum(q0 == q for q, (q0, _, _) in enumerate(_sources(layouts.toled()))) == 9
    assert sum(q0 == q for q, (q0, _, _) in enumerate(_sources(layouts.poled()))) == 6
    disordered = layouts.disordered(layouts.poled(), 2, 1.0, 0.02)
    assert all(q0 == q for q, (q0, _, _) in enumerate(_sources(disordered)))
    sources = _sources(layouts.toled())
    assert sources[3] == (1, False, True) and sources[12] == (4, True, False) and sources[15] == (5, True, True)


def test_reflected_phases_are_the_computed_ones_reflected():
    # The shared phases against the same stripe with its opening moved off centre by ε in x and y (no
    # symmetry left: every phase computed). The difference is linear in ε (measured 2.09e-8 of the peak at
    # 1 nm, 2.09e-9 at 0.1 nm), so at ε = 0 the reflected phases equal computed ones to rounding.
    from psf.layouts import PeriodicLayout, Rect
    base = layouts.toled(pitch_um=60.0)
    o = base.openings[0]
    kw = dict(wavelengths_nm=[520.0], size_px=31, pupil_samples=128, distance_mm=2.0, precision="float64")
    shared = _kernels(base, Lens(), **kw).field_kernels
    assert sum(q0 == q for q, (q0, _, _) in enumerate(_sources(base))) == 9
    errors = []
    for eps_um in (1e-3, 1e-4):
        off = PeriodicLayout("off", 60.0, 60.0, (Rect(o.cx_um + eps_um, o.cy_um + eps_um, o.width_um, o.height_um),))
        assert all(q0 == q for q, (q0, _, _) in enumerate(_sources(off)))
        full = _kernels(off, Lens(), **kw).field_kernels
        errors.append(np.abs(shared - full).max() / full.max())
    assert errors[1] < 1e-8 and 9 < errors[0] / errors[1] < 11, errors


@pytest.mark.parametrize("distance_mm", [1e-6, 1e5])
def test_stiff_distances_stay_finite(distance_mm):
    # d = 1 nm: the phases span 1e-6 of the sensor's mask shift and every field kernel is the mean;
    # d = 100 m: far beyond the Talbot length, the evanescent orders underflow to zero.
    ks = _kernels(layouts.toled(), Lens(), pupil_samples=64, distance_mm=distance_mm)
    assert np.all(np.isfinite(ks.field_kernels)) and np.all(np.isfinite(ks.field_power))
    np.testing.assert_allclose(ks.field_kernels.sum(axis=(-1, -2)), 1.0, rtol=0, atol=1e-5)
    if distance_mm < 1:
        assert np.abs(ks.field_kernels - ks.kernels[:, None, None]).max() < 1e-6
    assert np.all(np.isfinite(ks.energy_outside)) and np.all(np.isfinite(ks.transmittance))
