"""The `udc-render psf` command: outputs, metadata, clear one-line errors, cache reuse."""
import json
import subprocess
import sys

import numpy as np
import pytest

from udc_render.cli import main


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("UDC_RENDER_CACHE", str(tmp_path / "cache"))


def test_psf_writes_kernels_plots_and_parameters(tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["psf", "--display", "toled", "--wavelengths-nm", "450,640", "--size", "63", "--out", str(out)]) == 0
    with np.load(out / "psf.npz") as z:
        k = z["kernels"]
        assert k.shape == (2, 63, 63) and k.dtype == np.float32
        np.testing.assert_allclose(k.sum(axis=(1, 2)), 1.0, atol=1e-5)
        np.testing.assert_array_equal(z["wavelengths_nm"], [450.0, 640.0])
        assert float(z["pixel_um"]) == 3.1 and float(z["focal_length_um"]) == 6000.0
        params = json.loads(str(z["params_json"]))
        # r = δ_N N ρ / (λ f) with N δ_N = the aperture (docs/PHYSICS.md §2)
        np.testing.assert_allclose(z["ratio_r"], 3333 * 3.1 / (np.array([450, 640]) * 1e-3 * 6000))
    assert params["display"]["name"] == "toled" and params["method"] == "mft"
    for name in ("psf.png", "mtf.png", "psf.json"):
        assert (out / name).stat().st_size > 0
    import OpenEXR
    with OpenEXR.File(str(out / "psf.exr"), separate_channels=True) as f:
        chans = f.channels()
        assert set(chans) == {"psf_450nm", "psf_640nm"}
        np.testing.assert_array_equal(chans["psf_640nm"].pixels, k[1])
    assert not (out / "banding.png").exists()
    assert "450 nm" in capsys.readouterr().out


def test_psf_with_distance_writes_banding(tmp_path):
    out = tmp_path / "o"
    assert main(["psf", "--display", "poled", "--wavelengths-nm", "520", "--size", "31", "--distance-mm", "1",
                 "--field-phases", "2", "--out", str(out)]) == 0
    with np.load(out / "psf.npz") as z:
        assert z["field_kernels"].shape == (1, 2, 2, 31, 31)
        np.testing.assert_allclose(z["banding_period_um"], [6000 * 64 / 1000] * 2)
        assert z["banding_x_power"].shape == (1, 400)
        np.testing.assert_allclose(z["banding_x_power"].mean(), 1.0, atol=1e-12)
    assert (out / "banding.png").stat().st_size > 0


def test_small_distance_samples_field_phases_across_the_sensor(tmp_path):
    # d = 0.01 mm: the banding period z p / d = 36 mm exceeds a 3 mm sensor, so the phases span the
    # shifts the sensor sees (± sensor · d / 2z), not a whole display period.
    out = tmp_path / "o"
    assert main(["psf", "--wavelengths-nm", "520", "--size", "15", "--distance-mm", "0.01", "--field-phases", "2",
                 "--sensor-um", "3000,1500", "--out", str(out)]) == 0
    with np.load(out / "psf.npz") as z:
        np.testing.assert_allclose(z["field_positions_um"][0, :, 0], [-750.0, 750.0])
        np.testing.assert_allclose(z["field_positions_um"][:, 0, 1], [-375.0, 375.0])


def test_cache_hit_gives_identical_kernels(tmp_path, capsys):
    args = ["psf", "--display", "none", "--wavelengths-nm", "520", "--size", "31"]
    assert main(args + ["--out", str(tmp_path / "a")]) == 0
    assert main(args + ["--out", str(tmp_path / "b")]) == 0
    assert "(kernels from cache)" in capsys.readouterr().out
    with np.load(tmp_path / "a" / "psf.npz") as a, np.load(tmp_path / "b" / "psf.npz") as b:
        np.testing.assert_array_equal(a["kernels"], b["kernels"])


@pytest.mark.parametrize("args, fragment", [
    (["--size", "64"], "odd"),
    (["--size", "-3"], "odd"),
    (["--pixel-um", "-1"], "--pitch-um must be > 0"),
    (["--distance-mm", "-2"], "--distance-mm must be ≥ 0"),
    (["--display", "hexagon"], "--display = 'hexagon': expected glass (or none), toled, poled"),
    (["--display", "missing.png"], "no such file"),
    (["--wavelengths-nm", "450,abc"], "comma-separated"),
    (["--method", "fft"], "invalid choice"),
    (["--aperture-um", "0"], "--aperture-um must be > 0"),
    (["--pupil-samples", "300"], "need pupil_samples ≥"),
    (["--sensor-um", "3000"], "--sensor-extent-um must be two positive numbers"),
])
def test_bad_arguments_give_one_line_and_exit_2(tmp_path, capsys, args, fragment):
    assert main(["psf", "--out", str(tmp_path / "o")] + args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and fragment in err and "Traceback" not in err


def test_unreadable_micrograph_names_the_file(tmp_path, capsys):
    bad = tmp_path / "broken.png"
    bad.write_bytes(b"not a png")
    assert main(["psf", "--display", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "broken.png" in err and "cannot be read" in err


def test_console_script_exits_nonzero_without_traceback(tmp_path):
    r = subprocess.run([sys.executable, "-m", "udc_render.cli", "psf", "--size", "4", "--out", str(tmp_path)],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr and r.stderr.count("\n") == 1


def test_cache_key_changes_with_every_parameter(tmp_path):
    from psf import Lens, layouts
    from psf.cache import cache_key
    base = dict(wavelengths_nm=[520.0], size_px=31, distance_mm=0.0)
    k0 = cache_key("mono", layouts.toled(), Lens(), **base)
    assert k0 == cache_key("mono", layouts.toled(), Lens(), **base)
    assert k0 != cache_key("mono", layouts.toled(open_fraction=0.2), Lens(), **base)
    assert k0 != cache_key("mono", layouts.toled(), Lens(aperture_um=3000), **base)
    assert k0 != cache_key("mono", layouts.toled(), Lens(), **dict(base, distance_mm=0.5))
    assert k0 != cache_key("band", layouts.toled(), Lens(), **base)


def test_band_weight_spectrum_from_illuminant_changes_kernels(tmp_path):
    args = ["psf", "--bands-nm", "400-700", "--band-step-nm", "30", "--size", "31"]
    assert main(args + ["--weight", "E", "--out", str(tmp_path / "e")]) == 0
    assert main(args + ["--weight", "A", "--out", str(tmp_path / "a")]) == 0
    with np.load(tmp_path / "e" / "psf.npz") as e, np.load(tmp_path / "a" / "psf.npz") as a:
        assert np.abs(e["kernels"] - a["kernels"]).sum() > 1e-4
        assert json.loads(str(a["params_json"]))["weight"] == "A"


@pytest.mark.slow
def test_study_quick_writes_table_csv_and_plot(tmp_path):
    from udc_render.studies.psf_knobs import run_study
    rows = run_study(tmp_path, quick=True, progress=False)
    knobs = {r["knob"] for r in rows}
    assert knobs == {"pupil_samples", "method", "precision", "band_step_nm", "field_phases", "size_px"}
    assert all(r["time_s"] > 0 for r in rows)
    # each knob's error falls from its coarsest to its finest setting in the quick grid
    for knob in ("pupil_samples", "band_step_nm"):
        errs = [r["error_L1"] for r in rows if r["knob"] == knob and r.get("series", "") in ("band_limited", "bands")]
        assert errs[-1] < errs[0]
    for name in ("study_psf.csv", "study_psf.md", "study_psf.png"):
        assert (tmp_path / name).stat().st_size > 0
