"""Scene files, the rig's geometry, spectra in absolute units and what the monitor shows (no Mitsuba).

Oracles: the thin-lens framing written from its definition, the CIE tables read straight from
colour-science, closed forms for band means of linear spectra, IEC 61966-2-1 golden values.
"""
import math
from dataclasses import replace

import numpy as np
import pytest

from udc_render.content import monitor_image as di, spectra
from udc_render.scene import (
    Bands,
    HDRRoom,
    Monitor,
    Room,
    SceneError,
    geometry as rig,
    load_scene,
    parse_bands,
    parse_scene,
    scenes_dir,
)

# ---------------------------------------------------------------- shipped scene files


def test_shipped_scenes_load_with_their_documented_values():
    mon = load_scene("monitor")  # a bare name is looked up in scenes/
    assert mon.source == str(scenes_dir() / "monitor.toml")
    assert isinstance(mon.content, Monitor) and mon.content.resolution_px == (3840, 2160)
    assert mon.content.image == "builtin:astronaut" and mon.content.framing == "fit"
    assert (mon.lens.focal_length_mm, mon.lens.f_number, mon.lens.focus_distance_m) == (6.0, 1.8, None)
    assert (mon.sensor.width_px, mon.sensor.height_px, mon.sensor.pitch_um) == (2048, 1024, 1.55)
    assert (mon.render.spp, mon.render.max_depth, mon.render.margin_um, mon.render.path) == (16, 2, 396.0, "auto")
    assert mon.bands.count == 30 and mon.bands.edges_nm[0] == 400 and mon.bands.edges_nm[-1] == 700

    room = load_scene(scenes_dir() / "room.toml")
    assert isinstance(room.content, Room) and room.content.illuminant == "D65"
    assert room.camera.origin_m == (0.0, 1.1, 3.4) and room.camera.target_m == (0.0, 0.2, -2.0)
    hdr = load_scene("hdr")
    assert isinstance(hdr.content, HDRRoom) and hdr.content.sun_luminance_cd_m2 == 1.6e9
    assert hdr.render.max_depth == 6 and hdr.render.bands_per_render == 30


def test_monitor_size_from_diagonal_and_resolution():
    # 27 in of 16:9: width = d·16/√(16² + 9²) = 0.597727 m, height 0.336221 m (golden, 1e-6 m)
    w, h = Monitor().size_m
    assert w == pytest.approx(0.597727, abs=1e-6) and h == pytest.approx(0.336221, abs=1e-6)
    assert math.hypot(w, h) == pytest.approx(27 * 0.0254, rel=1e-12)


def test_defaults_auto_and_noise_target(udc, tmp_path):
    doc = udc.monitor_doc(render={"noise": 0.05, "max_depth": "auto", "depth": "auto"})
    del doc["render"]["spp"]
    doc["lens"] = {"focus_distance_m": "auto"}
    s = parse_scene(doc, str(tmp_path / "s.toml"))
    assert s.render.spp is None and s.render.noise == 0.05  # a noise target replaces spp
    assert s.render.max_depth is None and s.render.depth is None and s.lens.focus_distance_m is None
    # an integer is accepted where a number is expected, and stored as float
    s2 = parse_scene(dict(doc, lens={"f_number": 2}), "x.toml")
    assert s2.lens.f_number == 2.0 and isinstance(s2.lens.f_number, float)
    assert s2.lens.aperture_mm == pytest.approx(3.0, rel=1e-15)


def test_relative_paths_resolve_against_the_scene_folder(tmp_path, udc):
    (tmp_path / "sub").mkdir()
    s = udc.write_scene(tmp_path / "sub" / "s.toml", udc.monitor_doc())
    assert s.resolve("img.png") == (tmp_path / "sub" / "img.png").resolve()
    assert s.resolve(str(tmp_path / "abs.png")) == tmp_path / "abs.png"


def test_bands_edges_and_parse_bands():
    b = Bands(range_nm=(400.0, 700.0), step_nm=10.0)
    np.testing.assert_allclose(b.edges_nm, np.arange(400, 701, 10), rtol=0, atol=1e-12)
    # a step that does not divide the range is rounded to a whole number of equal bands
    assert Bands(range_nm=(400.0, 700.0), step_nm=7.0).count == 43
    assert parse_bands("450:650:50") == Bands(range_nm=(450.0, 650.0), step_nm=50.0)
    for bad in ("400:700", "a:b:c", "300:700:10", "400:900:10", "700:400:10", "400:700:0.1", "400:700:400"):
        with pytest.raises(SceneError, match="--bands-nm") as e:
            parse_bands(bad)
        assert "\n" not in str(e.value)


