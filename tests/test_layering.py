"""The package's import graph: no cycles, and evaluation is only imported from above it (the stages and the
command), so the solvers and the workflow's decisions never depend on how samples are scored."""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx

PACKAGE = Path(__file__).resolve().parent.parent / "dpi"
ABOVE_EVALUATION = {"dpi.stages", "dpi.stages.evaluate", "dpi.cli"}
"""modules that orchestrate solving and scoring and may import dpi.evaluation"""


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> set[str]:
    """dpi modules a file imports, at any depth except under `if TYPE_CHECKING:`."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            node.body = []
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("dpi"):
            found.add(node.module)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.startswith("dpi"))
    return found


def import_graph() -> nx.DiGraph:
    modules = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph = nx.DiGraph()
    for name, path in modules.items():
        graph.add_node(name)
        for target in imports(path):
            while target not in modules and "." in target:  # `from dpi.x import name` of a module or a symbol
                target = target.rsplit(".", 1)[0]
            if target in modules and target != name:
                graph.add_edge(name, target)
    return graph


def test_the_package_has_no_import_cycle():
    graph = import_graph()
    # a package's __init__ re-exporting its modules is not a cycle of the modules themselves
    graph.remove_edges_from([(a, b) for a, b in graph.edges if b.startswith(a + ".")])
    assert list(nx.simple_cycles(graph)) == []


def test_only_the_orchestration_imports_evaluation():
    graph = import_graph()
    below = sorted(a for a, b in graph.edges
                   if b.startswith("dpi.evaluation") and not a.startswith("dpi.evaluation") and a not in ABOVE_EVALUATION)
    assert below == []


def layer(module: str) -> str:
    """The package a module sits in (dpi.solve.dps.loop -> dpi.solve), or the module itself at the top."""
    return ".".join(module.split(".")[:2])


def test_the_layers_import_one_way():
    """Grouped by the package they sit in, the modules import one way: no two layers import each other, directly
    or round a loop, so each layer can be read with only the ones below it in mind."""
    layers = nx.DiGraph((layer(a), layer(b)) for a, b in import_graph().edges if layer(a) != layer(b))
    assert list(nx.simple_cycles(layers)) == []


def test_only_the_command_sits_at_the_top_of_the_package():
    """Every module belongs to the layer it serves; the `dpi` command is the one module of its own."""
    assert sorted(p.stem for p in PACKAGE.glob("*.py") if p.stem != "__init__") == ["cli"]
