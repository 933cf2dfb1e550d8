"""The synthesis's fused optics (band sums in Fourier space, shared band spectra) against the reference
path: every band blurred on its own (apply_kernels) and integrated by the sensor (electrons_spectral,
electrons_rgb). They differ only by float32 round-off."""
from dataclasses import replace

import numpy as np
import pytest

from udc_render.optics import apply_kernels
from udc_render.optics.displays import preset
from udc_render.optics.stray import StrayLight
from udc_render.pipeline import SynthConfig, auto_exposure_s, bin_pixels, plan_kernels, sensor_for_scene, synthesize
from udc_render.render import render_scene
from udc_render.scene import Bands, Sensor, load_scene
from udc_render.sensor import electrons_rgb, electrons_spectral

TOL = 2e-6  # relative to the image maximum: float32 spectra summed in another order


@pytest.fixture(scope="module")
def small():
    scene = replace(load_scene("monitor"), sensor=Sensor(96, 48, 12.4), bands=Bands((400.0, 700.0), 50.0))
    return scene.with_render(spp=2), render_scene(scene.with_render(spp=2), progress=False)


@pytest.mark.parametrize("distance_mm", [0.0, 2.0])
def test_fused_synthesis_equals_the_per_band_reference(small, distance_mm):
    scene, band_image = small
    displays = [preset("glass")] + [replace(preset(n), distance_mm=distance_mm) for n in ("toled", "poled")]
    # the stray light (optics.stray) acts after the optics, on the electrons: off, to compare the optics alone
    cfg = SynthConfig(field_phases=2 if distance_mm else None, use_cache=False, stray_light=StrayLight.off(),
                      field_print_sigma=None)  # every d > 0 view blended, as the reference (test_field_print.py)
    kernels = plan_kernels(scene, displays, cfg)
    result = synthesize(band_image, scene, displays, cfg, kernels=kernels)
    sensor = sensor_for_scene(cfg.sensor, scene)
    sensor = replace(sensor, exposure_s=auto_exposure_s(band_image, sensor)[0])
    glass = apply_kernels(band_image, kernels.band["glass"], None, cfg.precision,
                          far_field=kernels.far.get("glass")).images
    gt = bin_pixels(electrons_rgb(glass, band_image.edges_nm, sensor), band_image.pitch_um, sensor.pitch_um)
    gt /= sensor.full_well_e
    np.testing.assert_allclose(result.gt, gt, rtol=0, atol=TOL * gt.max())
    for d in displays:
        t = d.transmission.band_means(band_image.edges_nm)
        optics = apply_kernels(band_image, kernels.band[d.name], t, cfg.precision, field_rank=cfg.field_rank,
                               far_field=kernels.far.get(d.name))  # the far field per band (optics.far_field)
        want = electrons_spectral(optics.images, band_image.edges_nm, sensor)
        got = result.captures[d.name].electrons
        np.testing.assert_allclose(got, want, rtol=0, atol=TOL * want.max(), err_msg=d.name)
        assert result.display_meta[d.name]["optics"]["model"] == (
            "field-dependent" if distance_mm and not d.is_glass else "field-independent")


def test_compact_kernels_give_the_same_bytes(small):
    """A dataset worker keeps the rank-r phase bases instead of the phase kernels (compact_kernels):
    the same numbers as the bases convolve_field makes per call, so the captures are byte-identical."""
    from udc_render.pipeline import compact_kernels
    scene, band_image = small
    displays = [preset("glass"), replace(preset("toled"), distance_mm=2.0)]
    cfg = SynthConfig(field_phases=2, use_cache=False)
    full = plan_kernels(scene, displays, cfg)
    compact = compact_kernels(full, scene, cfg)
    assert compact.band["toled"].field_kernels is None and compact.field_bases["toled"].rank == cfg.field_rank
    a = synthesize(band_image, scene, displays, cfg, kernels=full)
    b = synthesize(band_image, scene, displays, cfg, kernels=compact)
    for name in ("glass", "toled"):
        assert a.captures[name].mosaic_dn.tobytes() == b.captures[name].mosaic_dn.tobytes()
    assert compact_kernels(full, scene, replace(cfg, field_rank=None)) is full  # exact: every phase kernel


