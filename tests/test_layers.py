"""The packages stack: ``rmm_bench`` -> ``rmm_guardians`` -> ``rmm_envs``, and no import runs upward.

Every module of ``rmm_envs`` and ``rmm_guardians`` is parsed (not imported), and every import
statement in it is read, at any depth: at module level, inside functions and classes, under
``if TYPE_CHECKING`` or ``try``.  Relative imports are resolved against the module's package.
In all three packages the project's own modules are imported at the top of a module, never
inside a function, except the documented lazy loads of optional heavy dependencies
(:data:`IMPORTS_IN_FUNCTIONS_ALLOWED`).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.layout import ROOT, module_package, package_files

#: package -> the packages above it, which it must never import (the repository's development
#: tools in ``benchmarks/`` are above them all)
ABOVE = {"rmm_envs": ("rmm_guardians", "rmm_bench", "benchmarks"), "rmm_guardians": ("rmm_bench", "benchmarks")}


def imported_modules(path: Path, package: str) -> list[tuple[int, str]]:
    """``(line, absolute module name)`` of every import in the file at ``path``, whose own
    package (dotted) is ``package``."""
    tree = ast.parse(path.read_text(), filename=str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            out.append((node.lineno, name))
    return out


_module_package = module_package


def upward_imports(package: str) -> list[str]:
    found = []
    for path in package_files(package):
        for line, name in imported_modules(path, _module_package(path)):
            top = name.split(".")[0]
            if top in ABOVE[package]:
                found.append(f"{path.relative_to(ROOT)}:{line} imports {name}")
    return found


def test_the_scanner_sees_imports_at_any_depth_and_resolves_relative_ones(tmp_path):
    src = (
        "import os\nfrom . import sibling\nfrom ..up import thing\n"
        "def f():\n    import rmm_bench\n    class C:\n        from rmm_guardians import make_guardian\n"
        "try:\n    import rmm_guardians.hj as hj\nexcept ImportError:\n    pass\n"
    )
    (tmp_path / "m.py").write_text(src)
    got = imported_modules(tmp_path / "m.py", "rmm_envs.envs")
    assert sorted(got) == [
        (1, "os"),
        (2, "rmm_envs.envs"),
        (3, "rmm_envs.up"),
        (5, "rmm_bench"),
        (7, "rmm_guardians"),
        (9, "rmm_guardians.hj"),
    ]
    assert _module_package(ROOT / "rmm_envs" / "envs" / "dubins4d.py") == "rmm_envs.envs"
    assert _module_package(ROOT / "rmm_envs" / "envs" / "__init__.py") == "rmm_envs.envs"


@pytest.mark.parametrize("package", sorted(ABOVE))
def test_no_import_runs_upward(package):
    assert upward_imports(package) == []


def _reads_environment(path: Path) -> list[int]:
    """Lines of ``path`` that read the process environment (``os.environ``, ``os.getenv``,
    ``os.environ.get``, ``from os import environ/getenv``)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    lines = []
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and node.attr in ("environ", "getenv", "environb")
            and isinstance(node.value, ast.Name)
            and node.value.id == "os"
        ):
            lines.append(node.lineno)
        elif (
            isinstance(node, ast.ImportFrom)
            and node.module == "os"
            and any(a.name in ("environ", "getenv", "environb") for a in node.names)
        ):
            lines.append(node.lineno)
    return lines


def test_environment_variables_are_read_in_one_configuration_module_only():
    """``rmm_envs/environment_variables.py`` reads every setting taken from the environment; the one other
    reader, ``benchmarks/arith.py``, copies the environment for its child interpreters."""
    allowed = {ROOT / "rmm_envs" / "environment_variables.py", ROOT / "benchmarks" / "arith.py"}
    found = {
        str(p.relative_to(ROOT)): lines
        for pkg in ("rmm_envs", "guardians", "benchmarks")
        for p in sorted((ROOT / pkg).rglob("*.py"))
        if p not in allowed and (lines := _reads_environment(p))
    }
    assert found == {}
    assert _reads_environment(ROOT / "rmm_envs" / "environment_variables.py")  # the check sees a real reader


