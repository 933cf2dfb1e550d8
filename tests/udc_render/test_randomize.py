"""Randomized panels (issue 31): the distributions file (types, ranges, one-line refusals), the draws
(in their ranges, their distributions' moments, independent streams, JSON records) and the drawn panel
(layout, T(λ) fitted to the paper's γ, the lens's focus error). No rendering: fast."""
import json
import math
from dataclasses import replace

import numpy as np
import pytest

from psf import layouts
from udc_render.dataset import randomize as R
from udc_render.optics import displays as D
from udc_render.scene import load_scene
from udc_render.scene.geometry import monitor_distance_m, psf_lens


@pytest.fixture(scope="module")
def dists():
    return R.load_distributions("default")


def write(tmp_path, text: str):
    path = tmp_path / "r.toml"
    path.write_text(text)
    return path


def test_default_file_holds_every_key_and_the_documented_ranges(dists):
    assert set(dists.dists) == set(R.SCHEMA)
    d = dists.dists
    assert d["display.distance_mm"].support == (0.5, 5.0)
    assert d["display.poled.urbach_width_nm"].support == (8.0, 30.0)
    assert d["sensor.hot_fraction"].kind == "log_uniform" and d["sensor.hot_fraction"].support == (1e-5, 1e-3)
    assert d["sensor.dead_fraction"].support == (1e-6, 1e-4)
    assert d["display.family"].values == ("toled", "poled") and d["display.family"].weights == (0.5, 0.5)
    assert d["display.toled.open_fraction"].describe() == 0.21  # the paper's: fixed


def test_draws_stay_within_their_ranges_and_are_recorded(dists):
    panels = R.draw_panels(dists, 300, seed=3)
    caps = [R.draw_capture(dists, len(panels), 3, i) for i in range(300)]
    for draw in panels + caps:
        for key, v in draw.values.items():
            sup = dists[key].support
            assert (v in sup) if dists[key].kind in ("fixed", "choice") else sup[0] <= v <= sup[1], (key, v)
        assert json.loads(json.dumps(R.as_record(draw))) == R.as_record(draw)
    assert {p.family for p in panels} == {"toled", "poled"}
    assert all(0 <= c.panel < 300 for c in caps) and len({c.panel for c in caps}) > 150
    p = panels[0]
    lay = p.display.layout
    assert p.display.name == R.PANEL_NAME and p.display.distance_mm == p.values["display.distance_mm"]
    assert lay.pitch_x_um == pytest.approx(p.values[f"display.{p.family}.pitch_um"])
    assert lay.open_fraction == pytest.approx(p.values[f"display.{p.family}.open_fraction"], rel=1e-12)
    rec = R.as_record(caps[0])
    assert rec["defects"]["hot_fraction"] == caps[0].values["sensor.hot_fraction"]
    assert rec["fpn"]["prnu"] == caps[0].values["sensor.prnu"]


def test_distributions_have_their_moments(tmp_path):
    """10 000 keyed draws per kind: uniform mean and variance, log-uniform log-mean, choice frequencies
    (4.5 σ bounds of the sample statistics)."""
    path = write(tmp_path, '[sensor]\nread_noise_e = {dist = "uniform", low = 2.0, high = 6.0}\n'
                           'hot_fraction = {dist = "log_uniform", low = 1e-6, high = 1e-2}\n'
                           'gain_scale = {dist = "choice", values = [0.5, 1.0, 2.0], weights = [1, 2, 1]}\n')
    dists = R.load_distributions(path)
    n = 10_000
    caps = [R.draw_capture(dists, 4, 0, i) for i in range(n)]
    u = np.array([c.read_noise_e for c in caps])
    assert abs(u.mean() - 4.0) < 4.5 * (4 / math.sqrt(12)) / math.sqrt(n)
    # a uniform sample's variance errs by √(0.8 / n) = 0.9 % (1σ): 4.5σ is 4 % (measured 0.17 %)
    assert u.var() == pytest.approx(16 / 12, rel=0.04) and 2.0 <= u.min() and u.max() < 6.0
    logs = np.log10([c.defects.hot_fraction for c in caps])
    assert abs(logs.mean() - (-4.0)) < 4.5 * (4 / math.sqrt(12)) / math.sqrt(n)  # log-uniform: uniform in log
    assert np.histogram(logs, bins=4, range=(-6, -2))[0].min() > n / 4 * 0.9
    g = np.array([c.gain_scale for c in caps])
    for v, w in ((0.5, 0.25), (1.0, 0.5), (2.0, 0.25)):
        assert abs((g == v).mean() - w) < 4.5 * math.sqrt(w * (1 - w) / n)
    panels = np.array([c.panel for c in caps])
    assert np.bincount(panels, minlength=4).min() > n / 4 * 0.9


