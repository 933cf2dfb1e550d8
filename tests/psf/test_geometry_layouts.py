"""Exact rasterisation (psf.geometry), display layouts (psf.layouts) and measured micrographs
(psf.micrograph): areas against independent quadrature and brute force, open fractions, Fourier
coefficients, file formats and the user-facing errors."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from psf import LayoutError, Lens, MicrographLayout, compute_kernels, layouts
from psf.geometry import ellipse_areas, interval_overlap, rect_areas, unit_disc_cell_areas
from psf.layouts import Ellipse, PeriodicLayout, Rect
from psf.micrograph import read_transmission_image
from psf.pupil import cell_raster

skio = pytest.importorskip("skimage.io")


# ---------------------------------------------------------------------------------------------
# geometry
# ---------------------------------------------------------------------------------------------

def _ellipse_cell_area_quad(x0, x1, y0, y1, cx, cy, rx, ry):
    """∫_{x0}^{x1} |[y0, y1] ∩ [cy − h(x), cy + h(x)]| dx by adaptive quadrature, with every kink
    of the integrand passed as a break point."""
    def h(x):
        t = (x - cx) / rx
        return ry * math.sqrt(max(1.0 - t * t, 0.0))

    def f(x):
        hx = h(x)
        return max(0.0, min(y1, cy + hx) - max(y0, cy - hx))

    pts = [cx, cx - rx, cx + rx]
    for y in (y0, y1):
        s = (y - cy) / ry
        if abs(s) < 1:
            pts += [cx - rx * math.sqrt(1 - s * s), cx + rx * math.sqrt(1 - s * s)]
    pts = sorted(p for p in pts if x0 < p < x1)
    return quad(f, x0, x1, points=pts or None, limit=200, epsabs=1e-13, epsrel=1e-13)[0]


@pytest.mark.parametrize("cx, cy, rx, ry", [(0.3, -0.2, 3.7, 2.1), (5.05, 4.95, 1.3, 3.9), (0.0, 0.0, 0.4, 0.4),
                                            (-2.0, 1.0, 9.0, 0.7)])
def test_ellipse_areas_match_quadrature_cell_by_cell(cx, cy, rx, ry):
    # Non-uniform rectilinear grid; every cell against independent quadrature. Measured ≤ 4e-15.
    rng = np.random.default_rng(7)
    xe = np.sort(np.concatenate([[-6.0, 6.5], rng.uniform(-6, 6.5, 13)]))
    ye = np.sort(np.concatenate([[-5.0, 6.0], rng.uniform(-5, 6, 11)]))
    got = ellipse_areas(xe, ye, cx, cy, rx, ry)
    assert got.shape == (ye.size - 1, xe.size - 1)
    ref = np.array([[_ellipse_cell_area_quad(xe[i], xe[i + 1], ye[j], ye[j + 1], cx, cy, rx, ry)
                     for i in range(xe.size - 1)] for j in range(ye.size - 1)])
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-11)


def test_ellipse_areas_total_and_brute_force():
    # Whole ellipse inside: the cells sum to π rx ry (measured 2e-16 relative). Brute force: 400 × 400
    # sub-samples per cell counted inside; its own error is ≤ ~ 2/400 of a cell near the boundary, but its
    # errors along an arc cancel: measured 6.4e-5 of a cell, asserted 2e-4.
    xe, ye = np.linspace(-4, 4, 17), np.linspace(-3, 3, 13)
    cx, cy, rx, ry = 0.37, -0.21, 3.1, 2.2
    got = ellipse_areas(xe, ye, cx, cy, rx, ry)
    assert abs(got.sum() / (math.pi * rx * ry) - 1) < 1e-13
    cell = (xe[1] - xe[0]) * (ye[1] - ye[0])
    assert got.min() >= 0 and got.max() <= cell * (1 + 1e-14)
    sub = 400
    brute = np.zeros_like(got)
    for j in range(ye.size - 1):
        ys = ye[j] + (np.arange(sub) + 0.5) * (ye[1] - ye[0]) / sub
        for i in range(xe.size - 1):
            xs = xe[i] + (np.arange(sub) + 0.5) * (xe[1] - xe[0]) / sub
            inside = ((xs[None, :] - cx) / rx) ** 2 + ((ys[:, None] - cy) / ry) ** 2 <= 1
            brute[j, i] = inside.mean() * cell
    assert np.max(np.abs(brute - got)) < 2e-4 * cell


def test_ellipse_partly_outside_and_disjoint():
    xe, ye = np.linspace(0, 4, 9), np.linspace(0, 4, 9)
    # centred on the grid corner: a quarter of the disc is on the grid
    assert abs(ellipse_areas(xe, ye, 0.0, 0.0, 2.0, 2.0).sum() - math.pi) < 1e-13
    # wholly outside: zeros; inside a single cell: that cell holds all of it
    assert not ellipse_areas(xe, ye, 10.0, 10.0, 1.0, 1.0).any()
    one = ellipse_areas(xe, ye, 1.25, 2.25, 0.2, 0.1)
    assert np.count_nonzero(one) == 1 and abs(one[4, 2] - math.pi * 0.02) < 1e-15


def test_unit_disc_cell_areas_symmetry_and_quadrant():
    x0, x1, y0, y1 = 0.13, 0.71, -0.4, 0.95
    a = unit_disc_cell_areas(x0, x1, y0, y1)
    for b in (unit_disc_cell_areas(-x1, -x0, y0, y1), unit_disc_cell_areas(x0, x1, -y1, -y0),
              unit_disc_cell_areas(y0, y1, x0, x1)):
        assert abs(a - b) < 1e-15
    assert abs(unit_disc_cell_areas(0.0, 2.0, 0.0, 2.0) - math.pi / 4) < 1e-15
    assert unit_disc_cell_areas(1.0, 2.0, 0.0, 1.0) == 0.0


def test_rect_areas_exact():
    rng = np.random.default_rng(3)
    xe = np.sort(rng.uniform(-3, 3, 14))
    ye = np.sort(rng.uniform(-3, 3, 10))
    cx, cy, w, h = 0.2, -0.3, 2.3, 1.7
    got = rect_areas(xe, ye, cx, cy, w, h)
    for j in range(ye.size - 1):
        for i in range(xe.size - 1):
            ox = max(0.0, min(xe[i + 1], cx + w / 2) - max(xe[i], cx - w / 2))
            oy = max(0.0, min(ye[j + 1], cy + h / 2) - max(ye[j], cy - h / 2))
            assert abs(got[j, i] - ox * oy) < 1e-15
    inside = rect_areas(np.linspace(-2, 2, 9), np.linspace(-2, 2, 7), cx, cy, w, h)
    assert abs(inside.sum() - w * h) < 1e-14
    np.testing.assert_array_equal(interval_overlap(np.array([0.0, 1.0, 2.0, 3.0]), 0.5, 2.25), [0.5, 1.0, 0.25])


# ---------------------------------------------------------------------------------------------
# layouts
# ---------------------------------------------------------------------------------------------

def test_builtin_open_fractions_are_the_papers():
    assert abs(layouts.toled(pitch_um=60.0).open_fraction - 0.21) < 1e-15
    assert abs(layouts.poled().open_fraction - 0.23) < 1e-15
    for f in (0.05, 0.3, 0.6):
        assert abs(layouts.toled(open_fraction=f, slit_height_fraction=0.8).open_fraction - f) < 1e-15
        assert abs(layouts.poled(open_fraction=f / 2).open_fraction - f / 2) < 1e-15
    assert layouts.toled(amplitude=0.5).power_transmittance == pytest.approx(0.25 * 0.21, rel=1e-15)


WRAPPED = PeriodicLayout("wrapped", 40.0, 30.0, (Rect(0.0, 0.0, 13.0, 7.0), Ellipse(39.0, 15.0, 6.0, 4.0)))


@pytest.mark.parametrize("layout", [layouts.toled(pitch_um=60.0), layouts.poled(), layouts.slit_grating(50.0, 17.0),
                                    layouts.toled(amplitude=0.6), WRAPPED],
                         ids=["toled", "poled", "slits", "toled-a0.6", "wrapped"])
@pytest.mark.parametrize("n", [(7, 7), (19, 23), (64, 48)])
def test_cell_rasters_carry_the_open_fraction(layout, n):
    # Area raster: mean intensity = amplitude² × open fraction, exactly (openings crossing the cell
    # border wrap around). Band-limited raster: mean amplitude = c0 = amplitude × open fraction.
    nx, ny = n
    amp, inten = layout.cell_raster(nx, ny)
    assert amp.shape == (ny, nx)
    assert abs(inten.mean() - layout.power_transmittance) < 1e-13
    assert abs(amp.mean() - layout.amplitude * layout.open_fraction) < 1e-13
    assert amp.min() >= 0 and amp.max() <= layout.amplitude + 1e-15
    bl, mean_intensity = cell_raster(layout, nx, ny, "band_limited")
    assert bl.shape == (ny, nx)
    assert abs(bl.mean() - layout.amplitude * layout.open_fraction) < 1e-13
    assert mean_intensity == layout.power_transmittance


def test_band_limited_raster_samples_the_fourier_series():
    # Odd n: the raster is the Fourier series over |k| ≤ (n−1)/2 at the cell centres (j + ½) p / n.
    lay, n = layouts.poled(), 15
    amp, _ = cell_raster(lay, n, n, "band_limited")
    assert np.isrealobj(amp)
    k = np.arange(-(n // 2), n // 2 + 1)
    c = lay.fourier_coefficients(k, k)
    x = (np.arange(n) + 0.5) * lay.pitch_x_um / n
    ex = np.exp(2j * np.pi * np.outer(k, x) / lay.pitch_x_um)
    series = (ex.T @ c @ ex).T  # [y, x]
    np.testing.assert_allclose(amp, series.real, rtol=0, atol=1e-13)
    assert np.max(np.abs(series.imag)) < 1e-13


@pytest.mark.parametrize("nu", [(0.0, 0.0), (0.031, 0.0), (0.017, -0.044), (0.2, 0.13)])
def test_opening_spectra_match_quadrature(nu):
    # ∫_opening e^{−2πi ν·x} dx reduced to one quad: ∫ e^{−2πiνx x} 2 sin(2πνy h(x))/(2πνy) dx.
    nux, nuy = nu
    e = Ellipse(3.0, -2.0, 7.5, 4.5)

    def inner(x, part):
        h = e.ry_um * math.sqrt(max(1 - ((x - e.cx_um) / e.rx_um) ** 2, 0.0))
        ylen = 2 * h if nuy == 0 else 2 * math.sin(2 * math.pi * nuy * h) / (2 * math.pi * nuy)
        val = np.exp(-2j * math.pi * (nux * x + nuy * e.cy_um)) * ylen
        return val.real if part == 0 else val.imag

    lo, hi = e.cx_um - e.rx_um, e.cx_um + e.rx_um
    ref = complex(*(quad(inner, lo, hi, args=(p,), limit=200, epsabs=1e-12)[0] for p in (0, 1)))
    got = e.spectrum(np.array([nux]), np.array([nuy]))[0, 0]
    assert abs(got - ref) < 1e-10 * e.area_um2
    r = Rect(1.0, 2.0, 6.0, 3.0)
    ref_r = (6.0 * np.sinc(nux * 6.0) * np.exp(-2j * math.pi * nux * 1.0)
             * 3.0 * np.sinc(nuy * 3.0) * np.exp(-2j * math.pi * nuy * 2.0))
    assert abs(r.spectrum(np.array([nux]), np.array([nuy]))[0, 0] - ref_r) < 1e-13


def test_fourier_coefficients_match_a_fine_area_raster():
    # c_k of the layout vs the DFT of a 1200² area raster divided by the box filter's sinc;
    # residual ~ aliasing of orders k ± 1200 (measured 1.4e-7, asserted 4e-7).
    lay, n = layouts.poled(), 1200
    amp, _ = lay.cell_raster(n, n)
    k = np.arange(-6, 7)
    dft = np.fft.fft2(amp)[np.ix_(k % n, k % n)] / n ** 2
    # cell centres at (j + ½) δ: undo that half-cell phase and the sinc of the box filter
    corr = np.outer(np.sinc(k / n), np.sinc(k / n)) * np.exp(1j * np.pi * (k[:, None] + k[None, :]) / n)
    np.testing.assert_allclose(dft / corr, lay.fourier_coefficients(k, k), rtol=0, atol=4e-7)


def test_poled_openings_are_disjoint_up_to_the_limit():
    # Just below the documented limit the four openings still do not overlap: area raster mean stays exact.
    limit = math.pi * (1 + 0.7 ** 2) / (2 * (1 + 0.7) ** 2)
    lay = layouts.poled(open_fraction=round(limit, 4) - 1e-4)
    _, inten = lay.cell_raster(400, 400)
    assert abs(inten.mean() - lay.open_fraction) < 1e-13


@pytest.mark.parametrize("make", [
    lambda: PeriodicLayout("bad", 0.0, 10.0),
    lambda: PeriodicLayout("bad", 10.0, 10.0, (), amplitude=1.5),
    lambda: layouts.toled(open_fraction=0.95),
    lambda: layouts.toled(open_fraction=-0.1),
    lambda: layouts.poled(open_fraction=0.85),
    lambda: layouts.slit_grating(60.0, 60.0),
    lambda: layouts.slit_grating(60.0, 0.0),
])
def test_bad_layouts_raise_one_line_layout_error(make):
    with pytest.raises(LayoutError) as err:
        make()
    assert "\n" not in str(err.value)


# ---------------------------------------------------------------------------------------------
# micrographs
# ---------------------------------------------------------------------------------------------

def _pattern(h=12, w=20):
    y, x = np.mgrid[0:h, 0:w]
    return ((x * 7 + y * 3) % 11) / 10.0  # values in [0, 1], not symmetric


def test_png_8_and_16_bit_are_scaled_by_their_maximum(tmp_path):
    v = _pattern()
    p8, p16 = tmp_path / "a8.png", tmp_path / "a16.png"
    skio.imsave(p8, np.round(v * 255).astype(np.uint8), check_contrast=False)
    skio.imsave(p16, np.round(v * 65535).astype(np.uint16), check_contrast=False)
    np.testing.assert_allclose(read_transmission_image(p8), np.round(v * 255) / 255, rtol=0, atol=1e-15)
    np.testing.assert_allclose(read_transmission_image(p16), np.round(v * 65535) / 65535, rtol=0, atol=1e-15)
    # colour: channels averaged; an alpha channel ignored
    rgb = np.stack([v, v ** 2, np.sqrt(v), np.ones_like(v)], axis=-1)
    prgba = tmp_path / "rgba.png"
    skio.imsave(prgba, np.round(rgb * 255).astype(np.uint8), check_contrast=False)
    expect = np.round(rgb[..., :3] * 255).mean(axis=-1) / 255
    np.testing.assert_allclose(read_transmission_image(prgba), expect, rtol=0, atol=1e-12)


def test_tiff_float_is_taken_as_is(tmp_path):
    v = _pattern().astype(np.float32)
    p = tmp_path / "t.tif"
    skio.imsave(p, v, check_contrast=False)
    img = read_transmission_image(p)
    assert img.dtype == np.float64 and img.shape == v.shape
    np.testing.assert_array_equal(img, v.astype(np.float64))


@pytest.mark.parametrize("channels", ["Y", "RGB"])
def test_exr_is_read_through_openexr(tmp_path, channels):
    OpenEXR = pytest.importorskip("OpenEXR")
    v = _pattern().astype(np.float32)
    data = v if channels == "Y" else np.stack([v, v, v], axis=-1)
    p = tmp_path / f"m{channels}.exr"
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, {channels: data}).write(str(p))
    np.testing.assert_array_equal(read_transmission_image(p), v.astype(np.float64))


def test_intensity_images_become_amplitudes(tmp_path):
    v = _pattern()
    p = tmp_path / "i.tif"
    skio.imsave(p, v.astype(np.float64), check_contrast=False)
    amp = MicrographLayout.load(p, pixel_um=2.0, values="amplitude")
    inten = MicrographLayout.load(p, pixel_um=2.0, values="intensity")
    np.testing.assert_allclose(amp.image, v, rtol=0, atol=1e-15)
    np.testing.assert_allclose(inten.image, np.sqrt(v), rtol=0, atol=1e-15)
    # power transmittance = mean |a|²: the intensity file's own mean
    assert abs(inten.open_fraction - v.mean()) < 1e-14
    assert abs(amp.open_fraction - (v ** 2).mean()) < 1e-14
    assert amp.period_um == (20 * 2.0, 12 * 2.0)  # (width, height) × pixel


@pytest.mark.parametrize("bad", [1.5, -0.1, float("nan")])
def test_out_of_range_values_are_rejected(tmp_path, bad):
    v = _pattern()
    v[3, 4] = bad
    p = tmp_path / "bad.tif"
    skio.imsave(p, v, check_contrast=False)
    with pytest.raises(LayoutError) as err:
        MicrographLayout.load(p, pixel_um=1.0)
    msg = str(err.value)
    assert "\n" not in msg and str(p) in msg


@pytest.mark.parametrize("case", ["garbage", "missing", "suffix", "one-row"])
def test_unreadable_files_are_one_line_errors_naming_the_file(tmp_path, case):
    if case == "garbage":
        p = tmp_path / "broken.png"
        p.write_bytes(b"\x89PNG\r\n\x1a\n this is not a png\n at all")
    elif case == "missing":
        p = tmp_path / "nowhere.tif"
    elif case == "suffix":
        p = tmp_path / "photo.jpg"
        p.write_bytes(b"\xff\xd8\xff")
    else:
        p = tmp_path / "row.png"
        skio.imsave(p, np.full((1, 8), 200, np.uint8), check_contrast=False)
    with pytest.raises(LayoutError) as err:
        MicrographLayout.load(p, pixel_um=1.0)
    msg = str(err.value)
    assert "\n" not in msg and str(p) in msg


def test_bad_micrograph_arguments(tmp_path):
    p = tmp_path / "ok.png"
    skio.imsave(p, np.full((4, 4), 255, np.uint8), check_contrast=False)
    for kw in (dict(pixel_um=0.0), dict(pixel_um=1.0, values="log")):
        with pytest.raises(LayoutError) as err:
            MicrographLayout.load(p, **kw)
        assert "\n" not in str(err.value)


def test_micrograph_rasters_conserve_power(tmp_path):
    # Area resampling onto any grid keeps the tile's mean |a|² and mean a exactly.
    p = tmp_path / "m.tif"
    skio.imsave(p, _pattern(), check_contrast=False)
    lay = MicrographLayout.load(p, pixel_um=3.0)
    for nx, ny in ((7, 5), (20, 12), (33, 41)):
        amp, inten = lay.cell_raster(nx, ny)
        assert abs(inten.mean() - lay.open_fraction) < 1e-13
        assert abs(amp.mean() - lay.image.mean()) < 1e-13


def test_micrograph_of_the_toled_cell_gives_the_toled_kernels(tmp_path):
    # A 60 × 60 px, 1 µm/px binary picture of the T-OLED cell (opening x ∈ [23, 37], y ∈ [3, 57])
    # has the same Fourier series as layouts.toled(pitch_um=60.0), hence the same engine output (measured 9e-16 of
    # peak).
    img = np.zeros((60, 60), np.uint8)
    img[3:57, 23:37] = 255
    p = tmp_path / "toled.png"
    skio.imsave(p, img, check_contrast=False)
    micro = MicrographLayout.load(p, pixel_um=1.0)
    ref = layouts.toled(pitch_um=60.0)
    k = np.arange(-9, 10)
    np.testing.assert_allclose(micro.fourier_coefficients(k, k), ref.fourier_coefficients(k, k), rtol=0, atol=1e-15)
    kw = dict(wavelengths_nm=[520.0], size_px=31, pupil_samples=256, precision="float64")
    a = compute_kernels(micro, Lens(), **kw)
    b = compute_kernels(ref, Lens(), **kw)
    assert np.max(np.abs(a.kernels - b.kernels)) < 1e-12 * b.kernels.max()
    np.testing.assert_allclose(a.transmittance, b.transmittance, rtol=1e-12)
    c = compute_kernels(micro, Lens(), distance_mm=1.0, field_phases=2, **kw)
    d = compute_kernels(ref, Lens(), distance_mm=1.0, field_phases=2, **kw)
    np.testing.assert_allclose(c.field_power, d.field_power, rtol=0, atol=1e-12)


def test_tile_rotations_are_seeded(tmp_path):
    p = tmp_path / "r.png"
    skio.imsave(p, np.round(_pattern() * 255).astype(np.uint8), check_contrast=False)
    fixed = MicrographLayout.load(p, pixel_um=1.0)
    assert fixed.periodic and not fixed.tile_rotations(5, 4).any()
    a = MicrographLayout.load(p, pixel_um=1.0, random_rotation=True, seed=11)
    b = MicrographLayout.load(p, pixel_um=1.0, random_rotation=True, seed=11)
    assert not a.periodic
    np.testing.assert_array_equal(a.tile_rotations(6, 5), b.tile_rotations(6, 5))
    # a non-square tile can only turn by 180°
    assert set(np.unique(a.tile_rotations(30, 30))) <= {0, 2}
    assert a.describe()["sha256_16"] == fixed.describe()["sha256_16"]