# ---------------------------------------------------------------- validation: one line naming file and key


def _mutate(doc, table, key, value):
    doc = {t: dict(v) for t, v in doc.items()}
    if key is None:
        doc[table] = value
    elif value is KeyError:
        doc.setdefault(table, {}).pop(key, None)
    else:
        doc.setdefault(table, {})[key] = value
    return doc


BAD = [  # (table, key, value, the key the message must name)
    ("optics", None, {"x": 1}, "optics"),                        # unknown top-level table
    ("content", "type", "hologram", "content.type"),
    ("content", "type", KeyError, "content.type"),               # no type at all
    ("content", "gamma", 2.2, "content.gamma"),                  # unknown key
    ("content", "transfer", "pq", "content.transfer"),
    ("content", "framing", "stretch", "content.framing"),
    ("content", "resolution_px", [3840.5, 2160], "content.resolution_px"),
    ("content", "resolution_px", [3840, 2160, 3], "content.resolution_px"),
    ("content", "peak_luminance_cd_m2", 0, "content.peak_luminance_cd_m2"),  # open lower bound
    ("content", "diagonal_in", "27", "content.diagonal_in"),
    ("lens", "foo", 1, "lens.foo"),
    ("lens", "f_number", 0.3, "lens.f_number"),
    ("lens", "f_number", 200, "lens.f_number"),
    ("lens", "model", "fisheye", "lens.model"),
    ("lens", "focus_distance_m", 0.005, "lens.focus_distance_m"),  # inside the 6 mm focal length
    ("sensor", "pitch_um", "1.55", "sensor.pitch_um"),
    ("sensor", "pitch_um", float("nan"), "sensor.pitch_um"),
    ("sensor", "width_px", 12.5, "sensor.width_px"),
    ("sensor", "width_px", True, "sensor.width_px"),
    ("sensor", "height_px", 0, "sensor.height_px"),
    ("bands", "range_nm", [300, 700], "bands.range_nm"),
    ("bands", "range_nm", [400, 900], "bands.range_nm"),
    ("bands", "range_nm", [700, 400], "bands.range_nm"),
    ("bands", "step_nm", 0.1, "bands.step_nm"),
    ("render", "noise", 0.01, "render.noise"),                   # together with spp
    ("render", "seed", -1, "render.seed"),
    ("render", "path", "raytrace", "render.path"),
    ("render", "depth", "yes", "render.depth"),
    ("render", "supersample", 0, "render.supersample"),
    ("camera", "origin_m", [0, 1], "camera.origin_m"),
    ("camera", "up", "y", "camera.up"),
]


@pytest.mark.parametrize("table, key, value, named", BAD, ids=[f"{b[3]}={b[2]!r}" for b in BAD])
def test_bad_values_name_file_and_key_in_one_line(udc, table, key, value, named):
    doc = _mutate(udc.monitor_doc(), table, key, value)
    with pytest.raises(SceneError) as e:
        parse_scene(doc, "/scenes/bad.toml")
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"/scenes/bad.toml: {named}"), msg


@pytest.mark.parametrize("doc, named", [
    ({"sensor": {"width_px": 64}}, "content"),                                   # no [content]
    ({"content": {"type": "room", "image": "x.png"}}, "content.image"),          # a monitor key on a room
    ({"content": {"type": "mitsuba_xml"}}, "content.file"),
    ({"content": {"type": "room"}, "render": {"path": "rgb_matrix"}}, "render.path"),
    ({"content": {"type": "room"}, "camera": {"origin_m": [1, 2, 3], "target_m": [1, 2, 3]}}, "camera.target_m"),
    ({"content": {"type": "hdr", "sun_luminance_cd_m2": -1}}, "content.sun_luminance_cd_m2"),
])
def test_bad_documents_name_file_and_key(doc, named):
    with pytest.raises(SceneError) as e:
        parse_scene(doc, "s.toml")
    assert "\n" not in str(e.value) and str(e.value).startswith(f"s.toml: {named}"), str(e.value)


