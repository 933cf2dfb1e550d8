"""`udc-render study banding`: the flat-field band period against z_i · p / d, the first harmonic
against psf.banding's analytic series, the files; and the fit on synthetic profiles."""
import csv
import math

import numpy as np
import pytest

from udc_render.cli import main
from udc_render.optics import displays as D
from udc_render.scene.geometry import psf_lens
from udc_render.studies import banding as B
from udc_render.studies import banding_fit as F


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    """The quick study through the CLI (one run for the module: ~40 s on 2 cores), its rows from the CSV."""
    out = tmp_path_factory.mktemp("banding")
    assert main(["study", "banding", "--out", str(out), "--quick"]) == 0
    with open(out / "study_banding.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return out, rows


def _num(v: str) -> float:
    return float(v) if v not in ("", None) else math.nan


def test_quick_study_writes_its_files(quick):
    out, rows = quick
    for name in ("study_banding.csv", "study_banding.md", "study_banding.png"):
        assert (out / name).stat().st_size > 0
    assert list(rows[0]) == F.COLUMNS
    assert {r["display"] for r in rows} == {"toled", "poled"}
    md = (out / "study_banding.md").read_text()
    assert "visible per pixel" in md and "sinc²" in md


def test_flat_field_period_is_zi_p_over_d(quick):
    """T-OLED bands on the flat field, along x and along y: the fitted period (found without the formula)
    within 1 % of z_i · p / d, z_i from the quick scene's lens (portrait for y) and p from the preset."""
    _, rows = quick
    w, h = B.QUICK["sensor"]
    z_i = {"x": psf_lens(B.flat_field_scene(B.QUICK)).image_distance_um,
           "y": psf_lens(B.flat_field_scene({**B.QUICK, "sensor": (h, w)})).image_distance_um}
    px, py = D.preset("toled").layout.period_um
    checked = set()
    for r in rows:
        if r["display"] != "toled" or r["regime"] != "bands":
            continue
        p = px if r["axis"] == "x" else py
        expected = z_i[r["axis"]] * p / (float(r["distance_mm"]) * 1000.0)
        assert int(r["harmonic_order"]) == 1
        assert abs(float(r["period_fit_um"]) / expected - 1) < 0.01
        checked.add((r["axis"], r["field_phases"]))
    assert checked == {("x", "4"), ("x", "2"), ("y", "4")}


def test_amplitude_ratio_to_the_analytic_series(quick):
    """The measured first harmonic over the analytic one of P(s) (bands along x): finite, in (0, 1.2];
    the phase interpolation alone explains most of the difference (the ratio to it is nearer 1, along
    y too, where the interpolation adds first harmonic instead of removing it)."""
    _, rows = quick
    for r in rows:
        if r["display"] != "toled" or r["regime"] != "bands":
            continue
        ratio, to_interp = float(r["ratio_measured_analytic"]), float(r["ratio_measured_interpolated"])
        if r["axis"] == "x":
            assert math.isfinite(ratio) and 0 < ratio <= 1.2
        assert abs(to_interp - 1) < abs(ratio - 1)
        assert float(r["a1_dn"]) > 0 and float(r["sigma_dn"]) > 0
        assert (r["visible_pixel"] == "True") == (float(r["a1_dn"]) >= float(r["sigma_dn"]))


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
        assert abs(a1 - F.sinc2(1, P)) < 1e-4
