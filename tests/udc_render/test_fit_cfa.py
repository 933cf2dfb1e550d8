"""fit.cfa: a CFA's sites balanced by the orders themselves, not by --camera's response. The measurements are
RGGB mosaics of another camera (the Sigma SDMerill's response at 650 nm: R/G/B 1 / 0.835 / 0.511, where the
default --camera, the Nikon 5100, has 1 / 0.079 / 0.017), the truth its sensitivities through
sensor.radiometry.photon_weights, which the fit does not call for the balance."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from psf import layouts
from udc_render.fit import FitSpec, run_fit, synthetic as S
from udc_render.fit.cfa import MAX_PASSES, converged
from udc_render.fit.inputs import read_frames
from udc_render.fit.psf_fit import first_lattice
from udc_render.io.dng import save_dng
from udc_render.sensor.radiometry import photon_weights

NIKON, SIGMA = "Nikon 5100 (NPL)", "Sigma SDMerill (NPL)"


def sigma_response() -> np.ndarray:
    r = photon_weights([645.0, 655.0], SIGMA)[:, 0]
    return r / r.max()


def mosaics(tmp_path: Path, shape_hw=(320, 384), window_px: int = 255) -> list[str]:
    """Two RGGB exposures (the core at 0.8 and 8× the full well) of a pentile at 70 µm through the Sigma's
    response, written as DNGs."""
    frames = S.psf_measurement(layouts.poled(70.0, 0.27, 0.6), shape_hw=shape_hw, offset_px=(3.3, -2.1),
                               rotation_deg=2.0, peaks_fw=(0.8, 8.0), seed=5, window_px=window_px, cfa=True,
                               camera_name=SIGMA)
    paths = [str(tmp_path / f"p{i}.dng") for i in range(len(frames))]
    for p, f in zip(paths, frames):
        save_dng(p, f, NIKON, 64, 65535)
    return paths


def test_the_passes_measure_another_cameras_response(tmp_path):
    """From the dimmest exposure's mean per site (not the --camera's response, 12× off in green), the passes of
    fit.cfa.converged give the Sigma's response: G and B within 3 σ and 3 % (measured: +0.9 % and +1.1 %, 0.7 σ
    and 0.6 σ, in 3 passes; a 191-px window of the same panel took 6 and left B 3.6 % low, 3.2 σ)."""
    paths = mosaics(tmp_path)
    frames = read_frames(paths, 64)
    optics = FitSpec(psf=tuple(paths)).optics()
    plane, gains, passes = converged(frames, frames[0].colour_map(), 650.0, NIKON, None,
                                     lambda p: first_lattice(p, optics, "poled", None, 255), optics)
    truth = sigma_response()
    g, s = np.array(gains.gains), np.array(gains.sigma)
    assert g[0] == 1.0 and np.all(s[1:] > 0) and min(gains.orders) >= 3 and passes < MAX_PASSES
    assert np.all(np.abs(g[1:] / truth[1:] - 1) < 0.03), (g, truth)
    assert np.all(np.abs(g[1:] - truth[1:]) < 3 * s[1:]), (g, s, truth)
    assert plane.colour_gain == pytest.approx(gains.gains)


@pytest.mark.slow
def test_the_fit_of_another_cameras_mosaics_recovers_the_panel(tmp_path):
    """Through run_fit (~45 s): fit.json records the measured response (within 3 σ and 3 % of the Sigma's) beside
    the --camera's, and the pentile's pitch within 1 %, open fraction and ratio within 10 % and 3 σ."""
    result = run_fit(FitSpec(psf=tuple(mosaics(tmp_path)), black_dn=64, family="poled", window_px=255),
                     tmp_path / "out")
    cfa = result["psf"]["cfa_response"]
    g, s, truth = np.array(cfa["measured"]), np.array(cfa["sigma"]), sigma_response()
    assert np.all(np.abs(g[1:] / truth[1:] - 1) < 0.03) and np.all(np.abs(g[1:] - truth[1:]) < 3 * s[1:])
    assert cfa["camera_response"][1] < 0.1  # the Nikon's green, which balanced it before
    assert abs(result["psf"]["lattice"]["pitch_x_um"]["value"] / 70.0 - 1) < 0.01
    for name, truth_value in (("open_fraction", 0.27), ("small_to_large", 0.6)):
        p = result["psf"]["parameters"][name]
        assert abs(p["value"] / truth_value - 1) < 0.1 and abs(p["value"] - truth_value) < 3 * p["sigma"]
