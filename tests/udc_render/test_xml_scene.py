"""A user's Mitsuba 3 XML scene through `udc-render synth` with the camera pose of its own sensor
(render.resolve_xml_camera), and the one-line refusals of what it cannot take."""
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from tests.udc_render.cornell_box import CBOX, LOOKAT, ORIGIN, SENSOR, TARGET, UP
from udc_render.cli import main
from udc_render.io.band_image import load_band_image
from udc_render.render import resolve_xml_camera
from udc_render.render.xml_camera import scalar_param
from udc_render.scene import load_scene

# a tiny sensor (64 x 32 px of 6.2 µm behind a 1 mm lens: a 23° view of the box), 3 bands, 4 spp and
# a 31 µm margin (kernels of 11 px): seconds, not minutes
TOML = """[lens]
focal_length_mm = 1.0
f_number = 2.0
[sensor]
width_px = 64
height_px = 32
pitch_um = 6.2
[bands]
range_nm = [400, 700]
step_nm = 100
[render]
spp = 4
margin_um = 31
[content]
type = "mitsuba_xml"
file = "{xml}"
"""


FOV = '\n    <float name="fov" value="40"/>'


def write_scene(folder, name="cbox", type="perspective", extra=FOV, transform=LOOKAT, sensor=True):
    xml = CBOX.format(sensor=SENSOR.format(type=type, extra=extra, transform=transform) if sensor else "")
    (folder / f"{name}.xml").write_text(xml)
    (folder / f"{name}.toml").write_text(TOML.format(xml=f"{name}.xml"))
    return folder / f"{name}.toml"


def one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("udc-render: error: ") and "Traceback" not in err
    return lines[0]


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("UDC_RENDER_CACHE", str(tmp_path / "cache"))


@pytest.mark.fallback
def test_synth_renders_the_xml_scene_from_its_own_camera(tmp_path, capsys):
    """`udc-render synth` on a Cornell box whose scene file has no camera: the pose is the XML's lookat,
    the focus its target, the field of view the scene's lens and sensor; the captures are written."""
    scene = write_scene(tmp_path)
    out = tmp_path / "o"
    assert main(["synth", str(scene), "--display", "toled", "--out", str(out), "--quiet"]) == 0
    for f in ("gt.exr", "synth.json", "glass/raw.dng", "glass/capture.json", "toled/raw.dng", "toled/capture.json"):
        assert (out / f).stat().st_size > 0, f
    meta = json.loads((out / "synth.json").read_text())["render"]
    xc = meta["xml_camera"]
    assert xc["file"] == str(tmp_path / "cbox.xml") and xc["sensor"] == "perspective" and xc["sensor_id"] == "cam"
    np.testing.assert_allclose(xc["origin_m"], ORIGIN, atol=1e-6)
    np.testing.assert_allclose(xc["target_m"], TARGET, atol=1e-6)
    forward = np.subtract(TARGET, ORIGIN) / np.linalg.norm(np.subtract(TARGET, ORIGIN))
    up = np.subtract(UP, np.dot(UP, forward) * forward)  # the lookat's up, made orthogonal to the axis
    np.testing.assert_allclose(xc["up"], up / np.linalg.norm(up), atol=1e-6)
    np.testing.assert_allclose(meta["camera"]["origin_m"], ORIGIN, atol=1e-6)
    np.testing.assert_allclose(meta["camera"]["target_m"], TARGET, atol=1e-6)
    focus = float(np.linalg.norm(np.subtract(TARGET, ORIGIN)))
    assert xc["focus_from"] == "lookat target" and xc["focus_distance_m"] == pytest.approx(focus)
    assert meta["camera"]["focus_distance_m"] == pytest.approx(focus)
    # the field of view is the scene's (1 mm lens, 64 + 2·5 px of 6.2 µm), not the XML's 40°
    v_um = 1 / (1 / 1000 - 1 / (focus * 1e6))
    assert meta["camera"]["fov_x_deg"] == pytest.approx(2 * np.degrees(np.arctan(74 * 6.2 / 2 / v_um)))
    assert xc["xml_fov_x_deg"] == pytest.approx(40) and meta["lens"]["focal_length_mm"] == 1.0
    assert meta["content"] == "mitsuba_xml" and meta["render_path"] == "spectral"
    assert "toled" in capsys.readouterr().out


MIRRORED = '<scale x="-1"/>' + LOOKAT
REFUSED = {  # name: (write_scene arguments, fragments of the one line besides the scene and XML file names)
    "ortho": (dict(type="orthographic", extra=""),
              ['<sensor type="orthographic" id="cam">', "perspective or thinlens"]),
    "nosensor": (dict(sensor=False), ["content.use_xml_camera", "no sensor"]),
    "mirrored": (dict(transform=MIRRORED), ['<sensor type="perspective" id="cam">', "to_world", "not a rigid pose",
                                            "lookat"]),
    "offaxis": (dict(extra=FOV + '\n    <float name="principal_point_offset_x" value="0.1"/>'),
                ["principal_point_offset_x = 0.1", "expected 0"]),
}


