"""The numbers the concept pages state about the code's defaults are the code's: each check finds the doc's
table row by its first cell, asserts the row prints the number, and asserts the code has it. A default that
moves without its page (or a page edited without the code) fails here."""
from __future__ import annotations

import math
import re

import pytest

from tests.docs.examples import ROOT

CONCEPTS = ROOT / "docs" / "concepts"


def _rows(page: str) -> dict[str, str]:
    """{first cell: the whole row} of every Markdown table row on docs/concepts/<page>."""
    rows = {}
    for line in (CONCEPTS / page).read_text(encoding="utf-8").splitlines():
        if line.startswith("| ") and not line.startswith("|---"):
            rows[line.split("|")[1].strip()] = line
    return rows


def _says(row: str, *numbers: str) -> None:
    for n in numbers:
        assert n in row, f"expected {n!r} in: {row[:160]}"


@pytest.fixture(scope="module")
def defaults() -> dict[str, str]:
    return _rows("defaults.md")


def test_rig_page_states_the_display_presets():
    """concepts/rig.md's displays table: the T-OLED stripe's cell, slit and open area, the P-OLED's cell and
    radii, T and gain, against psf.layouts and optics.displays."""
    from psf import layouts
    from udc_render.optics import displays as D
    rows = _rows("rig.md")
    toled, poled = layouts.toled(), layouts.poled()
    slit = toled.openings[0]
    _says(rows["`toled`"], "317 µm", "90 % of the cell tall (285.3 µm)", "74.0 µm wide", "21 % open",
          "flat, 0.786", "| 6 |")
    assert (toled.pitch_x_um, toled.pitch_y_um) == (317.0, 317.0)
    assert round(slit.height_um, 1) == 285.3 and round(slit.width_um, 1) == 74.0
    assert toled.open_fraction == pytest.approx(0.21, rel=1e-12)
    assert round(D.TOLED_T, 3) == 0.786 and D.PAPER_GAIN["toled"] == 6.0
    _says(rows["`poled`"], "64 µm cell", "radius 10.0 µm", "7.0 µm, ratio 0.7", "23 % open", "12.4 nm silver",
          "| 25 |")
    radii = sorted({round(e.rx_um, 1) for e in poled.openings})
    assert poled.pitch_x_um == 64.0 and radii == [7.0, 10.0]
    assert poled.open_fraction == pytest.approx(0.23, rel=1e-12)
    assert round(D.POLED_CATHODE_NM, 1) == 12.4 and D.PAPER_GAIN["poled"] == 25.0
    _says(rows["`glass`"], "| 1 | 1 |")
    assert D.PAPER_GAIN["glass"] == 1.0


def test_rig_page_states_the_cameras_distance_and_the_panel_pixel():
    """'the camera stands 1.28 m away and a panel pixel is 0.73 µm on the sensor' (concepts/rig.md) for the
    default scene: the thin-lens distance that fits the 27-inch 4K monitor's width in 2048 × 1.55 µm."""
    from udc_render.scene import load_scene
    from udc_render.scene.geometry import camera_geometry
    text = (CONCEPTS / "rig.md").read_text(encoding="utf-8")
    _says(text, "the camera stands 1.28 m away", "a panel pixel\n  is 0.73 µm on the sensor")
    scene = load_scene("monitor")
    geom = camera_geometry(scene)
    assert round(geom.focus_distance_m, 2) == 1.28
    panel_pixel_um = scene.content.size_m[0] / scene.content.resolution_px[0] * 1e6
    on_sensor_um = panel_pixel_um * geom.image_distance_um / (geom.focus_distance_m * 1e6)  # m = z_i / s
    assert round(on_sensor_um, 2) == 0.73


