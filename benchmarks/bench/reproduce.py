"""``rmm-bench reproduce``: rerun the commands behind published tables and check their numbers.

Offers :func:`fingerprint`, :func:`expected_rates` and the checks; the command line is
:mod:`rmm_bench.reproduce_command`; the manifests are read by :mod:`rmm_bench.manifest` and
printed into the docs by :mod:`rmm_bench.reproduce_docs`.

``--quick --check`` reruns the manifests' quick versions (a few episodes per agent under the
fixed clock, or a small dataset) and requires each fingerprint bit for bit.  A full ``--check``
reruns a manifest's ``rmm-bench`` commands and compares each published rate (a reference
manifest's ``[[expect]]``, a table manifest's ``[check]`` cells) with the rate measured
(:func:`_check_rates`: exactly under a fixed clock, within an interval under the wall clock) and
each ``[[ratio]]`` within its factor; manifests with neither (training runs, timings) are listed
as not rerun.
"""

from __future__ import annotations

import hashlib
import json
import re
import shlex
import sqlite3
import sys
from pathlib import Path

from rmm_bench.cli import main
from rmm_bench.manifest import COLUMNS, MANIFESTS, Manifest, load_manifests, rmm_bench_args
from rmm_bench.metrics import aggregate
from rmm_bench.paired import newcombe_unpaired
from rmm_bench.reference import reference_dbs
from rmm_bench.runner import TIMING_COLUMNS, is_timing_stat
from rmm_bench.store import ResultsStore
from rmm_envs.risk.datagen import main as datagen

__all__ = [
    "MANIFESTS",
    "Manifest",
    "expected_rates",
    "fingerprint",
    "load_manifests",
]

# ---------------------------------------------------------------- fingerprints


def _canonical_rows(db: Path, episodes: int | None = None) -> dict[str, list]:
    """Per agent, its rows in episode order (the first ``episodes`` when given) with the timing
    columns and timing statistics left out (what is the same on every machine under a fixed
    clock)."""

    con = sqlite3.connect(f"{db.resolve().as_uri()}?mode=ro", uri=True)
    try:
        cur = con.execute(
            "SELECT * FROM episodes WHERE episode < ? ORDER BY agent, episode",
            (episodes if episodes is not None else 1 << 62,),
        )
        names = [d[0] for d in cur.description]
        out: dict[str, list] = {}
        for values in cur:
            row = dict(zip(names, values, strict=True))
            stats = json.loads(row.get("guardian_stats") or "{}")
            row["guardian_stats"] = {k: v for k, v in sorted(stats.items()) if not is_timing_stat(k)}
            for col in list(row):
                if col in TIMING_COLUMNS or col in ("run_key",):
                    row.pop(col)
            out.setdefault(row["agent"], []).append(row)
        return out
    finally:
        con.close()


def fingerprint(db: Path, episodes: int | None = None) -> dict[str, str]:
    """Agent -> the first 16 hex digits of the SHA-256 of its canonical rows (:func:`_canonical_rows`;
    ``episodes``: of the first ones only, as a quick version runs them)."""
    return {
        agent: hashlib.sha256(json.dumps(rows, sort_keys=True, default=repr).encode()).hexdigest()[:16]
        for agent, rows in _canonical_rows(db, episodes).items()
    }


def quick_episodes(m: Manifest) -> int:
    """How many episodes the quick version runs (its commands' largest ``--episodes``)."""
    return max(int(c[c.index("--episodes") + 1]) for c in m.quick_commands if "--episodes" in c)


def _first_difference(db: Path, agent: str) -> str:
    rows = _canonical_rows(db).get(agent, [])
    return f"{len(rows)} episodes; replay one with rmm-bench replay DIR --agent {agent} --episode 0"


# ---------------------------------------------------------------- running


def _run(commands: list[list[str]], out: Path) -> None:

    for command in commands:
        code = main([*command, "--out", str(out), "--no-progress", "--no-figure"])
        if code != 0:
            raise RuntimeError(f"rmm-bench {' '.join(command)} exited with {code}")


def check_quick(m: Manifest, out: Path) -> list[str]:
    """Rerun ``m``'s quick version into ``out``; the mismatches with its fingerprints (none: it
    reproduces)."""
    got = _quick_fingerprints(m, out)
    problems = []
    for agent in sorted(set(got) | set(m.fingerprints)):
        if got.get(agent) != m.fingerprints.get(agent):
            where = (
                f"the dataset in {out / 'data'}" if agent == "dataset" else _first_difference(out / "results.db", agent)
            )
            problems.append(
                f"{m.name}: {agent}: fingerprint {got.get(agent)} (expected {m.fingerprints.get(agent)}), {where}"
            )
    return problems


def _quick_fingerprints(m: Manifest, out: Path) -> dict[str, str]:
    """Run the quick version: each agent's fingerprint of the ``rmm-bench`` runs, and the
    ``"dataset"``'s (the first 16 hex digits of its SHA-256, as ``rmm-datagen`` records it)."""
    got: dict[str, str] = {}
    if m.quick_commands:
        _run(m.quick_commands, out)
        got.update(fingerprint(out / "results.db"))
    if m.quick_datagen:
        got["dataset"] = _datagen_fingerprint(m.quick_datagen, out / "data")
    return got


