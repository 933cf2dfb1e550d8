"""Issue 47, item 1: the 'unet' model is the paper's architecture, counted from its description (not from the
code); 'unet-wide-fine' widens its two finest levels only; the capacity study's mechanics on a tiny dataset."""
import json

import pytest

from restore.counting import count_macs, count_parameters
from restore.models import UNET_CONFIG, UNET_WIDE_FINE_CONFIG, ModelConfigError, build_model


def conv(cin: int, cout: int, k: int) -> int:
    """Parameters of a k × k convolution (or transposed convolution) with bias."""
    return k * k * cin * cout + cout


def unet_parameters(widths: list[int], second_levels: int, cin: int = 4, out: int = 3) -> dict[str, int]:
    """The paper's UNet as RESTORE.md / restore.models describe it, counted by hand: per level two 3 × 3 convs
    (encoder, and a second encoder over the first `second_levels` levels), a 2 × 2 transposed conv up, two 3 × 3
    convs on the concatenation, a 1 × 1 conv to 4 · out channels (PixelShuffle(2) has none)."""
    ins = [cin] + widths[:-1]
    enc = [conv(ins[i], c, 3) + conv(c, c, 3) for i, c in enumerate(widths)]
    up = [conv(widths[i + 1], widths[i], 2) for i in range(len(widths) - 1)]
    dec = [conv(2 * c, c, 3) + conv(c, c, 3) for c in widths[:-1]]
    return {"encoder": sum(enc), "residual_encoder": sum(enc[:second_levels]), "up": sum(up), "decoder": sum(dec),
            "to_rgb": conv(widths[0], 4 * out, 1),
            "finest_two": 2 * sum(enc[:2]) + sum(up[:2]) + sum(dec[:2]) + conv(widths[0], 4 * out, 1)}


