"""The lens's wavefront aberrations through the scene file, the synthesis and the commands ([lens]
zernike_waves, psf.lens.Lens.zernike_waves; the physics: tests/psf/test_zernike.py)."""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from psf import Lens
from udc_render.cli import main
from udc_render.optics import displays as D
from udc_render.pipeline import SynthConfig, synthesize
from udc_render.render import render_scene
from udc_render.scene import SceneError
from udc_render.scene.geometry import psf_lens
from udc_render.sensor import SensorConfig

SPHERICAL = [[4, 0, 0.1]]


def _doc(udc, **lens):
    doc = udc.monitor_doc(image="pattern:checker", bands={"range_nm": [400, 700], "step_nm": 100})
    doc["lens"] = lens
    return doc


def test_scene_lens_carries_the_terms_to_the_psf_lens(udc, tmp_path):
    """[lens] zernike_waves is checked and sorted, reaches psf_lens, and replace() on the scene's lens (the gap
    study's switch) is checked the same way; the default is the diffraction-limited lens."""
    scene = udc.write_scene(tmp_path / "s.toml", _doc(udc, zernike_waves=[[3, 1, 0.02], [4, 0, 0.05]]))
    assert scene.lens.zernike_waves == ((3, 1, 0.02), (4, 0, 0.05))
    assert psf_lens(scene).zernike_waves == scene.lens.zernike_waves
    assert udc.write_scene(tmp_path / "d.toml", _doc(udc)).lens.zernike_waves == ()
    off = replace(scene, lens=replace(scene.lens, zernike_waves=()))
    assert psf_lens(off) == Lens(**{**psf_lens(scene).describe(), "zernike_waves": ()})
    with pytest.raises(SceneError, match=r"lens.zernike_waves = .*expected a list of \[n, m"):
        replace(scene.lens, zernike_waves=((4, 0, 2.0),))


@pytest.mark.parametrize("bad", [[[1, 1, 0.1]], [[4, 0]], "spherical", [[4, 0, 0.1], [4, 0, 0.1]]])
def test_bad_scene_terms_are_one_line(udc, tmp_path, bad):
    with pytest.raises(SceneError, match=r"s.toml: lens.zernike_waves = .*: expected a list of \[n, m") as e:
        udc.write_scene(tmp_path / "s.toml", _doc(udc, zernike_waves=bad))
    assert "\n" not in str(e.value)


def test_synthesis_blurs_with_the_aberrated_lens_and_records_it(udc, tmp_path, render_cache, monkeypatch):
    """The ground truth through an aberrated lens loses contrast on a checker (its kernels are the aberrated
    lens's, cached under their own key) and synth.json's lens records the terms, which restore.known reads
    back into the same psf.Lens."""
    monkeypatch.setenv("UDC_RENDER_CACHE", str(tmp_path / "cache"))
    doc = _doc(udc)
    doc["sensor"]["pitch_um"] = 1.55
    plain = udc.write_scene(tmp_path / "p.toml", doc)
    aberrated = replace(plain, lens=replace(plain.lens, zernike_waves=((4, 0, 0.15),)))
    band_image = render_scene(plain, progress=False)
    cfg = SynthConfig(sensor=SensorConfig(noise="none"), kernel_cache=str(tmp_path / "kc"))
    a = synthesize(band_image, plain, [D.preset("glass")], cfg)
    b = synthesize(band_image, aberrated, [D.preset("glass")], cfg)
    assert "zernike_waves" not in a.meta["lens"] and b.meta["lens"]["zernike_waves"] == [[4, 0, 0.15]]
    assert Lens(**json.loads(json.dumps(b.meta["lens"]))) == psf_lens(aberrated)
    contrast = [float(np.std(r.gt[1])) for r in (a, b)]
    assert contrast[1] < 0.97 * contrast[0]
    assert np.isclose(a.gt.mean(), b.gt.mean(), rtol=0.02)  # a phase error moves light, it does not absorb it


def test_psf_command_takes_zernike_terms(tmp_path, capsys):
    """`udc-render psf --zernike N,M,WAVES` (repeatable) writes the terms into psf.json; a bad term is one line."""
    out = tmp_path / "o"
    assert main(["psf", "--display", "glass", "--wavelengths-nm", "550", "--kernel-px", "31", "--no-cache",
                 "--zernike", "4,0,0.05", "--zernike", "2,2,0.02", "--out", str(out)]) == 0
    params = json.loads((out / "psf.json").read_text())
    assert params["lens"]["zernike_waves"] == [[2, 2, 0.02], [4, 0, 0.05]]
    capsys.readouterr()
    assert main(["psf", "--display", "glass", "--zernike", "1,1,0.1", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "zernike_waves" in err
