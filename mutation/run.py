"""Mutation testing of the decision-making modules: ``make mutate`` (``python mutation/run.py``).

For each target of ``mutation/targets.toml`` (default: all; name some to run only those) it
makes a scratch copy of the repository under ``build/mutate/<target>/``, writes mutmut's
configuration there (the target's files to mutate and the tests that judge them), runs
``mutmut run`` and reads back the verdict of every mutant.  Then it prints, and writes to
``build/mutate/report.md``, the score of each target and overall, and every surviving mutant
with its diff and its one-line classification from ``mutation/survivors.toml`` (equivalent,
or the test that would kill it).

Score: killed (a test failed, or the mutant ran past mutmut's timeout, which is how an
infinite loop shows) over all mutants that are not classified equivalent.  A mutant that no
selected test calls ("no tests") counts as surviving: nothing would catch it.

A mutant whose mutmut worker ended on a signal is judged again by running its tests directly
(:func:`rejudge`), under a wall-clock limit: ``TIMEOUT_MULTIPLIER`` times the time its tests took
on the unmutated code (as mutmut recorded it) plus ``TIMEOUT_CONSTANT`` seconds for pytest's
start (``--timeout`` sets one limit for all).  A mutant that runs past it counts as killed
("timeout"), as mutmut counts one that runs past its own limit; the test run's whole process
group is killed then, so that no process it started (a pool worker, a pytest-xdist worker) is
left running.  The report names every mutant killed by a time-out, and the limit it ran past.

Defaults and why: ``--jobs 2`` (the machine this is tuned for has 2 cores); each mutmut child
and the compiled kernels run single-threaded (``NUMBA_NUM_THREADS=1``, ``RMM_HJ_THREADS=1``)
so two children do not fight over the cores; every run starts from a fresh copy (``--keep``
reuses the previous copy and mutmut's cached verdicts, which is only sound when neither the
sources nor the tests changed since).

Needs the ``mutate`` extra (``pip install -e ".[test,mutate]"``).
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent
COPY_DIRS = ("rmm_envs", "guardians", "benchmarks", "tests", "docs")
COPY_FILES = ("README.md", "pyproject.toml")
SOURCE_PATHS = ["rmm_envs", "guardians", "benchmarks"]
KILLED = {1: "killed", 3: "killed", 36: "timeout", -24: "timeout", 24: "timeout", 152: "timeout", 255: "timeout"}
# everything else is not a detection: 0 survived, 5/33 no tests, None not checked, others suspicious
OTHER = {0: "survived", 5: "no tests", 33: "no tests", None: "not checked", 34: "skipped"}
# the time a mutant's tests may take, as a multiple of the time they took on the unmutated code
# plus a constant: written into mutmut's configuration, and the re-judging's limit (rejudge)
TIMEOUT_MULTIPLIER = 20.0
TIMEOUT_CONSTANT = 60.0


def load_targets(path: Path = ROOT / "mutation" / "targets.toml") -> dict:
    targets = tomllib.loads(path.read_text())["targets"]
    for name, t in targets.items():
        for key in ("mutate", "tests"):
            if not t.get(key) or not all(isinstance(x, str) for x in t[key]):
                raise ValueError(
                    f"target {name!r} of {path}: {key!r} must be a non-empty list of paths, got {t.get(key)!r}"
                )
        for f in t["mutate"]:
            if not (ROOT / f).is_file():
                raise ValueError(f"target {name!r}: {f!r} is not a file of the repository")
    return targets


SURVIVORS = ROOT / "mutation" / "survivors.toml"


def load_survivors(path: Path = SURVIVORS) -> tuple[dict[str, str], dict[str, str]]:
    """``(equivalent, to_test)``: mutant name -> one-line reason, from ``mutation/survivors.toml``."""
    if not path.exists():
        return {}, {}
    data = tomllib.loads(path.read_text())
    return dict(data.get("equivalent", {})), dict(data.get("to_test", {}))


#: Written at the top of the scratch copy's tests/conftest.py.  The wheel installs guardians/ and
#: benchmarks/bench/ as rmm_guardians and rmm_bench (pyproject's package-dir); the editable install
#: maps those names to the repository, not to the scratch copy that mutmut mutates.  mutmut names a
#: mutant by its file's path (guardians.baselines.x_f__mutmut_1) and matches it against the
#: ``__module__`` of the function it runs, so the tests must import the copy's modules under the
#: folder names: ``rmm_guardians.X`` is made the very module ``guardians.X``.  (Child processes a
#: test starts import the installed names, as before the rename they imported the folders.)
IMPORT_ALIASES = """# added by mutation/run.py: rmm_guardians.X is guardians.X of this copy, rmm_bench.X is benchmarks.bench.X
import importlib as _il
import importlib.abc as _ila
import importlib.util as _ilu
import sys as _sys


