"""The `udc-render render` command: outputs of a tiny render, overrides, and bad scene files that
must give one line naming the file and the key, exit status 2, no traceback."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from udc_render.cli import main

pytestmark = pytest.mark.usefixtures("render_cache")

SENSOR = "[sensor]\nwidth_px = 64\nheight_px = 32\npitch_um = 49.6\n"
MONITOR = '[content]\ntype = "monitor"\nresolution_px = [480, 270]\n'


def console_script() -> list[str]:
    exe = Path(sys.executable).parent / "udc-render"
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "udc_render.cli"]


def one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("udc-render: error: ") and "Traceback" not in err
    return lines[0]


# ---------------------------------------------------------------- a tiny render through the CLI


@pytest.mark.fallback
def test_render_writes_exr_json_and_preview(tmp_path, capsys):
    scene = tmp_path / "mon.toml"
    scene.write_text(MONITOR + "[render]\nspp = 16\n")  # the command line overrides spp, sensor and pitch
    out = tmp_path / "out"
    assert main(["render", str(scene), "--out", str(out), "--spp", "2", "--sensor-px", "64,32",
                 "--pitch-um", "49.6", "--path", "rgb_matrix", "--sampler", "independent", "--quiet"]) == 0
    std = capsys.readouterr()
    assert "rendered" in std.out and "rgb_matrix" in std.out and std.err == ""
    for name in ("render.exr", "render.json", "preview.png"):
        assert (out / name).stat().st_size > 0
    meta = json.loads((out / "render.json").read_text())
    assert meta["sensor"] == {"width_px": 64, "height_px": 32, "pitch_um": 49.6}
    assert meta["spp"] == 2 and meta["render_path"] == "rgb_matrix" and meta["scene"] == str(scene)
    assert meta["sampler"] == "independent"
    m = meta["margin_px"]
    assert m == 8  # ceil(396 µm / 49.6 µm)
    import OpenEXR
    with OpenEXR.File(str(out / "render.exr")) as f:
        chans = f.channels()
        assert len(chans) == 30 and "depth_m" not in chans  # 400–700 nm in 10 nm bands; no depth for the monitor
        assert np.asarray(chans["band_0555nm"].pixels).shape == (32 + 2 * m, 64 + 2 * m)
    import imageio.v3 as iio
    assert iio.imread(out / "preview.png").shape == (32, 64, 3)


@pytest.mark.fallback
def test_render_overrides_path_bands_image_and_seed(tmp_path):
    scene = tmp_path / "mon.toml"
    scene.write_text(SENSOR + MONITOR + '[render]\nmargin_um = 0\n')
    out = tmp_path / "out"
    assert main(["render", str(scene), "--out", str(out), "--spp", "2", "--path", "spectral", "--bands-nm",
                 "450:650:50", "--image", "pattern:white", "--seed", "3", "--quiet"]) == 0
    meta = json.loads((out / "render.json").read_text())
    assert meta["render_path"] == "spectral" and meta["seed"] == 3
    assert meta["band_edges_nm"] == [450.0, 500.0, 550.0, 600.0, 650.0]
    assert meta["display"] == {"pattern": "pattern:white"}
    assert meta["channels"] == ["band_0475nm", "band_0525nm", "band_0575nm", "band_0625nm"]


def test_noise_target_from_the_command_line(tmp_path):
    scene = tmp_path / "mon.toml"
    scene.write_text(SENSOR + MONITOR)
    out = tmp_path / "out"
    assert main(["render", str(scene), "--out", str(out), "--noise", "0.05", "--path", "rgb_matrix",
                 "--sampler", "independent", "--quiet"]) == 0
    meta = json.loads((out / "render.json").read_text())
    # the astronaut on a 480 × 270 panel: pilot noise ~0.12 at 8 spp → ~50 spp; ±35 % as in test_render (the
    # 1/√N law of the independent sampler: the correlated ones, the default, end below the target)
    assert meta["spp_from_noise_target"] == 0.05 and abs(meta["noise_rel"] / 0.05 - 1) < 0.35


@pytest.mark.parametrize("name", [pytest.param("room", marks=pytest.mark.fallback),
                                  pytest.param("hdr", marks=pytest.mark.fallback),
                                  pytest.param("monitor", marks=pytest.mark.slow)])
def test_shipped_scenes_render_by_name(tmp_path, name):
    """Each shipped scene by its bare name, shrunk to 32 × 16 px of 99.2 µm (the paper's field of
    view), 1 spp, 3 bands. 3D scenes also write depth (0.5–7 m inside the rooms; inf through the HDR room's window).
    The monitor is slow only for its 3840 × 2160 panel (~1 GB, ~5 s)."""
    out = tmp_path / name
    assert main(["render", name, "--out", str(out), "--spp", "1", "--sensor-px", "32,16", "--pitch-um", "99.2",
                 "--bands-nm", "400:700:100", "--quiet"]) == 0
    meta = json.loads((out / "render.json").read_text())
    assert meta["content"] == name and meta["render_path"] == ("analytic" if name == "monitor" else "spectral")
    import OpenEXR
    with OpenEXR.File(str(out / "render.exr")) as f:
        chans = {k: np.asarray(v.pixels) for k, v in f.channels().items()}
    assert all(np.all(np.isfinite(chans[n])) and chans[n].min() >= 0 for n in meta["band_names"])
    if name != "monitor":
        assert (out / "depth.png").is_file()
        d = chans["depth_m"]
        if name == "room":
            assert np.all(np.isfinite(d)) and 0.5 < d.min() and d.max() < 7.0, (d.min(), d.max())
        else:  # the window shows the sky (no surface: inf) and, 1000 m away, the sun sphere
            walls = d[d < 100]
            assert np.isinf(d).any() and 0.5 < walls.min() and walls.max() < 7.0


# ---------------------------------------------------------------- bad command lines


@pytest.mark.parametrize("args, fragment", [
    (["--spp", "4", "--noise", "0.1"], "not allowed with argument"),
    (["--spp", "0"], "--spp must be > 0"),
    (["--sensor-px", "64.5,32"], "--sensor-px = 64.5,32"),
    (["--sensor-px", "64"], "--sensor-px must be two"),
    (["--pitch-um", "-1"], "--pitch-um must be > 0"),
    (["--seed", "-1"], "--seed = -1"),
    (["--bands-nm", "300:700:10"], "--bands-nm = '300:700:10'"),
    (["--path", "fast"], "invalid choice"),
])
def test_bad_render_arguments_give_one_line_and_exit_2(tmp_path, capsys, args, fragment):
    scene = tmp_path / "mon.toml"
    scene.write_text(SENSOR + MONITOR)
    assert main(["render", str(scene), "--out", str(tmp_path / "o"), "--quiet"] + args) == 2
    std = capsys.readouterr()
    assert fragment in one_error_line(std.err) and std.out == ""
    assert not (tmp_path / "o").exists()


def test_rgb_matrix_override_is_refused_for_3d_content(tmp_path, capsys):
    scene = tmp_path / "room.toml"
    scene.write_text(SENSOR + '[camera]\norigin_m = [0, 1, 3]\n[content]\ntype = "room"\n')
    assert main(["render", str(scene), "--path", "rgb_matrix", "--out", str(tmp_path / "o")]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "--path rgb_matrix" in line and "room.toml" in line


# ---------------------------------------------------------------- bad scene files


BAD_SCENES = {  # name: (file text, fragments the one line must contain besides the file's name)
    "missing_content": (SENSOR, ["content", "a [content] table"]),
    "unknown_type": (SENSOR + '[content]\ntype = "hologram"\n', ["content.type", "'hologram'", "monitor"]),
    "unknown_key": (SENSOR + "[lens]\nzoom = 2\n" + MONITOR, ["lens.zoom", "a known key"]),
    "f_number_range": (SENSOR + "[lens]\nf_number = 0.2\n" + MONITOR, ["lens.f_number", "0.2", "[0.5, 128"]),
    "wrong_type": ('[sensor]\npitch_um = "1.55"\n' + MONITOR, ["sensor.pitch_um", "'1.55'", "a number"]),
    "range_outside": (SENSOR + "[bands]\nrange_nm = [300, 700]\n" + MONITOR, ["bands.range_nm", "360", "830"]),
    "spp_and_noise": (SENSOR + "[render]\nspp = 4\nnoise = 0.1\n" + MONITOR, ["render.noise", "render.spp"]),
    "room_without_camera": (SENSOR + '[content]\ntype = "room"\n', ["camera.origin_m", "room"]),
    "invalid_toml": (SENSOR + "[content\n", ["not valid TOML"]),
    "mitsuba_xml_missing": (SENSOR + '[content]\ntype = "mitsuba_xml"\nfile = "missing.xml"\n',
                            ["content.file", "missing.xml", "no such file"]),
    "mitsuba_xml_unknown_plugin": (SENSOR + '[content]\ntype = "mitsuba_xml"\nfile = "bad.xml"\n',
                                   ["content.file", "bad.xml", "nonexistent_plugin"]),
    "mitsuba_xml_no_sensor": (SENSOR + '[content]\ntype = "mitsuba_xml"\nfile = "nosensor.xml"\n',
                              ["content.use_xml_camera", "nosensor.xml", "no sensor"]),
}


@pytest.mark.parametrize("name", list(BAD_SCENES))
def test_bad_scene_file_gives_one_line_naming_file_and_key(tmp_path, capsys, name):
    text, fragments = BAD_SCENES[name]
    (tmp_path / "bad.xml").write_text('<scene version="3.0.0">\n  <shape type="nonexistent_plugin"/>\n</scene>\n')
    (tmp_path / "nosensor.xml").write_text('<scene version="3.0.0">\n  <shape type="sphere"/>\n</scene>\n')
    scene = tmp_path / f"{name}.toml"
    scene.write_text(text)
    assert main(["render", str(scene), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    std = capsys.readouterr()
    line = one_error_line(std.err)
    assert f"{name}.toml" in line, line
    for frag in fragments:
        assert frag in line, (frag, line)
    assert std.out == "" and not (tmp_path / "o" / "render.exr").exists()


@pytest.mark.parametrize("image, why", [("notes.txt", "cannot read"), ("nowhere.png", "cannot read"),
                                        ("builtin:mona_lisa", "expected one of")])
def test_unshowable_image_gives_one_line_naming_the_image_and_key(tmp_path, capsys, image, why):
    (tmp_path / "notes.txt").write_text("a text file, not an image\n")
    scene = tmp_path / "img.toml"
    scene.write_text(SENSOR + MONITOR + f'image = "{image}"\n')
    assert main(["render", str(scene), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    line = one_error_line(capsys.readouterr().err)
    # the line names the key and the image (the file at fault), not the scene file (see the report)
    assert f"content.image = '{image}'" in line and why in line, line
    if not image.startswith("builtin:"):
        assert str(tmp_path / image) in line


def test_unknown_primaries_give_one_line(tmp_path, capsys):
    scene = tmp_path / "prim.toml"
    scene.write_text(SENSOR + MONITOR + 'primaries = "Sony"\n')
    assert main(["render", str(scene), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert "content.primaries = 'Sony'" in one_error_line(capsys.readouterr().err)


def test_console_script_exit_status_and_single_line(tmp_path):
    """The installed `udc-render` itself (not main()): exit 2, one stderr line, nothing on stdout."""
    scene = tmp_path / "bad.toml"
    scene.write_text(SENSOR + "[lens]\nf_number = 0.2\n" + MONITOR)
    r = subprocess.run(console_script() + ["render", str(scene), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stdout == ""
    assert "lens.f_number" in one_error_line(r.stderr) and "bad.toml" in r.stderr
    r = subprocess.run(console_script() + ["render", str(scene), "--spp", "4", "--noise", "0.1"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "not allowed with argument" in one_error_line(r.stderr)
