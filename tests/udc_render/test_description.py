"""The panel's description (udc_render.description): its packing of kernels, its records, its producers (a bank's
panel, a display file or preset, `udc-render fit`'s folder) and its one-line refusals. Tiny rigs (24.8 µm pixels,
128 × 64 frames, 9-px windows) keep the kernels cheap."""
from __future__ import annotations

from dataclasses import replace

import imageio.v3 as iio
import numpy as np
import pytest

from udc_render.cli import main
from udc_render.dataset.bank import read_bank
from udc_render.description import DescriptionError, check_spec, load, packed_window, save, symmetric_modes, window
from udc_render.description.make import describe_display, describe_fit, describe_panel, scene_rig, with_sensor
from udc_render.sensor import SensorConfig

PITCH_UM, FRAME, K = 24.8, (128, 64), 9
TINY = ["--sensor-px", "128,64", "--pitch-um", str(PITCH_UM), "--bands-nm", "400:700:100", "--quiet"]


@pytest.fixture(scope="module")
def rig():
    """The monitor scene's rig at the tiny frame and pitch, γ's band kernels on a 9-px grid (cheap to make)."""
    r = scene_rig(frame_px=FRAME, pitch_um=PITCH_UM)
    return replace(r, grid=replace(r.grid, margin_px=4))


@pytest.fixture(scope="module")
def sensor():
    return SensorConfig(pitch_um=PITCH_UM)


def test_packing_sums_half_one_half_about_the_centre_and_keeps_what_leaves_the_window():
    """A sensor-pitch delta at the centre is a packed delta; 2 px right is 1 packed px right; a pixel between two
    packed centres splits ½ / ½; light past the K window is counted outside, not kept."""
    k = np.zeros((3, 33, 33))
    k[0, 16, 16] = 1.0
    k[1, 16, 18] = 1.0
    k[2, 16, 17], k[2, 16, 0] = 0.9, 0.1  # 0.1 of it 16 px left: packed offset −8, outside a 9-px window
    packed, outside = packed_window(k, K)
    c = K // 2
    assert packed[0, c, c] == 1 and packed[0].sum() == 1
    assert packed[1, c, c + 1] == 1
    np.testing.assert_allclose(packed[2, c, c:c + 2], [0.5, 0.5], rtol=1e-6)
    np.testing.assert_allclose(outside, [0, 0, 0.1], atol=1e-12)
    wide, out = window(packed, 13)  # a smaller kernel is zero-padded, nothing outside
    assert wide.shape == (3, 13, 13) and wide[0, 6, 6] == 1 and np.all(out == 0)
    with pytest.raises(DescriptionError, match="kernel_px = 8: expected an odd number"):
        window(packed, 8)


def test_symmetric_modes_of_known_kernels():
    """dihedral's modes (bit 0 transpose, 1 flip rows, 2 flip columns) a kernel is unchanged by."""
    r = np.arange(9) - 4
    gauss = np.exp(-(r[:, None] ** 2 + r[None, :] ** 2) / 4.0)
    line = np.zeros((9, 9))
    line[4, 1:8] = 1.0
    skew = line.copy()
    skew[4, 7] = 2.0
    assert symmetric_modes(np.stack([gauss] * 3), 1e-3)[0] == tuple(range(8))
    assert symmetric_modes(np.stack([line, gauss, line]), 1e-3)[0] == (0, 2, 4, 6)  # flips, no transpose
    modes, worst = symmetric_modes(np.stack([skew, gauss, gauss]), 1e-3)
    assert modes == (0, 2) and worst[4] == pytest.approx(0.5)  # |2 − 1| / 2: a column flip moves the bright end


@pytest.mark.slow
def test_a_fully_open_display_is_glass_at_its_gain_and_transmission(tmp_path, rig, sensor):
    """Oracle: a display whose micrograph transmits everywhere is the bare lens: its kernels are glass's and
    γ = gain · T (optics.gamma: the same τ(1 − o) as glass) in every channel, to the engine's rasters of the two
    pupils (measured: kernels 1.6e-4 of the peak apart, γ 2.9993–2.9994 for 3). ~25 s: the micrograph's kernels."""
    iio.imwrite(tmp_path / "open.png", np.full((16, 16), 65535, np.uint16))
    (tmp_path / "open.toml").write_text('[display]\nname = "open"\ngain = 6\n[display.layout]\ntype = "micrograph"\n'
                                        'file = "open.png"\npixel_um = 10\n[display.transmission]\ntype = "flat"\n'
                                        'value = 0.5\n')
    d = describe_display(tmp_path / "open.toml", sensor, FRAME, rig, kernel_px=K)
    glass = describe_display("glass", sensor, FRAME, rig, kernel_px=K)
    assert np.abs(d.kernels - glass.kernels).max() < 1e-3 * glass.kernels.max()
    np.testing.assert_allclose(d.gamma_rggb, [3.0] * 4, rtol=1e-3)
    assert d.gain == 6.0 and d.source.startswith("display file")