def test_unreadable_or_invalid_scene_file(tmp_path):
    with pytest.raises(SceneError, match="missing.toml: cannot read the scene file"):
        load_scene(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[content\ntype = 'monitor'\n")
    with pytest.raises(SceneError, match=r"bad\.toml: not valid TOML") as e:
        load_scene(bad)
    assert "\n" not in str(e.value)


# ---------------------------------------------------------------- the rig: framing and projection


@pytest.mark.parametrize("sensor_px", [(128, 64), (64, 128), (96, 54)])
@pytest.mark.parametrize("framing", ["fit", "fill"])
def test_monitor_framing_puts_its_edges_on_the_frame_edges(udc, framing, sensor_px):
    """fit: the whole panel inside the frame, touching it on one axis; fill: the frame inside the
    panel, touching it on one axis. Exact thin-lens geometry, so 1e-9 px."""
    s = parse_scene(udc.monitor_doc(framing=framing, sensor_px=sensor_px), "s.toml")
    g = rig.camera_geometry(s)
    w, h = s.content.size_m
    corners = np.array([[-w / 2, h / 2, 0], [w / 2, h / 2, 0], [w / 2, -h / 2, 0], [-w / 2, -h / 2, 0]])
    (x0, y0), (x1, _), (_, y1), _ = rig.projection_px(g, corners)
    m, W, H = g.margin_px, s.sensor.width_px, s.sensor.height_px
    assert x0 < x1 and y0 < y1  # panel left on the image's left, its top at the top
    inset = np.array([x0 - m, m + W - x1, y0 - m, m + H - y1])  # panel edge to frame edge, px (> 0: inside)
    tol = 1e-9
    if framing == "fit":
        assert np.all(inset > -tol) and np.min(np.abs(inset)) < tol
    else:
        assert np.all(inset < tol) and np.max(inset) > -tol
    # thin lens: magnification v/u, u = f (1 + 1/m)
    mag = g.image_distance_um / (rig.monitor_distance_m(s) * 1e6)
    f_m = s.lens.focal_length_mm * 1e-3
    assert mag == pytest.approx(f_m / (rig.monitor_distance_m(s) - f_m), rel=1e-12)


def test_render_grid_margin_supersampling_and_field_of_view(udc):
    s = parse_scene(udc.monitor_doc(sensor_px=(100, 50), pitch_um=10.0, render={"margin_um": 25.0}), "s.toml")
    g = rig.camera_geometry(s)
    assert (g.margin_px, g.width_px, g.height_px, g.pitch_um) == (3, 106, 56, 10.0)  # ceil(25 / 10) = 3
    ss = rig.camera_geometry(s.with_render(supersample=3))
    assert (ss.margin_px, ss.width_px, ss.height_px) == (9, 318, 168) and ss.pitch_um == pytest.approx(10 / 3)
    assert math.tan(math.radians(g.fov_x_deg) / 2) == pytest.approx(g.width_px * g.pitch_um / 2 / g.image_distance_um,
                                                                    rel=1e-12)
    # the same world point lands on the same physical sensor point at either sampling
    p = np.array([0.05, -0.03, 0.0])
    np.testing.assert_allclose(rig.projection_px(ss, p), 3 * rig.projection_px(g, p), rtol=1e-12)
    # an explicit focus distance sets the image distance v = 1 / (1/f − 1/u)
    near = rig.camera_geometry(replace(s, lens=replace(s.lens, focus_distance_m=0.5)))
    assert near.image_distance_um == pytest.approx(1 / (1 / 6000 - 1 / 0.5e6), rel=1e-12)


def test_3d_content_needs_a_camera_origin():
    with pytest.raises(SceneError, match=r"^r.toml: camera.origin_m = None: expected the camera position"):
        parse_scene({"content": {"type": "room"}}, "r.toml")
    parse_scene({"content": {"type": "mitsuba_xml", "file": "x.xml"}}, "r.toml")  # the XML's own camera


# ---------------------------------------------------------------- spectra in absolute units


def _colour_ybar():
    import colour
    c = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    return np.asarray(c.wavelengths, float), np.asarray(c.values[:, 1], float)


def test_monitor_white_has_the_peak_luminance():
    prim, desc = spectra.monitor_primaries("Apple Studio Display", 300.0)
    assert prim.shape == (3, spectra.GRID_NM.size) and "Apple Studio Display" in desc
    assert float(spectra.luminance_cd_m2(prim.sum(0))) == pytest.approx(300.0, rel=1e-12)
    # independently: 683 ∫ L ȳ dλ with colour-science's own 1 nm ȳ table and the trapezoid rule;
    # the two quadratures differ only by the end samples (ȳ(360), ȳ(830) < 1e-5), so 1e-6 relative
    wl, ybar = _colour_ybar()
    white = np.interp(wl, spectra.GRID_NM, prim.sum(0))
    assert 683.0 * np.trapezoid(white * ybar, wl) == pytest.approx(300.0, rel=1e-6)
    # each primary is a scaled copy of colour-science's spectrum, and white has D65's chromaticity
    raw, _ = spectra.load_primaries("Apple Studio Display")
    for c in range(3):
        ratio = prim[c][raw[c] > 0] / raw[c][raw[c] > 0]
        np.testing.assert_allclose(ratio, ratio[0], rtol=1e-12)
    X, Y, Z = spectra.cmfs() @ prim.sum(0)
    np.testing.assert_allclose([X / (X + Y + Z), Y / (X + Y + Z)], [0.3127, 0.3290], atol=1e-12)
    # "native" keeps the measured ratios between the primaries (white then greenish: y = 0.357)
    native, _ = spectra.monitor_primaries("Apple Studio Display", 300.0, white_point="native")
    ratio = native[raw > 0] / raw[raw > 0]
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-12)
    with pytest.raises(spectra.SpectrumError, match="content.white_point = 'D99'"):
        spectra.monitor_primaries("Apple Studio Display", 300.0, white_point="D99")


def test_band_means_of_a_linear_spectrum_is_its_value_at_the_band_centre():
    # the trapezoid rule is exact for linear functions, also on bands whose edges are off the grid
    spec = 0.3 + 0.002 * spectra.GRID_NM
    edges = np.array([360.0, 402.5, 417.3, 500.0, 555.55, 829.0])
    centres = (edges[:-1] + edges[1:]) / 2
    np.testing.assert_allclose(spectra.band_means(spec, edges), 0.3 + 0.002 * centres, rtol=1e-12)
    # stacked spectra keep their leading shape
    out = spectra.band_means(np.stack([spec, 2 * spec]), edges)
    assert out.shape == (2, 5)
    np.testing.assert_allclose(out[1], 2 * out[0], rtol=1e-14)


def test_band_xyz_luminance_of_a_flat_spectrum():
    """A flat 1 W·sr⁻¹·m⁻²·nm⁻¹ spectrum over 400–700 nm has Y = 683 ∫ ȳ dλ (cd/m²)."""
    wl, ybar = _colour_ybar()
    inside = (wl >= 400) & (wl <= 700)
    edges = np.arange(400.0, 701.0, 10.0)
    Y = spectra.band_xyz(edges)[1] @ np.ones(30)
    # band edges on the 1 nm grid: the same piecewise-linear integral, so 1e-12
    assert Y == pytest.approx(683.0 * np.trapezoid(ybar[inside], wl[inside]), rel=1e-12)
    # golden: CIE 1931 2°, ∫ ȳ over 360–830 nm = 106.857 nm (the sum of the 1 nm table)
    assert spectra.band_xyz([360.0, 830.0])[1, 0] == pytest.approx(683.0 * 106.857, rel=1e-5)
    assert 683.0 * 106.7 < Y < 683.0 * 106.857  # nearly all of ȳ lies in 400–700 nm


def test_scaled_spectra_illuminants_and_primaries_from_csv(tmp_path):
    d65 = spectra.scaled_to_luminance(spectra.illuminant("D65"), 2000.0)
    assert float(spectra.luminance_cd_m2(d65)) == pytest.approx(2000.0, rel=1e-12)
    with pytest.raises(spectra.SpectrumError, match="illuminant = 'D66'"):
        spectra.illuminant("D66")
    with pytest.raises(spectra.SpectrumError):
        spectra.scaled_to_luminance(np.zeros_like(spectra.GRID_NM), 1.0)
    csv = tmp_path / "prim.csv"
    csv.write_text("wavelength_nm,r,g,b\n400,0,0,1\n500,0,1,1\n600,1,1,0\n700,1,0,0\n")
    prim, desc = spectra.monitor_primaries("prim.csv", 100.0, base=tmp_path)
    assert desc.startswith("CSV:") and float(spectra.luminance_cd_m2(prim.sum(0))) == pytest.approx(100.0, rel=1e-12)
    # linear interpolation
    np.testing.assert_allclose(prim[0][spectra.GRID_NM == 650], prim[0][spectra.GRID_NM == 700], rtol=1e-12)
    assert np.all(prim[:, (spectra.GRID_NM < 400) | (spectra.GRID_NM > 700)] == 0)  # zero outside the table
    csv.write_text("wavelength_nm,r,g,b\n600,1,1,1\n500,1,1,1\n")
    with pytest.raises(spectra.SpectrumError, match="must increase"):
        spectra.load_primaries(str(csv))
    with pytest.raises(spectra.SpectrumError, match="content.primaries = 'Sony'"):
        spectra.load_primaries("Sony", tmp_path)


# ---------------------------------------------------------------- what the monitor shows


def test_srgb_decode_golden_values():
    # IEC 61966-2-1: ((0.5 + 0.055)/1.055)^2.4 = 0.21404114; the linear segment ends at
    # 0.04045 → 0.04045/12.92 = 0.0031308050 (goldens to 8 digits, hence rtol 1e-7)
    np.testing.assert_allclose(di.decode(np.array([0.0, 0.04045, 0.5, 1.0]), "srgb"),
                               [0.0, 0.0031308050, 0.21404114, 1.0], rtol=1e-7, atol=1e-12)
    # both branches meet at the threshold (continuity to 1e-7)
    lo, hi = 0.04045 / 12.92, ((0.04045 + 0.055) / 1.055) ** 2.4
    assert abs(lo - hi) < 1e-7
    np.testing.assert_allclose(di.decode(np.array([0.5]), "gamma2.2"), [0.5 ** 2.2], rtol=1e-15)
    x = np.linspace(0, 1, 7)
    assert di.decode(x, "linear") is x or np.array_equal(di.decode(x, "linear"), x)


def test_orientation_pattern_layout():
    img = di.pattern("orientation", 480, 270)
    s = 270 // 8
    assert img.shape == (3, 270, 480) and s == 33
    np.testing.assert_array_equal(img[0, :s, :s], 1)
    np.testing.assert_array_equal(img[1, :s, -s:], 1)
    np.testing.assert_array_equal(img[2, -s:, :s], 1)
    assert img.sum() == 3 * s * s  # nothing else lit
    assert di.pattern("white", 8, 4).min() == 1.0
    with pytest.raises(di.DisplayImageError, match="pattern:spiral"):
        di.pattern("spiral", 8, 4)


def test_portrait_image_is_rotated_to_landscape_and_letterboxed():
    code = np.zeros((60, 30, 3))
    code[:10, -10:] = 1.0  # a marker in the top-right corner
    out, how = di.fit_to_panel(code, 160, 90)
    # rotated a quarter turn counter-clockwise: 30 rows × 60 cols; scale min(160/60, 90/30) = 8/3
    assert how["rotated"] and how["shown_px"] == [160, 80] and how["offset_px"] == [0, 5]
    assert out.shape == (3, 90, 160)
    assert np.all(out[:, :5] == 0) and np.all(out[:, 85:] == 0)  # black bars above and below
    # counter-clockwise: the top-right corner goes to the top-left
    tl, tr = out[0, 5:25, :20].mean(), out[0, 5:25, -20:].mean()
    bl = out[0, 65:85, :20].mean()
    assert tl > 0.9 and tr < 0.05 and bl < 0.05


@pytest.mark.parametrize("shape, panel", [((333, 1000), (480, 270)), ((270, 480), (480, 270)), ((512, 512), (480, 270)),
                                          ((1000, 333), (480, 270)), ((90, 1600), (160, 90)), ((64, 48), (270, 480))])
def test_fit_keeps_the_aspect_within_one_pixel(shape, panel):
    code = np.full(shape + (3,), 0.5)
    cols, rows = panel
    out, how = di.fit_to_panel(code, cols, rows)
    w, h = how["shown_px"]
    r, c = (shape[1], shape[0]) if how["rotated"] else shape  # rows, cols after any rotation
    assert how["rotated"] == ((shape[0] > shape[1]) != (rows > cols) and shape[0] != shape[1])
    assert abs(w - h * c / r) <= 1 and (w == cols or h == rows) and w <= cols and h <= rows
    x0, y0 = how["offset_px"]
    assert abs(x0 - (cols - w - x0)) <= 1 and abs(y0 - (rows - h - y0)) <= 1  # centred
    lit = out[0] > 0
    assert lit.sum() == w * h and np.all(lit[y0:y0 + h, x0:x0 + w])
    np.testing.assert_allclose(out[:, y0:y0 + h, x0:x0 + w], 0.5, rtol=1e-12)  # a flat image stays flat


def _png16(path, a):
    """A 16-bit PNG written by hand (zlib, filter 0): imageio's Pillow cannot write 16-bit colour."""
    import struct
    import zlib
    a = np.ascontiguousarray(a, dtype=">u2")
    h, w = a.shape[:2]
    raw = b"".join(b"\x00" + a[y].tobytes() for y in range(h))

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)
    ihdr = struct.pack(">IIBBBBB", w, h, 16, 2 if a.ndim == 3 else 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw))
                     + chunk(b"IEND", b""))


