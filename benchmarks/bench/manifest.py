"""The manifests of the published tables: one TOML file per table, read and validated here.

Offers :class:`Manifest`, :func:`read_manifest`, :func:`load_manifests`, :func:`figures` and
:data:`MANIFESTS` (the shipped folder).  ``rmm-bench reproduce`` (:mod:`rmm_bench.reproduce`)
reruns and checks them and writes the docs' tables from them.

Two kinds.  A ``reference`` manifest names shipped results (``rmm_bench/reference/NAME.db``)
and the rates expected of them; its table is printed from those results.  A ``table`` manifest
holds its table as published (``header``, ``rows`` of printed cells, a ``note`` under it) with
the shell commands that made it and when they ran (``measured``); its optional ``[check]`` maps
rows to agents and columns to rates, so that a rerun of its ``rmm-bench`` commands is compared
with the printed rates.  Either kind may hold a ``[quick]`` version (``rmm-bench`` arguments on a
few fixed-clock episodes) with the fingerprint of every agent's rows.
"""

from __future__ import annotations

import json
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

__all__ = [
    "COLUMNS",
    "MANIFESTS",
    "Manifest",
    "figures",
    "load_manifests",
    "read_manifest",
    "clone_only",
    "in_clone",
    "rmm_bench_args",
    "table_manifest",
]

#: the folder of the shipped manifests
MANIFESTS = Path(__file__).resolve().parent / "manifests"
#: the rates a manifest can state, as Table I's aggregation names them
COLUMNS = ("goal", "collision", "timeout")
_COMMON = {"name", "kind", "title", "section", "quick"}
_KEYS = {
    "reference": _COMMON | {"reference", "commands", "expect"},
    "table": _COMMON | {"commands", "measured", "header", "rows", "note", "check", "ratio"},
}
_QUICK_KEYS = {"commands", "datagen", "fingerprints"}
_EXPECT_KEYS = {"agent", "column", "value"}
_CHECK_KEYS = {"agents", "rates", "commands", "columns"}
_RATIO_KEYS = {"name", "command", "pattern", "value", "factor"}
#: what counts as a figure in a page: a decimal, a percentage, a ratio (``12x``), a count with
#: thousands separators, or a number with a unit of time (what the guard test looks for)
_NUM = r"(?:\d{1,3}(?:,\d{3})+|\d+)(?:\.\d+)?"
_UNIT = r"(?:%|x\b|×|ns\b|ms\b|µs\b|μs\b|us\b|s\b|min\b|minutes\b|h\b|hours\b|MB\b|GB\b)"
FIGURE = re.compile(
    rf"(?<![\w.])-?{_NUM}(?:\s?(?:-|–|to)\s?{_NUM})?\s?{_UNIT}"  # with a unit, or a range with one
    r"|(?<![\w.])-?\d+(?:\.\d+)?e-?\d+(?!\w)"  # scientific notation
    r"|(?<![\w.])-?(?:\d{1,3}(?:,\d{3})+(?:\.\d+)?|\d+\.\d+)(?!\w|\.\d)"  # a decimal, a count with separators
)


@dataclass
class Manifest:
    """One published table.  ``kind`` ``"reference"``: ``reference`` names the shipped results,
    ``commands`` are ``rmm-bench`` argument lists and ``expect`` the rates (agent, column, value
    in %).  ``kind`` ``"table"``: ``shell`` holds the commands as printed, ``header``/``rows`` the
    table, ``note`` the text under it, ``measured`` when and where it ran, ``check`` the rows'
    agents and the rate columns.  Both: the ``section`` of ``docs/reproduction.md`` it belongs to,
    and the quick version: ``quick_commands`` (``rmm-bench`` arguments) and ``quick_datagen``
    (``rmm-datagen`` arguments), with ``fingerprints`` per agent and ``"dataset"``."""

    name: str
    title: str
    path: Path
    section: str
    kind: str = "reference"
    reference: str = ""
    commands: list[list[str]] = field(default_factory=list)
    quick_commands: list[list[str]] = field(default_factory=list)
    quick_datagen: list[str] = field(default_factory=list)
    fingerprints: dict[str, str] = field(default_factory=dict)
    expect: list[dict] = field(default_factory=list)
    shell: list[str] = field(default_factory=list)
    measured: str = ""
    header: list[str] = field(default_factory=list)
    rows: list[list[str]] = field(default_factory=list)
    note: str = ""
    check: dict = field(default_factory=dict)
    ratios: list[dict] = field(default_factory=list)


def _bad(path: Path, what: str) -> ValueError:
    return ValueError(f"manifest {path.name}: {what}")