def test_defaults_of_the_displays_and_the_profile(defaults):
    from psf import layouts
    from udc_render import profiles
    from udc_render.optics import displays as D
    from udc_render.sensor import defects
    toled, poled = layouts.toled(), layouts.poled()
    _says(defaults["T-OLED pitch"], "317 µm square cell")
    assert toled.pitch_x_um == toled.pitch_y_um == 317.0
    _says(defaults["T-OLED slit height"], "0.9 of the cell, 21 % open")
    assert toled.openings[0].height_um == pytest.approx(0.9 * 317.0, rel=1e-12)
    _says(defaults["P-OLED cell"], "64 µm pentile, small/large openings 0.7", "23 % open")
    small, large = sorted({e.rx_um for e in poled.openings})
    assert poled.pitch_x_um == 64.0 and small / large == pytest.approx(0.7, rel=1e-12)
    _says(defaults["T-OLED transmission"], "flat T = 0.786, gain 6")
    assert round(D.TOLED_T, 3) == 0.786
    _says(defaults["P-OLED transmission"], "(w = 20 nm) × a 12.4 nm silver cathode, gain 25")
    assert D.POLED_URBACH_WIDTH_NM == 20.0 and round(D.POLED_CATHODE_NM, 1) == 12.4
    _says(defaults["profile"], "`physical`")
    assert profiles.DEFAULT_PROFILE == "physical"
    _says(defaults["display-to-lens distance d"], "2 mm (`physical`")
    assert profiles.PHYSICAL_DISTANCE_MM == 2.0
    _says(defaults["defect pixels"], "hot 1e-4, dead 1e-5 of the pixels")
    assert (defects.HOT_FRACTION, defects.DEAD_FRACTION) == (1e-4, 1e-5)
    _says(defaults["hot-pixel dark current"], "3·10⁴ e⁻/s")
    assert defects.HOT_DARK_E_PER_S == 3e4


def test_defaults_of_the_psf_engine(defaults):
    import inspect

    from psf import compute_kernels, plan
    params = inspect.signature(compute_kernels).parameters
    _says(defaults["pupil samples N"], "auto: 1024, raised until λ_min z/δ ≥ 1.05 × window")
    assert (plan.DEFAULT_PUPIL_SAMPLES, plan.ALIAS_GUARD) == (1024, 1.05)
    assert params["pupil_samples"].default is None
    _says(defaults["mask raster"], "| band-limited |")
    assert params["mask_raster"].default == "band_limited"
    _says(defaults["method"], "| `mft` |")
    assert params["method"].default == "mft"
    _says(defaults["precision"], "| float32 |")
    assert params["precision"].default == "float32"
    _says(defaults["field phases P (d > 0)"], "| 4 per axis |")
    assert plan.DEFAULT_FIELD_PHASES == 4
    _says(defaults["kernel size S"], "255 (`psf`), 2·margin + 1 = 513 px at 1.55 µm (synthesis)")
    assert params["size_px"].default == 255


def test_defaults_of_rendering(defaults):
    from udc_render.scene import load_scene
    from udc_render.scene.model import DEFAULT_MARGIN_UM, Render
    _says(defaults["sampler (Monte Carlo paths)"], "| multijitter |")
    assert Render().sampler == "multijitter"
    _says(defaults["3D bands per render"], "| 30 |")
    assert Render().bands_per_render == 30
    _says(defaults["3D spp"], "| 64 |")
    assert load_scene("room").render.spp == 64 and load_scene("hdr").render.spp == 64
    _says(defaults["monitor spp (`rgb_matrix` only)"], "| 16 |")
    assert Render().spp == 16
    _says(defaults["render margin"], "396 µm (half the 255 × 3.1 µm kernel)")
    assert DEFAULT_MARGIN_UM == 396 == math.ceil(255 * 3.1 / 2)
    # the synthesis kernel: 2 · margin + 1 render pixels of 1.55 µm
    assert 2 * math.ceil(DEFAULT_MARGIN_UM / 1.55) + 1 == 513


def test_defaults_of_capture_synthesis(defaults):
    from udc_render.optics.far_field import acceptance_um
    from udc_render.pipeline import SynthConfig
    from udc_render.profiles import PAPER_GT_FRAMES
    from udc_render.scene.model import Bands, Render
    from udc_render.sensor import SensorConfig
    from udc_render.synth_config import EXPOSURE_FILL
    cfg, sensor = SynthConfig(), SensorConfig()
    _says(defaults["bands"], "| 30 of 10 nm |")
    assert (Bands().count, Bands().step_nm) == (30, 10.0)
    _says(defaults["form"], "| spectral (per band) |")
    assert cfg.form == "spectral"
    _says(defaults["field rank (d > 0)"], "| 4 |")
    assert cfg.field_rank == 4
    assert cfg.precision == "float32"
    _says(defaults["`render.supersample`"], "| 1 |")
    assert Render().supersample == 1
    _says(defaults["defocus tolerance"], "| 1 px |")
    assert cfg.defocus_tolerance_px == 1.0
    _says(defaults["far-field threshold"], "| 0.005 of a band's transmitted power |")
    assert cfg.far_field_threshold == 0.005
    _says(defaults["far-field coarse factor"], "15 render pixels (23 µm at 1.55 µm)")
    assert cfg.far_field_coarse == 15 and round(15 * 1.55) == 23
    _says(defaults["lens acceptance"], "1.77 mm from the chief ray", "2048 × 1024 sensor of 1.55 µm")
    assert acceptance_um((0.0, 0.0)) == pytest.approx(math.hypot(2048 * 1.55, 1024 * 1.55) / 2, rel=1e-12)
    assert round(acceptance_um((0.0, 0.0)) / 1000, 2) == 1.77
    _says(defaults["exposure"], "at 80 % of the full well")
    assert EXPOSURE_FILL == 0.8
    _says(defaults["sensor noise"], "Poisson + 4.87 e⁻ read noise, 15,506 e⁻ full well")
    assert (sensor.noise, sensor.read_noise_e, sensor.full_well_e) == ("poisson", 4.87, 15506.0)
    _says(defaults["ground truth frames (`gt_frames`)"], "16 under both profiles (`PAPER_GT_FRAMES`)",
          "`SynthConfig()` alone: None")
    assert PAPER_GT_FRAMES == 16 and cfg.gt_frames is None