@pytest.mark.parametrize("name", list(REFUSED))
@pytest.mark.fallback
def test_unsupported_xml_camera_is_one_line_before_any_work(tmp_path, capsys, name):
    kwargs, fragments = REFUSED[name]
    scene = write_scene(tmp_path, name, **kwargs)
    assert main(["synth", str(scene), "--display", "toled", "--out", str(tmp_path / "o"), "--quiet"]) == 2
    std = capsys.readouterr()
    line = one_error_line(std.err)
    for frag in [f"{name}.toml", f"{name}.xml"] + fragments:
        assert frag in line, (frag, line)
    # refused before any kernel or output folder was made
    assert std.out == "" and not (tmp_path / "o").exists() and not (tmp_path / "cache").exists()


def test_a_file_mitsuba_cannot_load_is_one_line(tmp_path, capsys):
    scene = write_scene(tmp_path, "bad")
    (tmp_path / "bad.xml").write_text('<scene version="3.0.0">\n  <shape type="hologram"/>\n</scene>\n')
    assert main(["synth", str(scene), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    line = one_error_line(capsys.readouterr().err)
    for frag in ("bad.toml", "content.file = 'bad.xml'", "Mitsuba cannot load", "hologram"):
        assert frag in line, (frag, line)


@pytest.mark.fallback
def test_thinlens_gives_pose_and_focus_and_its_aperture_is_not_used(tmp_path):
    """A thinlens sensor: its focus distance is taken, its aperture only recorded (the render stays the
    scene's lens model: the wave optics adds the defocus from the rendered depth)."""
    extra = FOV + '\n    <float name="aperture_radius" value="0.05"/><float name="focus_distance" value="2.5"/>'
    scene = load_scene(write_scene(tmp_path, "thin", type="thinlens", extra=extra))
    assert scene.camera.origin_m is None
    r = resolve_xml_camera(scene)
    xc = r.content.xml_camera
    assert xc.sensor == "thinlens" and xc.focus_from == "thinlens focus_distance"
    assert xc.xml_aperture_radius_m == pytest.approx(0.05)
    assert r.lens.focus_distance_m == pytest.approx(2.5) and r.lens.model == "pinhole"
    np.testing.assert_allclose(r.camera.origin_m, ORIGIN, atol=1e-6)
    np.testing.assert_allclose(r.camera.target_m, TARGET, atol=1e-6)
    assert resolve_xml_camera(r) is r  # once: resolving again changes nothing
    # the scene's own lens.focus_distance_m wins over the XML's
    toml = tmp_path / "thin.toml"
    toml.write_text(toml.read_text().replace("f_number = 2.0", "f_number = 2.0\nfocus_distance_m = 7.0"))
    r = resolve_xml_camera(load_scene(toml))
    assert r.lens.focus_distance_m == 7.0 and r.content.xml_camera.focus_from == "lens.focus_distance_m"


@pytest.mark.fallback
def test_pose_without_a_readable_lookat_focuses_at_infinity(tmp_path):
    """A to_world of rotations and translations: the pose is the same, but with no target distance the
    focus is at infinity (and the target at 1 m along the axis)."""
    transform = '<rotate y="1" angle="180"/><translate x="0.5" y="1" z="3"/>'  # at (0.5, 1, 3) looking down −z
    r = resolve_xml_camera(load_scene(write_scene(tmp_path, "rot", transform=transform)))
    np.testing.assert_allclose(r.camera.origin_m, (0.5, 1.0, 3.0), atol=1e-6)
    np.testing.assert_allclose(r.camera.target_m, (0.5, 1.0, 2.0), atol=1e-6)
    np.testing.assert_allclose(r.camera.up, (0.0, 1.0, 0.0), atol=1e-6)
    assert r.lens.focus_distance_m == np.inf and r.content.xml_camera.focus_from == "infinity"


def test_unresolved_scene_names_the_resolver(tmp_path):
    from udc_render.scene import SceneError
    from udc_render.scene.geometry import camera_geometry
    with pytest.raises(SceneError, match="camera.origin_m is required.*resolve_xml_camera"):
        camera_geometry(load_scene(write_scene(tmp_path)))


def test_dataset_refuses_images_for_the_xml_scene_in_one_line(tmp_path, capsys):
    """A dataset of an XML scene is made of views of it (tests/udc_render/test_dataset_3d.py): it has no
    monitor image to change per item, so --builtin is refused."""
    scene = write_scene(tmp_path)
    assert main(["dataset", "--builtin", "--count", "1", "--scene", str(scene), "--out", str(tmp_path / "d"),
                 "--quiet"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "cbox.toml" in line and "--builtin is for a monitor scene" in line and "mitsuba_xml" in line


# ---------------------------------------------------------------- the scalar variants (no LLVM) and llvm

# `udc-render synth` on the box: the paper's profile (d = 0: cheap kernels), noise off, and 16 spp of the
# independent sampler, so that every render pixel is an independent estimate (the z-test below)
CBOX_SYNTH = ["--display", "toled", "--profile", "paper", "--noise-model", "none", "--spp", "16", "--sampler",
              "independent", "--keep-render", "--quiet"]
Z_MAX = 4.5  # two-sided p = 6.8e-6 per band


def synth_in_a_process(scene, out, cache, variant: str | None, seed: int):
    """The band render of `udc-render synth` run in a fresh process (the variant is chosen once per
    process) with UDC_RENDER_VARIANT = `variant`, or unset: the llvm variants where LLVM works."""
    env = {k: v for k, v in os.environ.items() if k != "UDC_RENDER_VARIANT"}
    env.update({"UDC_RENDER_CACHE": str(cache)}, **({"UDC_RENDER_VARIANT": variant} if variant else {}))
    r = subprocess.run([sys.executable, "-m", "udc_render.cli", "synth", str(scene), *CBOX_SYNTH, "--seed", str(seed),
                        "--out", str(out)], env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    return load_band_image(out / "render")


@pytest.fixture(scope="module")
def cbox_scalar(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cbox")
    scene = write_scene(folder)
    return scene, synth_in_a_process(scene, folder / "scalar", folder / "cache", "scalar", seed=1)


def test_scalar_param_takes_a_float_or_a_one_element_array_and_nothing_else():
    """The scalar variants traverse to Python floats, the llvm ones to one-element Float arrays."""
    params = {"scalar": 0.25, "llvm": np.array([0.25], np.float32), "vector": np.array([0.25, 1.0])}
    assert scalar_param(params, "scalar") == scalar_param(params, "llvm") == 0.25
    with pytest.raises(ValueError):
        scalar_param(params, "vector")


@pytest.mark.fallback
def test_cornell_box_synth_on_the_scalar_variants(cbox_scalar):
    """The standard Cornell box through `udc-render synth` on the scalar variants (the TypeError of
    issue 28): finite, non-negative, lit band images, and the depth on the axis is the back wall's."""
    scene, b = cbox_scalar
    assert b.meta["variant"] == "scalar_spectral" and b.meta["backend"] == "scalar"
    assert np.all(np.isfinite(b.bands)) and b.bands.min() >= 0
    assert np.all(b.bands.mean((1, 2)) > 0.01) and np.all(b.bands.std((1, 2)) > 0)  # lit, with structure
    origin, target = np.array(ORIGIN), np.array(TARGET)
    forward = (target - origin) / np.linalg.norm(target - origin)
    back_wall = (-1.0 - origin[2]) / forward[2]  # (p − origin) · forward where the axis meets z = −1
    h, w = b.depth_m.shape  # even: the four central pixels straddle the axis; the plane's depth is linear
    assert b.depth_m[h // 2 - 1:h // 2 + 1, w // 2 - 1:w // 2 + 1].mean() == pytest.approx(back_wall, rel=1e-4)


@pytest.mark.fallback
def test_cornell_box_on_the_scalar_variants_matches_llvm(cbox_scalar, tmp_path):
    """Scalar and llvm renders of the box (another seed) are two independent Monte Carlo estimates of
    the same image: per band, the mean of their difference over the pixels is within Z_MAX of its own
    standard error, and the RMS difference is √2 × the renders' pass-estimated noise within a factor 1.6."""
    scene, scalar = cbox_scalar
    llvm = synth_in_a_process(scene, tmp_path / "llvm", tmp_path / "cache", None, seed=2)
    if not llvm.meta["variant"].startswith("llvm_"):
        pytest.skip(f"no working LLVM on this machine ({llvm.meta['backend_reason']}): nothing to compare with")
    d = (scalar.bands.astype(np.float64) - llvm.bands).reshape(len(scalar.bands), -1)
    z = d.mean(1) / (d.std(1, ddof=1) / math.sqrt(d.shape[1]))
    assert np.all(np.abs(z) < Z_MAX), z
    rms = np.linalg.norm(d) / np.linalg.norm(llvm.bands.astype(np.float64))
    expected = math.hypot(scalar.meta["noise_rel"], llvm.meta["noise_rel"])
    assert 1 / 1.6 < rms / expected < 1.6, (rms, expected)