def test_streams_are_per_key_and_per_index(tmp_path, dists):
    a, b = R.draw_panels(dists, 3, 7), R.draw_panels(dists, 5, 7)
    assert [p.values for p in a] == [p.values for p in b[:3]]  # panel i does not depend on N
    assert R.draw_panels(dists, 3, 8)[0].values != a[0].values
    other = R.load_distributions(write(tmp_path, "[display]\ndistance_mm = {dist = \"uniform\", low = 6.0, "
                                                  "high = 9.0}\n"))
    c = R.draw_panels(other, 3, 7)
    for p, q in zip(a, c):
        assert 6 <= q.values["display.distance_mm"] <= 9
        assert {k: v for k, v in p.values.items() if k != "display.distance_mm"} == \
               {k: v for k, v in q.values.items() if k != "display.distance_mm"}
    assert R.draw_capture(dists, 5, 7, 11) == R.draw_capture(dists, 5, 7, 11)


def test_panel_transmission_at_the_presets_width_is_the_presets():
    """The table's T(λ) at the preset's width is the preset's; T(450 nm) rises with the width over 0.1–1.9 %
    (study realism's span); transmission_scale multiplies T."""
    assert R.poled_fit(D.POLED_URBACH_WIDTH_NM) == pytest.approx((D.POLED_SCALE, D.POLED_EDGE_NM, D.POLED_CATHODE_NM),
                                                                rel=2e-6)
    widths = sorted(R.POLED_T_TABLE)
    assert widths[0] == 8.0 and widths[-1] == 30.0
    edges = np.arange(400.0, 701.0, 10.0)
    t = {w: R.panels.panel_transmission("poled", {"transmission_scale": 1.0, "urbach_width_nm": w})
         for w in (8.0, 13.0, 20.0, 29.0)}
    blue = [t[w](np.array([450.0]))[0] for w in (8.0, 13.0, 20.0, 29.0)]
    assert blue == sorted(blue) and 0.0005 < blue[0] < 0.003 and 0.012 < blue[-1] < 0.025  # T(450) 0.1–1.9 %
    s = R.panels.panel_transmission("poled", {"transmission_scale": 2.0, "urbach_width_nm": 13.0})
    assert np.allclose(s(edges), 2 * t[13.0](edges))
    assert R.panels.panel_transmission("toled", {"transmission_scale": 1.1})(550.0) == pytest.approx(1.1 * D.TOLED_T)


def test_default_values_give_the_presets_layouts(tmp_path):
    path = write(tmp_path, "[display]\nfamily = \"poled\"\n[display.poled]\npitch_um = 64.0\nsmall_to_large = 0.7\n"
                           "urbach_width_nm = 20.0\ntransmission_scale = 1.0\n")
    p = R.draw_panels(R.load_distributions(path), 1, 0)[0]
    assert p.display.layout == layouts.poled()
    assert p.display.transmission == D.preset("poled").transmission and p.display.gain == 25.0
    dis = R.load_distributions(write(tmp_path, "[display]\nfamily = \"toled\"\n[display.toled]\n"
                                               "disorder_position_um = 2.0\ndisorder_size_sd = 0.05\n"))
    lay = R.draw_panels(dis, 1, 0)[0].display.layout
    assert lay.name == "toled-disordered" and len(lay.openings) == 4  # 2 × 2 cells


def test_focus_error_is_the_lens_defocus():
    scene = load_scene("monitor")
    z = monitor_distance_m(scene)
    for delta in (-0.2, 0.0, 0.15):
        s = R.panel_scene(scene, R.LensDraw(delta, 2.8))
        lens = psf_lens(s, z)
        assert -lens.defocus_curvature_per_um * 1e6 == pytest.approx(delta, abs=1e-9)
        assert s.lens.f_number == 2.8
    with pytest.raises(R.RandomizeError, match="focus beyond infinity"):
        R.panel_scene(scene, R.LensDraw(-1.0 / z - 0.01, 1.8))