class _FolderNames(_ila.MetaPathFinder, _ila.Loader):
    names = {"rmm_guardians": "guardians", "rmm_bench": "benchmarks.bench"}
    specs = {}

    def find_spec(self, fullname, path=None, target=None):
        top, dot, rest = fullname.partition(".")
        if top not in self.names:
            return None
        real = _il.import_module(self.names[top] + dot + rest)
        return _ilu.spec_from_loader(fullname, self, is_package=hasattr(real, "__path__"))

    def create_module(self, spec):
        top, dot, rest = spec.name.partition(".")
        real = _il.import_module(self.names[top] + dot + rest)
        self.specs[spec.name] = real.__spec__  # the import machinery sets __spec__ to the alias's next
        return real

    def exec_module(self, module):  # already executed under its folder name: give its own spec back
        module.__spec__ = self.specs.pop(module.__spec__.name)


_sys.meta_path.insert(0, _FolderNames())
"""


def prepare(work: Path, target: dict, keep: bool) -> None:
    if work.exists() and not keep:
        shutil.rmtree(work)
    work.mkdir(parents=True, exist_ok=True)
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", ".hypothesis", ".pytest_cache")
    for d in COPY_DIRS:
        if (ROOT / d).is_dir():
            shutil.copytree(ROOT / d, work / d, ignore=ignore, dirs_exist_ok=True)
    for f in COPY_FILES:
        shutil.copy2(ROOT / f, work / f)
    conftest = work / "tests" / "conftest.py"
    if conftest.is_file() and not conftest.read_text().startswith(IMPORT_ALIASES):
        conftest.write_text(IMPORT_ALIASES + conftest.read_text())
    text = (work / "pyproject.toml").read_text()
    text += (
        "\n[tool.mutmut]\n"
        f"source_paths = {json.dumps(SOURCE_PATHS)}\n"
        f"only_mutate = {json.dumps(target['mutate'])}\n"
        f"pytest_add_cli_args_test_selection = {json.dumps(target['tests'])}\n"
        'pytest_add_cli_args = ["-p", "no:cacheprovider", "-p", "no:xdist"]\n'
        "use_git_change_detection = false\n"
        # a mutant's tests may take far longer than they took unmutated on a loaded shared machine
        # (or when the mutant sends a solver the long way): a generous limit, so that only a real
        # hang is a timeout, and a timeout is never the load
        f"timeout_multiplier = {TIMEOUT_MULTIPLIER}\ntimeout_constant = {TIMEOUT_CONSTANT}\n"
    )
    (work / "pyproject.toml").write_text(text)


def mutant_names(work: Path, target: dict, python: str) -> list[str]:
    """The names of the target's mutants (those of its files that ``only`` admits), as mutmut names them."""
    code = (
        "import json, sys\nfrom mutmut.mutation.file_mutation import mutate_file_contents\nout = []\n"
        "for f in sys.argv[1:]:\n    mod = f[:-3].replace('/', '.')\n"
        "    out += [mod + '.' + n for n in mutate_file_contents(f, open(f).read()).mutant_names]\n"
        "print(json.dumps(out))"
    )
    r = subprocess.run(
        [python, "-c", code, *target["mutate"]], cwd=work, capture_output=True, text=True, env=_env(), check=True
    )
    names = json.loads(r.stdout.strip().splitlines()[-1])
    only = target.get("only")  # mutants of the other functions of these files are not part of the target
    return sorted(n for n in names if not only or any(fnmatch.fnmatchcase(n, pat) for pat in only))


def verdicts(work: Path) -> dict[str, str]:
    out = {}
    for meta in sorted((work / "mutants").rglob("*.py.meta")):
        for name, code in json.loads(meta.read_text())["exit_code_by_key"].items():
            out[name] = KILLED.get(code) or OTHER.get(code, f"suspicious (exit {code})")
    return out