def _datagen_fingerprint(args: list[str], out: Path) -> str:
    import shutil

    if out.exists():
        shutil.rmtree(out)
    code = datagen([*args, "--out", str(out), "--no-progress"])
    if code != 0:
        raise RuntimeError(f"rmm-datagen {' '.join(args)} exited with {code}")
    return str(json.loads((out / "manifest.json").read_text())["dataset_sha256"])[:16]


def check_full(m: Manifest, out: Path) -> list[str]:
    """Rerun ``m``'s commands into ``out`` and compare: the published rates with the rates
    measured (:func:`_check_rates`), and the speed ratios within their factors (none: it
    reproduces).  Each run goes into a folder of its own, which must not hold results yet (a
    check never resumes old rows)."""
    problems: list[str] = []
    jobs: list[tuple[list[list[str]], Path, set[int] | None, set[str] | None]] = []
    if m.kind == "table" and m.check.get("commands"):
        for k, line in enumerate(m.check["commands"]):
            args = rmm_bench_args(m.path, line, f"[check] row {k + 1}") if line else None
            if args is not None:
                jobs.append(([args], out / f"row-{k + 1}", {k}, None))
    elif m.kind == "table" and m.check.get("columns"):
        for k, (col, line) in enumerate(m.check["columns"].items()):
            args = rmm_bench_args(m.path, line, f"[check] columns {col!r}")
            if args is not None:
                jobs.append(([args], out / f"column-{k + 1}", None, {col}))
    elif m.commands and (m.kind != "table" or m.check):
        jobs.append((m.commands, out, None, None))
    cells = len(expected_rates(m))
    for commands, folder, rows, columns in jobs:
        if (folder / "results.db").exists():
            problems.append(f"{m.name}: {folder} already holds results; a full check reruns: give an empty --out")
            continue
        try:
            _run(commands, folder)
        except RuntimeError as e:
            problems.append(f"{m.name}: {e}")
            continue
        exact = all(_fixed_clock(c) for c in commands)
        problems += _check_rates(m, folder / "results.db", rows, columns, exact=exact, cells=cells)
    outputs: dict[str, tuple[int, str, str]] = {}  # a command that states two ratios runs once
    return problems + [p for r in m.ratios for p in check_ratio(m, r, outputs=outputs)]


def _fixed_clock(args: list[str]) -> bool:
    """Whether ``rmm-bench`` arguments run under a fixed clock (the default is the wall clock)."""
    for i, a in enumerate(args):
        if a == "--clock" and i + 1 < len(args):
            return args[i + 1].startswith("fixed:")
        if a.startswith("--clock="):
            return a.split("=", 1)[1].startswith("fixed:")
    return False


def check_ratio(m: Manifest, ratio: dict, root: Path | None = None, outputs: dict | None = None) -> list[str]:
    """Run a ``[[ratio]]`` entry's command (a ``python ...`` line, run by this interpreter from the
    repository's root, where the ``benchmarks`` scripts live) and compare the ratio its output
    states with the published one: it must lie within ``factor`` of it either way, since a
    ratio measured in one run moves much less than the speeds themselves between machines."""
    import subprocess

    root = root or Path(__file__).resolve().parents[2]
    argv = shlex.split(ratio["command"])
    module = argv[2] if len(argv) > 2 and argv[1] == "-m" else ""
    if module.startswith("benchmarks.") and not (root / "benchmarks").is_dir():
        return [f"{m.name}: {ratio['name']}: {ratio['command']} needs a clone of the repository (benchmarks/)"]
    outputs = {} if outputs is None else outputs
    if ratio["command"] not in outputs:
        print(f"{m.name}: running {ratio['command']}", file=sys.stderr)
        done = subprocess.run([sys.executable, *argv[1:]], cwd=root, capture_output=True, text=True, check=False)
        outputs[ratio["command"]] = (done.returncode, done.stdout, done.stderr)
    code, stdout, stderr = outputs[ratio["command"]]
    found = re.search(ratio["pattern"], stdout)
    if code != 0 or found is None:
        tail = (stderr or stdout).strip().splitlines()[-1:] or ["no output"]
        return [f"{m.name}: {ratio['name']}: {ratio['command']} exited {code} without a ratio ({tail[0]})"]
    got, value, factor = float(found.group(1)), float(ratio["value"]), float(ratio["factor"])
    if not value / factor <= got <= value * factor:
        return [
            f"{m.name}: {ratio['name']}: {got:g}x measured, the published {value:g}x allows "
            f"{value / factor:.3g}x to {value * factor:.3g}x"
        ]
    print(f"{m.name}: {ratio['name']}: {got:g}x (published {value:g}x)")
    return []