def _check_keys(path: Path, table: dict, allowed: set[str], where: str) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise _bad(path, f"unknown key {unknown[0]!r} in {where} (expected {', '.join(sorted(allowed))})")


def _arg_lists(path: Path, value, where: str) -> list[list[str]]:
    if not (
        isinstance(value, list)
        and value
        and all(isinstance(c, list) and all(isinstance(a, str) for a in c) for c in value)
    ):
        raise _bad(path, f"{where} must be a list of commands, each a list of rmm-bench arguments (strings)")
    for c in value:
        if not c:
            raise _bad(path, f"{where}: an empty command")
        if any(a == "--out" or a.startswith("--out=") for a in c):
            raise _bad(path, f"{where}: leave --out out (reproduce chooses the folder)")
    return value


def rmm_bench_args(path: Path, line: str, where: str) -> list[str] | None:
    """The ``rmm-bench`` arguments of a shell command line (leading ``VAR=value`` settings and
    ``--out DIR`` left out), or ``None`` when it runs something else."""
    try:
        words = shlex.split(line)
    except ValueError as e:
        raise _bad(path, f"{where}: {line!r} is not a shell command line ({e})") from None
    while words and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*=.*", words[0]):
        words = words[1:]
    if not words or words[0] != "rmm-bench":
        return None
    args = words[1:]
    for i, a in enumerate(args):
        if a.startswith("--out="):
            return args[:i] + args[i + 1 :]
        if a == "--out":
            return args[:i] + args[i + 2 :]
    return args


def _numbers(text: str) -> set[float]:
    return {float(m.replace(",", "")) for m in re.findall(r"\d{1,3}(?:,\d{3})+(?:\.\d+)?|\d+(?:\.\d+)?", text)}


def _strings(path: Path, value, where: str) -> list[str]:
    if not (isinstance(value, list) and value and all(isinstance(s, str) and s.strip() for s in value)):
        raise _bad(path, f"{where} must be a non-empty list of strings")
    return value


def _read_table(path: Path, data: dict) -> dict:
    header = data.get("header")
    if not (isinstance(header, list) and header and all(isinstance(s, str) for s in header)):
        raise _bad(path, "header must be a non-empty list of column names (strings)")
    rows = data.get("rows")
    if not isinstance(rows, list) or not rows:
        raise _bad(path, "rows must be a non-empty list of rows, each a list of cells (strings)")
    for i, row in enumerate(rows):
        if not (isinstance(row, list) and all(isinstance(c, str) for c in row)) or len(row) != len(header):
            raise _bad(path, f"row {i + 1} must be {len(header)} cells (strings), one per header column")
    shell = _strings(path, data.get("commands"), "commands")
    check = data.get("check", {})
    if not isinstance(check, dict):
        raise _bad(path, "[check] must be a table")
    if check:
        _check_keys(path, check, _CHECK_KEYS, "[check]")
        agents = check.get("agents")
        if not (isinstance(agents, list) and len(agents) == len(rows) and all(isinstance(a, str) for a in agents)):
            raise _bad(path, f"[check] agents must be {len(rows)} names, one per row ('' for a row not ours)")
        if not any(agents):
            raise _bad(path, "[check] agents names no agent: the check would compare nothing")
        rates = check.get("rates")
        if not isinstance(rates, dict) or not rates:
            raise _bad(path, "[check] rates must map header columns to rates (goal, collision, timeout)")
        for col, rate in rates.items():
            if col not in header:
                raise _bad(path, f"[check] rates: column {col!r} is not in the header ({', '.join(header)})")
            if rate not in COLUMNS:
                raise _bad(path, f"[check] rates: {col!r} = {rate!r}, expected one of {', '.join(COLUMNS)}")
            for i, (agent, row) in enumerate(zip(agents, rows, strict=True)):
                if agent and not re.search(r"\d", row[header.index(col)]):
                    raise _bad(
                        path, f"[check] row {i + 1} ({agent}), column {col!r}: {row[header.index(col)]!r} holds no rate"
                    )
        per_column = check.get("columns")
        per_row = check.get("commands")
        if per_row is not None and per_column is not None:
            raise _bad(path, "[check] takes commands per row or per column, not both")
        if per_column is not None:
            if not isinstance(per_column, dict) or set(per_column) != set(rates):
                raise _bad(
                    path, f"[check] columns must give an rmm-bench command for each rate column ({', '.join(rates)})"
                )
            for col, line in per_column.items():
                if not isinstance(line, str) or rmm_bench_args(path, line, f"[check] columns {col!r}") is None:
                    raise _bad(path, f"[check] columns: {col!r} must be an rmm-bench command line")
        elif per_row is not None:
            if not (
                isinstance(per_row, list) and len(per_row) == len(rows) and all(isinstance(c, str) for c in per_row)
            ):
                raise _bad(
                    path, f"[check] commands must be {len(rows)} rmm-bench command lines, one per row ('' for none)"
                )
            for i, (agent, line) in enumerate(zip(agents, per_row, strict=True)):
                if bool(agent) != bool(line) or (line and rmm_bench_args(path, line, f"[check] row {i + 1}") is None):
                    raise _bad(
                        path, f"[check] row {i + 1}: an rmm-bench command for a row with an agent, '' for one without"
                    )
        elif not any(rmm_bench_args(path, c, "commands") is not None for c in shell):
            raise _bad(path, "[check] needs rmm-bench commands to rerun (the manifest's, or per row or per column)")
    ratios = data.get("ratio", [])
    if not isinstance(ratios, list):
        raise _bad(path, "[[ratio]] must be an array of tables")
    printed = " ".join(" ".join(r) for r in rows) + " " + str(data.get("note", ""))
    for i, r in enumerate(ratios):
        where = f"[[ratio]] {i + 1}"
        if not isinstance(r, dict):
            raise _bad(path, f"{where} must be a table")
        _check_keys(path, r, _RATIO_KEYS, where)
        missing = sorted(_RATIO_KEYS - set(r))
        if missing:
            raise _bad(path, f"{where}: missing key {missing[0]!r}")
        command = r["command"]
        if not (isinstance(command, str) and command.startswith("python ") and len(shlex.split(command)) >= 2):
            raise _bad(path, f"{where}: command {command!r}, expected a 'python ...' command line")
        try:
            groups = re.compile(r["pattern"]).groups
        except (re.error, TypeError) as e:
            raise _bad(path, f"{where}: pattern {r['pattern']!r} is not a regular expression ({e})") from None
        if groups != 1:
            raise _bad(path, f"{where}: pattern {r['pattern']!r} must capture the ratio in one group")
        value, factor = r["value"], r["factor"]
        if not (isinstance(value, (int, float)) and value > 0):
            raise _bad(path, f"{where}: value {value!r}, expected the published ratio (a number > 0)")
        if not (isinstance(factor, (int, float)) and factor >= 1):
            raise _bad(path, f"{where}: factor {factor!r}, expected a number >= 1 (the spread allowed either way)")
        if float(value) not in _numbers(printed):
            raise _bad(path, f"{where}: value {value:g} is not printed in the table or its note")
    return {
        "ratios": list(ratios),
        "shell": shell,
        "header": header,
        "rows": rows,
        "note": str(data.get("note", "")).strip(),
        "measured": str(data.get("measured", "")).strip(),
        "check": check,
    }


