"""The import layers (docs/ARCHITECTURE.md): psf ← udc_render stages ← restore ← experiments ← cli.

Every import in the source (top-level and inside functions) is read with ast; a module may import
only from its own layer or the layers below it, and the package import graph has no cycle.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# Lowest first. A module belongs to the longest prefix that matches it ("udc_render" alone: the
# package's own __init__, a docstring and the version).
LAYERS = [
    ("psf",),
    ("udc_render.errors", "udc_render.io.files", "udc_render.metrics", "udc_render"),
    ("udc_render.scene", "udc_render.scenes", "udc_render.content", "udc_render.render", "udc_render.optics",
     "udc_render.sensor", "udc_render.io", "udc_render.views", "udc_render.pipeline", "udc_render.dataset",
     "udc_render.profiles"),
    ("restore",),
    ("udc_render.studies", "udc_render.calibration", "restore.studies"),
    ("udc_render.cli",),
]


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[0] == "scenes":
        parts = ["udc_render", "scenes", *parts[1:]]
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def layer_of(module: str) -> int | None:
    best, best_len = None, -1
    for i, prefixes in enumerate(LAYERS):
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and len(p) > best_len:
                best, best_len = i, len(p)
    return best


def project_imports(path: Path) -> set[str]:
    """Absolute names of the project modules imported anywhere in the file."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    me = module_name(path)
    package = me if path.name == "__init__.py" else me.rpartition(".")[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            out.add(base)
    return {m for m in out if m.split(".")[0] in ("psf", "udc_render", "restore")}


def sources() -> list[Path]:
    return sorted(p for d in ("psf", "udc_render", "restore", "scenes") for p in (ROOT / d).rglob("*.py"))


def test_every_source_module_has_a_layer():
    assert all(layer_of(module_name(p)) is not None for p in sources()), \
        [module_name(p) for p in sources() if layer_of(module_name(p)) is None]


def test_imports_only_point_down():
    bad = []
    for path in sources():
        me = module_name(path)
        for target in project_imports(path):
            if layer_of(target) is not None and layer_of(target) > layer_of(me):
                bad.append(f"{me} (layer {layer_of(me)}) imports {target} (layer {layer_of(target)})")
    assert not bad, "\n".join(bad)


def test_no_library_module_uses_argparse_or_the_cli():
    bad = []
    for path in sources():
        me = module_name(path)
        if me.startswith("udc_render.cli"):
            continue
        names = {a.name for n in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
                 if isinstance(n, ast.Import) for a in n.names}
        if "argparse" in names or any(t.startswith("udc_render.cli") for t in project_imports(path)):
            bad.append(me)
    assert not bad, bad


def test_no_import_cycle_between_subpackages():
    """The graph of subpackages (udc_render.sensor, restore.studies, psf, …) is acyclic."""
    def unit(m: str) -> str:
        if m == "udc_render" or any(m == p or m.startswith(p + ".") for p in LAYERS[1][:-1]):  # leaves
            return m
        parts = m.split(".")
        return ".".join(parts[:2]) if parts[0] != "psf" else "psf"
    graph: dict[str, set[str]] = {}
    for path in sources():
        me = unit(module_name(path))
        graph.setdefault(me, set()).update(unit(t) for t in project_imports(path) if unit(t) != me)
    seen, stack = {}, []

    def visit(n):
        seen[n] = "open"
        stack.append(n)
        for m in graph.get(n, ()):
            if seen.get(m) == "open":
                pytest.fail("import cycle: " + " → ".join(stack[stack.index(m):] + [m]))
            if m not in seen:
                visit(m)
        seen[n] = "done"
        stack.pop()
    for n in list(graph):
        if n not in seen:
            visit(n)


def test_layers_catch_an_upward_import(tmp_path):
    """The check itself: a psf module importing udc_render is reported."""
    assert layer_of("udc_render.cli.psf") > layer_of("psf.engine")
    assert layer_of("restore.studies.results") > layer_of("restore.train") > layer_of("udc_render.pipeline")
