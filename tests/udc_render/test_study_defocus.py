"""The defocus study (udc_render/studies/defocus.py): its analytic pieces against closed forms, the
engine's defocused kernels against the thin lens and the diffraction limit, and the quick run's files."""
import csv
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from psf import layouts
from udc_render.studies import defocus as D, defocus_measures as M

V_F = M.focus_vergence_per_m()


def kernel(display, vergence_per_m, size_px=127, wavelength_nm=520.0, pupil_samples=256):
    cfg = M.Config(True, (wavelength_nm,), size_px, pupil_samples, (), ())
    return D.through_focus_kernels(display, vergence_per_m, cfg).kernels[0]


# ----------------------------------------------------------------------------------------------
# Closed forms


def test_geometric_coc_is_thin_lens_formula():
    lens = M.lens_at(V_F + 1.0)  # 1 m⁻¹ of defocus
    z_i = 1 / (1 / 6000.0 - 1 / 500e3)  # µm
    assert M.geometric_coc_px(lens) == pytest.approx(3333.0 * z_i * 1e-6 / 1.55, rel=1e-12)
    assert M.geometric_coc_px(M.lens_at(V_F)) == 0.0
    far, near = M.geometric_dof_vergence_per_m(M.lens_at(V_F), coc_px=2.0)
    assert M.geometric_coc_px(M.lens_at(near)) == pytest.approx(2.0, rel=1e-9)
    assert M.geometric_coc_px(M.lens_at(far)) == pytest.approx(2.0, rel=1e-9)


def test_disc_edge_width_tends_to_semicircle_constant():
    # A disc's LSF is a semicircle: its 10–90 % width is 2 t b / 2 with t√(1−t²) + asin t = 0.4 π.
    t = brentq(lambda t: t * math.sqrt(1 - t * t) + math.asin(t) - 0.4 * math.pi, 0.0, 1.0)
    for b in (60.0, 200.0):
        assert M.disc_esf_width_px(b) == pytest.approx(t * b, rel=5e-4)  # measured 1.1e-4 (the pixel's width)
    # A disc within its pixel (b ≤ 1) steps the edge-sampled ESF at one pixel edge: 0.8 px, the floor.
    assert M.disc_esf_width_px(0.0) == pytest.approx(0.8) and M.disc_esf_width_px(0.9) == pytest.approx(0.8)
    for b in (1.5, 3.0, 17.3, 80.0):
        assert M.equivalent_disc_px(M.disc_esf_width_px(b)) == pytest.approx(b, abs=3e-5)  # measured 9e-6
    assert M.equivalent_disc_px(0.5) == 0.0


def test_esf_width_of_a_box_line():
    line = np.zeros(41)
    line[10:30] = 1.0  # a 20-px box: ESF rises linearly over 20 px, 10–90 % over 16 px
    assert M.esf_width_px(line) == pytest.approx(16.0)


def test_mtf_of_line_is_sinc_for_a_box():
    line = np.zeros(63)
    line[31 - 4:31 + 5] = 1.0  # 9 px box centred: DFT = sin(9πf) / (9 sin(πf))
    f = np.array([0.05, 0.1, 0.3])
    assert np.allclose(M.mtf_of_line(line, f), np.abs(np.sin(9 * np.pi * f) / (9 * np.sin(np.pi * f))))


def test_dof_interval_interpolates_both_sides():
    v = [0.0, 1.0, 2.0, 3.0, 4.0]
    m = [0.0, 0.5, 1.0, 0.6, 0.2]
    far, near = M.dof_interval(v, m, 2.0, 0.4)
    assert far == pytest.approx(0.8) and near == pytest.approx(3.5)
    assert M.dof_interval(v, m, 2.0, 1.1) == (pytest.approx(math.nan, nan_ok=True),) * 2
    assert M.dof_interval(v, [1.0] * 5, 2.0, 0.5) == (0.0, 4.0)  # open on both sides: the grid's ends


def test_circular_mtf_values():
    assert M.circular_mtf(0.0) == pytest.approx(1.0)
    assert M.circular_mtf(1.0) == pytest.approx(0.0)
    assert M.circular_mtf(0.5) == pytest.approx(2 / math.pi * (math.acos(0.5) - 0.5 * math.sqrt(0.75)))


# ----------------------------------------------------------------------------------------------
# The engine's defocused kernels


