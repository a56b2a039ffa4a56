"""Build the reference results shipped in ``rmm_bench/reference`` from fixed-clock runs.

Run: ``python -m benchmarks.make_reference DIR NAME [DIR NAME ...]``, each ``DIR`` the ``--out``
of a fixed-clock run (commands in ``docs/comparing.md``), ``NAME`` the file's name
(``dubins4d`` -> ``benchmarks/bench/reference/dubins4d.db``).  For each, a copy of its database
is made portable and compact: the files each run read are named by their place in the package
(found by their SHA-256 among the installed package's files, so a run made in another checkout
is renamed correctly) and the run keys recomputed from the configurations so renamed; the
command line loses its ``--out`` folder; the doomed flags of the starts are assessed where the
env has a test; the file is migrated to the current schema and ``VACUUM``-ed.  Prints each
file's size and its runs.  The source databases are not changed.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sqlite3
import tempfile
from pathlib import Path

from rmm_bench.config import PROJECT_PACKAGES, AgentRun, file_sha256, run_key
from rmm_bench.store import ResultsStore

#: the repository's folder of the reference results (the rmm_bench.reference package's source):
#: a maintainer's tool writes into the clone, never into an installed copy of the package
REFERENCE = Path(__file__).resolve().parent / "bench" / "reference"


def _shipped_files() -> dict[str, str]:
    """SHA-256 -> package-relative name of every data file of the installed project packages."""
    import importlib.util

    out = {}
    for name in PROJECT_PACKAGES:
        spec = importlib.util.find_spec(name)
        if spec is None or spec.origin is None:
            continue
        root = Path(spec.origin).parent
        for f in root.rglob("*"):
            if f.is_file() and f.suffix in (".npz", ".json", ".urdf", ".npy"):
                out[file_sha256(f)] = f"{name}/{f.relative_to(root).as_posix()}"
    return out


def _portable_inputs(inputs: dict, shipped: dict[str, str]) -> dict:
    out = {}
    for path, digest in inputs.items():
        if path.split("/")[0] in PROJECT_PACKAGES:
            out[path] = digest
        elif digest in shipped:
            out[shipped[digest]] = digest
        else:
            raise ValueError(f"{path}: not a file of the installed package (sha256 {digest[:12]}...); cannot ship it")
    return dict(sorted(out.items()))


def make(src: Path, name: str, dest: Path = REFERENCE) -> Path:
    """Write ``dest/NAME.db`` from the results directory ``src``; returns its path."""
    from rmm_bench.run_plan import assess_starts

    shipped = _shipped_files()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp) / "results.db"
        con = sqlite3.connect(src / "results.db")
        try:
            con.execute(f"VACUUM INTO '{work}'")  # a consistent copy, whatever the source's journal
        finally:
            con.close()
        store = ResultsStore(work)  # migrated to the current schema
        try:
            db = store.db
            rename = {}
            with db:
                for key, config, provenance in db.execute("SELECT run_key, config, provenance FROM runs").fetchall():
                    config = json.loads(config)
                    if config.get("inputs"):
                        config["inputs"] = _portable_inputs(config["inputs"], shipped)
                    new = run_key(config)
                    prov = json.loads(provenance)
                    argv = list(prov.get("argv") or [])
                    if "--out" in argv and argv.index("--out") + 1 < len(argv):
                        argv[argv.index("--out") + 1] = name
                    prov["argv"] = argv
                    rename[key] = new
                    db.execute(
                        "UPDATE runs SET run_key = ?, config = ?, provenance = ? WHERE run_key = ?",
                        (new, json.dumps(config, sort_keys=True), json.dumps(prov, sort_keys=True), key),
                    )
                    for table in ("episodes", "clock_traces"):
                        db.execute(f"UPDATE {table} SET run_key = ? WHERE run_key = ?", (new, key))
                for inv_id, keys, args in db.execute("SELECT id, run_keys, args FROM invocations").fetchall():
                    keys = {a: rename.get(k, k) for a, k in json.loads(keys).items()}
                    args = json.loads(args)
                    if "out" in args:
                        args["out"] = name
                    db.execute(
                        "UPDATE invocations SET run_keys = ?, args = ?, pid = NULL, host = 'reference' WHERE id = ?",
                        (json.dumps(keys), json.dumps(args, sort_keys=True), inv_id),
                    )
            runs = {}
            for key, agent, config in db.execute("SELECT run_key, agent, config FROM runs"):
                c = json.loads(config)
                runs[agent] = AgentRun(
                    agent=agent, agent_kwargs=c["agent_kwargs"], env_id=c["env_id"], env_kwargs=c["env_kwargs"],
                    seed=c["seed"], episode_timeout=c["episode_timeout"], charge_precompute=c["charge_precompute"],
                    inputs=c.get("inputs") or {},
                )  # fmt: skip
                assert runs[agent].key == key, (agent, key)
            n = db.execute("SELECT MAX(episode) + 1 FROM episodes").fetchone()[0]
            assess_starts(store, runs, range(int(n)), progress=True)
            db.execute("VACUUM")
        finally:
            store.close()
        con = sqlite3.connect(work)  # read-only readers of a WAL file need to create its -shm beside it,
        con.execute("PRAGMA journal_mode=DELETE")  # which an installed package's folder may forbid
        con.close()
        dest.mkdir(parents=True, exist_ok=True)
        out = dest / f"{name}.db"
        shutil.copyfile(work, out)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("pairs", nargs="+", metavar="DIR NAME")
    p.add_argument("--dest", type=Path, default=REFERENCE)
    args = p.parse_args(argv)
    if len(args.pairs) % 2:
        p.error("expected pairs of DIR NAME")
    for src, name in zip(args.pairs[::2], args.pairs[1::2], strict=True):
        out = make(Path(src), name, args.dest)
        con = sqlite3.connect(out)
        agents = [r[0] for r in con.execute("SELECT agent FROM runs ORDER BY agent")]
        n = con.execute("SELECT COUNT(*) FROM episodes").fetchone()[0]
        doomed = con.execute("SELECT COUNT(*) FROM starts WHERE doomed = 1").fetchone()[0]
        con.close()
        print(
            f"{out.name}: {out.stat().st_size / 1e6:.2f} MB, {n} episodes of {', '.join(agents)}; {doomed} doomed starts"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
