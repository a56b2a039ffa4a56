"""Module openings stay short: each module of ``guardians`` and ``rmm_envs`` opens with what it is
and offers in at most 15 lines of docstring; longer reference goes into the class and function
docstrings, and the rationale into a decision record, ``docs/decisions/NNNN-title.md``.  Exempt:
the env modules whose docstring is the env's spec (the catalog renders them as the docs'
environment pages) and the few other Gymnasium-style specs of SPEC_OPENINGS.  Every pointer to a
decision record names one that exists, and the records' index lists every record."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIMIT = 15

#: modules whose docstring is a user-facing spec in the Gymnasium style, exempt as the env pages are:
#: path -> why (their rationale is in docs/decisions/ all the same)
SPEC_OPENINGS = {
    "rmm_envs/adapters/classic_control.py": "each adapter's spec: state, failure, controls, horizon, sampler, observation",
    "rmm_envs/adapters/mujoco_envs.py": "each adapter's spec: state, failure, controls, horizon, sampler, observation",
    "rmm_envs/envs/any_env.py": "guarded()'s spec: every argument, the controls, stepping, outcomes, labels",
    "rmm_envs/systems/dubins4d/vector.py": "the vector env's spec: spaces, autoreset, infos, clock, arguments",
}


def opening_lines(path: Path) -> int:
    doc = ast.get_docstring(ast.parse(path.read_text()), clean=False)
    return len(doc.splitlines()) if doc else 0


def spec_modules() -> set[str]:
    """The env modules whose docstring is a docs page (the env's spec)."""
    from rmm_envs.catalog import SYSTEMS

    return {s.envs[page.variants[0]].split(":")[0] for s in SYSTEMS for page in s.pages}


def test_the_counter_reads_the_docstring_only(tmp_path):
    f = tmp_path / "m.py"
    f.write_text('"""One.\n\nTwo.\n"""\n\nx = """not\nthe\nopening"""\n')
    assert opening_lines(f) == 3  # "One.", "", "Two."
    f.write_text("x = 1\n")
    assert opening_lines(f) == 0


def test_module_openings_are_short():
    spec = spec_modules()
    assert "rmm_envs.systems.dubins4d.env" in spec and len(spec) >= 7
    long = {}
    for pkg in ("guardians", "rmm_envs"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel in SPEC_OPENINGS or rel.removesuffix(".py").removesuffix("/__init__").replace("/", ".") in spec:
                continue
            n = opening_lines(path)
            if n > LIMIT:
                long[rel] = n
    assert not long, (
        f"module openings over {LIMIT} lines: {long}; say what the "
        "module is and offers, move longer reference into the class and function docstrings and the "
        "rationale into a decision record (docs/decisions/)"
    )
    missing = sorted(p for p in SPEC_OPENINGS if not (ROOT / p).exists())
    assert not missing, f"exempt modules that no longer exist (remove them): {missing}"


DECISIONS = ROOT / "docs" / "decisions"
#: a pointer to a decision record: ``docs/decisions/0004-clocks.md`` in the code, ``decisions/...``
#: or ``../decisions/...`` in the docs
POINTER = re.compile(r"decisions/(\d{4}-[\w\-]+\.md)")


def decision_records() -> set[str]:
    """The records' file names, ``NNNN-title.md``."""
    return {p.name for p in DECISIONS.glob("*.md") if re.fullmatch(r"\d{4}-[\w\-]+\.md", p.name)}


def test_a_pointer_is_found_as_written():
    text = "why: docs/decisions/0014-cbf-safety-filter.md (0015, 0016); [0001](../decisions/0001-import-names.md)."
    assert POINTER.findall(text) == ["0014-cbf-safety-filter.md", "0001-import-names.md"]


def test_every_pointer_to_a_decision_record_names_one():
    """A ``docs/decisions/NNNN-*.md`` in the code (the openings' and docstrings' pointers), in the
    tests, in the docs or in the README names a record that exists."""
    records = decision_records()
    assert "0001-import-names.md" in records and len(records) >= 20
    dangling, pointed = {}, 0
    sources = [ROOT / "README.md", ROOT / "CHANGELOG.md", ROOT / "Makefile", ROOT / "pyproject.toml"]
    for pkg, pattern in (("guardians", "*.py"), ("rmm_envs", "*.py"), ("benchmarks", "*.py"), ("tests", "*.py")):
        sources += sorted((ROOT / pkg).rglob(pattern))
    sources += sorted((ROOT / "docs").rglob("*.md")) + sorted((ROOT / "mutation").glob("*"))
    for path in sources:
        if not path.is_file():
            continue
        for name in POINTER.findall(path.read_text(errors="replace")):
            pointed += path.suffix == ".py" and path.relative_to(ROOT).parts[0] in ("guardians", "rmm_envs")
            if name not in records:
                dangling.setdefault(path.relative_to(ROOT).as_posix(), []).append(name)
    assert not dangling, f"pointers to decision records docs/decisions/ does not have: {dangling}"
    assert pointed >= 20  # the module openings point at the records of their decisions


def test_the_index_lists_every_record_once_and_nothing_else():
    index = (DECISIONS / "README.md").read_text()
    listed = re.findall(r"\]\((\d{4}-[\w\-]+\.md)\)", index)
    records = decision_records()
    assert sorted(set(listed)) == sorted(listed), "a record is listed twice in docs/decisions/README.md"
    assert set(listed) == records, (
        f"docs/decisions/README.md lists {sorted(set(listed) - records)} (no such record) and misses "
        f"{sorted(records - set(listed))}: one line per record"
    )
    numbers = sorted(name[:4] for name in records)
    assert numbers == [f"{i:04d}" for i in range(1, len(numbers) + 1)], (
        f"records are numbered 0001, 0002, ...: {numbers}"
    )


def test_every_record_states_its_context_decision_and_consequences():
    bad = {}
    for name in sorted(decision_records()):
        text = (DECISIONS / name).read_text()
        lines = text.splitlines()
        heads = {line.lstrip("#").strip() for line in lines if line.startswith("## ")}
        missing = {"Context", "Decision", "Consequences"} - heads
        if missing or not lines[0].startswith(f"# {name[:4]}: "):
            bad[name] = sorted(missing) or "the title must read '# NNNN: ...'"
        elif len(lines) > 70:
            bad[name] = f"{len(lines)} lines: a record is at most about a page"
    assert not bad, bad
