"""restore.studies.error_bands: the octave bands split the MSE exactly (Parseval), a sinusoid's error lands
in its own band, and the display transfer is 1 for a delta kernel and NaN past the packed Nyquist limit.
restore.studies.early_training: its variants parse, or fail in one line naming --variant."""
import numpy as np

from restore.studies.error_bands import OCTAVE_EDGES, band_mse, band_transfer


def test_bands_sum_to_the_mse():
    err = np.random.default_rng(0).normal(0, 0.03, (3, 96, 160))
    bands = band_mse(err)
    assert bands.shape == (len(OCTAVE_EDGES) - 1,) and np.all(bands >= 0)
    assert abs(bands.sum() - np.mean(err ** 2)) < 1e-12
    # white noise spreads by area: the top octave (1/4 to the corner) holds most of the spectrum's cells
    assert bands[-1] + bands[-2] > 0.8 * bands.sum()


def test_a_sinusoid_lands_in_its_band():
    x = np.arange(160)
    err = np.broadcast_to(0.1 * np.sin(2 * np.pi * 0.1 * x), (3, 64, 160))  # 0.1 cycles/px: band [1/16, 1/8)
    bands = band_mse(err)
    assert abs(bands[3] - 0.1 ** 2 / 2) < 1e-12 and bands.sum() - bands[3] < 1e-20


def test_band_transfer_of_a_delta_and_a_box():
    delta = np.zeros((5, 5))
    delta[2, 2] = 1.0
    t = band_transfer(delta)
    assert np.allclose(t[:5], 1.0) and np.all(np.isnan(t[5:]))  # bands from 1/4 up lie past 1/(2·2)
    box = band_transfer(np.full((5, 5), 1 / 25))
    assert box[0] > 0.9 and np.all(np.diff(box[:5]) < 0) and box[4] < 0.5  # a blur loses the high bands


def test_early_training_variants_parse_or_fail_in_one_line():
    import pytest

    from restore.models import ModelConfigError
    from restore.studies.early_training import parse_variant
    v = parse_variant('unet:128:2e-4:{"width": 64}')
    assert v["model"]["type"] == "unet" and v["model"]["width"] == 64 and v["crop_px"] == 128 and v["lr"] == 2e-4
    assert parse_variant("resnet:128:1e-3")["model"]["blocks"] == 16
    for bad in ("unet:128", "vgg:128:1e-3", "unet:big:1e-3", "unet:128:2e-4:{width"):
        with pytest.raises(ModelConfigError, match="--variant"):
            parse_variant(bad)
