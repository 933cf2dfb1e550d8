"""The online degradation in torch (restore.degrade) against the numpy synthesis it stands for.

Oracles: `synth --form per_channel` (udc_render.pipeline.synthesize) on a tiny monitor scene, its noise replayed
from its own seed (the same Poisson counts and normals, fed as a NoiseDraw); optics.field.convolve_field for the
d > 0 blend; sensor.fpn.fpn_maps and sensor.defects.defect_map for the frame maps; the Poisson–Gaussian moments
for the generator's own draws.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from psf import compute_kernels, layouts
from restore.degrade import Degrader, NoiseDraw, TorchPanel, blur, normalised
from restore.degrade_sensor import FrameMaps
from udc_render.dataset.bank import Panel
from udc_render.dataset.bank_make import panel_field, sensor_grid
from udc_render.optics import convolve_field, displays as D, field_basis, field_power_map, field_weights, live_phases
from udc_render.pipeline import SynthConfig, noise_seed, plan_kernels, sensor_for_scene, synthesize
from udc_render.render import render_scene
from udc_render.scene.geometry import psf_lens
from udc_render.sensor import DefectConfig, FpnConfig, SensorConfig, electrons_rgb, pack_rggb, readout
from udc_render.sensor.defects import defect_map
from udc_render.sensor.fpn import fpn_maps, mean_charge_e

DISPLAYS = [D.preset("toled"), D.preset("poled")]
DEFECTS = DefectConfig(dead_fraction=0.01, hot_fraction=0.01)  # many, so that both kinds fall in the tiny frame


@pytest.fixture(scope="module")
def tiny_scene(udc, tmp_path_factory):
    """A 128 × 64 px monitor scene of the astronaut (24.8 µm pixels, 3 bands, 33-px kernels), not rendered: the
    field and CUDA tests need its geometry alone (and run where Mitsuba is absent)."""
    folder = tmp_path_factory.mktemp("degrade")
    return udc.write_scene(folder / "s.toml", udc.monitor_doc(image="builtin:astronaut",
                                                              bands={"range_nm": [400, 700], "step_nm": 100}))


@pytest.fixture(scope="module")
def tiny(tiny_scene, render_cache):
    """The tiny scene rendered once, and its kernel cache folder."""
    return tiny_scene, render_scene(tiny_scene, progress=False), str(tiny_scene.resolve("kernels"))


def _synth(tiny, noise: str):
    """The numpy per-channel synthesis (float64 optics, defects and FPN) and the clean RGB it blurred."""
    scene, bi, cache = tiny
    sensor = SensorConfig(noise=noise, lambda_source="sensor" if noise == "gaussian" else "fixed")
    cfg = SynthConfig(form="per_channel", channel_kernels="paper", precision="float64", defects=DEFECTS,
                      fpn=FpnConfig(), sensor=sensor, kernel_cache=cache)
    kernels = plan_kernels(scene, DISPLAYS, cfg)
    res = synthesize(bi, scene, DISPLAYS, cfg, kernels=kernels)
    base = replace(sensor_for_scene(cfg.sensor, scene), exposure_s=res.meta["exposure_s"])
    rgb = (electrons_rgb(bi.bands, bi.edges_nm, base) / base.full_well_e).astype(np.float32)  # as the pipeline's
    return cfg, kernels, res, rgb


def _panel(name, kernels, pitch_um, gamma, sensor, cfg, field=None):
    return Panel(name, np.asarray(kernels, np.float32), pitch_um, tuple(gamma), sensor, cfg.defects, cfg.fpn, field, {})


def _replayed_draw(cap, cfg, sensor: SensorConfig, name: str) -> NoiseDraw:
    """The numpy capture's own draws, from its noise seed: Poisson counts of the mean charge, then normals."""
    rng = np.random.default_rng(noise_seed(cfg.seed, 0, name))
    e = cap.electrons
    if sensor.noise != "poisson":
        return NoiseDraw(None, torch.from_numpy(pack_rggb(rng.standard_normal(e.shape))))
    q = mean_charge_e(e, fpn_maps(*e.shape, cfg.fpn), cfg.fpn, sensor.exposure_s)
    shot = rng.poisson(np.minimum(q, readout.poisson_cap_e(sensor.full_well_e, sensor.read_noise_e))).astype(float)
    return NoiseDraw(torch.from_numpy(pack_rggb(shot)), torch.from_numpy(pack_rggb(rng.normal(0.0, 1.0, e.shape))))


