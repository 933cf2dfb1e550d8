"""udc-render fit reads what cameras write: a lossless-JPEG DNG with a black level per CFA site, row and column
deltas, a LinearizationTable and an ActiveArea smaller than the image (tests/udc_render/camera_files.py writes
it with its own encoder), 16-bit colour and grey PNG and TIFF; each read back against the values written. What
it cannot read is one line naming the file, and no traceback from the command."""
from __future__ import annotations

import numpy as np
import png
import pytest
import rawpy
import tifffile

from tests.udc_render.camera_files import CameraDng, companding_table, write_camera_dng
from udc_render.cli import main
from udc_render.fit.inputs import FitError, read_frame
from udc_render.streams import stream

ACTIVE = (3, 5, 67, 97)  # odd top and left: LibRaw's own crop moves them to 4 and 6


def _camera_dng(seed: int, tile=(32, 48)) -> CameraDng:
    """A 70 × 100 image of random 14-bit codes, GRBG at the ActiveArea's origin, four black levels, deltas."""
    rng = stream(seed, "camera-dng")
    y0, x0, y1, x1 = ACTIVE
    return CameraDng(rng.integers(0, 1 << 14, (70, 100)).astype(np.uint16), cfa=(1, 0, 2, 1),
                     black=((60.25, 64.0), (66.5, 70.0)), delta_v=rng.uniform(0, 5, y1 - y0),
                     delta_h=rng.uniform(-3, 3, x1 - x0), table=companding_table(), white=65000, active=ACTIVE,
                     tile=tile)


@pytest.mark.parametrize("tile", [(32, 48), None], ids=["lj92_tiles", "uncompressed_strips"])
def test_a_camera_dng_reads_as_written(tmp_path, tile):
    """Every pixel of the ActiveArea above its black level is table[code] − black(site) − ΔH − ΔV as written;
    the CFA pattern at the ActiveArea's origin, WhiteLevel as the saturation, the 16-bit linear range."""
    dng = _camera_dng(1, tile)
    write_camera_dng(tmp_path / "c.dng", dng)
    f = read_frame(tmp_path / "c.dng")
    assert f.kind == "cfa" and f.shape == (64, 92) and f.sites.tolist() == [[1, 0], [2, 1]]
    assert f.saturation_dn == 65000 and f.bits == 16
    assert np.allclose(f.above_black(), dng.linear(), rtol=0, atol=1e-9)  # the sums' rounding only
    assert f.black_map[0, 0] == pytest.approx(60.25 + round(dng.delta_h[0], 3) + round(dng.delta_v[0], 3))


def test_what_libraw_alone_would_give_differs_from_the_tags(tmp_path):
    """Why the reader takes the levels and the crop from the tags (fit/dng.py): LibRaw's visible crop starts
    on even rows and columns, and its per-channel black levels hold neither the sites' values nor the deltas."""
    dng = _camera_dng(2)
    write_camera_dng(tmp_path / "c.dng", dng)
    with rawpy.imread(str(tmp_path / "c.dng")) as raw:
        assert (raw.sizes.top_margin, raw.sizes.left_margin) != ACTIVE[:2]
        assert np.array_equal(raw.raw_image, dng.table[dng.stored])  # the table is applied by LibRaw
        libraw_black = sorted(raw.black_level_per_channel)
    assert libraw_black != sorted([60.25, 64.0, 66.5, 70.0])


def test_a_dng_without_a_table_or_deltas_and_options_over_tags(tmp_path):
    """No table: the codes are the linear values; --black-level replaces the per-site map by one level."""
    rng = stream(3, "plain-dng")
    dng = CameraDng(rng.integers(100, 4000, (48, 64)).astype(np.uint16), black=((64, 64), (64, 64)), white=4095)
    write_camera_dng(tmp_path / "c.dng", dng)
    f = read_frame(tmp_path / "c.dng")
    assert f.black_map is None and f.black_dn == 64 and np.allclose(f.above_black(), dng.linear(), rtol=0, atol=1e-9)
    g = read_frame(tmp_path / "c.dng", black_dn=10, saturation_dn=3000)
    assert (g.black_dn, g.saturation_dn, g.black_map) == (10.0, 3000.0, None)


