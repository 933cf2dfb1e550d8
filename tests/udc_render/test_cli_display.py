"""One --display vocabulary for every command (udc_render.optics.displays.load_display): a preset,
a display file (.toml) or a micrograph image, the same per item of a comma-separated list."""
import json

import numpy as np
import pytest
import skimage.io as skio

from udc_render.cli import build_parser, main
from udc_render.cli.args import capture_setup
from udc_render.cli.psf import layout_and_distance
from udc_render.optics import displays as D

# the smallest arguments of each command that takes --display, less --display and --out
COMMANDS = {
    "psf": ["psf", "--wavelengths-nm", "520", "--size", "15"],
    "synth": ["synth", "monitor"],
    "dataset": ["dataset", "--builtin", "--count", "1"],
    "calibrate": ["calibrate", "--quick"],
    "train": ["train", "--data", "DATA", "--model", "unet"],
    "evaluate": ["evaluate", "--data", "DATA", "--model", "input"],
    "bank": ["bank"],
    "study": ["study", "layout", "--quick"],
}
ALLOWED = "glass (or none), toled, poled, a display file (.toml) or a micrograph image (.png/.tif/.tiff/.exr)"


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("UDC_RENDER_CACHE", str(tmp_path / "cache"))


@pytest.fixture
def cell(tmp_path):
    """The T-OLED cell twice: a 60 × 60 px, 1 µm/px micrograph (opening x ∈ [23, 37], y ∈ [3, 57]: the
    same Fourier series as layouts.toled(pitch_um=60), tests/psf/test_geometry_layouts.py) and a display
    file of that layout 1 mm from the lens."""
    img = np.zeros((60, 60), np.uint8)
    img[3:57, 23:37] = 255
    skio.imsave(tmp_path / "cell.png", img, check_contrast=False)
    (tmp_path / "cell.toml").write_text('[display]\nname = "cell"\ndistance_mm = 1\n'
                                        '[display.layout]\ntype = "toled"\npitch_um = 60\n')
    return tmp_path / "cell.png", tmp_path / "cell.toml"


def test_every_command_with_display_is_covered():
    sub = next(a for a in build_parser()._actions if a.choices and "psf" in a.choices)
    taking = {name for name, p in sub.choices.items() if any("--display" in a.option_strings for a in p._actions)}
    assert taking == set(COMMANDS)