def test_the_environment_variables_module_reads_and_refuses_by_name(monkeypatch, tmp_path):
    from rmm_envs import environment_variables as variables

    monkeypatch.delenv("RMM_HJ_THREADS", raising=False)
    assert variables.hj_threads() is None
    monkeypatch.setenv("RMM_HJ_THREADS", "3")
    assert variables.hj_threads() == 3
    for bad in ("0", "two", "-1"):
        monkeypatch.setenv("RMM_HJ_THREADS", bad)
        with pytest.raises(ValueError, match=f"RMM_HJ_THREADS must be an integer >= 1, got '{bad}'"):
            variables.hj_threads()
    monkeypatch.setenv("RMM_HJ_CACHE", str(tmp_path))
    assert variables.hj_cache_dir() == tmp_path
    monkeypatch.setenv("RMM_HJ_CACHE", "")
    assert variables.hj_cache_dir() == Path.home() / ".cache" / "rmm-envs" / "hj"


#: what a guardian may not import: the envs, the drivers and the risk scenes (it meets a system
#: through rmm_envs.autonomy, the systems' dynamics and the worlds' geometry): the generic env and
#: scene modules, and in a system's folder (rmm_envs/systems/<system>/) the modules below
PAST_THE_CONTRACT = ("rmm_envs.envs", "rmm_envs.scenes")
SYSTEM_MODULES_PAST_THE_CONTRACT = ("env", "guarded", "driver", "scene", "vector", "step", "view")


def test_guardians_never_import_an_env_a_driver_or_a_scene():
    found = []
    for path in package_files("rmm_guardians"):
        for line, name in imported_modules(path, _module_package(path)):
            parts = name.split(".")
            in_system = parts[:2] == ["rmm_envs", "systems"] and len(parts) > 3
            if any(name == m or name.startswith(m + ".") for m in PAST_THE_CONTRACT) or (
                in_system and parts[3] in SYSTEM_MODULES_PAST_THE_CONTRACT
            ):
                found.append(f"{path.relative_to(ROOT)}:{line} imports {name}")
    assert found == []


