"""Every command example in the docs parses with the CLI's own parser and runs (docs/about.md).

Fast suite: every udc-render command of every example is parsed by udc_render.cli.build_parser; the `run` and `tiny`
examples and the python blocks run, page by page (those of HEAVY_PAGES in the slow suite), in a temporary folder
with a kernel cache shared by the session; `help` and `slow` examples run `udc-render COMMAND --help`.
`pytest -m slow tests/docs/test_docs_examples.py` runs the `slow` examples in full.
"""
from __future__ import annotations

import contextlib
import os
import subprocess
import sys

import pytest

from tests.docs.examples import ROOT, all_examples

EXAMPLES = all_examples()
PAGES = sorted({ex.path for ex in EXAMPLES}, key=lambda p: str(p.relative_to(ROOT)))
FAST = ("run", "tiny")


def _page_id(path):
    return str(path.relative_to(ROOT))


def test_every_example_is_classified():
    problems = [f"{ex.where}: {p}" for ex in EXAMPLES for p in ex.problems]
    assert not problems, "\n".join(problems)


def test_there_are_examples_of_every_command():
    from udc_render.cli import build_parser
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    commands = {c.argv[0] for ex in EXAMPLES for c in ex.commands if c.udc and c.argv}
    missing = sorted(set(sub.choices) - commands)
    assert not missing, f"no docs example for: {', '.join(missing)}"


def _udc_commands(ex):
    return [c for c in ex.commands if c.udc]


PARSED = [(ex, c) for ex in EXAMPLES for c in _udc_commands(ex)]


@pytest.mark.parametrize("ex,command", PARSED, ids=[f"{ex.where}:{c.argv[0] if c.argv else ''}" for ex, c in PARSED])
def test_command_parses(ex, command, tmp_path, monkeypatch):
    """The CLI's parser accepts the command as written (and with a tiny/slow example's arguments)."""
    from udc_render.cli import build_parser
    monkeypatch.chdir(tmp_path)
    variants = [command.argv] + ([command.argv + ex.args] if ex.args else [])
    for argv in variants:
        try:
            args = build_parser().parse_args(argv)
        except SystemExit as exc:  # argparse's own exit (--help, or an error the Parser did not catch)
            pytest.fail(f"{ex.where}: `{' '.join(argv)}` exits {exc.code} while parsing")
        except Exception as exc:   # udc_render.cli.args.Parser raises its UserError
            pytest.fail(f"{ex.where}: `udc-render {' '.join(argv)}` does not parse: {exc}")
        assert callable(getattr(args, "run", None)), f"{ex.where}: `{' '.join(argv)}` selects no command"


@pytest.fixture(scope="session")
def kernel_cache(tmp_path_factory):
    """One kernel cache (and LLVM probe verdict) for every docs example of the session, not the user's."""
    return tmp_path_factory.mktemp("docs_udc_cache")


def _run_udc(argv, env, kernel_cache, where):
    """udc-render ARGV in this process (subprocess when the example sets environment variables)."""
    if env:
        full = {**os.environ, "UDC_RENDER_CACHE": str(kernel_cache), **env}
        proc = subprocess.run([sys.executable, "-m", "udc_render.cli", *argv], env=full,
                              capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, \
            f"{where}: `udc-render {' '.join(argv)}` exits {proc.returncode}\n{proc.stderr[-3000:]}"
        return
    from udc_render.cli import main
    try:
        rc = main(list(argv))
    except SystemExit as exc:
        rc = exc.code
    assert rc in (0, None), f"{where}: `udc-render {' '.join(argv)}` exits {rc}"


def _help(command, kernel_cache, where):
    out = _capture(lambda: _run_udc([command.argv[0], "--help"], {}, kernel_cache, where))
    assert "usage: udc-render" in out, f"{where}: `udc-render {command.argv[0]} --help` printed no usage"


def _capture(fn):
    import io
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        fn()
    return buf.getvalue()


def _run_page(path, modes, tmp_path, monkeypatch, kernel_cache):
    """The page's examples in a temporary folder that sees the repository's docs/ (the committed figures and display
    files the pages name, as from the repository's root, where the docs run them); outputs go to its own out/."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "docs").symlink_to(ROOT / "docs", target_is_directory=True)
    monkeypatch.setenv("UDC_RENDER_CACHE", str(kernel_cache))
    namespace: dict = {"__name__": "__docs_example__"}
    for ex in (e for e in EXAMPLES if e.path == path):
        if ex.mode in ("setup", "shell"):
            continue
        if ex.mode not in modes:
            if ex.mode in ("help", "slow") or not modes:
                for c in _udc_commands(ex):
                    _help(c, kernel_cache, ex.where)
            continue
        if ex.lang == "python":
            exec(compile(ex.body, ex.where, "exec"), namespace)
            continue
        extra = ex.args if ex.mode in ("tiny", "slow") else []
        for c in ex.commands:
            _run_udc(c.argv + extra, c.env, kernel_cache, ex.where)


# Pages whose run/tiny examples run in the slow suite only (30–70 s each on the 2-core machine: CI's 20 minutes);
# the fast suite parses their every command (test_command_parses) and prints each command's help. Beside each, the
# fast tests that run the same commands.
HEAVY_PAGES = {
    "docs/guides/psf.md": "tests/udc_render/test_cli.py, test_cli_display.py",
    "docs/guides/randomize.md": "tests/udc_render/test_dataset_randomize.py, test_randomize.py",
    "docs/guides/fit.md": "tests/udc_render/test_fit_oracles.py, test_fit_roundtrip.py (through the command)",
    "docs/concepts/profiles.md": "tests/udc_render/test_profiles.py",
    "docs/troubleshooting.md": "tests/udc_render/test_cli.py (one-line errors)",
    "docs/guides/train.md": "tests/restore/test_train.py, test_models_conditioned.py",
    "docs/guides/design.md": "tests/udc_render/test_design_optimise.py, test_design_study.py, test_design_torch_psf.py",
}
FAST_PAGES = [p for p in PAGES if any(e.mode in ("run", "tiny", "help", "slow") for e in EXAMPLES if e.path == p)]
SLOW_PAGES = [p for p in PAGES if any(e.mode == "slow" for e in EXAMPLES if e.path == p) or _page_id(p) in HEAVY_PAGES]


def test_heavy_pages_are_pages():
    assert set(HEAVY_PAGES) <= {_page_id(p) for p in PAGES}


@pytest.mark.parametrize("path", FAST_PAGES, ids=_page_id)
def test_page_examples_run(path, tmp_path, monkeypatch, kernel_cache):
    """A page's run/tiny examples and python blocks run in order; help and slow ones print their help (a heavy
    page's run/tiny ones too: HEAVY_PAGES)."""
    _run_page(path, () if _page_id(path) in HEAVY_PAGES else FAST, tmp_path, monkeypatch, kernel_cache)


@pytest.mark.slow
@pytest.mark.parametrize("path", SLOW_PAGES, ids=_page_id)
def test_page_slow_examples_run(path, tmp_path, monkeypatch, kernel_cache):
    """The page's examples in full, slow ones included (a page's later blocks may need its earlier ones)."""
    _run_page(path, FAST + ("slow",), tmp_path, monkeypatch, kernel_cache)
