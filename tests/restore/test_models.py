"""Restoration models: the paper's parameter and MAC counts, shapes, padding, configs, training."""
from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F
from torch import nn

from restore.counting import count_macs, count_parameters, mac_breakdown
from restore.models import (
    MODELS,
    RESNET_CONFIG,
    UNET_CONFIG,
    UNET_SINGLE_ENCODER_CONFIG,
    ModelConfigError,
    ResNet,
    UNet,
    build_model,
    load_config,
    model_config,
)


@pytest.fixture(autouse=True, scope="module")
def _one_thread():
    """Tiny models on a shared 2-core machine: one thread is 10× faster than two under load."""
    old = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(old)


def _meta_parameters(config: dict) -> int:
    with torch.device("meta"):
        return count_parameters(build_model(config))


def _conv(cin, cout, k, pixels):
    """(parameters, MACs) of a k × k convolution (bias included in the parameters only)."""
    return cin * cout * k * k + cout, cin * cout * k * k * pixels


def _unet_oracle(width, depth, second_levels, h, w):
    """(parameters, MACs) of the SID UNet with a second encoder over `second_levels` levels, summed by hand."""
    ch = [width * 2 ** i for i in range(depth)]
    cin = [4] + ch[:-1]
    px = [h * w // 4 ** i for i in range(depth)]
    parts = []
    for i in range(depth):
        n = 1 + (i < second_levels)
        parts += [_conv(cin[i], ch[i], 3, px[i])] * n + [_conv(ch[i], ch[i], 3, px[i])] * n
    for i in range(depth - 1):
        parts += [_conv(ch[i + 1], ch[i], 2, px[i + 1]),          # ConvTranspose2d: per input pixel
                  _conv(2 * ch[i], ch[i], 3, px[i]), _conv(ch[i], ch[i], 3, px[i])]
    parts.append(_conv(ch[0], 12, 1, px[0]))
    return sum(p for p, _ in parts), sum(m for _, m in parts)


# ---------------------------------------------------------------- full-size counts (meta device)


def test_unet_matches_paper_baseline():
    params, macs = _meta_parameters(UNET_CONFIG), count_macs(UNET_CONFIG)
    assert abs(params / 8.93e6 - 1) < 0.01 and abs(macs / 124.36e9 - 1) < 0.02
    assert (params, macs) == (8_933_292, 124_084_289_536)
    assert (params, macs) == _unet_oracle(32, 5, 4, 512, 1024)


def test_unet_single_encoder_and_double_width_match_paper_ablation():
    params, macs = _meta_parameters(UNET_SINGLE_ENCODER_CONFIG), count_macs(UNET_SINGLE_ENCODER_CONFIG)
    assert abs(params / 7.76e6 - 1) < 0.01 and abs(macs / 97.09e9 - 1) < 0.02
    assert (params, macs) == _unet_oracle(32, 5, 0, 512, 1024)
    wide = {**UNET_SINGLE_ENCODER_CONFIG, "width": 64}
    assert abs(_meta_parameters(wide) / 31.03e6 - 1) < 0.01 and abs(count_macs(wide) / 386.37e9 - 1) < 0.02


def test_two_full_encoder_copies_do_not_match_paper():
    full = {**UNET_CONFIG, "second_encoder_levels": 5}
    params, macs = _meta_parameters(full), count_macs(full)
    assert (params, macs) == _unet_oracle(32, 5, 5, 512, 1024)
    assert params == 12_473_260 and abs(params / 8.93e6 - 1) > 0.3


def test_unet_second_encoder_is_the_paper_increment():
    parts = mac_breakdown(UNET_CONFIG)
    assert sum(parts.values()) == count_macs(UNET_CONFIG)
    assert abs(parts["residual_encoder"] / (124.36e9 - 97.09e9) - 1) < 0.01
    assert parts["residual_encoder"] == count_macs(UNET_CONFIG) - count_macs(UNET_SINGLE_ENCODER_CONFIG)


def test_resnet_counts_and_structure():
    params, macs = _meta_parameters(RESNET_CONFIG), count_macs(RESNET_CONFIG)
    assert (params, macs) == (1_370_435, 719_943_892_992)                 # paper: 1.37 M, 721.76 G
    assert abs(params / 1.37e6 - 1) < 0.01 and abs(macs / 721.76e9 - 1) < 0.01
    shuffle = {**RESNET_CONFIG, "tail": "shuffle"}
    assert (_meta_parameters(shuffle), count_macs(shuffle)) == (1_227_916, 642_634_481_664)
    m = ResNet()
    convs = [c for c in m.body.modules() if isinstance(c, nn.Conv2d)]
    assert len(convs) == 2 * 16 + 1 and all(c.in_channels == c.out_channels == 64 for c in convs)
    assert mac_breakdown(RESNET_CONFIG)["body"] == 33 * 64 * 64 * 9 * 512 * 1024


def test_no_batch_norm():
    for m in (UNet(width=4), ResNet(features=8, blocks=2)):
        assert not any(isinstance(x, nn.modules.batchnorm._BatchNorm) for x in m.modules())


# ---------------------------------------------------------------- shapes and padding


@pytest.mark.parametrize("shape", [(1, 4, 1, 1), (1, 4, 7, 13), (2, 4, 64, 48)])
@pytest.mark.parametrize("config", [{"type": "unet", "width": 4},
                                    {"type": "unet", "width": 4, "sub_encoders": 1},
                                    {"type": "unet", "width": 4, "second_encoder_levels": 5},
                                    {"type": "resnet", "features": 8, "blocks": 2},
                                    {"type": "resnet", "features": 8, "blocks": 2, "tail": "shuffle"}])
def test_output_shape(config, shape):
    torch.manual_seed(0)
    with torch.inference_mode():
        y = build_model(config)(torch.rand(shape))
    n, _, h, w = shape
    assert y.shape == (n, 3, 2 * h, 2 * w) and torch.isfinite(y).all()


def test_padding_is_reflect_then_crop():
    torch.manual_seed(0)
    m = UNet(width=4)
    x = torch.rand(1, 4, 21, 27)
    with torch.inference_mode():
        y = m(x)
        ref = m(F.pad(x, (0, 5, 0, 11), mode="reflect"))[..., :42, :54]
    torch.testing.assert_close(y, ref)


def test_padding_leaves_the_valid_region_alone():
    """A crop of a valid-size input gives the same output wherever the receptive field stays inside."""
    torch.manual_seed(0)
    m = UNet(width=4, depth=3)
    x = torch.rand(1, 4, 64, 64)
    with torch.inference_mode():
        full = m(x)
        cropped = m(x[..., :61, :59])
    assert cropped.shape[-2:] == (122, 118)
    torch.testing.assert_close(cropped[..., :48, :48], full[..., :48, :48])
    assert not torch.allclose(cropped[..., 116:, 110:], full[..., 116:122, 110:118])


def test_float64():
    torch.manual_seed(0)
    for config in ({"type": "unet", "width": 4}, {"type": "resnet", "features": 8, "blocks": 2}):
        m = build_model(config)
        x = torch.rand(1, 4, 9, 10)
        with torch.inference_mode():
            y32 = m(x)
            y64 = m.double()(x.double())
        assert y64.dtype == torch.float64
        torch.testing.assert_close(y64.float(), y32, atol=1e-5, rtol=1e-4)


# ---------------------------------------------------------------- registry and configs


def test_config_round_trip(tmp_path):
    for config in (UNET_CONFIG, UNET_SINGLE_ENCODER_CONFIG, RESNET_CONFIG):
        with torch.device("meta"):
            m = build_model(config)
            again = build_model(model_config(m))
        assert model_config(m) == config and type(again) is MODELS[config["type"]]
        assert count_parameters(again) == count_parameters(m)
        assert {k: v.shape for k, v in again.state_dict().items()} == {k: v.shape for k, v in m.state_dict().items()}
    assert model_config(UNet(width=4))["second_encoder_levels"] == 4
    path = tmp_path / "unet.toml"
    path.write_text('type = "unet"\nwidth = 16\nsub_encoders = 1\n')
    assert load_config(path) == {"type": "unet", "width": 16, "sub_encoders": 1}


@pytest.mark.parametrize("config, words", [
    ({"type": "vit"}, ["type = 'vit'", "unet, resnet"]),
    ({"width": 4}, ["type = None", "unet, resnet"]),
    ({"type": "unet", "widht": 4}, ["widht = 4", "not an argument of unet", "width"]),
    ({"type": "unet", "width": "32"}, ["width = '32'", "an integer"]),
    ({"type": "unet", "width": 3.5}, ["width = 3.5", "an integer"]),
    ({"type": "unet", "depth": True}, ["depth = True", "an integer"]),
    ({"type": "unet", "width": 0}, ["width = 0", ">= 1"]),
    ({"type": "unet", "sub_encoders": 3}, ["sub_encoders = 3", "1 or 2"]),
    ({"type": "unet", "second_encoder_levels": 6}, ["second_encoder_levels = 6", "1 to depth = 5"]),
    ({"type": "unet", "sub_encoders": 1, "second_encoder_levels": 4}, ["second_encoder_levels = 4"]),
    ({"type": "resnet", "tail": "bicubic"}, ["tail = 'bicubic'", "edsr, shuffle"]),
    ({"type": "resnet", "res_scale": "0.1"}, ["res_scale = '0.1'", "a number"]),
])
def test_config_errors(config, words):
    with pytest.raises(ModelConfigError) as e:
        build_model(config, source="cfg.toml")
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("cfg.toml: ") and all(w in msg for w in words), msg


def test_load_config_errors(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('type = "resnet"\nblocks = 1.5\n')
    with pytest.raises(ModelConfigError, match=r"bad\.toml: blocks = 1\.5: expected an integer"):
        load_config(bad)
    bad.write_text("type = \n")
    with pytest.raises(ModelConfigError, match="not valid TOML"):
        load_config(bad)
    with pytest.raises(ModelConfigError, match="cannot read"):
        load_config(tmp_path / "missing.toml")
    with pytest.raises(ModelConfigError, match="expected one of unet, resnet"):
        model_config(nn.Conv2d(1, 1, 1))


# ---------------------------------------------------------------- training


@pytest.mark.parametrize("config", [{"type": "unet", "width": 8, "depth": 3},
                                    {"type": "resnet", "features": 16, "blocks": 2}])
def test_overfits_one_batch(config):
    """50 Adam steps on one fixed batch: the MSE falls more than 5× (measured 14–46× over seeds 0–4;
    the L1 loss only 4–9×, most of its start being the output's mean offset)."""
    torch.manual_seed(0)
    m = build_model(config)
    x = torch.rand(2, 4, 16, 16)
    rgb = torch.stack([x[:, 0], (x[:, 1] + x[:, 2]) / 2, x[:, 3]], dim=1)
    target = F.interpolate(rgb, scale_factor=2, mode="bilinear", align_corners=False) ** 0.5
    opt = torch.optim.Adam(m.parameters(), lr=3e-3)
    losses = []
    for _ in range(50):
        opt.zero_grad()
        loss = F.mse_loss(m(x), target)
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < losses[0] / 5, losses[::10]