@pytest.mark.parametrize("noise", ["poisson", "gaussian", "none"])
def test_equals_the_per_channel_synthesis(tiny, noise):
    """Same kernels, clean input and noise draw: float64 gives the numpy capture's DN exactly (every pixel; dead,
    hot, FPN included); float32 differs by at most 1 DN (a rounding tie) on at most 0.5 % of the pixels."""
    cfg, kernels, res, rgb = _synth(tiny, noise)
    scene, bi, _ = tiny
    for d in DISPLAYS:
        cap = res.captures[d.name]
        sensor = SensorConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in cap.params["sensor"].items()})
        panel = _panel(d.name, kernels.channel[d.name].kernels, bi.pitch_um, res.display_meta[d.name]["gamma_rgb"],
                       sensor, cfg)
        draw = _replayed_draw(cap, cfg, sensor, d.name)
        ref = pack_rggb(cap.mosaic_dn).astype(np.float64)
        frame = cap.mosaic_dn.shape
        dn64 = Degrader([panel], "cpu", torch.float64).degrade(torch.from_numpy(rgb), 0, frame, (0, 0), draw=draw)
        np.testing.assert_array_equal(dn64.numpy(), ref)
        assert (ref == sensor.black_level_dn).any() and ref.max() > 0  # dead pixels and signal are there
        dn32 = Degrader([panel], "cpu", torch.float32).degrade(torch.from_numpy(rgb), 0, frame, (0, 0), draw=draw)
        diff = np.abs(dn32.double().numpy() - ref)
        assert diff.max() <= 1 and (diff > 0).mean() <= 0.005, (d.name, noise, diff.max(), (diff > 0).mean())


def test_electrons_and_blur_equal_the_numpy_path(tiny):
    """Without noise or quantisation: the blur of the clean RGB equals convolve_bands' (float64, 1e-12 relative)."""
    from udc_render.optics import convolve_bands
    cfg, kernels, res, rgb = _synth(tiny, "none")
    scene, bi, _ = tiny
    k = kernels.channel["toled"].kernels
    ref = convolve_bands(rgb, k, bi.margin_px, None, "float64")
    tp = TorchPanel(_panel("toled", k, bi.pitch_um, (1, 1, 1), SensorConfig(), cfg), "cpu", torch.float64)
    y = blur(torch.from_numpy(rgb).double(), tp, ref.shape[1:], (0, 0)).numpy()
    assert np.abs(y - ref).max() <= 1e-12 * np.abs(ref).max()


@pytest.fixture(scope="module")
def field_kernels(tiny_scene):
    """Kernels at 450 / 520 / 640 nm through the T-OLED at d = 2 mm, 4 × 4 field phases, 33 px (a stand-in for
    the channels: the blend's algebra does not care how the three kernel sets were weighted)."""
    scene = tiny_scene
    frame_um = (scene.sensor.width_px * scene.sensor.pitch_um, scene.sensor.height_px * scene.sensor.pitch_um)
    return compute_kernels(layouts.toled(), psf_lens(scene), (450.0, 520.0, 640.0), pixel_um=scene.sensor.pitch_um,
                           size_px=33, distance_mm=2.0, sensor_um=frame_um)