def unet_macs(widths: list[int], second_levels: int, hw=(512, 1024), cin: int = 4, out: int = 3) -> int:
    """MACs at packed input [1, cin, h, w] (counting.py's convention: C_in · C_out · k² per output pixel, per input
    pixel for the transposed conv): level i has (h / 2^i)(w / 2^i) pixels."""
    ins = [cin] + widths[:-1]
    px = [hw[0] * hw[1] // 4 ** i for i in range(len(widths))]
    enc = [px[i] * 9 * (ins[i] * c + c * c) for i, c in enumerate(widths)]
    up = [px[i + 1] * 4 * widths[i + 1] * widths[i] for i in range(len(widths) - 1)]
    dec = [px[i] * 9 * (2 * c * c + c * c) for i, c in enumerate(widths[:-1])]
    return sum(enc) + sum(enc[:second_levels]) + sum(up) + sum(dec) + px[0] * widths[0] * 4 * out


PAPER_WIDTHS = [32, 64, 128, 256, 512]


def test_unet_is_the_papers_architecture():
    hand = unet_parameters(PAPER_WIDTHS, 4)
    total = sum(v for k, v in hand.items() if k != "finest_two")
    assert total == 8_933_292 and round(total / 1e6, 2) == 8.93  # RESULTS.md's 8.93 M, the paper's baseline
    assert round(hand["finest_two"] / 1e6, 2) == 0.31  # RESTORE.md: its two finest levels hold 0.31 M
    assert UNET_CONFIG == {"type": "unet", "in_channels": 4, "out_channels": 3, "width": 32, "depth": 5,
                           "sub_encoders": 2, "second_encoder_levels": 4, "negative_slope": 0.2}
    model = build_model(UNET_CONFIG)
    assert type(model).__name__ == "UNet" and count_parameters(model) == total
    for part in ("encoder", "residual_encoder", "up", "decoder", "to_rgb"):
        assert sum(p.numel() for p in getattr(model, part).parameters()) == hand[part], part
    assert count_macs(UNET_CONFIG) == unet_macs(PAPER_WIDTHS, 4) == 124_084_289_536  # paper: 124.36 G


def test_wide_fine_widens_the_two_finest_levels_only():
    wide = [64, 96, 128, 256, 512]
    hand = unet_parameters(wide, 4)
    assert count_parameters(build_model(UNET_WIDE_FINE_CONFIG)) == sum(v for k, v in hand.items()
                                                                       if k != "finest_two") == 9_485_292
    assert count_macs(UNET_WIDE_FINE_CONFIG) == unet_macs(wide, 4) == 242_934_087_680
    paper, model = build_model(UNET_CONFIG), build_model(UNET_WIDE_FINE_CONFIG)
    for i in (3, 4):  # levels 3 and 4 take 128 and 256 channels in both: the same shapes
        assert [p.shape for p in model.encoder[i].parameters()] == [p.shape for p in paper.encoder[i].parameters()]
    with pytest.raises(ModelConfigError, match=r"^cfg: fine_levels = 6: expected 0 to depth = 5$"):
        build_model(dict(UNET_WIDE_FINE_CONFIG, fine_levels=6), source="cfg")
    assert build_model(dict(UNET_WIDE_FINE_CONFIG, fine_extra_width=0)).config["fine_extra_width"] == 0
    assert count_parameters(build_model(dict(UNET_WIDE_FINE_CONFIG, fine_extra_width=0))) == 8_933_292


@pytest.mark.slow  # CI time (20-min line): 8 s; the study mechanics end to end
def test_capacity_study_mechanics(tmp_path, monkeypatch):
    """Three runs from one seed (the 2× run's first epochs are the 1× run's: the same loss), scored, the band's
    share per run, a PNG; run again, nothing is trained or scored again. Tiny stand-ins for the two models."""
    from restore.studies import capacity
    from restore.studies.capacity import Recipe, capacity_study
    from tests.conftest import write_pairs
    data = write_pairs(tmp_path / "pairs", splits=(("train", 2), ("val", 1), ("test", 1)), size_px=(64, 64))
    recipe = Recipe(epochs=2, batch=2, crop_px=32, crops_per_pair=1, lr=1e-3, val_every=2)
    monkeypatch.setattr("restore.checkpoints.plot_loss", lambda log, path: None)  # training's figure: 1-2 s each
    tiny = ({"type": "unet", "width": 4, "depth": 3},
            {"type": "unet-wide-fine", "width": 4, "depth": 3, "fine_levels": 2, "fine_extra_width": 4})
    r = capacity_study(data, "blur", recipe, tmp_path / "study", device="cpu", progress=False, configs=tiny)
    assert [r["runs"][k]["steps"] for k in ("unet", "unet-wide-fine", "unet-2x")] == [2, 2, 4]
    hand = {k: sum(v for part, v in unet_parameters(w, 2).items() if part != "finest_two")
            for k, w in (("unet", [4, 8, 16]), ("unet-wide-fine", [8, 12, 16]))}
    assert {k: r["runs"][k]["parameters"] for k in hand} == hand and r["runs"]["unet-2x"]["model"] == tiny[0]
    loss = {k: (tmp_path / "study" / "train" / k / "loss.csv").read_text().splitlines() for k in ("unet", "unet-2x")}
    assert loss["unet"][1].split(",")[:4] == loss["unet-2x"][1].split(",")[:4]  # epoch 1: same lr, crops, loss
    assert set(r["band_share"]) == {"unet", "unet-wide-fine", "unet-2x"} and r["transfer"] is None
    assert all(v > 0 for v in r["band_share"].values())
    assert (tmp_path / "study" / "error_bands_blur.png").stat().st_size > 1000
    assert json.loads((tmp_path / "study" / "capacity.json").read_text())["scores"]["unet-2x"]["psnr_db_paper"] > 0
    made = (tmp_path / "study" / "train" / "unet" / "model.pt").stat().st_mtime_ns

    def refuse(*args, **kwargs):
        raise AssertionError("scored again")
    monkeypatch.setattr("restore.evaluate.evaluate", refuse)
    monkeypatch.setattr("restore.studies.error_bands.method_bands", refuse)
    again = capacity_study(data, "blur", recipe, tmp_path / "study", device="cpu", progress=False, configs=tiny)
    assert again["scores"] == r["scores"] and again["band_share"] == r["band_share"]
    assert (tmp_path / "study" / "train" / "unet" / "model.pt").stat().st_mtime_ns == made
    assert f"| unet-wide-fine | {hand['unet-wide-fine']:,} |" in capacity.markdown(again)
