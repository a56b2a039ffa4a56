"""mutation/run.py's direct re-judging of a mutant (the path taken when mutmut's worker ends on a
signal): its tests run under a wall-clock limit, a mutant that runs past it counts as killed by a
time-out, and the test run's whole process group goes with it.

The mutants are planted by hand in the layout mutmut leaves in a target's scratch copy: the
mutated module under ``mutants/`` choosing its variant from ``MUTANT_UNDER_TEST`` (as mutmut's
trampoline does), the tests beside it, and ``mutants/mutmut-stats.json`` recording which test
calls which function and how long it took unmutated."""

from __future__ import annotations

import importlib.util
import json
import os
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def run():
    spec = importlib.util.spec_from_file_location("mutation_run", ROOT / "mutation" / "run.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


PLANTED = """\
import os
import subprocess
import sys
import time


def f():
    which = os.environ.get("MUTANT_UNDER_TEST")
    if which == "planted.x_f__mutmut_1":  # hangs, with a child process of its own
        # for two minutes, forever as far as a limit of seconds goes (bounded so that a re-judging
        # without a limit fails this test after two minutes rather than hanging it)
        child = subprocess.Popen([sys.executable, "-c", "import time\\ntime.sleep(120)"])
        with open(os.environ["PLANTED_PIDS"], "w") as out:
            out.write(f"{os.getpid()} {child.pid}")
        end = time.monotonic() + 120
        while time.monotonic() < end:
            time.sleep(0.01)
    if which == "planted.x_f__mutmut_2":  # the same value another way: survives
        return 1 + 1
    if which == "planted.x_f__mutmut_3":  # another value: killed
        return 3
    return 2
"""


@pytest.fixture
def work(tmp_path):
    mutants = tmp_path / "mutants"
    (mutants / "tests").mkdir(parents=True)
    (mutants / "planted.py").write_text(PLANTED)
    (mutants / "tests" / "test_planted.py").write_text(
        "from planted import f\n\n\ndef test_f():\n    assert f() == 2\n"
    )
    (mutants / "mutmut-stats.json").write_text(
        json.dumps(
            {
                "tests_by_mangled_function_name": {"planted.x_f": ["tests/test_planted.py::test_f"]},
                "duration_by_test": {"tests/test_planted.py::test_f": 0.25},
            }
        )
    )
    return tmp_path


def _env(tmp_path) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "MUTANT_UNDER_TEST")}
    # the planted tests need no plugin: a quicker start
    return env | {"PLANTED_PIDS": str(tmp_path / "pids"), "PYTEST_DISABLE_PLUGIN_AUTOLOAD": "1"}


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie waiting for its new parent to reap it."""
    stat = Path(f"/proc/{pid}/stat")
    if stat.parent.parent.is_dir() and Path("/proc/self").exists():
        try:
            return stat.read_text().rpartition(")")[2].split()[0] != "Z"
        except FileNotFoundError:
            return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_a_mutant_that_loops_forever_is_killed_by_a_time_out_with_its_children(run, work):
    env = _env(work)
    t0 = time.monotonic()
    assert run.rejudge(work, "planted.x_f__mutmut_2", sys.executable, env)[0] == "survived"
    start = time.monotonic() - t0  # pytest's start and one passing test: the loop's limit is a few times that
    verdict, how = run.rejudge(work, "planted.x_f__mutmut_3", sys.executable, env)
    assert verdict == "killed" and how["tests_s"] == 0.25 and how["limit_s"] == 20 * 0.25 + 60
    limit = max(4.0, 3 * start)
    t0 = time.monotonic()
    verdict, how = run.rejudge(work, "planted.x_f__mutmut_1", sys.executable, env, timeout=limit)
    took = time.monotonic() - t0
    assert verdict == "timeout" and how["limit_s"] == round(limit, 1) and how["option"]
    assert limit <= took < limit + 15
    pids = [int(p) for p in (work / "pids").read_text().split()]  # the test run and the child it started
    deadline = time.monotonic() + 5
    while any(_running(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(_running(p) for p in pids)
    log = (work / "rejudge.log").read_text()
    assert "=== planted.x_f__mutmut_1: 1 tests, 0.2 s unmutated, limit" in log and "1 passed" in log


def test_the_limit_is_a_multiple_of_the_unmutated_time_plus_a_constant_or_the_option(run, work):
    assert run.time_limit(0.0) == 60.0 and run.time_limit(2.5) == 110.0
    assert run.time_limit(2.5, timeout=7) == 7.0
    assert run.recorded_tests(work, "planted.x_f__mutmut_9") == (["tests/test_planted.py::test_f"], 0.25)
    assert run.recorded_tests(work, "other.x_g__mutmut_1") == ([], 0)
    assert run.rejudge(work, "other.x_g__mutmut_1", sys.executable, _env(work))[0] == "no tests"
    (work / "mutants" / "mutmut-stats.json").write_text(json.dumps({"duration_by_test": {}}))
    with pytest.raises(
        ValueError, match=r"mutmut-stats.json is not mutmut 3's stats file .*tests_by_mangled_function_name"
    ):
        run.recorded_tests(work, "planted.x_f__mutmut_1")


@pytest.mark.parametrize("bad", ["0", "-3", "nan", "inf", "soon"])
def test_a_timeout_that_is_not_a_positive_number_of_seconds_is_refused(run, bad, capsys):
    with pytest.raises(SystemExit) as e:
        run.main(["--timeout", bad, "--report-only"])
    assert e.value.code == 2
    assert f"--timeout must be a finite number of seconds above 0, got {bad!r}" in capsys.readouterr().err


def test_the_report_names_each_mutant_killed_by_a_time_out_and_its_limit(run):
    res = {
        "target": "planted",
        "files": ["planted.py"],
        "mutants": 3,
        "of": 3,
        "equivalent": 0,
        "killed": 2,
        "survived": ["planted.x_f__mutmut_2"],
        "status": {"planted.x_f__mutmut_2": "survived"},
        "equivalent_mutants": [],
        "equivalent_but_killed": [],
        "score": 2 / 3,
        "seconds": 9,
        "diffs": {"planted.x_f__mutmut_2": "-    return 2\n+    return 1 + 1"},
        "timeouts": ["planted.x_f__mutmut_1", "planted.x_g__mutmut_4"],
        "rejudged": {"planted.x_f__mutmut_1": {"tests_s": 0.25, "limit_s": 65.0, "seconds": 65.3, "option": False}},
    }
    text = run.report([res], {}, {})
    assert "| planted | planted.py | 3 | 0 | 2 | 1 | 66.7% | 9 |" in text
    assert (
        "- `planted.x_f__mutmut_1` killed by a time-out: its tests ran past the re-judging's limit of 65 s "
        "(20 x 0.25 s unmutated + 60 s) and their process group was killed"
    ) in text
    assert "- `planted.x_g__mutmut_4` killed by a time-out: it ran past mutmut's own time limit" in text
    assert "- `planted.x_f__mutmut_2` (survived) UNCLASSIFIED" in text
    res["rejudged"]["planted.x_f__mutmut_1"] |= {"limit_s": 7.0, "option": True}
    assert (
        "- `planted.x_f__mutmut_1` killed by a time-out: its tests ran past the re-judging's limit of 7 s "
        "(--timeout) and their process group was killed"
    ) in run.report([res], {}, {})
