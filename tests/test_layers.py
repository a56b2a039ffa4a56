"""The packages stack: ``benchmarks`` -> ``guardians`` -> ``rmm_envs``, and no import runs upward.

Every module of ``rmm_envs`` and ``guardians`` is parsed (not imported), and every import
statement in it is read, at any depth: at module level, inside functions and classes, under
``if TYPE_CHECKING`` or ``try``.  Relative imports are resolved against the module's package.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: package -> the packages above it, which it must never import
ABOVE = {"rmm_envs": ("guardians", "benchmarks"), "guardians": ("benchmarks",)}


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


def _module_package(path: Path) -> str:
    """The dotted package a module file belongs to (a package's ``__init__.py`` belongs to that package)."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1])


def upward_imports(package: str) -> list[str]:
    found = []
    for path in sorted((ROOT / package).rglob("*.py")):
        for line, name in imported_modules(path, _module_package(path)):
            top = name.split(".")[0]
            if top in ABOVE[package]:
                found.append(f"{path.relative_to(ROOT)}:{line} imports {name}")
    return found


def test_the_scanner_sees_imports_at_any_depth_and_resolves_relative_ones(tmp_path):
    src = ("import os\nfrom . import sibling\nfrom ..up import thing\n"
           "def f():\n    import benchmarks.bench\n    class C:\n        from guardians import make_guardian\n"
           "try:\n    import guardians.hj as hj\nexcept ImportError:\n    pass\n")
    (tmp_path / "m.py").write_text(src)
    got = imported_modules(tmp_path / "m.py", "rmm_envs.envs")
    assert sorted(got) == [(1, "os"), (2, "rmm_envs.envs"), (3, "rmm_envs.up"), (5, "benchmarks.bench"), (7, "guardians"),
                           (9, "guardians.hj")]
    assert _module_package(ROOT / "rmm_envs" / "envs" / "dubins4d.py") == "rmm_envs.envs"
    assert _module_package(ROOT / "rmm_envs" / "envs" / "__init__.py") == "rmm_envs.envs"


@pytest.mark.parametrize("package", sorted(ABOVE))
def test_no_import_runs_upward(package):
    assert upward_imports(package) == []