def test_noise_levels_and_gamma_in_the_inputs_units():
    """Oracle (the fast sibling of the open display's): the photon model in the normalised input's units is
    λ_shot = g / R = gain / FW and λ_read = (gain σ_read / FW)² at the default conversion gain, the full well clips
    at w = gain, γ per packed channel is the panel's (R, G, G, B), the kernels are packed at 2 × the pitch."""
    from udc_render.dataset.bank import Panel
    k = np.zeros((3, 33, 33), np.float32)
    k[:, 16, 16] = 1.0
    s = SensorConfig(pitch_um=PITCH_UM, gain=6.0, read_noise_e=3.0, bit_depth=12, black_level_dn=64)
    d = describe_panel(Panel("p", k, PITCH_UM, (0.5, 0.4, 0.3), s, None, None, None, {}), FRAME, kernel_px=K)
    assert d.noise == "poisson" and d.gamma_rggb == (0.5, 0.4, 0.4, 0.3) and d.gain == 6.0
    np.testing.assert_allclose(d.lambda_shot, [6 / s.full_well_e] * 4, rtol=1e-12)
    np.testing.assert_allclose(d.lambda_read, [(6 * 3.0 / s.full_well_e) ** 2] * 4, rtol=1e-12)
    assert d.saturation == pytest.approx(6.0) and d.pitch_um == 2 * PITCH_UM and d.frame_px == FRAME
    assert (d.bit_depth, d.black_level_dn, d.white_level_dn) == (12, 64, 4095) and d.kernels[:, K // 2, K // 2].all()
    gauss = with_sensor(d, replace(s, noise="gaussian", lambda_source="fixed", lambda_read=1e-5, lambda_shot=2e-3))
    assert gauss.lambda_read == (1e-5,) * 4 and gauss.lambda_shot == (2e-3,) * 4 and gauss.gamma_rggb == d.gamma_rggb
    none = with_sensor(d, replace(s, noise="none"))
    assert none.lambda_read == none.lambda_shot == (0.0,) * 4


def test_a_banks_panel_and_its_display_are_described_alike(tmp_path, rig):
    """The two producers of one display agree: a bank's T-OLED panel (513-px kernels' stand-in: 33 px at the sensor
    pitch, packed) and describe_display of the preset (19 px, packed) differ by the engine's window and λ step:
    kernels within 1e-3 of the peak (measured 3.2e-4), γ, gain and noise equal."""
    out = tmp_path / "bank"
    assert main(["bank", "--display", "toled", "--profile", "paper", "--channel-kernels", "camera", "--kernel-px",
                 "33", "--out", str(out), *TINY]) == 0
    panel = read_bank(out).panels[0]
    a = describe_panel(panel, FRAME, kernel_px=K)
    b = describe_display("toled", panel.sensor, FRAME, rig, kernel_px=K)
    assert np.abs(a.kernels - b.kernels).max() < 1e-3 * b.kernels.max()
    assert a.gamma_rggb == b.gamma_rggb == (0.97,) * 4 and a.gain == b.gain == 6.0
    assert (a.lambda_read, a.lambda_shot, a.noise) == (b.lambda_read, b.lambda_shot, b.noise)
    assert a.spec() == b.spec() and a.source == "bank panel toled" and b.source == "preset toled"


def test_records_travel_and_come_back_whole(tmp_path, rig, sensor):
    """to_record / from_record and save / load give the same description, a field's arrays included."""
    from udc_render.description import FieldDescription
    d = describe_display("poled", sensor, FRAME, rig, kernel_px=K)
    field = FieldDescription(np.ones((3, 2, K, K), np.float32), np.arange(24.0).reshape(3, 4, 2),
                             ((0, 0), (0, 1), (1, 0), (1, 1)), np.array([0.0, 150.0]), np.array([0.0, 160.0]),
                             (300.0, 320.0), 2.0, 6014.0)
    d = replace(d, field=field)
    save(tmp_path / "desc", d)
    for back in (load(tmp_path / "desc"), type(d).from_record(*d.to_record())):
        meta, arrays = back.to_record()
        want_meta, want_arrays = d.to_record()
        assert meta == want_meta and arrays.keys() == want_arrays.keys()
        assert all(np.array_equal(arrays[k], want_arrays[k]) for k in arrays)
        assert back.field.live == field.live and back.field.rank == 2


def test_a_fit_folder_gives_its_sensor_files_noise_and_levels(tmp_path, rig, sensor):
    """describe_fit: display.toml described with sensor.toml's keys (the fit writes the Gaussian model's λ per
    channel, bits and levels) over the given sensor."""
    from udc_render.fit.noise import NoiseFit, sensor_toml
    fit = tmp_path / "fit"
    fit.mkdir()
    (fit / "display.toml").write_text('[display]\nname = "mine"\ngain = 4\n[display.layout]\ntype = "toled"\n')
    noise = NoiseFit(np.array([1e-6, 2e-6, 3e-6, 4e-6]), np.zeros(4), np.array([1e-4, 2e-4, 3e-4, 4e-4]),
                     np.zeros(4), 8, 2, (), 64.0, 4095.0, 12)
    (fit / "sensor.toml").write_text(sensor_toml(noise, "frames"))
    d = describe_fit(fit, sensor, FRAME, rig, kernel_px=K)
    assert d.noise == "gaussian" and d.lambda_read == (1e-6, 2e-6, 3e-6, 4e-6)
    assert d.lambda_shot == (1e-4, 2e-4, 3e-4, 4e-4)
    assert (d.bit_depth, d.black_level_dn, d.white_level_dn, d.gain) == (12, 64, 4095, 4.0)
    assert d.source == f"fit {fit}" and d.name == "mine"


def test_refusals_name_what_differs_or_is_missing(rig, sensor):
    d = describe_display("glass", sensor, FRAME, rig, kernel_px=K)
    check_spec(d.spec(), d)
    with pytest.raises(DescriptionError, match=r"frame_px = \(128, 64\), but the model was made for frame_px = "):
        check_spec(replace(d.spec(), frame_px=(2048, 1024)), d)
    with pytest.raises(DescriptionError, match="white_level_dn = 65535, but"):
        check_spec(replace(d.spec(), white_level_dn=4095), d)
    brooks = replace(sensor, noise="gaussian", lambda_source="brooks")
    with pytest.raises(DescriptionError, match="'brooks': λ is drawn per capture"):
        with_sensor(d, brooks)
