"""Where each installed package lives in the repository (pyproject's ``[tool.setuptools.package-dir]``).

The folders keep their names (``guardians/``, ``benchmarks/bench/``) while the wheel installs them
under this project's own import names (``rmm_guardians``, ``rmm_bench``); tests that read source
files statically map a file to its module name here.  ``tests/test_packaging.py`` checks this table
against ``pyproject.toml``.
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: import name -> the folder it is built from
PACKAGE_DIRS: dict[str, Path] = {
    "rmm_envs": ROOT / "rmm_envs",
    "rmm_guardians": ROOT / "guardians",
    "rmm_bench": ROOT / "benchmarks" / "bench",
}


def package_files(package: str) -> list[Path]:
    """Every ``.py`` file of an installed package (by its import name), sorted."""
    return sorted(PACKAGE_DIRS[package].rglob("*.py"))


def module_name(path: Path) -> str:
    """The dotted module name a source file installs as (a package's ``__init__.py`` is the package)."""
    path = path.resolve()
    for name, folder in PACKAGE_DIRS.items():
        if path.is_relative_to(folder):
            rel = path.relative_to(folder).with_suffix("").as_posix().removesuffix("__init__").strip("/")
            return ".".join([name] + ([rel.replace("/", ".")] if rel else []))
    raise ValueError(
        f"{path} is not in an installed package; expected a file under one of "
        f"{sorted(str(p.relative_to(ROOT)) for p in PACKAGE_DIRS.values())}"
    )


def module_package(path: Path) -> str:
    """The dotted package a module file belongs to (a package's ``__init__.py`` belongs to that package)."""
    name = module_name(path)
    return name if path.name == "__init__.py" else name.rpartition(".")[0]
