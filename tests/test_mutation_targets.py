"""mutation/targets.toml names tests that exist: a renamed test must not break `make mutate`'s
stats run (mutmut refuses the whole target when one node id is not found)."""

from __future__ import annotations

import ast

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from tests.layout import ROOT


def _functions(path):
    tree = ast.parse(path.read_text())
    return {n.name for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}


def test_every_test_a_mutation_target_names_exists():
    targets = tomllib.loads((ROOT / "mutation" / "targets.toml").read_text())["targets"]
    missing = []
    for name, target in targets.items():
        for item in target["tests"]:
            if not item.startswith("tests/"):
                continue  # a pytest option (-k ...)
            path, _, node = item.partition("::")
            if not (ROOT / path).is_file():
                missing.append(f"{name}: {path}")
            elif node and node.split("[")[0].split("::")[-1] not in _functions(ROOT / path):
                missing.append(f"{name}: {item}")
    assert missing == []