def _png16(path, data: np.ndarray) -> None:
    h, w = data.shape[:2]
    planes = 1 if data.ndim == 2 else data.shape[2]
    with open(path, "wb") as fh:
        png.Writer(w, h, greyscale=planes == 1, bitdepth=16).write(fh, data.reshape(h, -1))


def test_sixteen_bit_colour_and_grey_png_and_tiff_keep_every_bit(tmp_path):
    """300 DN reads as 300 (Pillow gave 1): a 16-bit colour and grey PNG, a colour TIFF interleaved and
    planar, all read back equal to the values written, saturation 65535."""
    rng = stream(4, "sixteen-bit")
    rgb = rng.integers(0, 65536, (20, 24, 3)).astype(np.uint16)
    rgb[0, 0] = (300, 301, 302)
    _png16(tmp_path / "c.png", rgb)
    _png16(tmp_path / "g.png", rgb[..., 1])
    tifffile.imwrite(tmp_path / "c.tif", rgb, photometric="rgb")
    tifffile.imwrite(tmp_path / "p.tif", np.moveaxis(rgb, -1, 0), photometric="rgb", planarconfig="separate")
    for name, want, kind in (("c.png", rgb, "rgb"), ("g.png", rgb[..., 1], "mono"), ("c.tif", rgb, "rgb"),
                             ("p.tif", rgb, "rgb")):
        f = read_frame(tmp_path / name, black_dn=0)
        assert (f.kind, f.bits, f.saturation_dn) == (kind, 16, 65535.0) and np.array_equal(f.dn, want), name
    assert read_frame(tmp_path / "c.png").dn[0, 0].tolist() == [300, 301, 302]


def _truncated_dng(tmp_path):
    dng = _camera_dng(5)
    write_camera_dng(tmp_path / "t.dng", dng)
    data = (tmp_path / "t.dng").read_bytes()
    (tmp_path / "t.dng").write_bytes(data[:len(data) // 2])
    return tmp_path / "t.dng"


def _bad_black_count(tmp_path):
    dng = CameraDng(np.zeros((48, 64), np.uint16), delta_h=np.zeros(10), tile=None)
    write_camera_dng(tmp_path / "b.dng", dng)
    return tmp_path / "b.dng"


@pytest.mark.parametrize("make, says", [
    (_truncated_dng, "cannot be decoded"),
    (_bad_black_count, "BlackLevelDeltaH holds 10 values: expected one per ActiveArea column"),
    (lambda p: (p / "x.png").write_bytes(b"\x89PNG\r\n\x1a\nnot a png") and p / "x.png", "cannot be read as a PNG"),
    (lambda p: (p / "x.tif").write_bytes(b"II*\0garbage") and p / "x.tif", "cannot be read as a TIFF"),
    (lambda p: tifffile.imwrite(p / "m.dng", np.zeros((32, 32), np.uint16)) or p / "m.dng", "no CFA or LinearRaw"),
])
def test_what_cannot_be_read_is_one_line_naming_the_file(tmp_path, capsys, make, says):
    """The reader raises one line naming the file; the command exits 2 with that line and no traceback."""
    path = make(tmp_path)
    with pytest.raises(FitError, match=says) as e:
        read_frame(path)
    assert str(path) in str(e.value) and "\n" not in str(e.value)
    assert main(["fit", "--psf", str(path), "--quiet", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert says in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_a_linear_raw_dng_with_a_black_level_per_sample(tmp_path):
    """A LinearRaw DNG (three samples a pixel, as a demosaicing camera writes): its BlackLevel holds one level
    per sample (BlackLevelRepeatDim 1 × 1), each subtracted from its own plane."""
    rgb = (np.arange(40 * 48 * 3).reshape(40, 48, 3) % 4000 + 100).astype(np.uint16)
    tags = [(50706, "B", 4, (1, 4, 0, 0), True), (50708, "s", 0, "udc-test linear", True),
            (50713, "H", 2, (1, 1), True), (50714, "H", 3, (60, 64, 70), True), (50717, "H", 1, 4095, True)]
    tifffile.imwrite(tmp_path / "l.dng", rgb, photometric=34892, extratags=tags, software=False, metadata=None)
    f = read_frame(tmp_path / "l.dng")
    assert f.kind == "rgb" and f.saturation_dn == 4095
    assert np.array_equal(f.above_black(), rgb - np.array([60.0, 64.0, 70.0]))
