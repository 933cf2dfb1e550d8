"""udc-render fit's parts (udc_render/fit): reading files and levels, hot pixels, the HDR factors, the
lattice's algebra, the orders' photometry, the noise frames and the white square, each against a truth
the test knows."""
from __future__ import annotations

import math

import imageio.v3 as iio
import numpy as np
import pytest
import tifffile

from psf import Lens, compute_kernels, layouts
from udc_render.fit import families as F, hdr, inputs, lattice, photometry, synthetic as S
from udc_render.fit.inputs import FitError
from udc_render.io.dng import save_dng
from udc_render.sensor import SensorConfig, sensor_lambdas

CAMERA = "Nikon 5100 (NPL)"


# ---------------------------------------------------------------- files and levels


def test_png_tiff_and_dng_levels(tmp_path):
    """8-bit PNG: saturation 255, black 0 (noted); 16-bit TIFF: 65535; a DNG's BlackLevel/WhiteLevel tags
    (LONG and RATIONAL); options win over the tags."""
    img8 = np.full((32, 32), 10, np.uint8)
    iio.imwrite(tmp_path / "a.png", img8)
    f = inputs.read_frame(tmp_path / "a.png")
    assert (f.kind, f.bits, f.saturation_dn, f.black_dn) == ("mono", 8, 255.0, 0.0) and "black level 0" in f.notes[0]
    tifffile.imwrite(tmp_path / "b.tif", np.full((32, 32, 3), 1000, np.uint16))
    f = inputs.read_frame(tmp_path / "b.tif", black_dn=64)
    assert (f.kind, f.bits, f.saturation_dn, f.black_dn, f.notes) == ("rgb", 16, 65535.0, 64.0, ())
    save_dng(tmp_path / "c.dng", np.full((32, 32), 500, np.uint16), CAMERA, 64, 4000)
    f = inputs.read_frame(tmp_path / "c.dng")
    assert (f.kind, f.black_dn, f.saturation_dn, f.sites.tolist()) == ("cfa", 64.0, 4000.0, [[0, 1], [1, 2]])
    assert inputs.read_frame(tmp_path / "c.dng", black_dn=10, saturation_dn=3000).black_dn == 10
    tifffile.imwrite(tmp_path / "d.dng", np.zeros((32, 32), np.uint16), photometric=32803,
                     extratags=[(50714, "2I", 1, (5120, 10), True), (33422, "B", 4, (2, 1, 1, 0), True)])
    f = inputs.read_frame(tmp_path / "d.dng")
    assert f.black_dn == 512.0 and f.sites.tolist() == [[2, 1], [1, 0]]


@pytest.mark.parametrize("name, data, says", [
    ("x.jpg", None, "unsupported file type '.jpg'"),
    ("missing.png", None, "no such file"),
    ("f.tif", np.zeros((32, 32), np.float32), "expected 8- or 16-bit integers"),
    ("tiny.png", np.zeros((8, 8), np.uint8), "at least 16 × 16"),
])
def test_bad_files_are_one_line(tmp_path, name, data, says):
    path = tmp_path / name
    if data is not None:
        (tifffile.imwrite if name.endswith(".tif") else iio.imwrite)(path, data)
    elif name.endswith(".jpg"):
        path.write_bytes(b"x")
    with pytest.raises(FitError, match=says) as e:
        inputs.read_frame(path)
    assert "\n" not in str(e.value)


def test_hot_pixel_flagged_but_not_an_airy_core():
    """An isolated spike is hot; the bare lens's core at 650 nm on 1.55 µm pixels (17× its brightest
    neighbour) is not."""
    k = compute_kernels(None, Lens(), [650.0], pixel_um=1.55, size_px=15, precision="float64").kernels[0] * 1e5
    img = np.zeros((40, 40))
    img[5:20, 5:20] = k
    img[30, 30] = 5000.0
    hot = inputs.hot_pixels(img, np.ones_like(img))
    assert hot[30, 30] and hot.sum() == 1