def test_defaults_of_fixed_pattern_noise(defaults):
    from udc_render.sensor.fpn import FpnConfig
    fpn = FpnConfig()
    _says(defaults["PRNU (`physical`: `FpnConfig.prnu`)"], "| 0.007 (0.7 % σ")
    _says(defaults["DSNU (`FpnConfig.dsnu_e`)"], "| 1.0 e⁻")
    _says(defaults["row / column offsets (`row_offset_e`, `column_offset_e`)"], "| 0.3 / 0.5 e⁻")
    _says(defaults["dark current (`dark_current_e_per_s`)"], "| 5 e⁻/s")
    _says(defaults["FPN seed"], "| 0 (`FpnConfig.seed`)")
    assert (fpn.prnu, fpn.dsnu_e, fpn.row_offset_e, fpn.column_offset_e) == (0.007, 1.0, 0.3, 0.5)
    assert (fpn.dark_current_e_per_s, fpn.seed) == (5.0, 0)


def test_defaults_of_stray_light(defaults):
    from udc_render.optics.stray import ON_VALUES, StrayLight, settings as S
    on = StrayLight()
    _says(defaults["room light on the monitor's screen (`room_illuminance_lux`)"],
          "off (on-value 500 lx; `screen_reflectance` 0.044")
    assert on.room_illuminance_lux in (0.0, None) and ON_VALUES["room_illuminance_lux"] == 500.0
    assert S.SCREEN_REFLECTANCE == 0.044
    _says(defaults["ghost between display and lens (`lens_reflectance`)"],
          "off (on-value 0.005; `underside_reflectance` glass 0.08", "`ghost_blur_um` 2000")
    assert on.lens_reflectance in (0.0, None) and ON_VALUES["lens_reflectance"] == 0.005
    assert (S.GLASS_UNDERSIDE, S.GHOST_BLUR_UM) == (0.08, 2000.0)
    _says(defaults["lens veiling glare (`lens_glare`)"], "off (on-value 0.02; tail θ⁻² from `glare_inner_deg` 1°)")
    assert on.lens_glare in (0.0, None) and ON_VALUES["lens_glare"] == 0.02 and on.glare_inner_deg == 1.0
    _says(defaults["haze of the display stack (`haze`)"], "P-OLED 0.015 (tail θ⁻² from `haze_inner_deg` 2.5°)")
    assert on.haze_of("poled") == 0.015 and on.haze_inner_deg == 2.5
    assert not on.haze_of("toled") and not on.haze_of("glass")
    _says(defaults["the driven display's own light (`display_luminance_cd_m2`)"], "off (on-value 1 cd/m²)")
    assert on.display_luminance_cd_m2 in (0.0, None) and ON_VALUES["display_luminance_cd_m2"] == 1.0


