"""Paired data for the restorers: reading the dataset layout, Bayer-preserving augmentation, SSIM."""
import json

import numpy as np
import pytest
import torch

from restore.data import DataError, PairDataset, augment_crop, dihedral, list_pairs, load_pair
from restore.losses import loss_fn, ssim
from udc_render.io.exr import read_exr, save_exr
from udc_render.sensor import mosaic_of, pack_rggb
from udc_render.streams import stream


def test_pairs_are_read_in_the_dataset_layout(pairs_dir):
    train, test = list_pairs(pairs_dir, "train", ["blur"]), list_pairs(pairs_dir, "test", ["blur"])
    assert [p.item for p in train] == list(range(6)) and [p.item for p in test] == [7, 8]
    packed, gt = load_pair(train[0])
    assert packed.shape == (4, 32, 48) and gt.shape == (3, 64, 96)
    assert packed.dtype == np.float32 and 0 <= packed.min() and packed.max() <= 1
    assert packed.mean() / gt.mean() == pytest.approx(0.5, rel=0.03)  # γ of write_pairs


@pytest.mark.parametrize("mode", range(8))
def test_augmentation_keeps_the_bayer_pattern(mode):
    """Oracle: for a noise-free capture (mosaic of the ground truth) the augmented packed crop must be
    exactly the packed mosaic of the augmented ground-truth crop, whatever the flip or transpose."""
    rng = np.random.default_rng(mode)
    gt = rng.random((3, 20, 26)).astype(np.float32)
    packed = pack_rggb(mosaic_of(gt))
    x, y = augment_crop(packed, gt, mode, 12, np.random.default_rng(1))
    assert x.shape == (4, 6, 6) and y.shape == (3, 12, 12)
    # (a transpose moves Gb values to Gr sites; both sample the G channel, so the oracle still holds)
    assert np.array_equal(x, pack_rggb(mosaic_of(y)))
    t = dihedral(gt, mode)  # y is a crop of the transformed ground truth starting on the moved R site
    offsets = [(i, j) for i in range(t.shape[1] - 11) for j in range(t.shape[2] - 11)
               if np.array_equal(t[:, i:i + 12, j:j + 12], y)]
    assert offsets and all((i % 2, j % 2) == (int(bool(mode & 2)), int(bool(mode & 4))) for i, j in offsets)


def test_full_frame_without_augmentation_is_the_identity():
    gt = np.random.default_rng(0).random((3, 8, 10)).astype(np.float32)
    packed = pack_rggb(mosaic_of(gt))
    x, y = augment_crop(packed, gt, 0, None, np.random.default_rng(0))
    assert np.array_equal(x, packed) and np.array_equal(y, gt)


def test_crops_are_deterministic_per_epoch_and_index(pairs_dir):
    ds = PairDataset(list_pairs(pairs_dir, "train", ["blur"]), crop_px=16, seed=3)
    a = ds[2]
    assert all(torch.equal(u, v) for u, v in zip(a, ds[2]))
    ds.set_epoch(1)
    assert not torch.equal(a[1], ds[2][1])
    assert len(ds) == 6


def test_a_crop_draws_from_its_own_named_stream(pairs_dir):
    """Crop i of epoch e draws its transform and place from stream (seed, 'pair crop', e, i), crop 0 included (a
    default_rng([seed, e, 0]) was default_rng([seed, e]))."""
    ds = PairDataset(list_pairs(pairs_dir, "train", ["blur"]), crop_px=16, seed=3)
    ds.set_epoch(2)
    rng = stream(3, "pair crop", 2, 0)
    x, y = augment_crop(*ds.arrays[0], int(rng.integers(0, 8)), 16, rng)
    assert all(torch.equal(a, torch.from_numpy(b)) for a, b in zip(ds[0], (x, y)))


def test_bad_data_gives_one_line_errors(tmp_path, pairs_dir):
    with pytest.raises(DataError, match="no manifest.jsonl"):
        list_pairs(tmp_path, "train", ["blur"])
    with pytest.raises(DataError, match="display = 'poled' not in item"):
        list_pairs(pairs_dir, "train", ["poled"])
    with pytest.raises(DataError, match="split = 'dev'"):
        list_pairs(pairs_dir, "dev", ["blur"])
    with pytest.raises(DataError, match="crop_px = 15"):
        PairDataset(list_pairs(pairs_dir, "train", ["blur"]), crop_px=15)
    with pytest.raises(DataError, match="empty"):
        PairDataset([], crop_px=16)
    gt = list_pairs(pairs_dir, "train", ["blur"])[2].folder / "gt.exr"
    save_exr(gt, {c: np.where(a > 0.5, np.inf, a) for c, a in read_exr(gt).items()})
    with pytest.raises(DataError, match="item_000002/gt.exr: NaN or infinite"):
        PairDataset(list_pairs(pairs_dir, "train", ["blur"]), crop_px=16)
    (pairs_dir / list_pairs(pairs_dir, "test", ["blur"])[0].folder / "gt.exr").unlink()
    with pytest.raises(DataError, match="gt.exr: missing"):
        load_pair(list_pairs(pairs_dir, "test", ["blur"])[0])
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "manifest.jsonl").write_text(json.dumps({"item": 0}) + "\n{oops\n")
    with pytest.raises(DataError, match=r"manifest.jsonl:2: not JSON"):
        list_pairs(bad, "train", ["blur"])


def test_ssim_matches_scikit_image():
    from skimage.metrics import structural_similarity
    rng = np.random.default_rng(0)
    a = rng.random((3, 40, 50))
    b = np.clip(a + rng.normal(0, 0.1, a.shape), 0, 1)
    ours = float(ssim(torch.from_numpy(a[None]), torch.from_numpy(b[None])))
    # skimage filters with reflection and crops (win − 1) / 2 = 5 px: the same pixels as our valid region
    ref = structural_similarity(a, b, channel_axis=0, data_range=1.0, gaussian_weights=True, sigma=1.5,
                                use_sample_covariance=False)
    assert ours == pytest.approx(ref, abs=2e-3)
    assert float(ssim(torch.from_numpy(a[None]), torch.from_numpy(a[None]))) == pytest.approx(1.0, abs=1e-12)


def test_losses():
    x = torch.zeros(1, 3, 16, 16)
    assert float(loss_fn("l1")(x, x + 0.25)) == pytest.approx(0.25)
    assert float(loss_fn("l1+ssim")(x + 0.5, x + 0.5)) == pytest.approx(0.0, abs=1e-6)
    with pytest.raises(ValueError, match="loss = 'l2'"):
        loss_fn("l2")