def test_read_code_values_from_files(tmp_path):
    import imageio.v3 as iio
    a16 = np.array([[[0, 32768, 65535], [1, 2, 3]]], dtype=np.uint16)
    iio.imwrite(tmp_path / "a.tif", a16)  # 16-bit colour TIFF (tifffile): exact
    np.testing.assert_array_equal(di.read_code_values("a.tif", tmp_path), a16 / 65535.0)
    g16 = np.array([[0, 1, 32768, 65535]], dtype=np.uint16)
    iio.imwrite(tmp_path / "g16.png", g16)  # 16-bit grey PNG: exact
    np.testing.assert_array_equal(di.read_code_values("g16.png", tmp_path)[..., 0], g16 / 65535.0)
    grey = np.array([[0, 255], [128, 64]], dtype=np.uint8)
    iio.imwrite(tmp_path / "g.png", grey)
    g = di.read_code_values(str(tmp_path / "g.png"))
    assert g.shape == (2, 2, 3) and np.array_equal(g[..., 1], grey / 255.0)
    rgba = np.zeros((2, 3, 4), dtype=np.uint8)
    rgba[..., 3] = 255
    rgba[0, 0, :3] = (10, 20, 30)
    iio.imwrite(tmp_path / "rgba.png", rgba)
    v = di.read_code_values("rgba.png", tmp_path)
    assert v.shape == (2, 3, 3) and np.array_equal(v[0, 0], np.array([10, 20, 30]) / 255.0)
    (tmp_path / "notes.txt").write_text("not an image\n")
    with pytest.raises(di.DisplayImageError, match=r"content.image = 'notes.txt': cannot read .*notes.txt") as e:
        di.read_code_values("notes.txt", tmp_path)
    assert "\n" not in str(e.value)
    with pytest.raises(di.DisplayImageError, match="builtin:astronaut"):
        di.read_code_values("builtin:mona_lisa")
    assert di.read_code_values("builtin:camera").shape == (512, 512, 3)  # grey sample, 3 channels


def test_16_bit_colour_png_keeps_its_precision(tmp_path):
    a16 = np.array([[[0, 32768, 65535], [1, 2, 3]]], dtype=np.uint16)
    _png16(tmp_path / "a.png", a16)
    np.testing.assert_array_equal(di.read_code_values("a.png", tmp_path), a16 / 65535.0)


def test_panel_drive_applies_the_transfer(tmp_path):
    import imageio.v3 as iio
    code = np.full((9, 16, 3), 128, dtype=np.uint8)  # the panel's own size: no resampling
    iio.imwrite(tmp_path / "c.png", code)
    for transfer, expect in (("srgb", di.decode(np.array(128 / 255), "srgb")), ("linear", 128 / 255),
                             ("gamma2.2", (128 / 255) ** 2.2)):
        drive, how = di.panel_drive("c.png", 16, 9, transfer, tmp_path)
        assert drive.shape == (3, 9, 16) and not how["rotated"]
        np.testing.assert_allclose(drive, expect, rtol=1e-12)
