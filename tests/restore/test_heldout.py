"""The held-out photographs (restore.studies.heldout): disjoint from the datasets' content, shipped with
scikit-image, written once; their document section computes its orderings from its own table. The profile
gap (restore.studies.profile_gap) tells noise, hot pixels and colour apart."""
import numpy as np

from restore.studies.heldout import HELD_OUT, load_held_out, write_held_out
from udc_render.content.monitor_image import BUILTIN_IMAGES, read_code_values


def test_held_out_images_are_photographs_no_split_uses():
    assert not set(HELD_OUT) & set(BUILTIN_IMAGES) and len(HELD_OUT) == 10
    for name in HELD_OUT:  # shipped in scikit-image's wheel: no download
        a = load_held_out(name)
        assert a.dtype == np.uint8 and min(a.shape[:2]) >= 256 and a.std() > 10, name


def test_write_held_out_writes_each_image_once(tmp_path):
    folder = write_held_out(tmp_path / "img", count=2)
    files = sorted(folder.glob("*.png"))
    assert [f.stem for f in files] == sorted(list(HELD_OUT)[:2])
    brick = read_code_values(str(folder / "brick.png"))
    assert np.array_equal(brick[..., 1], load_held_out("brick") / 255.0)  # grey kept exactly
    stamps = [f.stat().st_mtime_ns for f in files]
    write_held_out(folder, count=2)
    assert [f.stat().st_mtime_ns for f in files] == stamps


def test_heldout_section_checks_its_own_table(tmp_path):
    from restore.studies.results_document import heldout_section
    table = {"input": (15.0, 12.0), "dep": (20.0, 18.0), "unet": (30.0, 25.0)}  # (T-OLED, P-OLED)
    results = {"protocols": {"paper": "linear"}, "methods": {
        name: {"params": None, "macs_g": None, "displays": {
            d: {"images": 10, "psnr_db_paper": v, "ssim_paper": 0.9, "ms_per_mp": 1.0}
            for d, v in zip(("toled", "poled"), values)}} for name, values in table.items()}}
    text = "\n".join(heldout_section(results, tmp_path, {"heldout_unet_poled": "figures/heldout_unet_poled.png"}))
    assert "| UNet above DeP by ≥ 3 dB on toled (PSNR) | yes | 30.00 vs 20.00 dB (+10.00) |" in text
    assert "| P-OLED harder than T-OLED for unet (PSNR) | yes | 25.00 vs 30.00 dB |" in text
    assert text.count("| unet |") == 1 and "10 photographs" in text
    assert text.endswith("![UNet on a held-out photograph, poled](figures/heldout_unet_poled.png)")


def test_profile_gap_separates_noise_hot_pixels_and_colour():
    from restore.studies.profile_gap import capture_gap
    rng = np.random.default_rng(0)
    a = np.full((4, 256, 256), 0.3)
    b = a + rng.normal(0, 0.01, a.shape)  # white noise: 8 × 8 block means cut its variance 64×
    b[1, 10, 10] = 1.0  # a saturated hot pixel in B only
    g = capture_gap(a, b)
    assert g["hot_px"] == 1 and g["psnr_db"] < g["psnr_db_without_hot"]
    assert abs(g["psnr_db_without_hot"] - 40.0) < 0.05  # σ = 0.01
    assert abs(g["block_psnr_db"] - (40.0 + 10 * np.log10(64))) < 0.5  # the hot pixel adds (0.7 / 64)² / 4
    assert np.allclose(g["channel_ratio"], 1.0, atol=1e-3)
    assert np.allclose(capture_gap(a, 1.01 * a)["channel_ratio"], 1 / 1.01, rtol=1e-12, atol=0)
