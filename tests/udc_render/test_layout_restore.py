"""`study layout --restore dep` (udc_render.studies.layout_restore): the noise follows the restorability's
exposure convention, DeP gains over a noisy open display, a wider kernel restores worse, and the CLI's mechanics."""
from __future__ import annotations

import json

import numpy as np
import pytest

from udc_render import cli
from udc_render.design.metrics import noise_variance
from udc_render.sensor.config import SensorConfig
from udc_render.studies.layout_compare import paired, run_compare
from udc_render.studies.layout_restore import CROP_PX, CROP_SETS, natural_crops, restored_psnr

CORNER = (("astronaut", 64, 160),)


def test_input_noise_is_the_restorability_s_variance():
    """Delta kernel: MSE(y / t, x) = (t x̄ FW + read²) / (t FW)², metrics.noise_variance(x̄, t) / t² (oracle); 96²
    pixels leave a sampling error of about 2 %, the tolerance is 6 %."""
    sensor, t = SensorConfig(), 0.05
    r = restored_psnr(np.ones((3, 1, 1)), t, sensor, 96, CORNER)
    x = natural_crops(96, 0, CORNER)[0]
    for c in range(3):
        expected = noise_variance(sensor, float(x[c].mean()), t) / t ** 2
        assert 10 ** (-r["input_psnr_db"][c] / 10) == pytest.approx(expected, rel=0.06)


def test_dep_gains_over_a_noisy_open_display():
    """A delta kernel at t = 0.02: DeP's denoiser and Wiener step restore above the noisy input (measured gains
    2.7-5.0 dB over R, G, B and seeds 0, 1; at t = 1 DeP loses 3-4 dB: its prior smooths texture)."""
    r = restored_psnr(np.ones((3, 1, 1)), 0.02, None, 96, CORNER)
    assert min(np.subtract(r["psnr_db"], r["input_psnr_db"])) > 1.0


def test_a_wider_kernel_restores_worse_at_equal_transmission():
    narrow, wide = np.zeros((2, 3, 31, 31))
    narrow[:, 14:17, 14:17] = 1
    wide[:, :, :] = 1
    a, b = (restored_psnr(k, 0.2, None, 96, CORNER) for k in (narrow, wide))
    assert all(x > y + 1 for x, y in zip(a["psnr_db"], b["psnr_db"]))


def test_every_crop_lies_inside_its_photograph():
    """The crop sets' corners leave a whole 192-px crop inside each image (reflection only supplies the margin)."""
    import skimage.data
    for crops in CROP_SETS.values():
        for name, r, c in crops:
            h, w = getattr(skimage.data, name)().shape[:2]
            assert 0 <= r and r + CROP_PX <= h and 0 <= c and c + CROP_PX <= w, (name, r, c)


def test_paired_difference_golden():
    """Per-crop differences 1, 2, 3 dB (channels equal): mean 2, standard error 1 / √3, 3 wins of 3."""
    crops = [["astronaut", 0, 0]] * 3
    ref = {"crops": crops, "crop_px": 96, "crop_psnr_db": [[20.0] * 3] * 3}
    lay = dict(ref, crop_psnr_db=[[21.0] * 3, [22.0] * 3, [23.0] * 3])
    p = paired(lay, ref)
    assert p["mean_db"] == pytest.approx(2.0) and p["standard_error_db"] == pytest.approx(1 / np.sqrt(3))
    assert (p["wins"], p["crops"]) == (3, 3)
    with pytest.raises(ValueError, match="paired crops differ"):
        paired(dict(lay, crop_px=192), ref)


def test_cli_writes_the_restored_psnr(tmp_path):
    args = ["study", "layout", "--display", "toled", "--quick", "--restore", "dep", "--out", str(tmp_path)]
    assert cli.main(args) == 0
    for tiling in ("repeated", "turned"):
        assert (tmp_path / f"study_layout_restored_{tiling}.png").is_file()
    doc = run_compare(tmp_path / "compare", {"a": (tmp_path, "turned"), "b": (tmp_path, "turned")}, "a")
    assert doc["layouts"]["b"]["paired"]["mean_db"] == 0.0 and (tmp_path / "compare/study_layout_compare.png").is_file()
    doc = json.loads((tmp_path / "study_layout.json").read_text())
    for tiling in ("repeated", "turned"):
        d = doc["restored"][tiling]
        assert d["crop_px"] == 96 and len(d["psnr_db"]) == 3 and np.isfinite(d["psnr_db"]).all()
        assert np.shape(d["crop_psnr_db"]) == (1, 3) and "first_crop" not in d
        assert d["transmission"] == pytest.approx(np.multiply(doc["power_transmittance"],
                                                              doc["restorability"][tiling]["window_fraction"]))
    assert "Restored PSNR by DeP" in (tmp_path / "study_layout.md").read_text()


def test_restore_is_refused_outside_layout(capsys):
    assert cli.main(["study", "psf", "--restore", "dep"]) == 2
    assert "--restore dep" in capsys.readouterr().err
    assert cli.main(["study", "layout", "--restore-crops", "photos", "--out", "x"]) == 2
    assert "--restore-crops photos: only with --restore dep" in capsys.readouterr().err
