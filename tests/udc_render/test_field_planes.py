"""The field blend through a monitor's three planes (optics.field_planes, issue 46): by linearity, at full rank the
same images as convolve_field on the bands x_k = Σ_c M_ck r_c; truncated, within the recorded bound; in the
pipeline, a dataset worker's T-OLED takes it and its electrons stay within that bound of the band path."""
from dataclasses import replace

import numpy as np
import pytest

from udc_render.optics.displays import preset
from udc_render.optics.field import _basis_map, convolve_field, field_basis, live_phases, phase_weights
from udc_render.optics.field_planes import _SPECTRA, convolve_field_planes, plane_basis, planes_bound
from udc_render.optics.stray import StrayLight
from udc_render.pipeline import SynthConfig, SynthError, prepare_kernels, synthesize
from udc_render.render import render_scene
from udc_render.scene import Bands, Sensor, load_scene

K, P, S, H, W, M = 3, 3, 9, 40, 56, 6  # bands, phases per axis, kernel px, grid, margin


@pytest.fixture(scope="module")
def toy():
    """Random positive phase kernels of unit sum, periodic phase weights over a few banding periods, planes."""
    rng = np.random.default_rng(3)
    kernels = rng.random((K, P, P, S, S)) ** 3
    kernels /= kernels.sum(axis=(-2, -1), keepdims=True)
    power = 1.0 + 0.2 * rng.standard_normal((K, P, P))
    shifts = np.arange(P) * 30.0 / P
    wy = phase_weights((np.arange(H) - (H - 1) / 2) * 2.0, shifts, 1000.0, 4000.0, 30.0, True)
    wx = phase_weights((np.arange(W) - (W - 1) / 2) * 2.0, shifts, 1000.0, 4000.0, 30.0, True)
    basis = field_basis(kernels, live_phases(wy, wx), 2)
    planes = rng.random((3, H, W)).astype(np.float32)
    matrix = rng.random((3, K))
    weights = rng.random((3, K))
    gains = rng.uniform(0.2, 1.0, K)
    return basis, power, wy, wx, planes, matrix, weights, gains


def _band_path(toy, precision="float64"):
    basis, power, wy, wx, planes, matrix, weights, gains = toy
    bands = np.einsum("ck,chw->khw", matrix, planes.astype(np.float64))
    return convolve_field(bands, None, power, wy, wx, M, gains, precision=precision, rank=2,
                          channel_weights=weights, basis=basis)[0].astype(np.float64)


def test_at_full_rank_the_planes_are_the_band_path(toy):
    basis, power, wy, wx, planes, matrix, weights, gains = toy
    pb = plane_basis(basis, power, None, wy, wx, max_rank=K * 2)
    assert pb.maps.shape == (K * 2, H, W) and pb.residual_sup[:, -1].max() < 1e-6 * pb.residual_sup[:, 0].max()
    got = convolve_field_planes(planes, matrix, pb, basis, gains, weights, M, K * 2, "float64")
    want = _band_path(toy)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5 * np.abs(want).max())  # float32 maps: 6e-8 each


def test_the_residuals_and_the_bound_hold_at_every_rank(toy):
    basis, power, wy, wx, planes, matrix, weights, gains = toy
    pb = plane_basis(basis, power, None, wy, wx, max_rank=K * 2)
    k, r = 1, 1  # a weight map rebuilt apart: W_kr = w_yᵀ (c_qr P_q) w_x, map i = 2k + r (every band at rank 2)
    w = _basis_map(basis.coeffs[k][:, r], basis.live, power[k], wy, wx, np.float64)
    for J in range(pb.maps.shape[0] + 1):
        rest = w - np.tensordot(pb.coeffs[2 * k + r, :J], pb.maps[:J].astype(np.float64), axes=1)
        assert np.abs(rest).max() == pytest.approx(pb.residual_sup[2 * k + r, J], rel=1e-9, abs=1e-12)
    want = _band_path(toy)
    bound = planes_bound(pb, weights, gains, matrix, np.abs(planes).reshape(3, -1).max(axis=1))
    assert np.all(np.diff(bound) <= 1e-12 * bound[0])  # more maps never loosen it
    for J in range(1, pb.maps.shape[0]):
        change = np.abs(convolve_field_planes(planes, matrix, pb, basis, gains, weights, M, J, "float64") - want)
        assert change.max() <= bound[J] + 1e-9 * np.abs(want).max(), J


def test_refuses_a_rank_it_does_not_store(toy):
    basis, power, wy, wx, planes, matrix, weights, gains = toy
    pb = plane_basis(basis, power, None, wy, wx, max_rank=2)
    with pytest.raises(Exception, match="no rank 3"):
        convolve_field_planes(planes, matrix, pb, basis, gains, weights, M, 3)
    with pytest.raises(SynthError, match="field_planes_rank = 0"):
        SynthConfig(field_planes_rank=0)


def test_a_dataset_workers_toled_goes_through_the_planes(tmp_path):
    """prepare_kernels stores the T-OLED's plane basis in the kernel cache; synthesis takes it (recorded), and its
    electrons stay within the recorded bound of the band path (field_planes_rank None) on the same kernels."""
    scene = replace(load_scene("monitor"), sensor=Sensor(96, 48, 12.4), bands=Bands((400.0, 700.0), 100.0))
    scene = scene.with_render(spp=2)
    band_image = render_scene(scene, progress=False)
    displays = [preset("glass"), replace(preset("toled"), distance_mm=2.0)]
    cfg = SynthConfig(field_phases=2, kernel_cache=str(tmp_path), stray_light=StrayLight.off(),
                      field_print_sigma=None, far_field_threshold=None)
    kernels = prepare_kernels(scene, displays, cfg)
    assert set(kernels.field_planes) == {"toled"}
    _SPECTRA.clear()
    planes = synthesize(band_image, scene, displays, cfg, kernels=kernels)
    bands = synthesize(band_image, scene, displays, replace(cfg, field_planes_rank=None), kernels=kernels)
    record = planes.display_meta["toled"]["optics"]["field_planes"]
    assert record["maps"] == cfg.field_planes_rank and "field_planes" not in bands.display_meta["toled"]["optics"]
    got, want = planes.captures["toled"].electrons, bands.captures["toled"].electrons
    assert 0 < np.abs(got - want).max() <= record["bound_e"]


def test_kept_member_spectra_follow_the_field_basis_kernels():
    """The members' spectra are keyed by the field basis's kernels too: the same plane basis with kernels doubled
    is not served the kept spectra, and its spectra are doubled (linear in the kernels)."""
    from udc_render.optics.field_planes import PlaneBasis, _summed_spectra
    rng = np.random.default_rng(4)
    bases = [rng.random((2, 5, 5)).astype(np.float32) for _ in range(3)]  # 3 bands of rank 2
    pb = PlaneBasis(rng.random((2, 8, 8)), rng.random((6, 2)), rng.random((6, 3)), rng.random(6),
                    np.repeat(np.arange(3), 2), rng.random(6))
    w, m = rng.random((3, 3)), rng.random((3, 3))
    _SPECTRA.clear()
    one = _summed_spectra(pb, bases, w, m, 2, (16, 16), np.float64, 1)
    two = _summed_spectra(pb, [2 * b for b in bases], w, m, 2, (16, 16), np.float64, 1)
    np.testing.assert_allclose(two, 2 * np.asarray(one), rtol=1e-12)
