"""The held-out photographs (restore.studies.heldout): disjoint from the datasets' content, shipped with
scikit-image, written once; their document section computes its orderings from its own table."""
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
    from restore.studies.results import heldout_section
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
