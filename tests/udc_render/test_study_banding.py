"""`udc-render study banding`: the flat-field band period against z_i · p / d, the first harmonic
against psf.banding's exact series (the default power) and the interpolated powers, the files; and the
fit and the kernels' OTF on synthetic input."""
import csv
import math

import numpy as np
import pytest

from psf.banding import PowerSeries
from psf.engine import DEFAULT_FIELD_PHASES
from udc_render.cli import main
from udc_render.optics import displays as D
from udc_render.pipeline import SynthConfig
from udc_render.scene.geometry import psf_lens
from udc_render.studies import banding as B, banding_fit as F


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    """The quick study through the CLI (one run for the module: 1.5–3 min on 2 loaded cores), its rows from the CSV."""
    out = tmp_path_factory.mktemp("banding")
    assert main(["study", "banding", "--out", str(out), "--quick"]) == 0
    with open(out / "study_banding.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return out, rows


def _num(v: str) -> float:
    return float(v) if v not in ("", None) else math.nan


@pytest.mark.slow
def test_quick_study_writes_its_files(quick):
    out, rows = quick
    for name in ("study_banding.csv", "study_banding.md", "study_banding.png"):
        assert (out / name).stat().st_size > 0
    assert list(rows[0]) == F.COLUMNS
    assert {r["display"] for r in rows} == {"toled", "poled"}
    md = (out / "study_banding.md").read_text()
    assert "visible per pixel" in md and "sinc²" in md and "Cost of the exact series" in md


def _toled_rows(rows):
    return [r for r in rows if r["display"] == "toled" and r["regime"] == "bands"]


@pytest.mark.slow
def test_flat_field_period_is_zi_p_over_d(quick):
    """T-OLED bands on the flat field, along x and along y, every phase count and power: the fitted period
    (found without the formula) times its harmonic order within 1 % of z_i · p / d, z_i from the quick
    scene's lens (portrait for y) and p from the preset; the order the fit finds is the strongest harmonic
    of the exact series (× the kernels' OTF) on the frame's rows: the first along x, the second along y
    (test_toled_along_y_the_frame_sees_the_second_harmonic)."""
    _, rows = quick
    w, h = B.QUICK["sensor"]
    z_i = {"x": psf_lens(B.flat_field_scene(B.QUICK)).image_distance_um,
           "y": psf_lens(B.flat_field_scene({**B.QUICK, "sensor": (h, w)})).image_distance_um}
    px, py = D.preset("toled").layout.period_um
    checked = set()
    for r in _toled_rows(rows):
        p = px if r["axis"] == "x" else py
        expected = z_i[r["axis"]] * p / (float(r["distance_mm"]) * 1000.0)
        order = int(r["harmonic_order"])
        assert order == int(r["analytic_order"]) == {"x": 1, "y": 2}[r["axis"]]
        assert abs(float(r["period_fit_um"]) * order / expected - 1) < 0.01
        checked.add((r["axis"], r["field_phases"], r["field_power"], r["field_rank"]))
    r0 = str(SynthConfig().field_rank)
    assert checked == {("x", "4", "series", r0), ("x", "4", "series", "2"), ("x", "4", "series", "all"),
                       ("x", "2", "series", r0), ("x", "2", "interpolated", r0), ("x", "4", "interpolated", r0),
                       ("y", "4", "series", r0)}


def test_toled_along_y_the_frame_sees_the_second_harmonic():
    """psf.banding alone, 550 nm, d = 6 mm: bands along y averaged over the quick portrait frame's Gr columns
    (their mask shifts span 0.31 of the 317 µm cell along x) have harmonic 2 above harmonic 1 (the
    harmonic_order 2 of the quick study's y row is the series', not the synthesis'); averaged over a whole
    cell along x, harmonic 1 is the larger (the series is not separable in x and y)."""
    w, h = B.QUICK["sensor"]
    scene = B.flat_field_scene({**B.QUICK, "sensor": (h, w)})
    lens, d_um = psf_lens(scene), 6000.0
    layout = D.preset("toled").layout
    series = PowerSeries(layout, lens, 0.55, d_um)
    frame_x_um = F.site_positions_um((w, h), scene.sensor.pitch_um)[0] * d_um / lens.image_distance_um
    whole_x_um = np.arange(64) * layout.period_um[0] / 64

    def harmonics(x_um):
        s = np.stack(np.broadcast_arrays(x_um[:, None], (np.arange(64) * layout.period_um[1] / 64)[None, :]), -1)
        spec = np.abs(np.fft.rfft(series(s).mean(axis=0)))
        return spec[1] / spec[0], spec[2] / spec[0]

    h1, h2 = harmonics(frame_x_um)
    assert 0.25 < np.ptp(frame_x_um) / layout.period_um[0] < 0.4
    assert h2 > 2 * h1
    h1, h2 = harmonics(whole_x_um)
    assert h1 > 2 * h2


@pytest.mark.slow
def test_first_harmonic_against_the_exact_series(quick):
    """T-OLED, the blend's power from the exact series (optics.field_power), quick rig: along x with 4 phases,
    at the default field rank and with every phase kernel (rank 'all'), the measured harmonic is within 5 % of
    the exact series P(s) (6 mm: rank 4 0.98, all 0.97), nearer it than the phase-averaged kernel's smoothing
    (series × OTF, 'expected'; MTF 0.87). Where the kernels' phase-dependent shape is lost, the harmonic sits
    nearer that smoothing than the series: a rank-2 basis drops it (0.87 of the series, 1.00 of expected),
    2 phases keep sinc²(1/2) = 0.41 of it (0.88, 1.01), and along y the second harmonic is the Nyquist
    frequency of 4 phases (0.88, 0.95). The interpolated powers (the blend before the series, same kernels)
    give below 0.8 of the series (0.76 at P = 4, 0.68 at P = 2) and follow P(s) interpolated alone instead."""
    _, rows = quick
    ranks = set()
    for r in _toled_rows(rows):
        to_series, to_expected = float(r["ratio_measured_analytic"]), float(r["ratio_measured_expected"])
        to_interp = float(r["ratio_measured_interpolated"])
        assert 0.8 < float(r["psf_mtf"]) < 1.0
        if r["field_power"] == "interpolated":
            assert to_series < 0.8
            assert abs(to_interp - 1) < abs(to_series - 1)
        elif r["field_rank"] == "2" or r["field_phases"] == "2" or r["axis"] == "y":
            assert abs(to_expected - 1) < abs(to_series - 1), (r["axis"], r["field_phases"], r["field_rank"])
            assert abs(to_expected - 1) <= 0.05 or r["axis"] == "y"
        else:
            assert abs(to_series - 1) <= 0.05, (r["field_rank"], to_series)
            assert abs(to_series - 1) < abs(to_expected - 1)
        ranks.add(r["field_rank"])
        assert float(r["a1_dn"]) > 0 and float(r["sigma_dn"]) > 0
        assert (r["visible_pixel"] == "True") == (float(r["a1_dn"]) >= float(r["sigma_dn"]))
    assert ranks == {"2", str(SynthConfig().field_rank), "all"}


@pytest.fixture(scope="module")
def default_rig():
    """The quick study's rig (512 × 64 px, 3 bands, the default margin), bands along x, the default
    SynthConfig (kernels with the cache off; the study's own base turns the stray light off)."""
    return B.Rig(B.QUICK, "x", SynthConfig(use_cache=False))


def _default_ratio(rig, distance_mm: float) -> float:
    """study banding's measure of the T-OLED at distance_mm with the default SynthConfig: first harmonic / P(s)."""
    row, _, _ = B.measure(rig, "toled", distance_mm, None)
    assert (row["field_phases"], row["field_rank"]) == (DEFAULT_FIELD_PHASES, SynthConfig().field_rank)
    assert row["harmonic_order"] == 1
    return row["ratio_measured_analytic"]


def test_default_settings_band_within_5_percent_of_the_exact_series(default_rig):
    """The DEFAULT SynthConfig (no knob set: 4 field phases, its field rank, blend 'source', the power from the
    exact series) on a small T-OLED flat field (the quick rig), d = 16 mm, where the rank
    matters most: the first harmonic along x within 5 % of the exact series P(s) (rank 4: 0.97; a rank-2 basis
    gives 0.65, test_default_settings_band_at_4_and_8_mm). About 30 s."""
    ratio = _default_ratio(default_rig, 16.0)
    assert abs(ratio - 1) < 0.05, ratio


@pytest.mark.slow
@pytest.mark.parametrize("distance_mm", [4.0, 8.0])
def test_default_settings_band_at_4_and_8_mm(default_rig, distance_mm):
    """The same at 4 and 8 mm (rank 4: 1.00 at 8 mm), and the check can fail: a rank-2 basis on the same
    kernels gives 0.84 at 8 mm. About 40 s each: `pytest -m slow tests/udc_render/test_study_banding.py`."""
    ratio = _default_ratio(default_rig, distance_mm)
    assert abs(ratio - 1) < 0.05, ratio
    if distance_mm == 8.0:
        rank2, _, _ = B.measure(default_rig, "toled", distance_mm, None, rank=2)
        assert rank2["ratio_measured_analytic"] < 0.9


def test_kernel_otf_of_a_gaussian():
    """kernel_otf of a sampled Gaussian kernel (σ = 2 px, 1.5 µm pixels) at T = 30 µm: e^{−2π²σ²/T²} per
    harmonic, along either axis (a kernel shifted by one pixel gains the phase e^{−2πi h · 1.5 / T})."""
    u = np.arange(31) - 15
    g = np.exp(-(u[:, None] ** 2 + u[None, :] ** 2) / (2 * 2.0 ** 2))
    k = np.stack([g / g.sum(), np.roll(g, 1, axis=1) / g.sum()])
    sigma_um, T = 2.0 * 1.5, 30.0
    h = np.arange(1, 4)
    gauss = np.exp(-2 * np.pi ** 2 * sigma_um ** 2 * h ** 2 / T ** 2)
    otf_x = F.kernel_otf(k, 1.5, T, "x", 3)
    np.testing.assert_allclose(otf_x[0], gauss, rtol=1e-9)
    np.testing.assert_allclose(otf_x[1], gauss * np.exp(-2j * np.pi * h * 1.5 / T), rtol=1e-9)
    np.testing.assert_allclose(F.kernel_otf(k, 1.5, T, "y", 3)[1], gauss, rtol=1e-9)


def test_fit_period_recovers_a_synthetic_band_profile():
    """A sinusoid with harmonics and noise-free offset: period to 1e-4, first harmonic to 1e-3."""
    x = (np.arange(256) - 127.5) * 3.1
    period = 301.7
    y = 1 + 0.01 * np.cos(2 * np.pi * x / period + 0.4) + 0.004 * np.cos(4 * np.pi * x / period - 1.0)
    fit, amps = F.fit_period(x, y)
    assert abs(fit / period - 1) < 1e-4
    assert abs(amps[1] / 0.01 - 1) < 1e-3 and abs(amps[2] / 0.004 - 1) < 1e-3


def test_sinc2_is_the_linear_interpolation_factor():
    """Linear interpolation of cos(2πu) between P samples per period keeps sinc²(1/P) of it (P ≥ 3)."""
    for P in (3, 4, 6):
        u = np.arange(4096) / 4096
        interp = np.interp(u, np.arange(P + 1) / P, np.cos(2 * np.pi * np.arange(P + 1) / P))
        a1 = 2 * abs(np.fft.rfft(interp)[1]) / u.size
        assert abs(a1 - F.sinc2(1, P)) < 5e-7  # measured ≤ 1.6e-7: the 4096-point grid