@pytest.mark.parametrize("rank", [4, None])
def test_field_blend_equals_convolve_field(tiny_scene, field_kernels, rank):
    """d > 0: the panel's rank-r (or exact) blend with the exact power map equals optics.field.convolve_field on the
    frame with its margins (float64 1e-12, float32 1e-5 of the peak), and a crop of the frame equals the crop of
    the whole frame's result (the field follows the crop's place)."""
    scene = tiny_scene
    ks, grid = field_kernels, sensor_grid(scene, 33)
    m, H, W = grid.margin_px, scene.sensor.height_px, scene.sensor.width_px
    shape = (H + 2 * m, W + 2 * m)
    x = np.random.default_rng(0).random((3,) + shape)
    wy, wx, g = field_weights(ks, shape, grid.pitch_um, 2.0)
    pm = field_power_map(ks, shape, grid.pitch_um, 2.0, g["image_distance_um"], g["period_um"])
    basis = None if rank is None else field_basis(ks.field_kernels, live_phases(wy, wx), rank)
    ref, _ = convolve_field(x, ks.field_kernels, ks.field_power, wy, wx, m, None, "source", "float64", rank=rank,
                            basis=basis, power_map=pm)
    field = panel_field(ks, scene, grid, rank)
    assert field.rank == (rank or 16) and field.series is not None
    panel = _panel("toled", ks.kernels, grid.pitch_um, (1, 1, 1), SensorConfig(), SynthConfig(), field)
    for dtype, tol in ((torch.float64, 1e-12), (torch.float32, 1e-5)):
        tp = TorchPanel(panel, "cpu", dtype)
        y = blur(torch.from_numpy(x), tp, (H, W), (0, 0)).double().numpy()
        assert np.abs(y - ref).max() <= tol * np.abs(ref).max(), dtype
        y0, x0, h, w = 10, 36, 32, 48
        crop = blur(torch.from_numpy(x[:, y0:y0 + h + 2 * m, x0:x0 + w + 2 * m]), tp, (H, W), (y0, x0)).double().numpy()
        assert np.abs(crop - y[:, y0:y0 + h, x0:x0 + w]).max() <= tol * np.abs(ref).max(), dtype


def _mixed_panels(scene, field_kernels) -> list[Panel]:
    """d = 0 and d > 0 panels (33-px kernels) with Poisson noise, FPN and defects; Brooks' Gaussian noise; no
    noise with cos⁴; two gains, two black levels."""
    grid = sensor_grid(scene, 33)
    ks = field_kernels
    field = panel_field(ks, scene, grid, 4)
    noisy = SynthConfig(defects=DEFECTS, fpn=FpnConfig())
    sensors = [SensorConfig(form="per_channel", gain=6.0, gamma_rggb=(0.16,) * 4),
               SensorConfig(form="per_channel", noise="gaussian", lambda_source="brooks", black_level_dn=64),
               SensorConfig(form="per_channel", noise="none", cos4_falloff=True, gain=25.0, gamma_rggb=(0.03,) * 4)]
    return [_panel("flat", ks.kernels, grid.pitch_um, (0.97,) * 3, sensors[0], noisy),
            _panel("banded", ks.kernels, grid.pitch_um, (0.97,) * 3, sensors[0], noisy, field),
            _panel("gauss", ks.kernels, grid.pitch_um, (0.9,) * 3, sensors[1], SynthConfig()),
            _panel("cos4", ks.kernels, grid.pitch_um, (0.5,) * 3, sensors[2], noisy, field)]


