"""The import graph of ddfbench has no circles: no module imports (directly or through others, at the
top or inside a function) a module that imports it back."""

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


def imports(path: str, name: str, known: set[str]) -> set[str]:
    """The ddfbench modules `name` imports anywhere in its file: `from pkg import sub` counts as pkg.sub
    where sub is a module, as pkg otherwise; a module's own package, which Python runs first, is not counted."""
    is_package = path.endswith("__init__.py")
    out = set()
    for node in ast.walk(ast.parse(open(path).read(), path)):
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
    assert "ddfbench.shapes" in graph["ddfbench.runner"]
    assert "ddfbench.sampling" in graph["ddfbench.runner"]  # imported inside a function


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
    runner (training's clock lives in ddfbench.clock, not in ddfbench.render.timing)."""
    graph = import_graph()
    above = ("ddfbench.render", "ddfbench.bench", "ddfbench.report", "ddfbench.runner", "ddfbench.cli")
    families = [m for m in graph if m.startswith("ddfbench.models")]
    assert "ddfbench.models.ddf.fit" in families
    for family in families:
        bad = sorted(m for m in reachable(graph, family) if m.startswith(above))
        assert not bad, f"{family} reaches {bad}"