@pytest.mark.parametrize("text, says", [
    ("[display]\ndistance_mm = -1.0\n", "display.distance_mm = -1.0: expected a number in [0, 100] mm"),
    ("[display]\nfamily = \"lcd\"\n", "display.family = 'lcd': expected one of toled, poled"),
    ("[display]\ndistance_mm = {dist = \"normal\", low = 1, high = 2}\n", "expected a table with dist = one of"),
    ("[display]\ndistance_mm = {dist = \"uniform\", low = 3.0, high = 1.0}\n", "expected low < high"),
    ("[sensor]\nprnu = {dist = \"log_uniform\", low = 0.0, high = 0.01}\n", "low > 0 for dist = 'log_uniform'"),
    ("[sensor]\nprnu = {dist = \"uniform\", low = 0.0, high = 0.01, mean = 3}\n", "not mean"),
    ("[sensor]\nprnu = {dist = \"choice\", values = [0.1, 0.2], weights = [1]}\n", "weights = 2 numbers"),
    ("[sensor]\nread_noise = 3.0\n", "sensor.read_noise = 3.0: expected a known key"),
    ("[camera]\ngain = 3.0\n", "[camera]: expected a known table or key (display, exposure, lens, sensor)"),
    ("[display.lcd]\npitch_um = 3.0\n", "[display.lcd]: expected a known table or key"),
    ("[display.toled]\nopen_fraction = 0.95\n", "display.toled.open_fraction = 0.95: expected a number in (0, 0.75]"),
    ("[display.toled]\nopen_fraction = 0.7\n", "at most the smallest display.toled.slit_height_fraction (0.6)"),
    ("[display.toled]\ntransmission_scale = 1.5\n", "expected at most 1.27 (T(λ) ≤ 1)"),
    ("[display.poled]\nurbach_width_nm = 40.0\n", "urbach_width_nm = 40.0: expected a number in [8, 30] nm"),
    ("[display.toled]\ndisorder_cells = {dist = \"uniform\", low = 1, high = 3}\n", "a fixed value or dist = 'choice'"),
    ("[display\n", "not valid TOML"),
])
def test_bad_files_are_refused_in_one_line(tmp_path, text, says):
    path = write(tmp_path, text)
    with pytest.raises(R.RandomizeError) as e:
        R.load_distributions(path)
    msg = str(e.value)
    assert "\n" not in msg and str(path) in msg and says in msg, msg


def test_only_default_or_a_toml_file(tmp_path):
    with pytest.raises(R.RandomizeError, match="expected default or a .toml file"):
        R.load_distributions("ranges.json")
    with pytest.raises(R.RandomizeError, match="cannot read"):
        R.load_distributions(tmp_path / "missing.toml")
    with pytest.raises(R.RandomizeError, match="--panels = 0"):
        R.draw_panels(R.default_distributions(), 0, 0)
    assert replace(R.default_distributions()).source == "randomize default"


@pytest.mark.slow
def test_table_refits_and_gives_the_papers_gamma_between_its_rows():
    """On the default rig's gains (optics.fit_gains, as study realism; minutes without the kernel cache):
    two rows re-fitted to 3e-5 (measured 5.8e-6 and 1.5e-6: 5×, an optimiser's stop), and γ within 0.1 % of the
    paper's at every 0.5 nm from 8 to 30 nm, the table every 1 nm (randomize.md: "within 0.08 %"; measured
    8.1e-4 at 29.5 nm, the largest: a linear interpolation's error between rows, deterministic, 1.2×)."""
    from udc_render.calibration.fit_gains import FIT_EDGES_NM as edges, fit_gains
    from udc_render.optics import gamma as G
    gains = {name: fit_gains(lay) for name, lay in (("glass", None), ("poled", layouts.poled()))}
    for w in (8.0, 26.0):
        fit = D.fit_poled_transmission(gains["poled"], gains["glass"], edges, urbach_width_nm=w)
        assert fit == pytest.approx(R.POLED_T_TABLE[w], rel=3e-5)
    white = G.white_weights(edges, "Nikon 5100 (NPL)")
    for w in np.arange(8.0, 30.01, 0.5):
        d = D.Display("p", layouts.poled(), R.panels.panel_transmission(
            "poled", {"transmission_scale": 1.0, "urbach_width_nm": float(w)}), D.PAPER_GAIN["poled"])
        g = G.channel_gamma(white, d, gains["poled"], gains["glass"], edges)
        assert np.abs(g / np.array(D.PAPER_GAMMA["poled"]) - 1).max() < 1e-3, (w, g)


def test_capture_config_sets_the_sensor_and_the_panels_haze(dists):
    from udc_render.optics.stray import StrayLight
    from udc_render.pipeline import SynthConfig
    panel = next(p for p in R.draw_panels(dists, 8, 0) if p.family == "poled")
    cap = R.draw_capture(dists, 8, 0, 5)
    cfg = R.capture_config(SynthConfig(), cap, panel)
    assert cfg.sensor.read_noise_e == cap.read_noise_e and cfg.defects == cap.defects and cfg.fpn == cap.fpn
    assert cfg.stray_light.haze_of(R.PANEL_NAME) == panel.haze and 0.006 <= panel.haze <= 0.028
    assert cfg.stray_light.haze_of("poled") == 0.015  # the preset's stays
    off = R.capture_config(SynthConfig(stray_light=StrayLight.off()), cap, panel)
    assert off.stray_light.haze_of(R.PANEL_NAME) == 0.0  # --stray-light off wins
    assert R.capture_display(panel, cap).gain == 25.0 * cap.gain_scale
    assert R.capture_panel(8, 0, 5) == cap.panel
