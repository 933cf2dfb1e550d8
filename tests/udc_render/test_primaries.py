"""A monitor's bands are x_k = Σ_c M_ck r_c of its three planes (BandImage.primaries_image), so the optics convolve
the planes with each channel's summed kernels (optics.primaries) instead of every band: the same electrons as the
band path but for float32 round-off (the blur and the far field of d = 0 views, the far field of a d > 0 one)."""
from dataclasses import replace

import numpy as np
import pytest

from udc_render.optics.displays import preset
from udc_render.optics.stray import StrayLight
from udc_render.pipeline import SynthConfig, plan_kernels, synthesize
from udc_render.render import render_scene
from udc_render.scene import Bands, Sensor, load_scene

TOL = 2e-6  # of the image maximum: float32 FFTs summed in another order (test_synth_fused's)


@pytest.fixture(scope="module")
def small():
    scene = replace(load_scene("monitor"), sensor=Sensor(96, 48, 12.4), bands=Bands((400.0, 700.0), 50.0))
    return scene, render_scene(scene, progress=False)


def test_the_render_keeps_its_planes_and_replace_drops_them(small):
    _, band_image = small
    planes, matrix = band_image.primaries_image, band_image.primaries_matrix
    assert planes.shape == (3,) + band_image.bands.shape[1:] and band_image.meta["render_path"] == "analytic"
    assert np.array_equal(np.einsum("ck,chw->khw", matrix.astype(np.float32), planes), band_image.bands)
    assert replace(band_image, bands=band_image.bands * 2).primaries_image is None  # stale planes never kept


@pytest.mark.parametrize("distance_mm", [0.0, 2.0])
def test_through_the_planes_equals_the_band_path(small, distance_mm):
    scene, band_image = small
    displays = [preset("glass")] + [replace(preset(n), distance_mm=distance_mm) for n in ("toled", "poled")]
    cfg = SynthConfig(field_phases=2 if distance_mm else None, use_cache=False, stray_light=StrayLight.off(),
                      far_field_threshold=0.0, field_print_sigma=None)
    kernels = plan_kernels(scene, displays, cfg)
    assert set(kernels.far) == {"glass", "toled", "poled"}
    planes = synthesize(band_image, scene, displays, cfg, kernels=kernels)
    bands = synthesize(replace(band_image), scene, displays, cfg, kernels=kernels)  # replace: no planes
    np.testing.assert_allclose(planes.gt, bands.gt, rtol=0, atol=TOL * bands.gt.max())
    for d in displays:
        got, want = planes.captures[d.name].electrons, bands.captures[d.name].electrons
        np.testing.assert_allclose(got, want, rtol=0, atol=TOL * want.max(), err_msg=d.name)
        optics, old = planes.display_meta[d.name]["optics"], bands.display_meta[d.name]["optics"]
        through = "the far field" if distance_mm and not d.is_glass else "the blur and the far field"
        assert optics["primaries"].startswith(through) and "primaries" not in old


def test_the_kept_kernel_spectra_give_the_same_bits_and_follow_the_weights():
    """convolve_primaries keeps its summed kernels' spectra per process: a second call returns the same bits as the
    first, and a change of the weights (another view or sensor) is not served the kept spectra: its result is the
    cold path's, and linear in the weights."""
    from udc_render.optics import primaries as pr
    rng = np.random.default_rng(3)
    planes = rng.random((3, 48, 40)).astype(np.float32)
    kernels = rng.random((5, 7, 7)).astype(np.float32)
    p = pr.Primaries(planes, rng.random((3, 5)))
    w = rng.random((3, 5))

    def run(weights):
        return pr.convolve_primaries(p, kernels, 4, np.ones(5), weights)

    pr._SPECTRA.clear()
    first = run(w)
    assert np.array_equal(run(w), first)
    doubled = run(2 * w)
    pr._SPECTRA.clear()
    assert np.array_equal(run(2 * w), doubled)
    np.testing.assert_allclose(doubled, 2 * first, rtol=1e-5, atol=1e-6 * np.abs(first).max())


def test_the_band_norms_from_the_planes_gram_matrix_equal_the_bands():
    """bright_pixels' gate takes ‖x_k‖² from the planes' Gram matrix when the bands are made of three planes:
    the bands' own sums of squares to within their float32 rounding (relative 1e-6; it measures ~1e-10)."""
    from udc_render.render.band_image import BandImage
    from udc_render.views import _band_norms_sq
    rng = np.random.default_rng(5)
    planes = rng.random((3, 40, 56)).astype(np.float32)
    b = BandImage.of_primaries(planes, rng.random((3, 7)), np.arange(8) * 10.0 + 400, 1.55, 4)
    want = np.einsum("khw,khw->k", b.bands, b.bands, dtype=np.float64)
    np.testing.assert_allclose(_band_norms_sq(b), want, rtol=1e-6)


