"""Augmentation that respects the panel (restore.augment): dataset pairs take only the flips and transposes the
display's kernel is symmetric under; the online path turns the clean crop before degrading it."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from restore.augment import SYMMETRY_TOLERANCE, display_modes, pair_dataset, pair_modes
from restore.data import PairBatches, PairDataset, augment_crop, dihedral, list_pairs
from restore.degrade import Degrader, blur, normalised
from restore.online import OnlineBatches, clean_images
from restore.train import TrainSettings
from tests.conftest import write_pairs
from udc_render.dataset.bank import Panel, read_bank, save_panel, write_bank_json
from udc_render.description.make import dataset_rig
from udc_render.optics.displays import preset
from udc_render.sensor import SensorConfig
from udc_render.streams import stream

LENS = {"aperture_um": 6000.0 / 1.8, "focal_length_um": 6000.0, "focus_distance_mm": 1276.9973215978162,
        "object_distance_mm": 1276.9973215978162}  # the monitor scene's (synth.json of the default rig)


def with_display_records(data, display: str = "toled", source: str = "preset", gain: float = 1.0):
    """write_pairs' dataset as `udc-render dataset` records it: each capture names its display (a preset or a
    file) and its sensor (1.55 µm pixels, the display's gain), each item its rig (synth.json: the lens, a 9-px kernel
    grid, three bands)."""
    sensor = json.loads(json.dumps(SensorConfig(gain=gain).__dict__))
    for r in (json.loads(line) for line in (data / "manifest.jsonl").read_text().splitlines()):
        item = data / r["folder"]
        for d in r["displays"][1:]:
            (item / d / "capture.json").write_text(json.dumps({"sensor": sensor, "display": {
                "name": display, "source": source}}))
        (item / "synth.json").write_text(json.dumps({"lens": LENS, "kernel_pixel_um": 1.55, "kernel_size_px": 9,
                                                     "render": {"band_edges_nm": [400.0, 500.0, 600.0, 700.0]}}))
    return data


def _worst(why: str) -> list[float]:
    return [float(w) for w in why.split("per mode ")[1].rstrip(")").split(", ")]


def test_the_toled_kernel_allows_its_flips_and_not_the_transpose(tmp_path):
    """The T-OLED's slits are vertical: its kernel spreads along the rows. Flipping rows or columns leaves it as it
    is (every flip allowed); any transpose turns its diffraction vertical, which no T-OLED capture shows: 0.69 of
    the peak at the default rig (docs/guides/train.md)."""
    data = with_display_records(write_pairs(tmp_path / "pairs", splits=(("train", 1),)))
    pair = list_pairs(data, "train", ["blur"])[0]
    modes, why = display_modes(preset("toled"), dataset_rig(pair.folder), SensorConfig().__dict__, (96, 64))
    assert modes == (0, 2, 4, 6) and "toled" in why
    worst = _worst(why)
    assert max(worst[m] for m in (2, 4, 6)) < 1e-3 * SYMMETRY_TOLERANCE  # flips: to the kernels' rounding
    assert all(abs(worst[m] - 0.69) < 0.005 for m in (1, 3, 5, 7))  # transposes: far outside the tolerance
    assert pair_modes(pair) == (modes, why)


@pytest.mark.slow
def test_the_poled_kernel_allows_all_eight(tmp_path):
    """The P-OLED's kernel at the default rig is symmetric under its transposes (5e-8 of the peak) and nearly under
    single flips (3.4e-5, 30× below the tolerance): all eight transforms (docs/guides/train.md). ~60 s cold."""
    data = with_display_records(write_pairs(tmp_path / "pairs", splits=(("train", 1),)), "poled")
    modes, why = pair_modes(list_pairs(data, "train", ["blur"])[0])
    worst = _worst(why)
    assert modes == tuple(range(8)) and max(worst[m] for m in (1, 6, 7)) < 1e-7
    assert all(abs(worst[m] - 3.4e-5) < 0.2e-5 for m in (2, 3, 4, 5))


def test_dataset_crops_draw_only_the_allowed_transforms_and_say_so(tmp_path):
    """A T-OLED dataset's crops are the pairs turned by flips only, each crop's mode drawn among them from its named
    stream; a dataset whose captures name no display keeps the identity. train_summary.json's record says which."""
    plain = write_pairs(tmp_path / "plain", splits=(("train", 3),))
    toled = with_display_records(write_pairs(tmp_path / "toled", splits=(("train", 3),)))
    s = TrainSettings(model={"type": "unet"}, display="blur", crop_px=16, crops_per_pair=4)
    ds = pair_dataset(toled, s)
    assert ds.modes == (0, 2, 4, 6) and PairBatches(ds, 2, 0).record["augment"]["modes"] == [0, 2, 4, 6]
    drawn = set()
    for e in range(3):
        ds.set_epoch(e)
        for i in range(len(ds)):
            rng = stream(0, "pair crop", e, i)
            mode = ds.modes[int(rng.integers(0, 4))]
            x, y = augment_crop(*ds.arrays[i % 3], mode, 16, rng)
            assert all(torch.equal(a, torch.from_numpy(b)) for a, b in zip(ds[i], (x, y)))
            drawn.add(mode)
    assert drawn == {0, 2, 4, 6}
    none = pair_dataset(plain, s)
    assert none.modes == (0,) and "records no display" in PairBatches(none, 2, 0).record["augment"]["why"]
    every = PairDataset(list_pairs(plain, "train", ["blur"]), crop_px=16, seed=3)  # the default: all 8, as before
    assert every.modes == tuple(range(8))