def _module_level_names(path: Path) -> set[str]:
    """Names a file binds at module level (assignments, annotated assignments, defs, classes),
    also under a module-level ``if``, ``try`` or ``with``."""
    out: set[str] = set()
    nodes = list(ast.parse(path.read_text(), filename=str(path)).body)
    while nodes:
        node = nodes.pop()
        if isinstance(node, (ast.If, ast.Try, ast.With)):
            nodes += [*node.body, *getattr(node, "orelse", []), *getattr(node, "finalbody", [])]
            nodes += [s for h in getattr(node, "handlers", []) for s in h.body]
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.add(node.name)
        targets = (
            node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) else []
        )
        out |= {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
    return out


def test_one_table_of_systems():
    """``SYSTEMS`` is the catalog's table (``rmm_envs/catalog.py``) and nothing else in the
    repository's code: a tool that needs systems reads them from there (glossary, docs/concepts.md)."""
    files = [
        p for d in ("rmm_envs", "guardians", "benchmarks", "tests", "docs") for p in sorted((ROOT / d).rglob("*.py"))
    ]
    defining = sorted(str(p.relative_to(ROOT)) for p in files if "SYSTEMS" in _module_level_names(p))
    assert defining == ["rmm_envs/catalog.py"]


def test_the_name_scanner_sees_every_binding(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("A = 1\nB: int = 2\nC, (D, E) = 1, (2, 3)\ndef F(): G = 1\nclass H: I = 1\nif True:\n    J = 1\n")
    assert _module_level_names(f) == {"A", "B", "C", "D", "E", "F", "H", "J"}


#: the project's own packages, as an import statement names them
OWN_PACKAGES = ("rmm_envs", "rmm_guardians", "rmm_bench", "benchmarks")

#: ``(file, module)`` of the project's own imports that may sit inside a function, in any of the
#: three packages, each with its reason: only a module that loads an optional heavy dependency on
#: import, for the callers that need it.  Third-party imports are not checked: an optional or heavy
#: one (matplotlib, torch, pandas, imageio-ffmpeg, pybullet, ray, ...) loads where it is used.
IMPORTS_IN_FUNCTIONS_ALLOWED = {
    ("rmm_envs/adapters/__init__.py", "rmm_envs.adapters.mujoco_envs"): (
        "imports mujoco (the optional extra rmm-envs[mujoco], 0.1 s); loaded for a MuJoCo env only"
    ),
}


def imports_in_functions(path: Path, package: str) -> list[tuple[int, str]]:
    """``(line, absolute module name)`` of the project's own imports inside a function (or a
    lambda, or a class within one) of the file at ``path``, whose own package is ``package``;
    module-level imports, also under ``if``/``try`` or ``TYPE_CHECKING``, are not listed."""
    tree = ast.parse(path.read_text(), filename=str(path))
    out: list[tuple[int, str]] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inside = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if in_function and isinstance(child, (ast.Import, ast.ImportFrom)):
                for line, name in _import_names(child, package):
                    if name.split(".")[0] in OWN_PACKAGES:
                        out.append((line, name))
            visit(child, inside)

    visit(tree, False)
    return out


def _import_names(node: ast.Import | ast.ImportFrom, package: str) -> list[tuple[int, str]]:
    if isinstance(node, ast.Import):
        return [(node.lineno, a.name) for a in node.names]
    if node.level:
        base = package.split(".")[: len(package.split(".")) - node.level + 1]
        return [(node.lineno, ".".join(base + ([node.module] if node.module else [])))]
    return [(node.lineno, node.module or "")]


def _own_imports_in_functions(package: str) -> list[tuple[str, int, str]]:
    return [
        (str(path.relative_to(ROOT)), line, name)
        for path in package_files(package)
        for line, name in imports_in_functions(path, _module_package(path))
    ]


def test_the_function_import_scanner_sees_nested_and_relative_imports_only(tmp_path):
    src = (
        "import rmm_envs\nfrom rmm_envs import catalog\nif True:\n    import rmm_guardians\n"
        "def f():\n    import os\n    from . import sibling\n    class C:\n        import rmm_bench.cli\n"
        "class D:\n    def g(self):\n        from rmm_guardians.hj import solver\n"
        "h = lambda: __import__('x')\n"
    )
    (tmp_path / "m.py").write_text(src)
    got = imports_in_functions(tmp_path / "m.py", "rmm_envs.envs")
    assert got == [(7, "rmm_envs.envs"), (9, "rmm_bench.cli"), (12, "rmm_guardians.hj")]


@pytest.mark.parametrize("package", ["rmm_envs", "rmm_guardians", "rmm_bench"])
def test_the_projects_own_modules_are_imported_at_the_top(package):
    """An import of the project's own module inside a function hides a tie between modules (and
    a cycle, broken by moving code to where it belongs); only the documented lazy loads of optional
    heavy dependencies (:data:`IMPORTS_IN_FUNCTIONS_ALLOWED`) may sit in a function."""
    found = [
        f"{path}:{line} imports {name} inside a function"
        for path, line, name in _own_imports_in_functions(package)
        if (path, name) not in IMPORTS_IN_FUNCTIONS_ALLOWED
    ]
    assert found == []


def test_every_allowed_import_in_a_function_is_still_there():
    seen = {
        (path, name)
        for pkg in ("rmm_envs", "rmm_guardians", "rmm_bench")
        for path, _, name in _own_imports_in_functions(pkg)
    }
    assert set(IMPORTS_IN_FUNCTIONS_ALLOWED) <= seen
    assert all(reason.strip() for reason in IMPORTS_IN_FUNCTIONS_ALLOWED.values())
