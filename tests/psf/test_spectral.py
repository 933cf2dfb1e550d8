"""Band and channel kernels: weighting, normalisation, convergence in the wavelength step."""
import numpy as np
import pytest

from psf import Lens, compute_kernels, layouts
from psf.engine import PSFError
from psf.spectral import band_kernels, band_samples, channel_kernels


def test_band_samples_cover_the_band_with_midpoints():
    lam, dl = band_samples(400, 500, 3.0)
    assert lam.size == 34 and np.isclose(dl.sum(), 100) and lam[0] > 400 and lam[-1] < 500
    assert np.all(np.diff(lam) <= 3.0)


def test_single_sample_band_equals_monochromatic_kernel():
    disp = layouts.toled(pitch_um=60.0)
    band = band_kernels(disp, Lens(), [(500, 540)], step_nm=40, size_px=63, precision="float64")
    mono = compute_kernels(disp, Lens(), [520], size_px=63, precision="float64")
    np.testing.assert_allclose(band.kernels, mono.kernels, atol=1e-14)
    np.testing.assert_allclose(band.energy_outside, mono.energy_outside, atol=1e-14)


def test_band_kernel_is_power_weighted_mean_and_converges():
    disp = layouts.toled(pitch_um=60.0)
    ref = band_kernels(disp, Lens(), [(500, 600)], step_nm=2, size_px=63, pupil_samples=512)
    errs = [np.abs(band_kernels(disp, Lens(), [(500, 600)], step_nm=s, size_px=63, pupil_samples=512).kernels
                   - ref.kernels).sum() for s in (50, 10, 5)]
    assert errs[0] > errs[1] > errs[2]
    np.testing.assert_allclose(ref.kernels.sum(), 1.0, atol=1e-5)


def test_weight_spectrum_shifts_band_towards_its_weight():
    disp = layouts.toled(pitch_um=60.0)
    blue = band_kernels(disp, Lens(), [(450, 650)], step_nm=20, size_px=63, weight=lambda nm: (nm < 500) * 1.0 + 1e-9)
    mono = compute_kernels(disp, Lens(), [475], size_px=63)
    red = band_kernels(disp, Lens(), [(450, 650)], step_nm=20, size_px=63, weight=lambda nm: (nm > 600) * 1.0 + 1e-9)
    assert np.abs(blue.kernels - mono.kernels).sum() < np.abs(red.kernels - mono.kernels).sum()


def test_channel_kernels_for_a_builtin_camera():
    ks = channel_kernels(layouts.poled(), Lens(), step_nm=20, size_px=31, pupil_samples=256)
    assert ks.kernels.shape == (3, 31, 31) and ks.params["channels"] == ["red", "green", "blue"]
    r, g, b = ks.wavelengths_nm
    assert r > g > b  # effective centre wavelengths in channel order
    np.testing.assert_allclose(ks.kernels.sum(axis=(1, 2)), 1.0, atol=1e-5)
    assert any("skipped" in n for n in ks.notes)


def test_channel_kernels_from_csv_and_bad_csv(tmp_path):
    csv = tmp_path / "cam.csv"
    csv.write_text("wavelength_nm,mono\n500,0\n520,1\n540,0\n")
    ks = channel_kernels(None, Lens(), camera=str(csv), step_nm=5, size_px=31, pupil_samples=128)
    assert ks.params["channels"] == ["mono"] and abs(ks.wavelengths_nm[0] - 520) < 1
    bad = tmp_path / "bad.csv"
    bad.write_text("wavelength_nm,c\n540,1\n520,1\n")
    with pytest.raises(PSFError, match="increasing wavelengths"):
        channel_kernels(None, Lens(), camera=str(bad))