def read_manifest(path: Path) -> Manifest:
    """Read and validate one manifest file; ``ValueError`` naming the file and the bad key or value."""
    import tomllib

    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise _bad(path, f"not valid TOML ({e})") from None
    kind = data.get("kind", "reference")
    if not isinstance(kind, str) or kind not in _KEYS:
        raise _bad(path, f"kind {kind!r}, expected one of {', '.join(_KEYS)}")
    _check_keys(path, data, _KEYS[kind], "the manifest")
    required = ("name", "title", "section", "commands") + (("reference", "quick") if kind == "reference" else ())
    for key in required:
        if key not in data:
            raise _bad(path, f"missing key {key!r}")
    for key in ("name", "title", "section") + (("reference",) if kind == "reference" else ()):
        if not isinstance(data[key], str):
            raise _bad(path, f"{key} must be a string, got {data[key]!r}")
    if data["name"] != path.stem:
        raise _bad(path, f"name {data['name']!r} must be the file's name {path.stem!r}")
    quick = data.get("quick", {})
    if not isinstance(quick, dict):
        raise _bad(path, "quick must be a table")
    _check_keys(path, quick, _QUICK_KEYS, "[quick]")
    m = Manifest(name=data["name"], title=data["title"], path=path, section=data["section"], kind=kind)
    if quick:
        if "commands" in quick or "datagen" not in quick:
            m.quick_commands = _arg_lists(path, quick.get("commands"), "[quick] commands")
            if not any("--episodes" in c for c in m.quick_commands):
                raise _bad(path, "[quick] commands must say --episodes (a quick version runs a few)")
        if "datagen" in quick:
            datagen = quick["datagen"]
            if not (isinstance(datagen, list) and datagen and all(isinstance(a, str) for a in datagen)):
                raise _bad(path, "[quick] datagen must be one rmm-datagen command, a list of arguments (strings)")
            if "--out" in datagen:
                raise _bad(path, "[quick] datagen: leave --out out (reproduce chooses the folder)")
            m.quick_datagen = list(datagen)
        fingerprints = quick.get("fingerprints", {})
        if not (isinstance(fingerprints, dict) and all(isinstance(v, str) for v in fingerprints.values())):
            raise _bad(path, "[quick.fingerprints] must map agents (and 'dataset') to fingerprints (strings)")
        m.fingerprints = dict(fingerprints)
    if kind == "table":
        for key, value in _read_table(path, data).items():
            setattr(m, key, value)
        parsed = [rmm_bench_args(path, c, "commands") for c in m.shell]
        m.commands = [c for c in parsed if c is not None]
        return m
    m.reference = data["reference"]
    m.commands = _arg_lists(path, data["commands"], "commands")
    expect = data.get("expect", [])
    if not isinstance(expect, list):
        raise _bad(path, "expect must be an array of tables ([[expect]] with agent, column, value)")
    for i, entry in enumerate(expect):
        if not isinstance(entry, dict):
            raise _bad(path, f"[[expect]] {i + 1} must be a table with agent, column, value")
        _check_keys(path, entry, _EXPECT_KEYS, f"[[expect]] {i + 1}")
        if not isinstance(entry.get("agent"), str) or not entry["agent"]:
            raise _bad(path, f"[[expect]] {i + 1}: agent {entry.get('agent')!r}, expected an agent's name")
        if entry.get("column") not in COLUMNS:
            raise _bad(
                path, f"[[expect]] {i + 1}: column {entry.get('column')!r}, expected one of {', '.join(COLUMNS)}"
            )
        value = entry.get("value")
        if not isinstance(value, (int, float)) or not 0 <= value <= 100:
            raise _bad(path, f"[[expect]] {i + 1}: value {value!r}, expected a rate in % (0 to 100)")
    m.expect = list(expect)
    return m


