"""The import layers (docs/ARCHITECTURE.md): psf ← udc_render stages ← restore ← experiments ← cli.

Every import in the source (top-level and inside functions) is read with ast; a module may import
only from its own layer or the layers below it, neither the package nor the module import graph has
a cycle, and no module is longer than MAX_LINES.
"""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

# Lowest first. A module belongs to the longest prefix that matches it ("udc_render" alone: the
# package's own __init__, a docstring and the version).
LAYERS = [
    ("psf",),
    ("udc_render.errors", "udc_render.io.files", "udc_render.metrics", "udc_render"),
    ("udc_render.scene", "udc_render.scenes", "udc_render.content", "udc_render.render", "udc_render.optics",
     "udc_render.sensor", "udc_render.io", "udc_render.views", "udc_render.synth_config", "udc_render.synth_kernels",
     "udc_render.pipeline", "udc_render.dataset",
     "udc_render.profiles", "udc_render.description", "udc_render.design"),
    ("restore",),
    ("udc_render.studies", "udc_render.calibration", "udc_render.fit", "restore.studies"),
    ("udc_render.cli",),
]


MAX_LINES = 400


def module_name(path: Path, root: Path = ROOT) -> str:
    rel = path.relative_to(root).with_suffix("")
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


def import_nodes(tree: ast.AST, in_functions: bool | None = None) -> list[ast.Import | ast.ImportFrom]:
    """The import statements of a module: all (None), those inside functions (True) or outside (False)."""
    out, todo = [], [(tree, False)]
    while todo:
        node, inside = todo.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)) and in_functions in (None, inside):
            out.append(node)
        inside = inside or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
        todo += [(child, inside) for child in ast.iter_child_nodes(node)]
    return sorted(out, key=lambda n: n.lineno)


def imported_names(path: Path, root: Path = ROOT, in_functions: bool | None = None) -> list[tuple[str, list[str]]]:
    """(absolute module, the names taken from it) of the file's imports (import_nodes); `import a.b`
    takes no names."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    me = module_name(path, root)
    package = me if path.name == "__init__.py" else me.rpartition(".")[0]
    out = []
    for node in import_nodes(tree, in_functions):
        if isinstance(node, ast.Import):
            out += [(a.name, []) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            out.append((base, [a.name for a in node.names]))
    return out


def project_imports(path: Path, root: Path = ROOT) -> set[str]:
    """Absolute names of the project modules imported anywhere in the file."""
    return {m for m, _ in imported_names(path, root) if m.split(".")[0] in ("psf", "udc_render", "restore")}


def sources(root: Path = ROOT) -> list[Path]:
    return sorted(p for d in ("psf", "udc_render", "restore", "scenes") for p in (root / d).rglob("*.py"))


def module_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Module → the project modules it imports (top level and inside functions); `from pkg import name`
    counts as an import of the module pkg.name when there is one, else of pkg."""
    paths = sources(root)
    modules = {module_name(p, root) for p in paths}
    graph = {}
    for path in paths:
        targets = set()
        for base, names in imported_names(path, root):
            subs = {f"{base}.{n}" for n in names if f"{base}.{n}" in modules}
            targets |= subs
            if base in modules and (not names or len(subs) < len(names)):
                targets.add(base)
        graph[module_name(path, root)] = targets - {module_name(path, root)}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle of the directed graph as [a, b, …, a], or None (depth-first search)."""
    state, stack = {}, []

    def visit(n):
        state[n] = "open"
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == "open":
                return stack[stack.index(m):] + [m]
            if m not in state and (cycle := visit(m)):
                return cycle
        state[n] = "done"
        stack.pop()
        return None
    for n in sorted(graph):
        if n not in state and (cycle := visit(n)):
            return cycle
    return None


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
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " → ".join(cycle)


def test_no_import_cycle_between_modules():
    """The graph of modules (psf.engine, udc_render.studies.defocus, …) is acyclic."""
    cycle = find_cycle(module_graph())
    assert cycle is None, "import cycle: " + " → ".join(cycle)


def test_module_cycles_are_caught(tmp_path):
    """The check itself: psf.alpha imports psf.beta (`from psf import beta`), whose function imports
    psf.alpha back: reported; `from psf import gamma_value` (a name, not a module) is an edge to psf."""
    pkg = tmp_path / "psf"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("gamma_value = 1\n")
    (pkg / "alpha.py").write_text("from psf import beta, gamma_value\n")
    (pkg / "beta.py").write_text("def f():\n    from .alpha import x\n    return x\n")
    graph = module_graph(tmp_path)
    assert graph == {"psf": set(), "psf.alpha": {"psf", "psf.beta"}, "psf.beta": {"psf.alpha"}}
    assert find_cycle(graph) == ["psf.alpha", "psf.beta", "psf.alpha"]
    (pkg / "beta.py").write_text("def f():\n    return 0\n")
    assert find_cycle(module_graph(tmp_path)) is None


def test_modules_are_short():
    """Every module at most MAX_LINES lines: split by content, not grown."""
    long = {module_name(p): n for p in sources() if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES}
    assert not long, long


def test_layers_catch_an_upward_import(tmp_path):
    """The check itself: a psf module importing udc_render is reported."""
    assert layer_of("udc_render.cli.psf") > layer_of("psf.engine")
    assert layer_of("restore.studies.results") > layer_of("restore.train") > layer_of("udc_render.pipeline")
