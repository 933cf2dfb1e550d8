"""The README is a five-minute page: at most 200 lines, and its two commands are the ones that work."""
from __future__ import annotations

import shlex

from tests.docs.examples import ROOT, examples

README = ROOT / "README.md"
DEMO = "bash scripts/setup.sh && .venv/bin/udc-render demo"


def _setup_lines():
    return [ex.body.strip() for ex in examples(README) if ex.mode == "setup"]


def _ci_command() -> str:
    """The last command line of .ci/run (the CI script runs the README's test command verbatim)."""
    lines = [ln.strip() for ln in (ROOT / ".ci" / "run").read_text().splitlines()]
    commands = [ln for ln in lines if ln and not ln.startswith("#") and not ln.startswith(("set ", "cd "))]
    return commands[-1]


def test_readme_is_short():
    n = len(README.read_text(encoding="utf-8").splitlines())
    assert n <= 200, f"README.md has {n} lines; the manual belongs in docs/ (at most 200)"


def test_readme_states_the_two_commands():
    lines = _setup_lines()
    assert len(lines) == 2, f"README.md: expected the two `setup` commands, found {lines}"
    assert lines[0] == DEMO
    assert shlex.split(lines[1]) == shlex.split(_ci_command()), \
        f"README.md's test command differs from .ci/run's:\n  {lines[1]}\n  {_ci_command()}"


def test_getting_started_states_the_same_commands():
    page = [ex.body.strip() for ex in examples(ROOT / "docs" / "getting-started.md") if ex.mode == "setup"]
    assert page == _setup_lines()


def test_readme_picture_exists():
    import re
    text = README.read_text(encoding="utf-8")
    pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert pictures, "README.md shows no picture"
    for p in pictures:
        assert (ROOT / p).is_file(), f"README.md: picture {p} is not in the repository"