@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize("value, says", [
    ("nowhere.toml", "--display = 'nowhere.toml': no such file; expected " + ALLOWED),
    ("nowhere.tif", "--display = 'nowhere.tif': no such file; expected " + ALLOWED),
    ("toled,nowhere.png", "--display = 'nowhere.png': no such file; expected " + ALLOWED),
])
def test_a_missing_display_file_is_the_same_one_line_everywhere(command, value, says, tmp_path, capsys):
    if command in ("psf", "train", "calibrate", "study") and "," in value:
        value = value.split(",")[1]  # one display; the error names the item either way
    argv = [str(tmp_path) if a == "DATA" else a for a in COMMANDS[command]]
    assert main([*argv, "--display", str(value), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.splitlines() == [f"udc-render: error: {says}"]


@pytest.mark.parametrize("command", ["psf", "synth", "dataset", "calibrate"])
def test_an_unknown_word_is_one_line_naming_option_value_and_vocabulary(command, tmp_path, capsys):
    assert main([*COMMANDS[command], "--display", "hexagon", "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err.strip() == f"udc-render: error: --display = 'hexagon': expected {ALLOWED}"


def test_a_micrograph_is_the_display_file_of_its_layout(cell, tmp_path):
    png, _ = cell
    (tmp_path / "m.toml").write_text(f'[display]\nname = "cell"\n[display.layout]\ntype = "micrograph"\n'
                                     f'file = "{png.name}"\n')
    a, b = D.load_display(str(png)), D.load_display(str(tmp_path / "m.toml"))
    assert (a.name, a.gain, a.distance_mm, a.source) == ("cell", 1.0, 0.0, str(png))
    assert (a.name, a.gain, a.distance_mm, a.transmission) == (b.name, b.gain, b.distance_mm, b.transmission)
    assert a.layout.describe() == b.layout.describe()
    np.testing.assert_array_equal(a.layout.image, b.layout.image)
    assert D.load_display(str(png), pixel_um=2.0).layout.period_um == (120.0, 120.0)


def test_synth_and_dataset_take_presets_files_and_micrographs_per_item(cell):
    png, toml = cell
    for command in ("synth", "dataset"):
        args = build_parser().parse_args([*COMMANDS[command], "--display", f"none,poled,{toml},{png}"])
        _, displays = capture_setup(args)
        assert [d.name for d in displays] == ["glass", "poled", "cell", "cell"]
        assert [d.source for d in displays[2:]] == [str(toml), str(png)]


def test_dataset_names_of_files_presets_and_words(cell):
    png, toml = cell
    assert [D.display_name(s) for s in ("toled", "none", str(toml), str(png), "blur")] == [
        "toled", "glass", "cell", "cell", "blur"]


def test_dataset_names_read_no_image_and_name_a_missing_file(cell, tmp_path, monkeypatch):
    """display_name takes a micrograph's stem and a display file's [display] name without reading an image
    (MicrographLayout.load is not called, also for a file whose layout is a micrograph); the names equal
    load_display's; a missing file is refused in one line naming it."""
    png, _ = cell
    micro_toml = tmp_path / "micro.toml"
    micro_toml.write_text(f'[display]\nname = "m1"\n[display.layout]\ntype = "micrograph"\nfile = "{png.name}"\n')
    want = [D.load_display(str(p)).name for p in (png, micro_toml)]
    monkeypatch.setattr(D.MicrographLayout, "load", lambda *a, **k: pytest.fail("an image was read"))
    assert [D.display_name(str(p)) for p in (png, micro_toml)] == want == ["cell", "m1"]
    with pytest.raises(D.DisplayError, match="gone.png.*no such file"):
        D.display_name(str(tmp_path / "gone.png"))


def _psf(tmp_path, name, *argv):
    out = tmp_path / name
    assert main(["psf", *argv, "--wavelengths-nm", "520", "--size", "31", "--field-phases", "2",
                 "--precision", "float64", "--out", str(out)]) == 0
    with np.load(out / "psf.npz") as z:
        return {k: z[k] for k in z.files}


def test_psf_takes_a_display_files_layout_and_distance_and_distance_mm_wins(cell, tmp_path):
    """The file's toled layout at its own 1 mm equals the micrograph of the same cell at --distance-mm 1
    (field kernels and banding); --distance-mm 0 overrides the file's distance."""
    png, toml = cell
    from_file = _psf(tmp_path, "file", "--display", str(toml))
    from_image = _psf(tmp_path, "image", "--display", str(png), "--distance-mm", "1")
    peak = from_file["kernels"].max()
    assert np.max(np.abs(from_file["kernels"] - from_image["kernels"])) < 1e-12 * peak
    assert np.max(np.abs(from_file["field_kernels"] - from_image["field_kernels"])) < 1e-12 * peak
    display = json.loads(str(from_file["params_json"]))["display"]
    assert (display["name"], display["pitch_x_um"]) == ("toled", 60)
    at_zero = _psf(tmp_path, "zero", "--display", str(toml), "--distance-mm", "0")
    assert "field_kernels" not in at_zero and "field_kernels" in from_file
    assert np.max(np.abs(at_zero["kernels"] - _psf(tmp_path, "img0", "--display", str(png))["kernels"])) < 1e-12 * peak


@pytest.mark.parametrize("flip, says", [(True, None), ('"yes"', "display.layout.tile_flip = 'yes': expected true "
                                                                 "or false"),
                                        ("true\ntile_rotation = false", "needs tile_rotation = true")])
def test_a_display_files_tile_flip_mirrors_the_turned_tiles(cell, tmp_path, capsys, flip, says):
    """tile_flip = true: the micrograph's tiles turned and mirrored (psf.micrograph.quarter_turns' D4 draws); any other
    value, or a flip without turns, is refused in one line by every command (here psf)."""
    png, _ = cell
    path = tmp_path / "f.toml"
    rotation = "" if "tile_rotation" in str(flip) else "tile_rotation = true\n"
    path.write_text(f'[display]\nname = "f"\n[display.layout]\ntype = "micrograph"\nfile = "{png.name}"\n'
                    f'{rotation}tile_flip = {str(flip).lower()}\n')
    if says is None:
        layout = D.load_display(str(path)).layout
        assert layout.flip and set(np.unique(layout.tile_rotations(30, 30))) == set(range(8))
        return
    assert main(["psf", "--display", str(path), "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err
    assert says in err and str(path) in err and len(err.strip().splitlines()) == 1


def test_psf_mirrors_a_micrographs_turned_tiles_or_refuses_in_one_line(cell, tmp_path, capsys):
    png, _ = cell
    assert main(["psf", "--display", str(png), "--tile-flip", "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err
    assert "needs random_rotation (--tile-rotation)" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "never").exists()
    args = build_parser().parse_args(["psf", "--display", str(png), "--tile-rotation", "--tile-flip"])
    assert layout_and_distance(args)[0].flip


@pytest.mark.parametrize("arrangement, says", [
    ("[[1, 6], [3, 0]]", None),
    ("[[1, 6], [3, 8]]", "tile_arrangement must be a K × K list of D4 elements 0 … 7"),
    ("[[1, 6], [3]]", "tile_arrangement must be a K × K list of D4 elements 0 … 7"),
    ("[[1, 6], [3, 0]]\ntile_rotation = true", "without tile_rotation"),
])
def test_a_display_files_tile_arrangement_turns_the_tiles_by_its_pattern(cell, tmp_path, capsys, arrangement, says):
    """tile_arrangement: the micrograph's tiles turned by a fixed K × K pattern of D4 elements, repeated from the
    window's first tile, rastered as turned tiles are (not periodic to the engine) and in the cache's description;
    a pattern not K × K of 0 … 7, or with random turns, is refused in one line by every command (here psf)."""
    png, _ = cell
    path = tmp_path / "a.toml"
    path.write_text(f'[display]\nname = "a"\n[display.layout]\ntype = "micrograph"\nfile = "{png.name}"\n'
                    f'tile_arrangement = {arrangement}\n')
    if says is None:
        layout = D.load_display(str(path)).layout
        assert not layout.periodic and layout.describe()["arrangement"] == [[1, 6], [3, 0]]
        assert np.array_equal(layout.tile_rotations(3, 5), [[1, 6, 1], [3, 0, 3], [1, 6, 1], [3, 0, 3], [1, 6, 1]])
        return
    assert main(["psf", "--display", str(path), "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err
    assert says in err and str(path) in err and len(err.strip().splitlines()) == 1
