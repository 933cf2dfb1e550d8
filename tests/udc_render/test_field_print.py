"""What an item leaves out and what it makes once (issue 46): a d > 0 view's field blend when it cannot print
(views.field_print: a bound on any pixel's change against the read noise), and the kernels' spectra made once
into the kernel cache (synth_kernels.kernel_spectra: the same numbers as made per call)."""
from dataclasses import replace

import numpy as np
import pytest

from udc_render.optics.displays import preset
from udc_render.optics.stray import StrayLight
from udc_render.pipeline import (
    SynthConfig,
    auto_exposure_s,
    capture_views,
    field_prints,
    plan_kernels,
    prepare_kernels,
    sensor_for_scene,
    synthesize,
)
from udc_render.render import render_scene
from udc_render.scene import Bands, Sensor, load_scene
from udc_render.views import channel_electrons

DISPLAYS = [preset("glass")] + [replace(preset(n), distance_mm=2.0) for n in ("toled", "poled")]
CFG = SynthConfig(field_phases=2, use_cache=False, stray_light=StrayLight.off())


@pytest.fixture(scope="module")
def small():
    scene = replace(load_scene("monitor"), sensor=Sensor(96, 48, 12.4), bands=Bands((400.0, 700.0), 100.0))
    scene = scene.with_render(spp=2)
    band_image = render_scene(scene, progress=False)
    sensor = sensor_for_scene(CFG.sensor, scene)
    return scene, band_image, replace(sensor, exposure_s=auto_exposure_s(band_image, sensor)[0])


def test_the_bound_holds_and_decides(small):
    """Per d > 0 view: the largest change the field blend makes to any pixel's electrons (the blend against the
    mean kernel with the mean power) is within views.field_print's bound, and a threshold above the bound (in
    read-noise σ) leaves the blend out, one below keeps it."""
    scene, band_image, sensor = small
    kernels = plan_kernels(scene, DISPLAYS, CFG)
    prints = field_prints(band_image, kernels, DISPLAYS, sensor, CFG)
    assert set(prints) == {"toled", "poled"}
    for view in capture_views(kernels, DISPLAYS, band_image.edges_nm):
        if view.name not in prints:
            continue
        verdict = prints[view.name]
        blended = channel_electrons(band_image, replace(view, field_print=verdict | {"prints": True}), sensor, CFG)
        mean = channel_electrons(band_image, replace(view, field_print=verdict | {"prints": False}), sensor, CFG)
        assert blended[1]["model"] == "field-dependent" and mean[1]["model"] == "field-independent"
        change = float(np.abs(blended[0] - mean[0]).max())
        assert 0 < change <= verdict["bound_e"], view.name
        sigma = verdict["bound_e"] / sensor.read_noise_e
        for threshold, prints_ in ((1.01 * sigma, False), (0.99 * sigma, True)):
            again = field_prints(band_image, kernels, DISPLAYS, sensor, replace(CFG, field_print_sigma=threshold))
            assert again[view.name]["prints"] is prints_


def test_a_view_left_out_is_recorded_and_off_keeps_the_old_bytes(small):
    """field_print_sigma large: every blend left out, capture.json says why (and the bound); None: every blend
    kept, the bytes of the path before field_print."""
    scene, band_image, _ = small
    kernels = plan_kernels(scene, DISPLAYS, CFG)
    left = synthesize(band_image, scene, DISPLAYS, replace(CFG, field_print_sigma=1e9), kernels=kernels)
    for name in ("toled", "poled"):
        optics = left.display_meta[name]["optics"]
        assert optics["model"] == "field-independent" and optics["field_print"]["prints"] is False
        assert "field-dependent blur" in optics["skipped"][0] and optics["field_print"]["bound_e"] > 0
    kept = synthesize(band_image, scene, DISPLAYS, replace(CFG, field_print_sigma=None), kernels=kernels)
    assert kept.display_meta["toled"]["optics"]["field_print"] == {
        "prints": True, "rule": "always blended (field_print_sigma None)", "threshold_sigma": None}
    assert "field_print_sigma" in repr(CFG) and kept.display_meta["poled"]["optics"]["model"] == "field-dependent"
    no_print = replace(kernels, field_spread={})  # the blend as it was made before field_print existed
    old = synthesize(band_image, scene, DISPLAYS, CFG, kernels=no_print)
    for name in ("glass", "toled", "poled"):
        assert kept.captures[name].mosaic_dn.tobytes() == old.captures[name].mosaic_dn.tobytes()


def test_cached_kernel_spectra_give_the_same_bytes(small, tmp_path, monkeypatch):
    """A dataset worker's kernels (prepare_kernels: cache_spectra) take their spectra from the kernel cache, made
    on first use: the same bytes as spectra made per call, and a second synthesis makes none."""
    from udc_render.optics import convolution, field
    scene, band_image, _ = small
    cfg = replace(CFG, use_cache=True, kernel_cache=str(tmp_path), field_print_sigma=None,
                  field_planes_rank=None)  # the band path's spectra (test_field_planes: the planes')
    worker = prepare_kernels(scene, DISPLAYS, cfg)
    assert worker.cache_spectra
    per_call = synthesize(band_image, scene, DISPLAYS, cfg, kernels=replace(worker, cache_spectra=False))
    first = synthesize(band_image, scene, DISPLAYS, cfg, kernels=worker)
    entries = set(tmp_path.glob("*.npz"))
    made = []
    spectrum = convolution._kernel_spectrum
    for module in (convolution, field):
        monkeypatch.setattr(module, "_kernel_spectrum", lambda *a: made.append(1) or spectrum(*a))
    again = synthesize(band_image, scene, DISPLAYS, cfg, kernels=worker)
    assert made == [] and set(tmp_path.glob("*.npz")) == entries
    synthesize(band_image, scene, DISPLAYS, cfg, kernels=replace(worker, cache_spectra=False))
    assert made  # the spy sees spectra made per call
    for result in (first, again):
        assert result.gt.tobytes() == per_call.gt.tobytes()
        for name in ("glass", "toled", "poled"):
            assert result.captures[name].mosaic_dn.tobytes() == per_call.captures[name].mosaic_dn.tobytes()


def test_the_guides_state_the_default():
    """guides/synth.md ('--field-print-sigma', default 0.25) and concepts/defaults.md's row against SynthConfig."""
    from pathlib import Path
    docs = Path(__file__).resolve().parents[2] / "docs"
    synth = " ".join((docs / "guides" / "synth.md").read_text(encoding="utf-8").split())
    defaults = (docs / "concepts" / "defaults.md").read_text(encoding="utf-8")
    assert SynthConfig().field_print_sigma == 0.25
    assert "(`--field-print-sigma`, default 0.25:" in synth and "[--field-print-sigma 0.25|off]" in synth
    assert "| field print threshold (d > 0) | 0.25 σ of the read noise (`field_print_sigma`) |" in defaults
