"""The command examples of the documentation, found and classified (docs/about.md, "The examples are tests").

An example is a fenced block of language console, bash or python in docs/**/*.md or README.md. The line
right before it is `<!-- docs-test: MODE [ARGS] -->`:

    run          run as written
    tiny ARGS    run each command with ARGS appended (later options win)
    help         parse each command; run `udc-render COMMAND --help`
    slow [ARGS]  as help in the fast suite; run (with ARGS) under `pytest -m slow`
    setup        the README's two commands (scripts/setup.sh ...): parse the udc-render part
    shell        other shell commands, not run; no udc-render command inside

In console/bash blocks every line is a command: a trailing backslash continues it, `#` starts a
comment, a leading `$ ` is dropped, `&&`, `||` and `;` separate commands, and leading VAR=value words
set the environment. A command is a udc-render command when its program is `udc-render` or ends with
`/udc-render` (`.venv/bin/udc-render`).
"""
from __future__ import annotations

import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LANGS = ("console", "bash", "python")
MODES = ("run", "tiny", "help", "slow", "setup", "shell")
MARK = re.compile(r"^\s*<!--\s*docs-test:\s*(?P<mode>\S+)(?P<args>.*?)\s*-->\s*$")
FENCE = re.compile(r"^(?P<indent>\s*)(?P<fence>`{3,}|~{3,})\s*(?P<info>[^`\s]*)")
SEPARATORS = ("&&", "||", ";")


@dataclass
class Command:
    argv: list            # the arguments after the program
    env: dict             # VAR=value words before the program
    udc: bool             # a udc-render command
    text: str


@dataclass
class Example:
    path: Path
    line: int             # 1-based line of the opening fence
    lang: str
    mode: str | None
    args: list
    body: str
    commands: list = field(default_factory=list)
    problems: list = field(default_factory=list)

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"


def doc_files() -> list[Path]:
    """docs/**/*.md (not the build output) and README.md, sorted."""
    docs = sorted(p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.relative_to(ROOT).parts)
    return docs + [ROOT / "README.md"]


def split_commands(body: str) -> list[Command]:
    """The commands of a console/bash block."""
    lines, joined = body.splitlines(), []
    pending = ""
    for raw in lines:
        line = raw.rstrip()
        if not pending and line.lstrip().startswith("$ "):
            line = line.lstrip()[2:]
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        joined.append(pending + line)
        pending = ""
    if pending:
        joined.append(pending)
    commands = []
    for line in joined:
        lex = shlex.shlex(line, posix=True, punctuation_chars=";&|")
        lex.whitespace_split = True
        lex.commenters = "#"
        segment: list = []
        for token in list(lex) + [";"]:
            if token in SEPARATORS:
                if segment:
                    commands.append(_command(segment, line))
                segment = []
            else:
                segment.append(token)
    return commands


def _command(tokens: list, text: str) -> Command:
    env = {}
    while tokens and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*=.*", tokens[0]):
        key, value = tokens[0].split("=", 1)
        env[key] = value
        tokens = tokens[1:]
    program = tokens[0] if tokens else ""
    udc = program == "udc-render" or program.endswith("/udc-render")
    return Command(argv=tokens[1:], env=env, udc=udc, text=text.strip())


def examples(path: Path) -> list[Example]:
    """Every console/bash/python block of one Markdown file, with its marker and problems."""
    lines = path.read_text(encoding="utf-8").splitlines()
    found, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, lang = m["fence"], m["info"].lower()
        start, i = i, i + 1
        body = []
        while i < len(lines):
            close = FENCE.match(lines[i])
            if close and close["fence"][0] == fence[0] and len(close["fence"]) >= len(fence) and not close["info"]:
                break
            body.append(lines[i][len(m["indent"]):] if lines[i].startswith(m["indent"]) else lines[i])
            i += 1
        i += 1
        if lang not in LANGS:
            continue
        mark = MARK.match(lines[start - 1]) if start > 0 else None
        ex = Example(path, start + 1, lang, mark["mode"] if mark else None,
                     shlex.split(mark["args"]) if mark else [], "\n".join(body) + "\n")
        _classify(ex)
        found.append(ex)
    return found


def _classify(ex: Example) -> None:
    if ex.mode is None:
        ex.problems.append("no `<!-- docs-test: MODE -->` line right before the block")
        return
    if ex.mode not in MODES:
        ex.problems.append(f"unknown mode {ex.mode!r} (one of {', '.join(MODES)})")
        return
    if ex.mode == "tiny" and not ex.args:
        ex.problems.append("mode tiny needs the arguments to append")
    if ex.args and ex.mode not in ("tiny", "slow"):
        ex.problems.append(f"mode {ex.mode} takes no arguments")
    if ex.lang == "python":
        if ex.mode not in ("run", "slow"):
            ex.problems.append(f"a python block runs (run or slow), not {ex.mode}")
        return
    ex.commands = split_commands(ex.body)
    if not ex.commands:
        ex.problems.append("no command in the block")
    udc = [c for c in ex.commands if c.udc]
    if ex.mode == "shell":
        if udc:
            ex.problems.append("a shell block holds a udc-render command: give it a mode that tests it")
    elif ex.mode != "setup":
        others = [c.text for c in ex.commands if not c.udc]
        if others:
            ex.problems.append(f"mode {ex.mode} runs udc-render commands only, found: {others[0]!r}")


def all_examples() -> list[Example]:
    return [ex for path in doc_files() for ex in examples(path)]