def _batch_and_alone(panels, device: str, dtype) -> tuple[torch.Tensor, torch.Tensor, list[int]]:
    """(degrade_batch of six crops (corners of a 64 × 128 frame, all four panels), each crop degraded alone with the
    same generator seed, the crops' panel indices), on the device."""
    frame, h, w, m = (64, 128), 32, 48, 16
    origins = [(0, 0), (32, 80), (10, 36), (0, 80), (32, 0), (20, 40)]
    indices = [0, 1, 2, 3, 1, 0]
    x = torch.from_numpy(np.random.default_rng(3).random((len(origins), 3, h + 2 * m, w + 2 * m)) * 0.6).to(dtype)
    deg = Degrader(panels, device, dtype, batched=True)
    batch = deg.degrade_batch(x.to(device), indices, [(frame, o) for o in origins],
                              [torch.Generator(device).manual_seed(s) for s in range(len(origins))])
    alone = torch.stack([deg.degrade(x[b].to(device), i, frame, o, torch.Generator(device).manual_seed(b))
                         for b, (i, o) in enumerate(zip(indices, origins))])
    assert batch.shape == (6, 4, h // 2, w // 2) and batch.max() > 0
    return batch.cpu(), alone.cpu(), indices


def test_a_batch_gives_each_crop_its_own_numbers(tiny_scene, field_kernels):
    """On the CPU, degrade_batch of crops through mixed panels (_mixed_panels; crops in the frame's corners) gives
    each crop exactly the DN of that crop degraded alone with the same generator, in float32 and float64:
    batching changes the launches, not the numbers (restore.online's batches and its worker processes' single
    crops agree)."""
    panels = _mixed_panels(tiny_scene, field_kernels)
    for dtype in (torch.float32, torch.float64):
        batch, alone, indices = _batch_and_alone(panels, "cpu", dtype)
        assert torch.equal(batch, alone), (dtype, (batch - alone).abs().max())
        np.testing.assert_array_equal(normalised(batch, [panels[i] for i in indices]).numpy(),
                                      torch.stack([normalised(a, panels[i]) for a, i in zip(alone, indices)]).numpy())
    assert not Degrader(panels).batched  # on the CPU, crop by crop by default
    with pytest.raises(ValueError, match="one size per batch"):
        small = replace(panels[0], kernels=panels[0].kernels[:, 8:-8, 8:-8])
        Degrader([panels[0], small]).degrade_batch(torch.zeros(2, 3, 64, 64), [0, 1], [((64, 64), (0, 0))] * 2)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_a_batch_on_a_gpu_gives_each_crop_its_numbers(tiny_scene, field_kernels):
    """On a GPU (batched by default), the mixed batch's DN equal each crop's alone but for rounding ties: at most
    1 DN on at most 0.5 % of the sites in float32, none in float64 (cuFFT's batched plans may round otherwise
    than a single transform's)."""
    panels = _mixed_panels(tiny_scene, field_kernels)
    assert Degrader(panels, "cuda").batched
    for dtype, share in ((torch.float32, 0.005), (torch.float64, 0.0)):
        batch, alone, _ = _batch_and_alone(panels, "cuda", dtype)
        diff = (batch - alone).abs()
        assert diff.max() <= 1 and (diff > 0).double().mean() <= share, (dtype, diff.max(), (diff > 0).double().mean())


def test_frame_maps_are_the_sensors():
    """The FPN and defect maps of crops are the regions of sensor.fpn.fpn_maps / sensor.defects.defect_map, each
    crop its own sensor's (two seeds in one batch)."""
    fpns = [FpnConfig(seed=7, prnu=0.2), FpnConfig(seed=8, prnu=0.1, row_offset_e=2.0)]
    defects = [DefectConfig(dead_fraction=0.05, hot_fraction=0.1, seed=3), DefectConfig(dead_fraction=0.1, seed=4)]
    frame, origins = (40, 60), [(8, 14), (20, 0)]
    maps = FrameMaps(torch.device("cpu"), torch.float64)
    gain, offset = maps.fpn([(frame, o) for o in origins], (20, 30), fpns)
    kind = maps.defect_classes([(frame, o) for o in origins], (20, 30), defects).numpy()
    for b, ((y0, x0), fpn, d) in enumerate(zip(origins, fpns, defects)):
        ref = fpn_maps(*frame, fpn)
        np.testing.assert_array_equal(gain[b].numpy(), pack_rggb(ref.gain[y0:y0 + 20, x0:x0 + 30]))
        np.testing.assert_array_equal(offset[b].numpy(), pack_rggb(ref.offset_e[y0:y0 + 20, x0:x0 + 30]))
        np.testing.assert_array_equal(kind[b], pack_rggb(defect_map(*frame, d)[y0:y0 + 20, x0:x0 + 30]))
    assert (kind[0] == 1).any() and (kind[0] == 2).any()


def test_generator_noise_has_the_poisson_gaussian_moments():
    """A flat field through a delta kernel at gain 1: mean DN = g e, variance g² (e + σ²) + 1/12 (Poisson shot,
    Gaussian read noise, rounding) within 5 %; the same seed gives the same DN, another seed other DN."""
    k = np.zeros((3, 5, 5), np.float32)
    k[:, 2, 2] = 1
    sensor = SensorConfig(form="per_channel")
    deg = Degrader([_panel("flat", k, 1.55, (1, 1, 1), sensor, SynthConfig())], "cpu", torch.float64)
    x = torch.full((3, 132, 132), 0.3, dtype=torch.float64)
    dn = [deg.degrade(x, 0, (128, 128), (0, 0), torch.Generator().manual_seed(s)) for s in (1, 1, 2)]
    g, e = sensor.dn_per_electron, 0.3 * sensor.full_well_e
    assert abs(dn[0].mean().item() / (g * e) - 1) < 0.005
    assert abs(dn[0].var().item() / (g * g * (e + sensor.read_noise_e ** 2) + 1 / 12) - 1) < 0.05
    assert torch.equal(dn[0], dn[1]) and not torch.equal(dn[0], dn[2])
    assert abs(normalised(dn[0], deg.panels[0].panel).mean().item() - 0.3) < 0.0015


def test_bad_crops_are_refused():
    k = np.zeros((3, 5, 5), np.float32)
    k[:, 2, 2] = 1
    deg = Degrader([_panel("flat", k, 1.55, (1, 1, 1), SensorConfig(form="per_channel"), SynthConfig())])
    with pytest.raises(ValueError, match="whole RGGB cells"):
        deg.degrade(torch.zeros(3, 13, 14), 0, (64, 64), (0, 0))
    with pytest.raises(ValueError, match="leaves the 64 × 64 px frame"):
        deg.degrade(torch.zeros(3, 14, 14), 0, (64, 64), (60, 0))
    for x, indices in ((torch.zeros(0, 3, 14, 14), []), (torch.zeros(2, 3, 14, 14), [0])):
        with pytest.raises(ValueError, match="expected one of each per crop, at least one crop"):
            deg.degrade_batch(x, indices, [((64, 64), (0, 0))] * len(indices))


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_equals_cpu(tiny_scene, field_kernels):
    """The one code path on a GPU (d > 0, FPN, defects): its blur within 1e-12 of the CPU's (float64), the same DN
    for the same draw, and its own generator's draws on the device."""
    scene = tiny_scene
    grid = sensor_grid(scene, 33)
    panel = _panel("toled", field_kernels.kernels, grid.pitch_um, (0.97, 0.97, 0.97), SensorConfig(form="per_channel"),
                   SynthConfig(defects=DEFECTS, fpn=FpnConfig()), panel_field(field_kernels, scene, grid, 4))
    x = torch.from_numpy(np.random.default_rng(1).random((3, 64 + 32, 128 + 32)))
    draw = NoiseDraw(torch.full((4, 32, 64), 100.0, dtype=torch.float64), torch.randn(4, 32, 64, dtype=torch.float64))
    cpu, gpu = Degrader([panel], "cpu", torch.float64), Degrader([panel], "cuda", torch.float64)
    y_cpu = blur(x, cpu.panels[0], (64, 128), (0, 0))
    y_gpu = blur(x.cuda(), gpu.panels[0], (64, 128), (0, 0)).cpu()
    assert (y_gpu - y_cpu).abs().max() <= 1e-12 * y_cpu.abs().max()
    assert torch.equal(cpu.degrade(x, 0, (64, 128), (0, 0), draw=draw),
                       gpu.degrade(x, 0, (64, 128), (0, 0), draw=draw).cpu())
    dn = gpu.degrade(x, 0, (64, 128), (0, 0), torch.Generator("cuda").manual_seed(0))
    assert dn.is_cuda and torch.isfinite(dn).all() and dn.max() > 0