@pytest.mark.slow  # CI time (20-min line): 10 s; the same bytes are checked by test_compact_kernels_give_the_same_bytes
def test_stored_power_maps_are_made_once_and_give_the_same_bytes(small, monkeypatch, tmp_path):
    """A dataset worker makes each d > 0 display's exact-power map once (store_power_maps, in worker_kernels):
    two captures with it call psf.banding.power_lattice no more (a capture without it calls it once per band)
    and give the bytes of the map made per call; a map of another grid is refused."""
    from udc_render.dataset.executors import Shared, worker_kernels
    from udc_render.optics import OpticsError, field_power
    from udc_render.pipeline import compact_kernels, store_power_maps
    scene, band_image = small
    displays = [preset("glass"), replace(preset("toled"), distance_mm=2.0)]
    cfg = SynthConfig(field_phases=2, use_cache=False)
    compact = compact_kernels(plan_kernels(scene, displays, cfg), scene, cfg)
    calls = []
    lattice = field_power.power_lattice
    monkeypatch.setattr(field_power, "power_lattice", lambda *a: calls.append(1) or lattice(*a))
    fresh = synthesize(band_image, scene, displays, cfg, kernels=compact)
    K = band_image.bands.shape[0]
    assert len(calls) == K
    stored = store_power_maps(compact, scene)
    assert set(stored.power_maps) == {"toled"}
    assert stored.power_maps["toled"].maps.shape == (K,) + band_image.bands.shape[1:]
    assert len(calls) == 2 * K
    for _ in range(2):
        again = synthesize(band_image, scene, displays, cfg, kernels=stored)
        assert again.captures["toled"].mosaic_dn.tobytes() == fresh.captures["toled"].mosaic_dn.tobytes()
    assert len(calls) == 2 * K
    shared = Shared(scene, displays, cfg, tmp_path, side_by_side=False, previews=False)
    first = worker_kernels(shared)
    assert first.power_maps["toled"].maps is not None and worker_kernels(shared) is first
    small_grid = replace(band_image, bands=band_image.bands[:, 2:, 2:])
    with pytest.raises(OpticsError, match="power_map"):
        apply_kernels(small_grid, stored.band["toled"], None, field_rank=cfg.field_rank,
                      field_basis=stored.field_bases["toled"], power_map=stored.power_maps["toled"])


def test_kernel_products_are_made_once_into_the_cache_then_loaded(small, monkeypatch, tmp_path):
    """prepare_kernels (a dataset's parent) puts the far fields, the rank-r field bases and the exact-power maps
    into the kernel cache beside the kernels; a second call (a worker) makes none of them and has the same bits
    (loaded: tests/psf/test_cache.py)."""
    import udc_render.synth_kernels as synth_kernels
    from udc_render.optics import field_power
    from udc_render.pipeline import prepare_kernels
    scene, _ = small
    displays = [preset("glass"), replace(preset("toled"), distance_mm=2.0), preset("poled")]
    cfg = SynthConfig(field_phases=2, kernel_cache=str(tmp_path), far_field_threshold=0.0)
    first = prepare_kernels(scene, displays, cfg)
    assert set(first.far) == {"glass", "toled", "poled"}
    assert set(first.field_bases) == set(first.power_maps) == {"toled"}

    def refuse(*args, **kwargs):
        raise AssertionError("made again: expected from the cache")
    for module, name in ((synth_kernels, "field_basis"), (synth_kernels, "make_far_field"),
                         (field_power, "power_lattice")):
        monkeypatch.setattr(module, name, refuse)
    again = prepare_kernels(scene, displays, cfg)
    for name, far in first.far.items():
        assert again.far[name].kernels.tobytes() == far.kernels.tobytes()
        assert again.far[name].describe() == far.describe()
    a, b = first.field_bases["toled"], again.field_bases["toled"]
    assert (a.rank, a.live, a.residuals) == (b.rank, b.live, b.residuals)
    assert all(x.tobytes() == y.tobytes() for x, y in zip(a.bases + a.coeffs, b.bases + b.coeffs))
    maps = again.power_maps["toled"].maps
    assert maps.tobytes() == first.power_maps["toled"].maps.tobytes()