#: a command line that runs one of the repository's development scripts, which a wheel does not install
_CLONE_ONLY = re.compile(r"^(?:[A-Za-z_][A-Za-z0-9_]*=\S*\s+)*python3?\s+-m\s+(benchmarks\.\w+)")


def in_clone(root: Path | None = None) -> bool:
    """Whether this install runs from a clone of the repository (its ``benchmarks/`` scripts
    beside this package, as an editable install has them), not from a wheel."""
    root = root or Path(__file__).resolve().parents[2]
    return (root / "benchmarks" / "bench").is_dir() and (root / "benchmarks" / "__init__.py").is_file()


def clone_only(m: Manifest) -> list[str]:
    """The development scripts (``benchmarks.NAME``) that ``m``'s commands run, each once, in
    order: a wheel does not install them, so these commands need a clone of the repository."""
    lines = [*m.shell, *m.check.get("commands", []), *(r["command"] for r in m.ratios)]
    found = [match.group(1) for line in lines if line and (match := _CLONE_ONLY.match(line.strip()))]
    return list(dict.fromkeys(found))


def load_manifests(names: list[str] | None = None, folder: Path = MANIFESTS) -> list[Manifest]:
    """The manifests of ``folder`` (all, or ``names``: each must exist)."""
    found = {p.stem: p for p in sorted(folder.glob("*.toml"))}
    for n in names or []:
        if n not in found:
            raise ValueError(f"reproduce {n}: no such manifest (expected one of: {', '.join(found) or 'none'})")
    return [read_manifest(found[n]) for n in (names or list(found))]


def figures(text: str) -> list[str]:
    """The figures of ``text`` (see :data:`FIGURE`), as printed, code spans and fenced code left out."""
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    text = re.sub(r"`[^`]+`", "", text)
    return [re.sub(r"\s", "", m.group(0)) for m in FIGURE.finditer(text)]


def _toml(value) -> str:
    """``value`` (a string, number, bool or a list or dict of them) as TOML (strings as basic
    strings: JSON's escapes are TOML's)."""
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml(v)}" for k, v in value.items()) + "}"
    return json.dumps(value, ensure_ascii=False)


def table_manifest(fields: dict, check: dict | None = None, quick: list[list[str]] | None = None) -> str:
    """The text of a ``table`` manifest (as :func:`read_manifest` reads it) from its top-level
    ``fields`` (``name``, ``title``, ``section``, ``commands``, ``measured``, ``header``, ``rows``,
    ``note``), an optional ``[check]`` table and optional quick ``commands`` (their fingerprints
    are stored by ``rmm-bench reproduce NAME --quick --update``)."""
    lines = ['kind = "table"'] + [f"{k} = {_toml(v)}" for k, v in fields.items()]
    if check:
        lines += ["", "[check]"] + [f"{k} = {_toml(v)}" for k, v in check.items()]
    if quick:
        lines += ["", "[quick]", "commands = ["] + [f"    {_toml(c)}," for c in quick] + ["]"]
    return "\n".join(lines) + "\n"