# ---------------------------------------------------------------- HDR


def _frames(images, black=64.0):
    return [inputs.Frame(f"f{i}", x.astype(float), "mono", None, black, 65535.0, 16) for i, x in enumerate(images)]


def test_hdr_factors_noise_gain_and_hot_pixels():
    """Three exposures 10× apart of the T-OLED PSF: factors within 1.5 % of 0.01, 0.1, κ within 25 % of the
    camera's DN per electron, the brightest one's saturated pixels filled from the others, and hot pixels
    (the same in every exposure) masked."""
    cam = S.Camera()
    frames = S.psf_measurement(layouts.toled(), camera=cam, shape_hw=(256, 256), peaks_fw=(0.8, 8.0, 80.0),
                               hot_pixels=4, seed=4, window_px=255)
    plane = hdr.merge_psf(_frames(frames), 650.0, CAMERA)
    assert plane.factors[0] == pytest.approx(0.01, rel=0.015) and plane.factors[1] == pytest.approx(0.1, rel=0.015)
    assert plane.dn_per_e == pytest.approx(cam.sensor().dn_per_electron, rel=0.25)
    sat = plane.exposures[2].saturated
    assert sat.sum() > 20 and plane.usable[sat].all() and not plane.clipped.any()
    assert "4 hot pixel(s) masked" in plane.notes


# ---------------------------------------------------------------- the lattice's algebra


def test_visible_orders_of_the_families():
    """The stripe's orders fill Z²; the pentile's m + n odd vanish (a centred lattice, reduced to
    (1, ±1)); a generated set's basis spans exactly its vectors."""
    assert abs(np.linalg.det(F.family("toled")[0].index_basis())) == 1
    m = F.family("poled")[0].index_basis()
    assert abs(round(np.linalg.det(m))) == 2 and sorted(np.abs(m).sum(axis=0).tolist()) == [2, 2]
    b = F.integer_basis(np.array([[2, 0], [0, 3], [2, 3], [4, 6]]))
    assert abs(round(np.linalg.det(b))) == 6
    assert F.integer_basis(np.array([[1, 1], [2, 2]])) is None


def test_cell_basis_finds_rotation_and_the_pentile_cell():
    """A pentile's visible lattice turned by 3°: the cell comes back turned by 3° with its own spacing."""
    phi = math.radians(3.0)
    rot = np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])
    e_true = rot * 20.0
    visible = e_true @ np.array([[1, 1], [1, -1]])
    e = lattice.cell_basis(visible[:, ::-1], F.family("poled")[0].index_basis())
    assert np.allclose(e, e_true)
    assert lattice.cell_basis(visible, np.eye(2, dtype=int)) is None  # as a stripe it is turned by 45°


# ---------------------------------------------------------------- photometry


def airy_pixels_midpoint(dx, dy, lens: Lens, wavelength_nm: float, pixel_um: float, samples: int = 48):
    """The closed-form Airy density (π D² / 4 λ² z²) (2 J₁(v) / v)², v = π D r / (λ z), integrated over each pixel
    centred at (dx, dy) px by a samples × samples midpoint rule: no call into fit.photometry."""
    from scipy.special import j1
    u = ((np.arange(samples) + 0.5) / samples - 0.5) * pixel_um
    x = dx[..., None, None] * pixel_um + u[:, None]
    y = dy[..., None, None] * pixel_um + u[None, :]
    lz = wavelength_nm * 1e-3 * lens.image_distance_um
    v = np.maximum(math.pi * lens.aperture_um * np.hypot(x, y) / lz, 1e-12)
    density = math.pi * lens.aperture_um ** 2 / 4 / lz ** 2 * (2 * j1(v) / v) ** 2
    return density.mean(axis=(-2, -1)) * pixel_um ** 2