def _rays_panel() -> Panel:
    """A panel whose kernel is two rays from the centre, 4 px right and 2 px down (no flip or transpose keeps it),
    no noise: the degradation is then a function of the scene alone."""
    k = np.zeros((3, 9, 9), np.float32)
    k[:, 4, 4:], k[:, 5:7, 4] = 0.15, 0.125
    sensor = SensorConfig(form="per_channel", gain=2.0, gamma_rggb=(0.25,) * 4, exposure_s=0.03, noise="none")
    return Panel("rays", k, 1.55, (0.5,) * 3, sensor, None, None, None, {"brightness": 1.0})


@pytest.mark.parametrize("mode", [1, 2, 7])
def test_the_online_crop_is_turned_before_it_is_degraded(tmp_path, mode):
    """The online path's input is the capture of the turned scene: it equals degrading the turned clean crop, and
    differs from turning the degraded crop (what a dataset pair's augmentation would give) for this kernel."""
    out = tmp_path / "bank"
    write_bank_json(out, {"frame_px": [64, 48]}, [save_panel(out, 0, _rays_panel())], 1)
    bank = read_bank(out)
    data = write_pairs(tmp_path / "pairs", splits=(("train", 1),), size_px=(48, 64))
    batches = OnlineBatches(clean_images(data, "train"), bank, Degrader(bank.panels), 32, 1, seed=0, workers=0)
    d = dict(batches.draw(0, 0), mode=mode)
    x, y = batches.sample(d)
    m, gt = batches.degrader.margin_px, clean_images(data, "train")[0].pixels
    n = 32 + 2 * m
    scene = np.pad(gt, ((0, 0), (m, m), (m, m)), "reflect")[:, d["y0"]:d["y0"] + n, d["x0"]:d["x0"] + n]
    turned = torch.from_numpy(np.ascontiguousarray(dihedral(scene, mode)))
    dn = batches.degrader.degrade(turned, 0, gt.shape[1:], (d["y0"], d["x0"]))
    assert torch.equal(x, normalised(dn, bank.panels[0]).float()) and torch.equal(y, turned[:, m:-m, m:-m])
    frame, origin = gt.shape[1:], (d["y0"], d["x0"])  # and turning the blurred scene would be another capture:
    blurred = blur(torch.from_numpy(np.ascontiguousarray(scene)), batches.degrader.panels[0], frame, origin)
    assert (blur(turned, batches.degrader.panels[0], frame, origin) - dihedral(blurred, mode)).abs().max() > 0.01
