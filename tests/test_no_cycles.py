"""No file circle: the modules of ``rmm_bench``, ``rmm_guardians`` and ``rmm_envs`` import one
another without a cycle (a shared piece lives below both of its users), read statically at any
depth, ``if TYPE_CHECKING`` included."""

from __future__ import annotations

import ast
from pathlib import Path

from tests.layout import PACKAGE_DIRS

PACKAGES = {name: PACKAGE_DIRS[name] for name in ("rmm_bench", "rmm_guardians", "rmm_envs")}


def _module_name(path: Path, package: str, folder: Path) -> str:
    rel = path.relative_to(folder).with_suffix("").as_posix().removesuffix("__init__").strip("/")
    return ".".join([package] + ([rel.replace("/", ".")] if rel else []))


def import_graph(packages: dict[str, Path] = PACKAGES) -> dict[str, set[str]]:
    """module -> the modules of ``packages`` (import name -> folder) it imports (``from pkg import
    sub`` is an edge to the submodule when ``sub`` is one, else to the package)."""
    paths = {_module_name(p, pkg, folder): p for pkg, folder in packages.items() for p in folder.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for mod, path in paths.items():
        is_pkg = path.name == "__init__.py"
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                deps |= {a.name for a in node.names if a.name in paths}
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = mod.split(".")[: len(mod.split(".")) - node.level + (1 if is_pkg else 0)]
                    base = ".".join(parts + ([base] if base else []))
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    deps.add(sub if sub in paths else base)
        graph[mod] = {d for d in deps if d in paths and d != mod}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
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


def test_the_cycle_finder_finds_a_planted_circle(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from pkg.b import f\n")
    (pkg / "b.py").write_text("def f():\n    from . import a\n")
    (pkg / "c.py").write_text("from pkg import a\n")
    graph = import_graph({"pkg": pkg})
    assert graph["pkg.a"] == {"pkg.b"} and graph["pkg.b"] == {"pkg.a"} and graph["pkg.c"] == {"pkg.a"}
    assert cycles(graph) == [["pkg.a", "pkg.b"]]


def test_no_file_circle():
    graph = import_graph()
    assert "rmm_guardians.hj.maze" in graph and "rmm_guardians.hj.guardian" not in graph["rmm_guardians.hj.maze"]
    assert cycles(graph) == []