def test_photometry_of_a_shifted_airy_pattern():
    """The matched filter returns the power of a pixel-integrated Airy pattern placed off the pixel grid: the
    image is the closed form integrated by a 48 × 48 midpoint rule (airy_pixels_midpoint), the filter's template
    fit.photometry's Gauss-Legendre rule; within 3e-4 (measured 8.6e-5: the two quadratures' difference). The
    square window's share lies between the encircled energies 1 − J₀²(v) − J₁²(v) of its in- and circumcircle."""
    from scipy.special import j0, j1
    lens, px = Lens(), 1.55
    g = np.arange(41) - 20
    dx, dy = np.meshgrid(g - 0.3, g + 0.2)
    pixels = airy_pixels_midpoint(dx, dy, lens, 650.0, px)
    o = photometry.measure(500.0 * pixels, np.ones_like(pixels), np.ones(pixels.shape, bool),
                           np.array([[0.3, -0.2]]), np.array([[0, 0]]), 5.0, lens, 650.0, px)
    assert o.measured[0] and o.power[0] == pytest.approx(500.0, rel=3e-4)
    lz = 650e-3 * lens.image_distance_um
    v_in, v_out = (math.pi * lens.aperture_um * r_px * px / lz for r_px in (19.7, 20.8 * math.sqrt(2)))
    inner, outer = (1 - j0(v) ** 2 - j1(v) ** 2 for v in (v_in, v_out))
    assert inner < pixels.sum() < outer


# ---------------------------------------------------------------- noise frames and the white square


def test_noise_frames_give_the_sensors_lambdas_and_a_loadable_sensor_toml(tmp_path):
    """16 RGGB frames at gain 4: λ_shot within 3 % of g / R and λ_read within 30 % of (g σ_r / R)²
    (sensor_lambdas), each within 3 σ; sensor.toml loads as a SensorConfig with those λ."""
    from udc_render.fit.noise import fit_noise, sensor_toml
    cam = S.with_gain(S.Camera(), 4.0)
    for i, f in enumerate(S.noise_frames(16, cam, shape_hw=(128, 128), seed=2)):
        save_dng(tmp_path / f"n{i:02d}.dng", f, CAMERA, cam.black_level_dn, 65535)
    fit = fit_noise(tmp_path)
    lr, ls = sensor_lambdas(cam.sensor())
    assert np.all(np.abs(fit.lambda_shot / ls - 1) < 0.03)
    assert np.all(np.abs(fit.lambda_shot - ls) < 3 * fit.lambda_shot_sigma)
    assert np.all(np.abs(fit.lambda_read / lr - 1) < 0.3)
    assert np.all(np.abs(fit.lambda_read - lr) < 3 * fit.lambda_read_sigma)
    (tmp_path / "sensor.toml").write_text(sensor_toml(fit, "frames"))
    s = SensorConfig.from_toml(tmp_path / "sensor.toml")
    assert s.noise == "gaussian" and s.lambda_shot == pytest.approx(tuple(fit.lambda_shot), rel=1e-5)
    assert s.black_level_dn == cam.black_level_dn


def test_white_square_gives_gamma_per_channel(tmp_path):
    """γ (R, Gr, Gb, B) of a white-square pair through a display at gain 6 comes back within 3 σ and 1 %."""
    from udc_render.fit.white import measure_gamma
    truth = np.array([0.42, 0.5, 0.5, 0.61])
    glass, disp = S.white_pair(truth, display_gain=6.0, seed=3)
    for name, m in (("g.dng", glass), ("d.dng", disp)):
        save_dng(tmp_path / name, m, CAMERA, 64, 65535)
    m = measure_gamma(inputs.read_frame(tmp_path / "g.dng"), inputs.read_frame(tmp_path / "d.dng"))
    assert m.pixels > 500 and np.all(np.abs(m.gamma - truth) < 3 * m.sigma)
    assert np.all(np.abs(m.gamma / truth - 1) < 0.01)
    # the 128-px square (rows and columns 64 … 191) and its central half: 31 px in from each side, 66 px
    assert m.square_xy_px == (128, 128) and m.region_xy_px == (66, 66)

