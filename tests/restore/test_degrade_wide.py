"""The far field and the haze of the online degradation (restore.degrade_wide) against the numpy synthesis.

Oracles: optics.far_field.far_light on the same frame (float64); optics.stray.apply.apply_view's haze on the
exactly blurred frame (optics.convolution, float64) where the veil's cells are pixels; the conservation of light
(the veil keeps what lands on the frame); at b > 1 the veil of the exact blur, measured.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from restore.degrade import Degrader, WideSource
from restore.degrade_wide import WideLight
from restore.online import OnlineBatches, clean_images
from restore.tensors import region
from tests.conftest import write_pairs
from udc_render.dataset.bank import Panel, PanelFar, PanelHaze, read_bank, save_panel, write_bank_json
from udc_render.optics import convolve_bands
from udc_render.optics.far_field import FarField, far_light
from udc_render.optics.stray import Spread, StrayContext, StrayLight, apply_view, convolve
from udc_render.sensor import SensorConfig

PITCH_UM = 24.8  # the tests' tiny sensor: the haze's 2.5° is 10.6 px, so its cells are pixels (b = 1)


def _kernel(size: int, sigma_px: float) -> np.ndarray:
    r = np.arange(size) - size // 2
    k = np.exp(-(r[:, None] ** 2 + r[None, :] ** 2) / (2 * sigma_px ** 2))
    return np.repeat((k / k.sum())[None], 3, axis=0)


def _far(coarse: int = 3, size: int = 9) -> PanelFar:
    """A far field of a few percent per channel with a ring: light spread past a 9-px core."""
    r = np.hypot(*np.meshgrid(np.arange(size) - size // 2, np.arange(size) - size // 2))
    ring = np.where((r >= 2) & (r <= 4), 1.0 / (1.0 + r), 0.0)
    return PanelFar(np.stack([s * ring / ring.sum() for s in (0.08, 0.06, 0.05)]), coarse)


def _panel(far=None, haze=None, pitch_um=PITCH_UM, kernel_px=9, sensor=None) -> Panel:
    sensor = sensor or SensorConfig(form="per_channel", noise="none", gain=4.0, gamma_rggb=(0.1,) * 4,
                                    pitch_um=pitch_um)
    return Panel("p", _kernel(kernel_px, 1.5).astype(np.float32), pitch_um, (0.4,) * 3, sensor, None, None, None, {},
                 far=far, haze=haze)


def _frame(h=32, w=48, seed=0) -> np.ndarray:
    """A dark frame with a bright square and texture: what a veil shows."""
    x = 0.02 * np.random.default_rng(seed).random((3, h, w))
    x[:, 8:16, 10:22] += 0.9
    return x


def test_the_far_field_is_far_light():
    """The far field of crops of a frame equals optics.far_field.far_light on the frame with the same mirrored margin
    (float64, 4e-14 of the peak: 100× the 4.0e-16 measured), through its rows and columns and whatever the crop's
    place."""
    f, m, x = _far(), 4, _frame()
    H, W = x.shape[1:]
    ext = region(torch.from_numpy(x), -m, -m, H + 2 * m, W + 2 * m).numpy()
    ff = FarField(f.kernels, f.coarse_px, PITCH_UM, *(np.zeros(3),) * 3, np.ones(3, bool), 1e9, 0.0, 0.0)
    ref = far_light(ext, ff, m, np.eye(3))
    wide = WideLight([_panel(far=f)], m, torch.device("cpu"), torch.float64)
    for (y0, x0), (h, w) in (((0, 0), (H, W)), ((10, 14), (12, 20)), ((20, 0), (12, 48))):
        far, veil = wide.crops([0], [((H, W), (y0, x0))], [WideSource("x", torch.from_numpy(x))], (h, w))
        assert veil == [None]
        np.testing.assert_allclose(far[0].numpy(), ref[:, y0:y0 + h, x0:x0 + w], rtol=0, atol=4e-14 * ref.max())
    assert ref.sum() > 0.03 * x.sum()  # the far field brings light: a share of the frame's, as F's


def test_the_haze_is_the_stray_lights_where_its_cells_are_pixels():
    """b = 1: the veil of a d = 0 panel with a far field equals optics.stray's haze (apply_view) on the frame's
    exact blur plus far light (float64, 1e-14 of the peak: 300× the 3.1e-17 measured): e ← (1 − h) e + h (e ⊗ ρ)."""
    f, haze, m, x = _far(), PanelHaze(0.02, 2.5), 4, _frame()
    H, W = x.shape[1:]
    panel = _panel(far=f, haze=haze)
    ext = region(torch.from_numpy(x), -m, -m, H + 2 * m, W + 2 * m).numpy()
    ff = FarField(f.kernels, f.coarse_px, PITCH_UM, *(np.zeros(3),) * 3, np.ones(3, bool), 1e9, 0.0, 0.0)
    y = convolve_bands(ext, panel.kernels.astype(np.float64), m, None, "float64") + far_light(ext, ff, m, np.eye(3))
    ctx = StrayContext(np.array([400.0, 700.0]), panel.sensor, False, np.ones(1))
    ref, rec = apply_view(StrayLight(haze={"p": haze.share}), y, "p", False, np.ones(1), ctx)
    assert rec["haze"]["coarse_px"] == 1
    wide = WideLight([panel], m, torch.device("cpu"), torch.float64)
    far, veil = wide.crops([0], [((H, W), (0, 0))], [WideSource("x", torch.from_numpy(x))], (H, W))
    ours = (1 - haze.share) * y + haze.share * veil[0].numpy()
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-14 * ref.max())


def _hazy_and_clear(x: np.ndarray, h_share: float, m: int = 4) -> tuple[np.ndarray, np.ndarray, Panel]:
    """(hazy DN, clear DN, the clear panel) of the whole frame x through the Degrader (noise 'none', float64)."""
    H, W = x.shape[1:]
    clear = _panel()
    deg = Degrader([clear, replace(clear, haze=PanelHaze(h_share, 2.5))], "cpu", torch.float64)
    ext = region(torch.from_numpy(x), -m, -m, H + 2 * m, W + 2 * m)
    dn = [deg.degrade(ext, i, (H, W), (0, 0), source=WideSource("x", torch.from_numpy(x))).numpy() for i in (1, 0)]
    return dn[0], dn[1], clear


def test_the_haze_moves_its_share_into_a_veil():
    """Through the Degrader (noise 'none', float64, grey frames): a bright square on black loses about h of its
    light and every site 6 px and more from it gains; on a textured grey ground the frame loses h (1 − landed) of its
    light, landed the share of the veil that stays on the frame (optics.stray.spread.convolve's), to the DN's
    rounding (4 σ of the sum of the sites' rounding errors, each uniform in ±0.5 DN)."""
    h_share, m = 0.02, 4
    x = np.zeros((3, 32, 48))
    x[:, 8:16, 10:22] = 0.9
    hazy, clear, panel = _hazy_and_clear(x, h_share)
    moved = hazy - clear
    inside, away = np.zeros((16, 24), bool), np.ones((16, 24), bool)
    inside[4:8, 5:11], away[1:11, 2:14] = True, False  # the square's sites; those 6 px and more from it
    ratio = moved[:, inside].sum() / clear[:, inside].sum()
    assert -h_share <= ratio <= -0.9 * h_share and (moved[:, away] >= 0).all() and moved[:, away].max() > 2, ratio
    x += 0.2 + 0.05 * np.random.default_rng(1).random((1, 32, 48))  # texture: the sites' roundings independent
    hazy, clear, panel = _hazy_and_clear(x, h_share)
    ext = region(torch.from_numpy(x), -m, -m, 32 + 2 * m, 48 + 2 * m).numpy()
    y = convolve_bands(ext, panel.kernels.astype(np.float64), m, None, "float64")
    _, landed, _ = convolve(y[:1], Spread("tail", panel.sensor.focal_length_um, inner_deg=2.5), PITCH_UM)
    expected = -h_share * (1 - landed) * clear.sum()
    assert (hazy - clear).sum() == pytest.approx(expected, abs=4 * np.sqrt(2 * clear.size / 12)), landed


def test_a_crop_needs_its_frame_and_is_turned_with_it():
    """A panel with a far field refuses a crop without its frame in one line; a crop turned by a dihedral mode gets
    its wide light turned the same way."""
    f, m, x = _far(), 4, _frame()
    H, W = x.shape[1:]
    deg = Degrader([_panel(far=f)], "cpu", torch.float64)
    ext = region(torch.from_numpy(x), -m, -m, H + 2 * m, W + 2 * m)
    with pytest.raises(ValueError, match="needs its whole clean frame of 32 × 48 px"):
        deg.degrade(ext[:, :20, :20], 0, (H, W), (0, 0))
    wide = WideLight([_panel(far=f)], m, torch.device("cpu"), torch.float64)
    plain = wide.crops([0], [((H, W), (4, 6))], [WideSource("x", torch.from_numpy(x))], (12, 12))[0][0]
    turned = wide.crops([0], [((H, W), (4, 6))], [WideSource("x", torch.from_numpy(x), 0.5, 3)], (12, 12))[0][0]
    assert torch.equal(turned, 0.5 * plain.transpose(-1, -2).flip(-2))


def test_the_veil_of_coarse_cells_is_the_exact_blurs():
    """At 1.55 µm (the haze's 2.5° is 169 px: 8-px cells) the veil made from the clean frame's cells through the
    kernel binned to them is within 1e-3 of its peak of the veil of the exact blur (measured 7.2e-4; the clean
    frame's cells unblurred: 4.4e-2), with a kernel of orders 28 px apart, as a P-OLED's, on the astronaut."""
    from skimage import data
    x = np.ascontiguousarray(data.astronaut()[128:384].transpose(2, 0, 1) / 255.0) ** 2.2  # 256 × 512
    k = np.zeros((129, 129))
    for oy, ox in np.ndindex(5, 5):  # a core and its orders, each a Gaussian of σ 2 px
        r = np.arange(129) - 64
        k += (1.0 if (oy, ox) == (2, 2) else 0.15 / ((oy - 2) ** 2 + (ox - 2) ** 2)) * np.exp(
            -((r[:, None] - 28 * (oy - 2)) ** 2 + (r[None, :] - 28 * (ox - 2)) ** 2) / 8.0)
    panel = replace(_panel(haze=PanelHaze(0.015, 2.5), pitch_um=1.55), kernels=np.repeat(k[None] / k.sum(), 3, 0))
    m, (H, W) = 64, x.shape[1:]
    ext = region(torch.from_numpy(x), -m, -m, H + 2 * m, W + 2 * m).numpy()
    y = convolve_bands(ext, panel.kernels, m, None, "float64")
    ref, _, b = convolve(y, Spread("tail", panel.sensor.focal_length_um, inner_deg=2.5), 1.55)
    veil = WideLight([panel], m, torch.device("cpu"), torch.float64).crops(
        [0], [((H, W), (0, 0))], [WideSource("x", torch.from_numpy(x))], (H, W))[1][0].numpy()
    assert b == 8 and np.abs(veil - ref).max() <= 1e-3 * ref.max()


def test_online_batches_through_a_hazy_panel_are_the_same_in_a_worker(tmp_path):
    """restore.online: crops through a panel with a far field and a haze get their frames' wide light, the same
    numbers in the process and in a worker process (the frames' sums made before it forks), and other numbers
    than through the same panel without either."""
    data = write_pairs(tmp_path / "pairs", splits=(("train", 2),), size_px=(48, 64))
    sensor = SensorConfig(form="per_channel", gain=4.0, gamma_rggb=(0.1,) * 4, exposure_s=0.03, pitch_um=PITCH_UM)
    wide = _panel(far=_far(), haze=PanelHaze(0.02, 2.5), sensor=sensor)
    for name, panel in (("wide", wide), ("plain", replace(wide, far=None, haze=None))):
        write_bank_json(tmp_path / name, {"test": name}, [save_panel(tmp_path / name, 0, panel)], 1)
    batches = {}
    for name, workers in (("wide", 0), ("wide", 1), ("plain", 0)):
        b = read_bank(tmp_path / name)
        ob = OnlineBatches(clean_images(data, "train"), b, Degrader(b.panels), 32, 2, seed=0, workers=workers)
        batches[name, workers] = next(ob.epoch(0)[1])
    assert all(torch.equal(a, b) for a, b in zip(batches["wide", 0], batches["wide", 1]))
    assert not torch.equal(batches["wide", 0][0], batches["plain", 0][0])
    assert torch.equal(batches["wide", 0][1], batches["plain", 0][1])  # the targets: the clean crops
