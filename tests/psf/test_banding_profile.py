"""The fine banding profile agrees with the engine's per-phase transmitted power, and has
the period z_i p / d on the sensor."""
import numpy as np

from psf import Lens, compute_kernels, layouts
from psf.banding import banding_profile


def test_profile_matches_field_power_ratios():
    disp, d = layouts.toled(pitch_um=60.0), 1.0
    ks = compute_kernels(disp, wavelengths_nm=[520], distance_mm=d, field_phases=4, size_px=15, precision="float64",
                         pupil_samples=512)
    z = Lens().image_distance_um
    x = np.arange(4) * disp.pitch_x_um / 4 * z / (d * 1000)
    _, p = banding_profile(disp, wavelength_nm=520, distance_mm=d, positions_um=x)
    row = ks.field_power[0, 0]
    np.testing.assert_allclose(p / p.mean(), row / row.mean(), rtol=1e-12)


def test_profile_period_is_z_p_over_d():
    disp = layouts.poled()
    for d in (0.5, 2.0):
        period = Lens().image_distance_um * disp.pitch_x_um / (d * 1000)
        x = np.linspace(0, period, 64, endpoint=False)
        _, a = banding_profile(disp, distance_mm=d, positions_um=x)
        _, b = banding_profile(disp, distance_mm=d, positions_um=x + period)
        np.testing.assert_allclose(a, b, rtol=1e-10)
        assert a.max() - a.min() > 1e-7  # there is banding to see
