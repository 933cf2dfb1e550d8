"""Every command checks its output folder before any work, and bad files are one-line errors (exit 2)."""
from __future__ import annotations

import time

import pytest

from udc_render.cli import main

BAD_OUT = {  # the command's arguments, less --out (each must fail on --out before computing anything)
    "psf": ["psf"],
    "render": ["render", "monitor"],
    "synth": ["synth", "monitor"],
    "demo": ["demo"],
    "dataset": ["dataset", "--builtin", "--count", "1"],
    "calibrate": ["calibrate", "--display", "toled"],
    "study": ["study", "psf"],
    "train": ["train", "--data", "DATA", "--model", "unet", "--display", "toled"],
    "evaluate": ["evaluate", "--data", "DATA", "--model", "input"],
    "results": ["results"],
}


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("command", list(BAD_OUT))
@pytest.mark.parametrize("where", ["existing_file", "under_a_file"])
def test_out_that_cannot_be_a_folder_is_one_line_at_once(command, where, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("UDC_RENDER_CACHE", str(tmp_path / "cache"))
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    out = blocker if where == "existing_file" else blocker / "sub"
    argv = [str(tmp_path) if a == "DATA" else a for a in BAD_OUT[command]]
    t0 = time.perf_counter()
    assert main([*argv, "--out", str(out)]) == 2
    assert time.perf_counter() - t0 < 10  # refused before any rendering or kernel computation
    err = _one_line(capsys)
    assert "--out" in err and str(out) in err


@pytest.mark.parametrize("argv,says", [
    (["render", "{bad}"], "not UTF-8"),
    (["synth", "monitor", "--display", "{bad_display}"], "not UTF-8"),
    (["psf", "--display", "{bad_display}"], "not UTF-8"),
    (["synth", "monitor", "--sensor-config", "{bad}"], "not UTF-8"),
])
def test_non_utf8_toml_is_one_line(argv, says, tmp_path, capsys):
    bad = tmp_path / "latin1.toml"
    bad.write_bytes('name = "caf\xe9"\n'.encode("latin-1"))
    display = tmp_path / "latin1_display.toml"
    display.write_bytes(bad.read_bytes())
    argv = [a.format(bad=bad, bad_display=display) for a in argv]
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    err = _one_line(capsys)
    assert says in err and "latin1" in err


def test_results_carry_that_cannot_be_a_folder_is_one_line_at_once(tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert main(["results", "--budget", "quick", "--out", str(tmp_path / "o"), "--carry", str(blocker)]) == 2
    err = _one_line(capsys)
    assert "--carry" in err and str(blocker) in err