def recorded_tests(work: Path, name: str) -> tuple[list[str], float]:
    """The tests mutmut recorded as calling mutant ``name``'s function, and the seconds they took
    together on the unmutated code (from its ``mutants/mutmut-stats.json``)."""
    path = work / "mutants" / "mutmut-stats.json"
    stats = json.loads(path.read_text())
    try:
        tests = sorted(stats["tests_by_mangled_function_name"].get(name.partition("__mutmut_")[0], ()))
        seconds = sum(float(stats["duration_by_test"].get(t, 0.0)) for t in tests)
    except (KeyError, AttributeError, TypeError, ValueError) as e:
        raise ValueError(
            f"{path} is not mutmut 3's stats file (tests_by_mangled_function_name, duration_by_test): {e!r}"
        ) from e
    return tests, seconds


def time_limit(seconds: float, timeout: float | None = None) -> float:
    """The re-judging's wall-clock limit for tests that took ``seconds`` unmutated: ``timeout``
    when given, else ``TIMEOUT_MULTIPLIER * seconds + TIMEOUT_CONSTANT``."""
    return float(timeout) if timeout is not None else TIMEOUT_MULTIPLIER * seconds + TIMEOUT_CONSTANT


def run_limited(cmd: list[str], cwd: Path, env: dict, limit: float, log) -> int | None:
    """Run ``cmd`` in a process group of its own, its output to ``log``; its exit code, or ``None``
    when it ran past ``limit`` seconds: then (or on any error or Ctrl-C while waiting) the whole
    group is killed and reaped, so that no child of it is left running."""
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        return proc.wait(timeout=limit)
    except subprocess.TimeoutExpired:
        return None
    finally:
        if proc.returncode is None:  # still running: the group's leader is alive, so its id is the group's
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait()


def rejudge(work: Path, name: str, python: str, env: dict, timeout: float | None = None) -> tuple[str, dict]:
    """The verdict of one mutant from its tests run directly, without mutmut's forked worker, and
    how it was reached (the tests' unmutated seconds, the limit, the seconds taken).

    Used for the mutants whose worker ended on a signal (mutmut's "suspicious"): the HJ solver's
    compiled threads do not always survive the fork, which is the harness's failure, not a
    verdict.  The tests are the ones mutmut recorded as calling the mutant's function; they run
    under :func:`time_limit` (``timeout``: one limit for every mutant), and a mutant that runs
    past it is killed by a time-out ("timeout").  Their output goes to ``<work>/rejudge.log``."""
    tests, seconds = recorded_tests(work, name)
    if not tests:
        return "no tests", {"tests_s": 0.0}
    limit = time_limit(seconds, timeout)
    cmd = ["nice", "-n", "19", python, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", "-p", "no:xdist", *tests]
    t0 = time.monotonic()
    with open(work / "rejudge.log", "a") as log:
        log.write(f"\n=== {name}: {len(tests)} tests, {seconds:.1f} s unmutated, limit {limit:.0f} s\n")
        log.flush()
        code = run_limited(cmd, work / "mutants", env | {"MUTANT_UNDER_TEST": name, "PYTHONPATH": "."}, limit, log)
    how = {
        "tests_s": round(seconds, 2),
        "limit_s": round(limit, 1),
        "seconds": round(time.monotonic() - t0, 1),
        "option": timeout is not None,
    }
    if code is None:
        return "timeout", how
    return {0: "survived", 1: "killed"}.get(code, f"suspicious (pytest exit {code})"), how


def mutant_diff(work: Path, name: str, python: str) -> str:
    r = subprocess.run([python, "-m", "mutmut", "show", name], cwd=work, capture_output=True, text=True, env=_env())
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith(("+", "-")) and not ln.startswith(("+++", "---"))]
    return "\n".join(lines) if lines else r.stdout.strip()


def _env() -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "MUTANT_UNDER_TEST")}
    env.update(
        NUMBA_NUM_THREADS="1", RMM_HJ_THREADS="1", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1"
    )
    return env