def test_the_kept_far_field_spectra_give_the_same_bits():
    """far_light_primaries keeps its summed far kernels' spectra per process: a second call gives the first's bits,
    and the cold path after clearing them gives them too."""
    from udc_render.optics import primaries as pr
    from udc_render.optics.far_field import FarField
    rng = np.random.default_rng(6)
    k = rng.random((2, 9, 9))
    far = FarField(k, 4, 1.0, np.full(2, 0.06), np.full(2, 0.05), np.full(2, 0.01), np.ones(2, bool), 1e9, 0.0, 0.0)
    p = pr.Primaries(rng.random((3, 64, 72)).astype(np.float32), rng.random((3, 2)))
    w = rng.random((3, 2))
    first = pr.far_light_primaries(p, far, 8, w)
    assert np.array_equal(pr.far_light_primaries(p, far, 8, w), first)
    pr._FAR.clear()
    assert np.array_equal(pr.far_light_primaries(p, far, 8, w), first)


def test_kept_spectra_on_disk_are_loaded_by_a_fresh_process_with_the_same_bits(tmp_path, monkeypatch):
    """Inside kept.on_disk(folder) the summed spectra go into the kernel cache: a process that has not made them
    (the store cleared) loads them without making them (memory-mapped when large: psf.kernel_io), and gets the
    first call's bits; other weights make their own entry; outside the block nothing is written."""
    from udc_render.optics import kept, primaries as pr
    rng = np.random.default_rng(7)
    p = pr.Primaries(rng.random((3, 48, 40)).astype(np.float32), rng.random((3, 5)))
    kernels, w = rng.random((5, 7, 7)).astype(np.float32), rng.random((3, 5))

    def run(weights):
        pr._SPECTRA.clear()
        return pr.convolve_primaries(p, kernels, 4, np.ones(5), weights)

    want = run(w)
    assert not list(tmp_path.iterdir())
    with kept.on_disk(tmp_path):
        assert np.array_equal(run(w), want)
        assert len(list(tmp_path.glob("*.npz"))) == 1
        monkeypatch.setattr(pr, "_kernel_spectrum", lambda *a: pytest.fail("made again, not loaded"))
        assert np.array_equal(run(w), want)
        monkeypatch.undo()
        run(2 * w)
    assert len(list(tmp_path.glob("*.npz"))) == 2


@pytest.mark.parametrize("value, band", [(np.nan, r"a \(index 0\)"), (np.inf, r"a \(index 0\)"),
                                         (3e38, r"b \(index 1\)")])
def test_bands_of_bad_planes_are_refused_naming_the_band(value, band):
    """With the planes given, apply_kernels checks them in place of the bands; a NaN, an infinity or planes whose
    bands overflow float32 (band b: 2 × 3e38) still get the first bad band's one-line error (0 × NaN is NaN)."""
    from udc_render.optics.apply import _check_finite
    from udc_render.optics.convolution import OpticsError
    from udc_render.optics.primaries import Primaries
    planes = np.ones((3, 8, 8), np.float32)
    planes[1, 2, 3] = value
    matrix = np.array([[0.0, 0.5, 0.5], [0.0, 2.0, 0.5], [1.0, 0.5, 0.0]])
    with np.errstate(over="ignore", invalid="ignore"):
        bands = np.einsum("ck,chw->khw", matrix.astype(np.float32), planes)
    with pytest.raises(OpticsError, match=band + " holds 1 NaN or infinite"):
        _check_finite(bands, ["a", "b", "c"], Primaries(planes, matrix))
    planes[1, 2, 3] = 1.0
    _check_finite(np.einsum("ck,chw->khw", matrix.astype(np.float32), planes), None, Primaries(planes, matrix))


def test_digest_is_the_bytes_sha1_hashed_once_while_the_arrays_live(monkeypatch):
    """optics.kept.digest: SHA-1 of the arrays' bytes in turn (hashlib's own, on the bytes), the same for equal
    bytes in other objects, and not hashed again for the same living objects."""
    import gc
    import hashlib

    from udc_render.optics import kept as kept_mod
    a, b = np.arange(12, dtype=np.float32).reshape(3, 4), np.ones((2, 2))
    assert kept_mod.digest(a) == hashlib.sha1(a.tobytes()).hexdigest()
    assert kept_mod.digest(a, b) == hashlib.sha1(a.tobytes() + b.tobytes()).hexdigest()
    assert kept_mod.digest(a.T.copy()) == hashlib.sha1(a.T.copy().tobytes()).hexdigest()
    want = hashlib.sha1(a.tobytes()).hexdigest()
    monkeypatch.setattr(kept_mod.hashlib, "sha1", None)  # hashing again would fail
    assert kept_mod.digest(a) == want
    monkeypatch.undo()
    ids = (id(a),)
    del a
    gc.collect()
    assert ids not in kept_mod._DIGESTS
