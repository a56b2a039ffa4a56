"""``rmm-bench run``: run guardians over seeded episodes and reproduce the paper's Table I.

    rmm-bench --agent lrmm --episodes 2048                 # the same as rmm-bench run --agent lrmm ...
    rmm-bench --agent all --episodes 64                    # every guardian at its defaults
    rmm-bench --agent paper --episodes 64                  # the paper's agents with the paper's rules
    rmm-bench --agent lrmm,cbf --clock fixed:2             # reproducible: every decision takes 2 ms
    rmm-bench --agent mypkg.guard:MyGuardian               # a third-party guardian
    rmm-bench --agent lrmm --shard 1/2 --out part1         # one machine's share; then: rmm-bench merge part1 part2 --out all
    rmm-bench --agent lrmm --episodes 2048 --retry-errors  # after fixing a guardian: rerun its error episodes
    rmm-bench --agent lrmm --env-opt n_obstacles=3         # an argument of the env's constructor

Env options (``--env-opt KEY=JSON``, repeatable): arguments of the env's constructor, stored in
the run's configuration (``env_kwargs``, beside the clock), so they key the run and a replay
rebuilds the same env; a run without them keeps the key it always had.  A value that is not
JSON, or an argument the env does not take, is refused in one line (exit 2).

Results go to ``--out`` (default ``results/``): ``results.db`` (SQLite: every episode and run),
``table_I.md``/``.csv``/``.tex`` and ``outcomes.png`` (rates and compute time against collisions);
a sweep writes ``latency_sweep.md`` and ``latency_sweep.png`` (``--no-figure``: the tables only;
``rmm-bench report DIR`` draws a run's figure later, a sweep's comes with its rerun without the
flag).  Rerunning the same command,
or adding ``--resume``, finishes an interrupted run without repeating stored episodes.

Environments (``--env``): any registered env offering the parallel-autonomy contract (an
action ``active_ctrl`` choosing between the built-in driver and the guardian's control, a
``clock`` argument timing the guardian, and the episode statistics in the last step's info;
described in ``rmm_bench.run_checks``): ``Dubins4DParallel-v0`` (default, non-blocking: the
guardian's compute time passes in the world) and ``Dubins4DGuarded-v0`` (blocking), the maze car's
``Dubins3DMazeParallel-v0`` / ``Dubins3DMazeGuarded-v0``, the quadrotor's ``QuadrotorRoomParallel-v0`` /
``QuadrotorRoomGuarded-v0`` and the map envs ``Dubins4DMapParallel-v0`` / ``Dubins4DMapGuarded-v0`` in this
package.  Another env is refused with one line naming it and what it lacks.

Your own code: ``--agent module:Class`` (a guardian), ``--env module:Id`` (an env that
``module`` registers on import) and a ``module:Name`` in an option (a strategy of your own,
``--agent-opt 'lrmm.strategies="+my_rules:Coast"'``) are found in the current directory, in this
process and in every worker: ``rmm-bench --agent my_guard:MyGuardian`` finds ``my_guard.py``
where you run it, without ``PYTHONPATH``, and so do the modules beside it that it imports.  The
current directory comes after the installed packages and serves only the modules you name and
theirs: a ``tqdm.py`` or ``pyarrow.py`` there is never imported in place of this project's
dependencies, and a module you name that shares its name with an installed one (``numpy.py``
and ``--agent numpy:X``) is refused in one line naming both (rename yours).

Clock modes (``--clock``): ``wall`` (default, the paper's: real time between steps, scaled by
``--time-accel``, passes in the world; results depend on the machine and on how many workers
share its cores), ``cpu`` (the worker's own CPU time: insensitive to other processes) and
``fixed:MS`` (every decision takes exactly MS ms: bit-reproducible whatever the worker count).
Each worker warms every guardian up with one untimed decision before its first timed one, so
compiling (or loading compiled) code is never charged to a decision (``--charge-precompute``
charges all setup, this included).

Progress: the bar's postfix counts each agent's finished episodes by outcome, by initial: ``g``
goal, ``c`` collision, ``t`` timeout, ``e`` guardian error, ``l`` lost worker (``lrmm: c3 g20 t9``:
3 collisions, 20 goals, 9 timeouts so far).

Failures.  Every option is checked before any episode runs, including building the env and
each guardian with its ``--agent-opt`` values: a bad one exits with status 2 and one line
naming the flag.  While running, an episode whose guardian raises is stored as that
guardian's error, a result: it counts in the success, collision and timeout rates as a failure
(none of the three, so they add up to 100% less the errors' share: a guardian failing exactly
when it would intervene must not look perfect), the Errors column counts it, and the command
exits with status 1 with one line per agent naming the count and the first error;
``--retry-errors`` runs them again after a fix.  An exception the env itself raises (in its
``reset`` or ``step``, e.g. its driver) is the env's error, not the guardian's: stored as kind
``env`` with the innermost frames of its traceback (where your code raised), it has no result,
the command exits 1 with one line naming the env, and a rerun retries it.  A run is keyed on
its options and on the SHA-256 of every file it reads (a model file, given or shipped, and the
source file of the module of a ``module:Class`` agent, a ``module:Id`` env or a ``module:Name``
in an option: its own ``.py``, a package's ``__init__.py``): the same command after such a file
changed starts a new run, said in one line, instead of appending to the old one.  Files that module imports are not covered:
after editing one, run with another ``--out`` (the same seeds in a fresh database) or another
``--seed``, or change the module's own file.  An episode over ``--episode-timeout`` (default
600 s: generous, as a worker's first episode also pays for imports and, for ``hj``, a
value-function solve of tens of seconds before it is cached) or whose worker process died (out of memory, a crash, a guardian
calling ``os._exit``) is a failure of the run, not a result: it is stored with its cause, a
fresh worker takes over, and any rerun retries it.  After ``max(4, 2 x workers)`` episodes in
a row lost their worker the run stops (a cause that kills every worker, such as too little
memory, would otherwise restart workers for every remaining episode).  A run that leaves
episodes without a result exits with status 1 and says how to finish; Ctrl-C exits 130 (in any
subcommand: one line, no traceback); both keep every finished episode.  Storage failures are
told apart, one line each: an ``--out`` that is a file or cannot be written, or a read-only
``results.db``, exit 2 (change the path); a full disk, a file-size limit (``ulimit -f``) or a
database locked by another command exit 1 and keep every stored episode (rerun the same command
once fixed); only a truly damaged ``results.db`` (its integrity check fails) is to be moved
aside, after exporting what is readable, as its message says.  In short: 2 is bad input, 1 a
run that could not finish.
``rmm-bench report`` prints how many episodes each agent actually has and flags a run that was
killed (its invocation still says ``running`` but its process is gone).
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import rmm_envs
from rmm_bench import run_execute
from rmm_bench.config import BenchConfig
from rmm_bench.metrics import aggregate
from rmm_bench.names import md_cell
from rmm_bench.report import plot_latency, write_report
from rmm_bench.run_plan import applicable
from rmm_bench.store import ResultsStore

__all__ = ["cmd_run", "cmd_sweep", "done_line", "env_error_lines", "guardian_error_lines"]


def _provenance(argv) -> dict:

    rev = None
    try:
        rev = (
            subprocess.run(
                ["git", "rev-parse", "--short", "HEAD"],
                capture_output=True,
                text=True,
                timeout=5,
                cwd=Path(__file__).resolve().parent,
            ).stdout.strip()
            or None
        )
    except Exception:
        pass
    return {
        "package_version": rmm_envs.__version__,
        "git_revision": rev,
        "argv": list(argv),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
    }


def guardian_error_lines(store: ResultsStore, run_keys: dict[str, str], episodes: int) -> list[str]:
    """One line per agent whose first ``episodes`` stored episodes hold guardian errors: the
    count and the first error.  Those episodes count as failures in the rates (see
    :mod:`rmm_bench.metrics`); the command exits with status 1 so they are never missed."""
    lines = []
    for agent, key in run_keys.items():
        errs = [
            e
            for e in store.episodes(key, episodes)
            if e["outcome"] == "error" and (e["error_kind"] or "guardian") == "guardian"
        ]
        if errs:
            first = (errs[0]["error"] or "").splitlines()[0][:300] if errs[0]["error"] else "no message"
            lines.append(
                f"{agent}: {len(errs)} of {episodes} episodes ended in a guardian error, counted as failures in the "
                f"rates (first, episode {errs[0]['episode']}: {first}); fix the guardian or its --agent-opt values "
                "and rerun with --retry-errors"
            )
    return lines


def env_error_lines(store: ResultsStore, run_keys: dict[str, str], episodes: int, env_id: str) -> list[str]:
    """Up to two lines naming ``env_id`` for episodes of this command that ended in an error of
    kind ``env``: those whose worker could not make the env, and those in which the env itself
    raised (its ``reset`` or ``step``, e.g. its driver; or it ended an episode without the
    contract's statistics), each with the count and the first cause.  Failures of the run (a
    rerun retries them), never guardian errors."""
    errs = [
        e
        for key in run_keys.values()
        for e in store.episodes(key, episodes)
        if e["outcome"] == "error" and e["error_kind"] == "env"
    ]
    unmade = [e for e in errs if (e["error"] or "").startswith("EnvUnavailable")]
    raised = [e for e in errs if not (e["error"] or "").startswith("EnvUnavailable")]
    lines = []
    if unmade:
        first = (unmade[0]["error"] or "no message").splitlines()[0][:400]
        lines.append(
            f"--env {env_id}: {len(unmade)} episodes could not make the env in their worker, a failure of the run, "
            f"not of a guardian (first: {first}); make the env importable in every worker and rerun the same command"
        )
    if raised:
        first = (raised[0]["error"] or "no message").splitlines()[0][:400]
        lines.append(
            f"--env {env_id}: {len(raised)} episodes ended in an error of the env itself (its reset or step, "
            f"e.g. its driver), not of a guardian, and have no result (first, episode {raised[0]['episode']}: "
            f"{first}); fix the env (the traceback in the error column of {store.path} ends where it raised) "
            "and rerun the same command"
        )
    return lines


def _invoke(
    store: ResultsStore,
    command: str,
    config: BenchConfig,
    argv,
    meta: dict,
    record_args: dict,
    tally: dict[str, int] | None = None,
) -> tuple[int, str]:
    """Record an invocation, run it, and end it as finished, interrupted or failed (``tally``:
    :func:`execute`'s)."""
    keys = {a: r.key for a, r in config.agent_runs().items()}
    inv = store.add_invocation(command, record_args, keys, config.episodes)
    try:
        unfinished = run_execute.execute(store, config, _provenance(argv), meta, inv, tally)
    except KeyboardInterrupt:
        store.finish_invocation(inv, "interrupted", "Ctrl-C")
        raise
    except BaseException as e:
        store.finish_invocation(inv, "failed", f"{type(e).__name__}: {e}"[:1000])
        raise
    msg = run_execute.unfinished_message(unfinished, store)
    store.finish_invocation(inv, "failed" if msg else "finished", msg or None)
    return inv, msg


def _episodes(n: int) -> str:
    return f"{n} episode{'' if n == 1 else 's'}"


def done_line(reused: int, ran: int, seconds: float) -> str:
    """What a run says when it ends: the episodes it ran and how long they took, and the stored
    episodes it reused (all of them: it ran nothing, so no time is worth giving)."""
    if not ran:
        return f"reused {reused} stored episode{'' if reused == 1 else 's'}: none left to run"
    line = f"finished in {seconds:.1f} s: ran {_episodes(ran)}"
    return line + (f", reused {reused} stored" if reused else "")


def _interrupted(out: Path) -> int:
    print(
        f"\ninterrupted: finished episodes are saved in {out / 'results.db'}; rerun the same command to finish",
        file=sys.stderr,
    )
    return 130


def cmd_run(config: BenchConfig, argv) -> int:
    config, meta = applicable(config)  # every option, env and guardian checked before anything is written
    out = Path(config.out)
    store = ResultsStore(out / "results.db")
    try:
        store.mark_stale_invocations()
        t0 = time.perf_counter()
        tally: dict[str, int] = {}
        try:
            inv, msg = _invoke(store, "run", config, argv, meta, config.parsed, tally)
        except KeyboardInterrupt:
            return _interrupted(out)
        print(done_line(tally.get("reused", 0), tally.get("ran", 0), time.perf_counter() - t0))
        record = store.invocation(inv)
        write_report(store, out, record, config.batch_size, figure=config.figure)
        errors = env_error_lines(store, record["run_keys"], config.episodes, config.env_id) + guardian_error_lines(
            store, record["run_keys"], config.episodes
        )
        for line in ([msg] if msg else []) + errors:
            print(f"rmm-bench: {line}", file=sys.stderr)
        return 1 if msg or errors else 0
    finally:
        store.close()


def cmd_sweep(config: BenchConfig, argv) -> int:
    config, meta = applicable(config)  # validates the options before anything is written
    out = Path(config.out)
    store = ResultsStore(out / "results.db")
    agents, latencies = config.agents, config.latencies
    series: dict[str, list] = {a: [] for a in agents}
    lines = ["| agent | " + " | ".join(f"{x:g} ms" for x in latencies) + " |", "|---|" + "---|" * len(latencies)]
    table: dict[str, list[str]] = {a: [] for a in agents}
    failed = []
    try:
        store.mark_stale_invocations()
        for lat in latencies:
            at = config.with_clock(f"fixed:{lat:g}")
            try:
                _, msg = _invoke(store, "sweep", at, argv, meta, at.parsed | {"clock": at.clock, "latency_ms": lat})
            except KeyboardInterrupt:
                return _interrupted(out)
            keys = {a: r.key for a, r in at.agent_runs().items()}
            failed += [
                f"{lat:g} ms: {line}"
                for line in ([msg] if msg else [])
                + env_error_lines(store, keys, at.episodes, at.env_id)
                + guardian_error_lines(store, keys, at.episodes)
            ]
            for agent, run in at.agent_runs().items():
                agg = aggregate(store.episodes(run.key, at.episodes), at.batch_size)
                series[agent].append((lat, agg["collision"][0], agg["collision"][1]))
                table[agent].append(f"{agg['collision'][0]:.1f} ± {agg['collision'][1]:.1f}")
    finally:
        store.close()
    lines += [f"| {md_cell(a)} | " + " | ".join(table[a]) + " |" for a in agents]
    md = (
        f"Collision rate [% episodes] against added decision latency (fixed clock, time accel {config.parsed['time_accel']}, "
        f"{config.episodes} episodes, seed {config.seed})\n\n" + "\n".join(lines) + "\n"
    )
    (out / "latency_sweep.md").write_text(md)
    if config.figure:
        plot_latency(series, out / "latency_sweep.png")
    else:  # one from an earlier sweep would not match the table
        (out / "latency_sweep.png").unlink(missing_ok=True)
    print(md)
    if failed:
        for line in failed:
            print(f"rmm-bench sweep: {line}", file=sys.stderr)
        return 1
    return 0