def test_profiles_page_states_what_each_profile_sets():
    """concepts/profiles.md's table against udc_render.profiles.PROFILES."""
    from udc_render.profiles import PROFILES
    rows = _rows("profiles.md")
    paper, physical = PROFILES["paper"], PROFILES["physical"]
    _says(rows["`paper`"], "`per_channel`", "`paper`: its recipe at 640 / 520 / 450 nm", "| 0: the display",
          "| none | none |", "the mean of 16 glass frames")
    assert (paper.form, paper.channel_kernels, paper.distance_mm) == ("per_channel", "paper", 0.0)
    assert paper.defects is None and paper.fpn is None and paper.gt_frames == 16
    row = rows["`physical` (**default**)"]
    _says(row, "`spectral`", "2 mm (`PHYSICAL_DISTANCE_MM`)", "dead 1e-5 and hot 1e-4",
          "PRNU 0.7 %, DSNU 1 e⁻, row / column offsets 0.3 / 0.5 e⁻, dark current 5 e⁻/s", "the mean of 16 glass")
    assert (physical.form, physical.distance_mm, physical.gt_frames) == ("spectral", 2.0, 16)
    assert (physical.defects.dead_fraction, physical.defects.hot_fraction) == (1e-5, 1e-4)
    f = physical.fpn
    assert (f.prnu, f.dsnu_e, f.row_offset_e, f.column_offset_e, f.dark_current_e_per_s) == (0.007, 1.0, 0.3, 0.5, 5.0)
    printed_r = re.search(r"printed r = ([\d.]+), ([\d.]+), ([\d.]+)", (CONCEPTS / "profiles.md").read_text())
    from psf.paper import PRINTED_R
    assert [float(v) for v in printed_r.groups()] == [PRINTED_R[640.0], PRINTED_R[520.0], PRINTED_R[450.0]]


def test_psf_guide_states_the_commands_defaults_and_limits():
    """guides/psf.md's synopsis defaults (--wavelengths-nm 450,520,640, --pitch-um 3.1, --kernel-px 255), its lens
    (f = 6000 µm, aperture 3333 µm) and what it refuses at once (200–2000 nm, beyond f/0.5, pupil windows over
    8192² samples at d > 0 and 16384² at d = 0) against the parser and psf.plan."""
    from psf import Lens, LensError, plan
    from udc_render.cli import build_parser
    text = (ROOT / "docs" / "guides" / "psf.md").read_text(encoding="utf-8")
    _says(text, "--wavelengths-nm 450,520,640", "[--pitch-um 3.1] [--kernel-px 255]",
          "f = 6000 µm, aperture 3333 µm", "wavelengths outside 200–2000 nm, apertures beyond f/0.5",
          "pupil windows over 8192² samples at d > 0 (16384² at d = 0)")
    args = build_parser().parse_args(["psf", "--out", "x"])
    assert (args.wavelengths_nm, args.pitch_um, args.kernel_px) == ([450.0, 520.0, 640.0], 3.1, 255)
    assert (args.focal_length_um, args.aperture_um) == (6000.0, 3333.0) == (Lens().focal_length_um,
                                                                             Lens().aperture_um)
    assert plan.WAVELENGTH_RANGE_NM == (200.0, 2000.0)
    assert (plan.MAX_PUPIL_WINDOW_SAMPLES, plan.MAX_PUPIL_WINDOW_SAMPLES_D0) == (8192 ** 2, 16384 ** 2)
    Lens(aperture_um=2 * 6000.0)  # f/0.5 itself is allowed, a hair beyond it is not
    with pytest.raises(LensError):
        Lens(aperture_um=2 * 6000.0 * (1 + 1e-9))


def test_readme_states_the_demos_bands_and_sensor():
    """README.md: the demo renders '30 bands at the paper's 2048 × 1024 sensor' (pixels of 1.55 µm, rig.md)."""
    from udc_render.scene import load_scene
    _says((ROOT / "README.md").read_text(encoding="utf-8"), "rendered to 30\nbands at the paper's 2048 × 1024 sensor")
    scene = load_scene("monitor")
    assert scene.bands.count == 30 and (scene.sensor.width_px, scene.sensor.height_px) == (2048, 1024)
    assert scene.sensor.pitch_um == 1.55


def test_synth_guide_states_the_sensor_and_the_field_convolution():
    """guides/synth.md: 'Nikon 5100 sensitivities × QE 0.6', 'Poisson + 4.87 e⁻ read noise with a 15,506 e⁻ full
    well', '16-bit quantisation', 'a rank-4 basis of each band's 16 phase kernels (--field-rank, default 4',
    '--defocus-tolerance-px, default 1 px' and the kernels' '2·margin + 1 = 513 px at 1.55 µm'."""
    from psf.plan import DEFAULT_FIELD_PHASES
    from udc_render.pipeline import SynthConfig
    from udc_render.scene.model import DEFAULT_MARGIN_UM
    from udc_render.sensor import SensorConfig
    text = " ".join((ROOT / "docs" / "guides" / "synth.md").read_text(encoding="utf-8").split())
    _says(text, "Nikon 5100 sensitivities × QE 0.6", "Poisson + 4.87 e⁻ read noise with a 15,506 e⁻ full well",
          "16-bit quantisation", "a rank-4 basis of each band's 16 phase kernels (`--field-rank`, default 4",
          "(`--defocus-tolerance-px`, default 1 px", "2·margin + 1 = 513 px at 1.55 µm")
    s, cfg = SensorConfig(), SynthConfig()
    assert (s.camera, s.peak_qe, s.noise, s.read_noise_e, s.full_well_e, s.bit_depth) == (
        "Nikon 5100 (NPL)", 0.6, "poisson", 4.87, 15506.0, 16)
    assert cfg.field_rank == 4 and DEFAULT_FIELD_PHASES ** 2 == 16 and cfg.defocus_tolerance_px == 1.0
    assert 2 * math.ceil(DEFAULT_MARGIN_UM / 1.55) + 1 == 513