def expected_rates(m: Manifest, rows: set[int] | None = None, columns: set[str] | None = None) -> list[dict]:
    """``m``'s published rates as ``expect`` entries (agent, column, value in %): a reference
    manifest's ``[[expect]]``; a table manifest's cells of its ``[check]`` rate columns (the
    leading number of a cell such as ``75.1 ± 4.1``), rows of agent ``""`` left out (and, given
    ``rows`` or ``columns``, the cells outside them)."""
    if m.kind != "table":
        return m.expect
    out = []
    for k, (agent, row) in enumerate(zip(m.check.get("agents", []), m.rows, strict=False)):
        if rows is not None and k not in rows:
            continue
        for col, rate in m.check.get("rates", {}).items():
            if columns is not None and col not in columns:
                continue
            match = re.search(r"-?\d+(?:\.\d+)?", row[m.header.index(col)].replace("*", ""))
            if agent and match:
                out.append({"agent": agent, "column": rate, "value": float(match.group(0))})
    return out


def _rates(db: Path) -> dict[str, dict[str, tuple[float, int]]]:
    """Agent -> column -> (rate in %, episodes with a result) of the last run of each agent."""

    store = ResultsStore(db, read_only=True)
    try:
        out = {}
        for key, agent in store.db.execute("SELECT run_key, agent FROM runs ORDER BY rowid"):
            agg = aggregate(store.episodes(key))
            out[agent] = {c: (agg[f"total_{c}"], agg["episodes"] - agg["errors"]) for c in COLUMNS}
        return out
    finally:
        store.close()


def _check_rates(
    m: Manifest,
    db: Path,
    rows: set[int] | None = None,
    columns: set[str] | None = None,
    exact: bool = True,
    cells: int = 1,
) -> list[str]:
    """The published rates (of ``rows`` and ``columns``) that the run in ``db`` does not bear out.

    A fixed-clock rerun simulates the same episodes bit for bit, so its rate must be the published
    one (to the printed 0.1 point): ``exact``.  A wall-clock rerun is another sample: the
    difference between the published and the measured rate must be within its 95% interval
    (Newcombe's, for two proportions over the same number of episodes), Bonferroni-corrected
    over the manifest's ``cells`` rates so that a faithful rerun of a large table passes."""
    from scipy.stats import norm

    rates = _rates(db)
    z = float(norm.ppf(1 - 0.025 / max(1, cells)))
    problems = []
    for e in expected_rates(m, rows, columns):
        got = rates.get(e["agent"], {}).get(e["column"])
        if got is None:
            problems.append(f"{m.name}: {e['agent']}: no {e['column']} rate measured")
            continue
        rate, n = got
        if exact:
            if abs(rate - e["value"]) > 0.05 + 1e-9:
                problems.append(
                    f"{m.name}: {e['agent']} {e['column']} {rate:.1f}% over {n} episodes under the fixed clock; "
                    f"the published {e['value']}% differs (a fixed-clock rerun gives the same episodes)"
                )
            continue
        d, lo, hi = newcombe_unpaired(round(rate / 100 * n), n, round(e["value"] / 100 * n), n, z)
        if not lo <= 0 <= hi:
            problems.append(
                f"{m.name}: {e['agent']} {e['column']} {rate:.1f}% over {n} episodes; the published "
                f"{e['value']}% differs by {100 * d:+.1f} points, outside the interval [{100 * lo:.1f}, "
                f"{100 * hi:.1f}] (95%, Bonferroni over {cells} rates)"
            )
    return problems


def update(m: Manifest, out: Path) -> None:
    """Rerun the quick version and store its fingerprints in the manifest (after a change meant
    to move them); a reference manifest's ``[[expect]]`` rates are rewritten from its shipped
    results too (after they were regenerated)."""
    fps = _quick_fingerprints(m, out)
    text = m.path.read_text()
    if m.kind == "reference":
        text = _with_expects(m, text)
    block = "[quick.fingerprints]\n" + "".join(f'"{a}" = "{fp}"\n' for a, fp in sorted(fps.items()))
    if "[quick.fingerprints]" in text:
        text = re.sub(r"\[quick\.fingerprints\]\n(?:[^\[\n][^\n]*\n)*", block, text)
    else:
        text = text.rstrip() + "\n\n" + block
    m.path.write_text(text)
    m.fingerprints = fps


def _with_expects(m: Manifest, text: str) -> str:
    """``text`` (a reference manifest) with its ``[[expect]]`` entries the shipped results' rates."""

    dbs = {db.stem: db for db in reference_dbs()}
    rates = _rates(dbs[m.reference])
    entries = "".join(
        f'[[expect]]\nagent = "{agent}"\ncolumn = "{col}"\nvalue = {round(rates[agent][col][0], 1)}\n\n'
        for agent in sorted(rates)
        for col in COLUMNS
    )
    text = re.sub(r"\[\[expect\]\]\n(?:[a-z]+ = [^\n]*\n)*\n*", "", text)
    return text.replace("[quick]", entries + "[quick]", 1)
