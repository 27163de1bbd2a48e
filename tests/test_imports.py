"""The import graph of ddfbench has no circles (no module imports, directly or through others, at the top or
inside a function, a module that imports it back), and its stage packages are layered: a stage imports only
itself and the stages below it."""

import ast
import os

import ddfbench

PACKAGE_DIR = os.path.dirname(ddfbench.__file__)


def module_names() -> dict[str, str]:
    """Dotted name -> file of every module of the package (a package is its __init__)."""
    out = {}
    for root, _, files in os.walk(PACKAGE_DIR):
        for f in files:
            if f.endswith(".py"):
                rel = os.path.relpath(os.path.join(root, f), os.path.dirname(PACKAGE_DIR))[:-3].split(os.sep)
                out[".".join(rel[:-1] if rel[-1] == "__init__" else rel)] = os.path.join(root, f)
    return out


def runtime_nodes(tree: ast.AST):
    """Every node of `tree` but those under `if TYPE_CHECKING:` (annotations only: nothing is imported at run time)."""
    todo = [tree]
    while todo:
        node = todo.pop()
        yield node
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and isinstance(child.test, ast.Name) and child.test.id == "TYPE_CHECKING":
                todo.extend(child.orelse)
            else:
                todo.append(child)


def imports(path: str, name: str, known: set[str]) -> set[str]:
    """The ddfbench modules `name` imports anywhere in its file at run time: `from pkg import sub` counts as
    pkg.sub where sub is a module, as pkg otherwise; a module's own package, which Python runs first, is not
    counted."""
    is_package = path.endswith("__init__.py")
    out = set()
    for node in runtime_nodes(ast.parse(open(path).read(), path)):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name in known}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative import
                parts = name.split(".")[: len(name.split(".")) - node.level + (1 if is_package else 0)]
                base = ".".join(parts + ([base] if base else []))
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                out.add(sub if sub in known else base)
    return {m for m in out if m in known and m != name}


def import_graph() -> dict[str, set[str]]:
    mods = module_names()
    return {name: imports(path, name, set(mods)) for name, path in mods.items()}


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_graph_sees_lazy_imports():
    graph = import_graph()
    assert "ddfbench.truth.shapes" in graph["ddfbench.run.runner"]
    assert "ddfbench.sampling" in graph["ddfbench.run.runner"]  # imported inside a function


def test_a_circle_is_found():
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_module_imports_one_that_imports_it_back():
    assert circles(import_graph()) == []


def reachable(graph: dict[str, set[str]], start: str) -> set[str]:
    """Every module `start` imports, directly or through others."""
    seen, todo = set(), [start]
    while todo:
        for w in graph[todo.pop()] - seen:
            seen.add(w)
            todo.append(w)
    return seen


def test_a_family_reaches_no_layer_above_it():
    """DESIGN.md: imports only point down; a family never imports the renderer, a bench, the reports or the
    runner (training's clock lives in ddfbench.core.clock, not in ddfbench.render.timing)."""
    graph = import_graph()
    above = ("ddfbench.render", "ddfbench.bench", "ddfbench.report", "ddfbench.run.runner", "ddfbench.cli")
    families = [m for m in graph if m.startswith("ddfbench.models")]
    assert "ddfbench.models.ddf.fit" in families
    for family in families:
        bad = sorted(m for m in reachable(graph, family) if m.startswith(above))
        assert not bad, f"{family} reaches {bad}"


# The stage packages, bottom first: the data flow of one run (docs/architecture.md).
STAGES = ("core", "truth", "sampling", "evaluate", "fit", "models", "render", "run", "report", "bench")
ENTRY_POINTS = ("ddfbench", "ddfbench.__main__", "ddfbench.cli", "ddfbench.suite")


def stage_of(module: str) -> str | None:
    """The stage a ddfbench module belongs to; None for an entry point."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in STAGES else None


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    """'a -> b' for every import of a stage module into a stage above its own, or into an entry point."""
    rank = {s: i for i, s in enumerate(STAGES)}
    bad = []
    for module, targets in sorted(graph.items()):
        if stage_of(module) is None:
            continue
        for target in sorted(targets):
            t = stage_of(target)
            if t is None or rank[t] > rank[stage_of(module)]:
                bad.append(f"{module} -> {target}")
    return bad


def test_the_top_level_holds_only_entry_points_and_stages():
    graph = import_graph()
    loose = sorted(m for m in graph if stage_of(m) is None and m not in ENTRY_POINTS)
    assert loose == []
    assert {stage_of(m) for m in graph} - {None} == set(STAGES)


def test_an_upward_import_is_found():
    graph = {"ddfbench.truth.oracle": {"ddfbench.core.errors", "ddfbench.render.scene"},
             "ddfbench.models.mesh": {"ddfbench.truth.oracle", "ddfbench.models.base"},
             "ddfbench.core.errors": {"ddfbench.cli"}, "ddfbench.cli": {"ddfbench.report.tables"}}
    assert upward_imports(graph) == ["ddfbench.core.errors -> ddfbench.cli", "ddfbench.truth.oracle -> ddfbench.render.scene"]


def test_annotation_only_imports_are_not_run_time_imports(tmp_path):
    path = tmp_path / "m.py"
    path.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import ddfbench.bench\nelse:\n    import ddfbench.cli\n")
    assert imports(str(path), "ddfbench.core.m", {"ddfbench.bench", "ddfbench.cli"}) == {"ddfbench.cli"}


def test_every_stage_imports_only_itself_and_the_stages_below():
    assert upward_imports(import_graph()) == []