@pytest.mark.parametrize("display", ["glass", "toled"])
def test_blur_grows_with_defocus_on_both_sides(display):
    layout = D.display_layout(display)
    offsets = (0.0, 0.15, 0.4, 1.0, 2.0)  # m⁻¹; 2.0 on the far side is infinity
    for sign in (-1, 1):
        ks = [kernel(layout, V_F + sign * d) for d in offsets]
        widths = [M.blur_measures(k)["esf_width_px"] for k in ks]  # mean of the x and y widths
        assert all(a < b for a, b in zip(widths, widths[1:])), (sign, widths)
        # Within the first lobe of the defocus MTF (b < 1.22 / f) the reference MTF falls too.
        mtf = [M.blur_measures(k)["mtf_ref"] for k in ks[:3]]
        assert all(a > b for a, b in zip(mtf, mtf[1:])), (sign, mtf)


def test_poled_reference_mtf_falls_with_defocus():
    layout = layouts.poled()
    for sign in (-1, 1):
        mtf = [M.blur_measures(kernel(layout, V_F + sign * d))["mtf_ref"] for d in (0.0, 0.1, 0.2, 0.4)]
        assert all(a > b for a, b in zip(mtf, mtf[1:])), (sign, mtf)


@pytest.mark.parametrize("vergence_per_m", [0.0, 5.0])  # b = 26 and 39 px
def test_strongly_defocused_edge_matches_thin_lens_disc(vergence_per_m):
    k = kernel(None, vergence_per_m)
    b = M.geometric_coc_px(M.lens_at(vergence_per_m))
    assert b > 20
    ratio = M.esf_width_px(M.lsf(k, "x")) / M.disc_esf_width_px(b)
    assert abs(ratio - 1) <= 0.03, ratio  # measured 1.3 % (b = 26 px), 0.55 % (39 px); the study's GEOM_TOL 10 %


@pytest.mark.parametrize("wavelength_nm", [450.0, 640.0])
def test_in_focus_glass_mtf_is_diffraction_limited(wavelength_nm):
    k = kernel(None, V_F, size_px=255, wavelength_nm=wavelength_nm, pupil_samples=None)
    m = M.mtf_of_line(M.lsf(k, "x"))
    n_w = M.lens_at(V_F).image_distance_um / M.APERTURE_UM
    model = np.abs(M.diffraction_limit(M.FREQS_CPP, wavelength_nm, n_w))
    assert np.max(np.abs(m - model)) <= 3e-3  # measured 7.9e-4 (450 nm), 1.1e-3 (640 nm); the study's DIFF_TOL 0.01
    # The folding (pixel sampling) matters: the unfolded product alone is far off near Nyquist.
    assert np.max(np.abs(m - M.diffraction_limit(M.FREQS_CPP, wavelength_nm, n_w, folded=False))) > 0.05
    # The comparison can fail: the diffraction limit of another f-number (f/2.2) is refused.
    assert np.max(np.abs(m - np.abs(M.diffraction_limit(M.FREQS_CPP, wavelength_nm, 2.2)))) > M.DIFF_TOL


# ----------------------------------------------------------------------------------------------
# The quick study


def test_quick_study_writes_files_and_passes_checks(tmp_path):
    result = D.run_study(tmp_path, quick=True, progress=False)
    for name in ("study_defocus.csv", "study_defocus.md", "study_defocus.png", "study_defocus_psf.png",
                 "study_defocus_mtf.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    with open(tmp_path / "study_defocus.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(M.QUICK.displays) * len(M.QUICK.vergences_per_m) * len(M.QUICK.wavelengths_nm)
    assert set(rows[0]) == set(M.COLUMNS)
    assert result["checks"] and all(c["passed"] for c in result["checks"]), result["checks"]  # none would pass
    md = (tmp_path / "study_defocus.md").read_text()
    assert "## Checks" in md and "## Depth of field" in md and "FAIL" not in md
    dof = {r["display"]: r for r in result["dof"]}
    # The displays lower the in-focus MTF and so the absolute DoF; the relative DoF stays near the glass's
    # (the orders' factor on the OTF does not depend on the defocus at d = 0).
    for disp in ("toled", "poled"):
        assert dof[disp]["mtf_ref_focus"] < dof["glass"]["mtf_ref_focus"]
        assert dof[disp]["abs_width_per_m"] < dof["glass"]["abs_width_per_m"]
        assert dof[disp]["rel_width_per_m"] == pytest.approx(dof["glass"]["rel_width_per_m"], rel=0.15)
