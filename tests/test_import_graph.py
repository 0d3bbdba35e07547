"""The folder tree is the architecture: packages by role, in layers, no import cycles, the core free of drawing.

Every module of the three installed packages is imported in a fresh interpreter, and the graph of
imports read from their source (imports inside functions and `importlib.import_module("orthosim.x")`
strings included, since those are how a cycle hides) must have no cycle, between modules or between
orthosim's packages. Each orthosim package imports only the packages of the layers below it, in the
order DEVELOPERS.md writes down. The core (`orthosim`, but for its command line `orthosim.cli`, the
composition root) never imports `orthosim_render`, `orthosim_bench` or OpenGL; `orthosim_render`
never imports the benchmarks; only `orthosim.cli` imports click.
"""

from __future__ import annotations

import ast
import importlib.util
import subprocess
import sys
from pathlib import Path

import networkx as nx

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = {"orthosim": ROOT / "orthosim", "orthosim_render": ROOT / "render", "orthosim_bench": ROOT / "bench"}
# the modules at the top of orthosim/: its face (__init__) and the errors every layer raises
TOP_LEVEL_MODULES = {"__init__.py", "errors.py"}
COMPOSITION_ROOT = "orthosim.cli"
DEVELOPERS = ROOT / "DEVELOPERS.md"


def _modules() -> dict[str, Path]:
    found = {}
    for name, folder in FOLDERS.items():
        for path in folder.rglob("*.py"):
            parts = list(path.relative_to(folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join([name, *parts])] = path
    return found


def _imported_names(node: ast.AST, package: str, modules: dict) -> list[str]:
    """What one AST node imports: `import a.b`, `from a import b` (relative or not), or a string
    constant given to `import_module(...)`."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if isinstance(node, ast.ImportFrom):
        base = node.module or ""
        if node.level:
            anchor = package.split(".")[: len(package.split(".")) - (node.level - 1)]
            base = ".".join(anchor + ([base] if base else []))
        return [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
    if (isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", None)) == "import_module"
            and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
        return [node.args[0].value]
    return []


def _import_graph() -> nx.DiGraph:
    modules = _modules()
    graph = nx.DiGraph()
    graph.add_nodes_from(modules)
    for name, path in modules.items():
        is_package = path.name == "__init__.py"
        package = name if is_package else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            for target in _imported_names(node, package, modules):
                while target and target not in modules and "." in target:
                    target = target.rpartition(".")[0]
                if target in modules and target != name:
                    graph.add_edge(name, target)
    return graph


def test_orthosim_has_no_top_level_module_but_its_faces():
    top = {p.name for p in FOLDERS["orthosim"].glob("*.py")}
    assert top <= TOP_LEVEL_MODULES, f"modules at the top of orthosim/ that belong in a role package: {sorted(top - TOP_LEVEL_MODULES)}"


def test_the_import_graph_has_no_cycle():
    graph = _import_graph()
    # a package's __init__ importing its own submodules is how a package shows its face, not a cycle
    for u, v in list(graph.edges):
        if v.startswith(u + "."):
            graph.remove_edge(u, v)
    cycles = [sorted(c) for c in nx.strongly_connected_components(graph) if len(c) > 1]
    assert not cycles, f"import cycles: {cycles}"


def _layers() -> list[set[str]]:
    """The order of orthosim's layers as DEVELOPERS.md writes it (its "Layers" block, bottom first):
    one line a layer, `N. package, package` (the errors module counts as a package)."""
    text = DEVELOPERS.read_text()
    block = text.split("<!-- layers -->", 2)[1]
    layers = []
    for line in block.splitlines():
        line = line.strip()
        if line[:1].isdigit():
            names = line.split(".", 1)[1].split("(")[0]
            layers.append({n.strip(" `") for n in names.split(",") if n.strip(" `")})
    return layers


def _package_of(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if parts[0] == "orthosim" and len(parts) > 1 else None


def _package_graph() -> nx.DiGraph:
    graph = nx.DiGraph()
    for u, v in _import_graph().edges:
        pu, pv = _package_of(u), _package_of(v)
        if pu and pv and pu != pv:
            graph.add_edge(pu, pv, via=(u, v))
    return graph


def test_every_orthosim_package_has_a_layer():
    written = set().union(*_layers())
    packages = {p.name for p in FOLDERS["orthosim"].iterdir() if (p / "__init__.py").exists()} | {"errors"}
    assert packages == written, f"packages without a layer in DEVELOPERS.md: {sorted(packages - written)}; " \
                                f"layers naming no package: {sorted(written - packages)}"


def test_orthosim_packages_form_layers_without_cycles():
    """A package imports only the layers below it (imports inside functions and import_module
    strings counted): the package graph has no cycle and follows the written order."""
    rank = {name: i for i, layer in enumerate(_layers()) for name in layer}
    graph = _package_graph()
    upward = [f"{u} -> {v} ({graph.edges[u, v]['via'][0]} imports {graph.edges[u, v]['via'][1]})"
              for u, v in graph.edges if rank.get(v, -1) >= rank.get(u, -1)]
    assert not upward, f"imports of a package in the same or a higher layer: {upward}"
    assert nx.is_directed_acyclic_graph(graph)


def test_only_the_command_line_imports_click():
    offending = [name for name, path in _modules().items()
                 if name != COMPOSITION_ROOT and not name.startswith(COMPOSITION_ROOT + ".")
                 and any(t.split(".")[0] == "click" for node in ast.walk(ast.parse(path.read_text()))
                         for t in _imported_names(node, name, {}))]
    assert not offending, f"modules outside orthosim.cli importing click: {offending}"


def test_the_core_never_imports_drawing_or_measurement():
    graph = _import_graph()
    offending = [(u, v) for u, v in graph.edges
                 if u.startswith("orthosim.") and u != COMPOSITION_ROOT and not u.startswith(COMPOSITION_ROOT + ".")
                 and (v.startswith("orthosim_render") or v.startswith("orthosim_bench"))]
    assert not offending, f"core modules importing render or bench: {offending}"
    offending = [(u, v) for u, v in graph.edges if u.startswith("orthosim_render") and v.startswith("orthosim_bench")]
    assert not offending, f"render modules importing bench: {offending}"
    for name, path in _modules().items():
        if name.startswith("orthosim.") or name == "orthosim":
            source = path.read_text()
            assert "import OpenGL" not in source and "import pyrender" not in source, name


def test_every_module_imports_in_a_fresh_interpreter():
    names = sorted(_modules())
    code = ("import importlib, sys\n"
            "bad = []\n"
            f"for n in {names!r}:\n"
            "    try:\n        importlib.import_module(n)\n"
            "    except Exception as e:\n        bad.append(f'{n}: {e!r}')\n"
            "print('\\n'.join(bad)); sys.exit(1 if bad else 0)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert importlib.util.find_spec("render") is None or "site-packages" not in str(importlib.util.find_spec("render").origin)


MAX_FUNCTION_LINES = 80


def test_no_function_of_the_product_or_its_measurement_is_over_80_lines():
    """A function a newcomer can read in one screen: the product, the renderer and the bench alike."""
    long = []
    for name, path in _modules().items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    long.append(f"{name}.{node.name}: {lines} lines")
    assert not long, long
