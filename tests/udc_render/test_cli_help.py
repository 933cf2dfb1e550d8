"""Every command's --help says what it does and what each option and each choice does; --version."""
import argparse
import re
import subprocess
import sys
from importlib import metadata

import pytest

import udc_render
from udc_render import cli


def walk(parser: argparse.ArgumentParser, path: tuple = ("udc-render",)):
    """(command path, action) for every action of the parser and its subparsers, recursively."""
    for action in parser._actions:
        yield path, action
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from walk(sub, path + (name,))


ACTIONS = list(walk(cli.build_parser()))


def _id(item):
    path, action = item
    return " ".join(path[1:] + ((action.option_strings or [action.dest])[0],))


def mentions(text: str, word: str) -> bool:
    """`word` in `text` as a word of its own ('l1' not inside 'l1+ssim', 'none' not inside 'nonempty')."""
    return re.search(rf"(?<![\w+.-]){re.escape(word)}(?![\w+-])", text) is not None


def test_the_walk_sees_every_command_and_choice_option():
    commands = {path for path, _ in ACTIONS}
    assert len(commands) == 1 + 15 and {("udc-render", "study"), ("udc-render", "cache")} <= commands
    assert sum(1 for _, a in ACTIONS if a.choices) > 15


@pytest.mark.parametrize("item", ACTIONS, ids=map(_id, ACTIONS))
def test_every_option_has_help_and_names_each_choice(item):
    path, action = item
    assert action.help and action.help.strip(), f"{' '.join(path)} {action.option_strings or action.dest}: no help"
    if isinstance(action, argparse._SubParsersAction):
        helps = {c.dest: c.help for c in action._choices_actions}
        for name in action.choices:
            assert helps.get(name) and "\n" not in helps[name], f"{' '.join(path)} {name}: no one-line help"
    elif action.choices:
        missing = [c for c in action.choices if not mentions(action.help, str(c))]
        assert not missing, f"{' '.join(path)} {action.option_strings or action.dest}: help names no {missing}"


def test_mentions_is_a_word_match():
    assert mentions("l1: x; l1+ssim: y", "l1") and not mentions("l1+ssim: y", "l1")
    assert mentions("none: off", "none") and not mentions("nonempty", "none")


def test_version_prints_the_installed_version_and_exits_0(capsys):
    with pytest.raises(SystemExit) as exit_:
        cli.main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"udc-render {metadata.version('udc-render')}"
    r = subprocess.run([sys.executable, "-m", "udc_render.cli", "--version"], capture_output=True, text=True)
    assert (r.returncode, r.stdout.strip(), r.stderr) == (0, f"udc-render {metadata.version('udc-render')}", "")


def test_version_falls_back_to_the_package_version(monkeypatch):
    def not_installed(name):
        raise metadata.PackageNotFoundError(name)
    monkeypatch.setattr(cli, "version", not_installed)
    assert cli.package_version() == udc_render.__version__