def run_target(name: str, target: dict, args, equivalent: dict) -> dict:
    work = Path(args.out) / name
    prev = None
    if args.rerun_survivors:
        prev = json.loads((work / "result.json").read_text())
    prepare(work, target, args.keep or prev is not None)
    t0 = time.monotonic()
    log = work / "mutmut.log"
    env = _env() | {k: v.replace("{work}", str(work.resolve())) for k, v in target.get("env", {}).items()}
    names = mutant_names(work, target, args.python)
    if prev is not None:
        # only the survivors again, judged by the tests as they are now: mutmut must re-learn which
        # test calls which function (new tests), so its stats go; the killed stay killed
        chosen = sorted(set(prev["survived"]) | set(prev["equivalent_mutants"]))
        (work / "mutants" / "mutmut-stats.json").unlink(missing_ok=True)
    else:
        chosen = (
            names
            if not args.sample or args.sample >= len(names)
            else sorted(random.Random(0).sample(names, args.sample))
        )
    with open(log, "w") as f:
        r = subprocess.run(
            [
                "nice",
                "-n",
                str(args.nice),
                args.python,
                "-m",
                "mutmut",
                "run",
                "--max-children",
                str(args.jobs),
                *chosen,
            ],
            cwd=work,
            stdout=f,
            stderr=subprocess.STDOUT,
            env=env,
        )
    v = verdicts(work)
    rejudged = {}
    for m in chosen:
        if v.get(m, "").startswith("suspicious"):
            v[m], rejudged[m] = rejudge(work, m, args.python, env, args.timeout)
    seconds = time.monotonic() - t0
    if prev is not None:
        if "killed_mutants" in prev:
            tested = set(prev["status"]) | set(prev["equivalent_mutants"]) | set(prev["killed_mutants"])
        else:  # the same fixed-seed sample as the previous run drew
            k = prev["mutants"]
            tested = set(names if k >= len(names) else random.Random(0).sample(names, k))
        v = {m: ("killed" if m not in chosen else v.get(m, "not checked")) for m in tested}
        chosen = sorted(tested)
    else:
        v = {m: v.get(m, "not checked") for m in chosen}
    if r.returncode != 0 or not v:
        print(f"[{name}] mutmut failed (exit {r.returncode}); see {log}", file=sys.stderr)
    equiv = {m for m in v if m in equivalent}
    detected = [m for m, s in v.items() if s in ("killed", "timeout")]
    counted = [m for m in v if m not in equiv]
    survivors = sorted(m for m in counted if v[m] not in ("killed", "timeout"))
    equiv_survived = sorted(m for m in equiv if v[m] not in ("killed", "timeout"))
    killed_equiv = sorted(m for m in equiv if v[m] in ("killed", "timeout"))  # stale classification
    res = {
        "target": name,
        "files": target["mutate"],
        "tests": target["tests"],
        "seconds": round(seconds),
        "mutants": len(v),
        "of": len(names),
        "killed_mutants": sorted(m for m in detected),
        "rerun": prev is not None,
        "killed": len([m for m in detected if m not in equiv]),
        "equivalent": len(equiv),
        "survived": survivors,
        "equivalent_mutants": equiv_survived,
        "equivalent_but_killed": killed_equiv,
        "status": {m: v[m] for m in survivors},
        "exit": r.returncode,
        "timeouts": sorted(m for m in detected if v[m] == "timeout"),
        "rejudged": rejudged,
    }
    res["score"] = res["killed"] / len(counted) if counted else float("nan")
    res["diffs"] = {m: mutant_diff(work, m, args.python) for m in survivors + equiv_survived}
    (work / "result.json").write_text(json.dumps(res, indent=1))
    print(
        f"[{name}] {res['killed']}/{len(counted)} killed ({100 * res['score']:.1f}%), {len(equiv)} equivalent, "
        f"{len(survivors)} surviving; {seconds:.0f} s",
        flush=True,
    )
    return res


def _reclassify(r: dict, equivalent: dict) -> None:
    """Apply the current equivalence list to a stored result (its verdicts are unchanged)."""
    status = {**{m: "survived" for m in r["equivalent_mutants"]}, **r["status"]}
    undetected = set(status)
    r["survived"] = sorted(m for m in undetected if m not in equivalent)
    r["equivalent_mutants"] = sorted(m for m in undetected if m in equivalent)
    r["status"] = {m: status[m] for m in r["survived"]}
    unlisted = [m for m in r["equivalent_but_killed"] if m not in equivalent]  # killed, no longer listed
    r["killed"] += len(unlisted)
    r["equivalent_but_killed"] = [m for m in r["equivalent_but_killed"] if m in equivalent]
    r["equivalent"] = len(r["equivalent_mutants"]) + len(r["equivalent_but_killed"])
    counted = r["mutants"] - r["equivalent"]
    r["score"] = r["killed"] / counted if counted else float("nan")


