"""A system's name appears outside its own folder only where it, or a method's part for it, is
registered: adding a system touches its folder (and optionally its guardians' parts).

The scan reads the code of the three installed packages for any system of the table (its name,
its classes named after it, its env ids) outside ``rmm_envs/systems/<its folder>/``: identifiers
and the string constants that are one word (an id, a key), not prose (docstrings, comments, help
and messages, which may name a system as an example).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import rmm_envs  # noqa: F401  (fills the table of systems)
from rmm_envs.catalog import SYSTEMS

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("rmm_envs", "guardians", "benchmarks/bench")

#: Where naming a system is its registration (folder prefix -> why)
REGISTRATIONS = {
    "rmm_envs/systems/": "the systems' own folders",
    "rmm_envs/builtin.py": "this package's systems, registered through the public entry point",
    "guardians/": "a method's parts for a system (cbf's rows, hj's dynamics and look-ahead, lrmm's models), registered by name",
    "rmm_envs/adapters/": "adapters of Gymnasium's own envs (CartPole-v1, InvertedPendulum-v5), not of this package's systems",
    "rmm_envs/defaults.py": "the package's default system, named once",
    "benchmarks/bench/paper_figures.py": "the paper's Figures 1 and 3, each drawn from one of its systems and its model",
}


def _names() -> re.Pattern:
    names = sorted((s.name for s in SYSTEMS), key=len, reverse=True)
    return re.compile(r"\b(?:" + "|".join(names) + r")(?:[A-Z][A-Za-z]*)?(?:-v\d+)?\b")


def code_strings(source: str) -> list[str]:
    """The identifiers and one-word string constants of a module's code (docstrings and prose
    left out)."""
    tree = ast.parse(source)
    docs = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                docs.add(id(first.value))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
            if not any(c.isspace() for c in node.value):
                out.append(node.value)
        elif isinstance(node, ast.Name):
            out.append(node.id)
        elif isinstance(node, ast.Attribute):
            out.append(node.attr)
        elif isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            out.append(node.name)
    return out


def system_names_outside_registrations() -> dict[str, list[str]]:
    """Module -> the system names its code holds, for modules that are no registration."""
    pattern = _names()
    found: dict[str, list[str]] = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if any(rel.startswith(prefix) for prefix in REGISTRATIONS):
                continue
            hits = {m.group(0) for text in code_strings(path.read_text()) for m in pattern.finditer(text)}
            if hits:
                found[rel] = sorted(hits)
    return found


def test_the_scan_reads_code_not_docstrings():
    source = (
        '"""Dubins3DMaze-v0 in a docstring."""\n'
        'X = "QuadrotorRoomParallel-v0"  # Dubins4D in a comment\n'
        'raise ValueError("not for CartPole-v1")\n'
    )
    assert code_strings(source) == ["X", "QuadrotorRoomParallel-v0", "ValueError"]
    assert _names().findall("QuadrotorRoomParallel-v0 Dubins4DGuardedEnv CartPoleX") == [
        "QuadrotorRoomParallel-v0",
        "Dubins4DGuardedEnv",
        "CartPoleX",
    ]


def test_a_system_is_named_only_where_it_is_registered():
    found = system_names_outside_registrations()
    assert not found, (
        "a system named outside its folder and the registrations "
        f"({', '.join(REGISTRATIONS)}): {found}; read it from its spec (rmm_envs.catalog) instead"
    )