def test_physics_page_states_the_stray_lights_coarse_grids():
    """concepts/physics.md: the spreads are convolved on a grid coarser by a power of two, 'at most the inner
    radius / 16: 8 px for the haze at 2048 × 1024, 4 px for the glare, 32 px for the ghost's disc'."""
    from udc_render.optics.stray import StrayLight, settings
    from udc_render.optics.stray.spread import COARSE_PER_RADIUS, Spread, coarse_factor
    text = " ".join((CONCEPTS / "physics.md").read_text(encoding="utf-8").split())
    _says(text, "(at most the inner radius / 16: 8 px for the haze at 2048 × 1024, 4 px for the glare, 32 px for "
                "the ghost's disc)")
    on = StrayLight()
    spreads = {"haze": Spread("tail", 6000.0, inner_deg=on.haze_inner_deg),
               "glare": Spread("tail", 6000.0, inner_deg=on.glare_inner_deg),
               "ghost": Spread("disc", 6000.0, radius_um=settings.GHOST_BLUR_UM / 2)}
    got = {k: coarse_factor(1024, 2048, s.inner_radius_um() / 1.55) for k, s in spreads.items()}
    assert COARSE_PER_RADIUS == 16 and got == {"haze": 8, "glare": 4, "ghost": 32}


def test_physics_page_states_the_poled_orders_spacing():
    """concepts/physics.md: 'the P-OLED's orders are 52 µm apart at 550 nm, 33 render pixels' (λ z_i / p on the
    default scene's 1.55 µm render grid, z_i of the monitor at its framing distance)."""
    from psf import layouts
    from udc_render.scene import load_scene
    from udc_render.scene.geometry import camera_geometry
    text = " ".join((CONCEPTS / "physics.md").read_text(encoding="utf-8").split())
    _says(text, "the P-OLED's orders are 52 µm apart at 550 nm, 33 render pixels")
    geom = camera_geometry(load_scene("monitor"))
    spacing_um = 0.55 * geom.image_distance_um / layouts.poled().pitch_x_um
    assert round(spacing_um) == 52 and round(spacing_um / geom.pitch_um) == 33


def test_defaults_of_the_layout_design(defaults):
    """concepts/defaults.md's design rows against udc_render.design's constants."""
    from udc_render.design import bands, floor, job, metrics, options
    from udc_render.design.config import DesignConfig
    _says(defaults["minimum feature size (`--feature-um`)"], "8 µm; at least 1.5 µm")
    assert options.DEFAULT_FEATURE_UM == 8.0 and options.LITHOGRAPHY_UM == 1.5
    _says(defaults["the `crop` objective's scene contrast (`--contrast`)"], "| 1.0 (RMS) |")
    assert options.CONTRAST_DEFAULTS["crop"] == 1.0
    _says(defaults["the objective's scene mean (`--mean-level`; the far veil's level)"], "μ = 0.5 of the full well")
    assert metrics.MEAN_LEVEL == 0.5 and DesignConfig().mean_level == 0.5
    _says(defaults["the UPC floor's weight (`design.floor.FLOOR_WEIGHT`)"], "| 10 |")
    assert floor.FLOOR_WEIGHT == 10.0
    _says(defaults["UPC's ratio over more tilings (`design.job.UPC_DRAWS`)"], "| 8 D4 draws |")
    assert job.UPC_DRAWS == 8
    _says(defaults["the banding ceiling's weight (`design.bands.BANDING_WEIGHT`)"], "| 10, the floor's |")
    assert bands.BANDING_WEIGHT == floor.FLOOR_WEIGHT == 10.0
    _says(defaults["the ceiling's search draws (`design.bands.BANDING_DRAWS`)"], "| 8 D4 draws |")
    assert bands.BANDING_DRAWS == 8