def report(results: list[dict], equivalent: dict, to_test: dict) -> str:
    killed = sum(r["killed"] for r in results)
    counted = sum(r["mutants"] - r["equivalent"] for r in results)
    lines = [
        "| target | files | mutants | equivalent | killed | surviving | score | time (s) |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        sampled = f" of {r['of']}" if r.get("of", r["mutants"]) != r["mutants"] else ""
        lines.append(
            f"| {r['target']} | {', '.join(r['files'])} | {r['mutants']}{sampled} | {r['equivalent']} | {r['killed']} | "
            f"{len(r['survived'])} | {100 * r['score']:.1f}% | {r['seconds']} |"
        )
    lines.append(
        f"| **all** | | {sum(r['mutants'] for r in results)} | {sum(r['equivalent'] for r in results)} | "
        f"{killed} | {counted - killed} | **{100 * killed / max(counted, 1):.1f}%** | "
        f"{sum(r['seconds'] for r in results)} |"
    )
    for r in results:
        timeouts = r.get("timeouts", [])
        if r["survived"] or r["equivalent_mutants"] or r["equivalent_but_killed"] or timeouts:
            lines.append(f"\n### {r['target']}\n")
        for m in timeouts:
            how = r.get("rejudged", {}).get(m)
            if how is None:
                limit = "it ran past mutmut's own time limit"
            else:
                rule = (
                    "--timeout"
                    if how.get("option")
                    else f"{TIMEOUT_MULTIPLIER:g} x {how['tests_s']:g} s unmutated + {TIMEOUT_CONSTANT:g} s"
                )
                limit = (
                    f"its tests ran past the re-judging's limit of {how['limit_s']:g} s ({rule}) and their process "
                    "group was killed"
                )
            lines.append(f"- `{m}` killed by a time-out: {limit}")
        for m in r["survived"]:
            why = f"to test: {to_test[m]}" if m in to_test else "UNCLASSIFIED (add it to mutation/survivors.toml)"
            lines.append(f"- `{m}` ({r['status'][m]}) {why}\n\n```diff\n{r['diffs'][m]}\n```")
        for m in r["equivalent_mutants"]:
            lines.append(f"- `{m}` equivalent: {equivalent[m]}\n\n```diff\n{r['diffs'][m]}\n```")
        for m in r["equivalent_but_killed"]:
            lines.append(f"- `{m}` is listed as equivalent but a test kills it: remove it from mutation/survivors.toml")
    return "\n".join(lines) + "\n"


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"--timeout must be a finite number of seconds above 0, got {text!r}")
    return value


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("targets", nargs="*", help="targets of mutation/targets.toml (default: all)")
    p.add_argument("--jobs", type=int, default=2, help="mutants tested at once (default 2)")
    p.add_argument("--nice", type=int, default=19, help="niceness of the runs (default 19: a shared machine)")
    p.add_argument("--out", default=str(ROOT / "build" / "mutate"), help="scratch folder (default build/mutate)")
    p.add_argument(
        "--sample",
        type=int,
        default=0,
        help="test only this many of each target's mutants, drawn at random with a fixed seed (default 0: all)",
    )
    p.add_argument(
        "--rerun-survivors",
        action="store_true",
        help="re-test only the previous run's survivors with the current tests (after adding tests)",
    )
    p.add_argument(
        "--timeout",
        type=_seconds,
        default=None,
        help="wall-clock limit in seconds of the direct re-judging of a mutant whose mutmut worker ended on "
        f"a signal; past it the mutant counts as killed (timeout) (default: {TIMEOUT_MULTIPLIER:g} x the "
        f"time its tests took unmutated + {TIMEOUT_CONSTANT:g} s)",
    )
    p.add_argument("--keep", action="store_true", help="reuse the previous scratch copy and mutmut's cached verdicts")
    p.add_argument("--python", default=sys.executable, help="python with mutmut and the test extra (default: this one)")
    p.add_argument(
        "--report-only",
        action="store_true",
        help="run nothing: rebuild the report from the targets' last results (build/mutate/<target>/result.json)",
    )
    args = p.parse_args(argv)
    targets = load_targets()
    unknown = [t for t in args.targets if t not in targets]
    if unknown:
        p.error(f"unknown targets {unknown}; known: {sorted(targets)}")
    equivalent, to_test = load_survivors()
    names = args.targets or list(targets)
    if args.report_only:
        results = [
            json.loads((Path(args.out) / n / "result.json").read_text())
            for n in names
            if (Path(args.out) / n / "result.json").exists()
        ]
        for r in results:  # the classification may have changed since the run
            _reclassify(r, equivalent)
    else:
        results = [run_target(n, targets[n], args, equivalent) for n in names]
    text = report(results, equivalent, to_test)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "report.md").write_text(text)
    (Path(args.out) / "report.json").write_text(json.dumps(results, indent=1))
    print(text)
    return 0 if all(r["exit"] == 0 for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
