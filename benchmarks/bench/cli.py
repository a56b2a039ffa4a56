"""``rmm-bench``: run guardians over seeded episodes and reproduce the paper's Table I.

    rmm-bench --agent lrmm --episodes 2048                 # run (the default command)
    rmm-bench --agent all --episodes 64                    # every guardian at its defaults
    rmm-bench --agent paper --episodes 64                  # the paper's agents with the paper's rules
    rmm-bench --agent lrmm,cbf --clock fixed:2             # reproducible: every decision takes 2 ms
    rmm-bench --agent mypkg.guard:MyGuardian               # a third-party guardian
    rmm-bench report results/                              # rebuild Table I: every agent of the newest configuration
    rmm-bench replay results/ --agent lrmm --episode 17    # re-simulate a stored episode and verify its row
    rmm-bench compare results/ --agents lrmm,cbf           # paired comparison on the episodes both ran
    rmm-bench --agent lrmm --shard 1/2 --out part1         # one machine's share; then: rmm-bench merge all part1 part2
    rmm-bench export results/ --format parquet             # the episodes in a documented, versioned schema
    rmm-bench reproduce --quick --check                    # rerun small versions of the published tables
    rmm-bench --agent lrmm --episodes 2048 --retry-errors  # after fixing a guardian: rerun its error episodes
    rmm-bench sweep --agent lrmm,cbf --latency 0,1,5,20,50 # collision rate against decision latency
    rmm-bench riskmap --seed 3                             # the paper's Fig. 1 (a maze, by inferred risk)
    rmm-bench quadrisk --seed 1                            # the paper's Fig. 3 (the quadrotor, by inferred risk)

Results go to ``--out`` (default ``results/``): ``results.db`` (SQLite: every episode and run),
``table_I.md``/``.csv``/``.tex`` and ``outcomes.png`` (rates and compute time against collisions);
a sweep writes ``latency_sweep.md`` and ``latency_sweep.png`` (``--no-figure``: the tables only;
``rmm-bench report DIR`` draws a run's figure later, a sweep's comes with its rerun without the
flag).  Rerunning the same command,
or adding ``--resume``, finishes an interrupted run without repeating stored episodes.

Environments (``--env``): any registered env offering the parallel-autonomy contract (an
action ``active_ctrl`` choosing between the built-in driver and the guardian's control, a
``clock`` argument timing the guardian, and the episode statistics in the last step's info;
described in ``rmm_bench.checks``): ``Dubins4DParallel-v0`` (default, non-blocking: the
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
import sys

from rmm_bench import args as _args
from rmm_bench.run import RunFailed, cmd_run, cmd_sweep
from rmm_bench.store import ResultsDatabaseError
from rmm_envs.failures import describe_os_error
from rmm_envs.user_modules import user_folders

__all__ = ["SUBCOMMANDS", "build_parser", "build_replay_parser", "build_report_parser", "build_sweep_parser", "main"]

#: Subcommands that live in a module of their own: name -> module, which offers ``build_parser()``
#: (its ``argparse`` parser, for ``--help`` and docs/cli.md) and ``cmd(argv) -> int`` (the exit status).
SUBCOMMANDS = {
    "compare": "rmm_bench.compare",
    "merge": "rmm_bench.merge",
    "export": "rmm_bench.export",
    "reproduce": "rmm_bench.reproduce",
    "check-system": "rmm_bench.check_system",
    "tune": "rmm_bench.tune",
    "calibrate": "rmm_bench.calibration",
    "knob-sweep": "rmm_bench.knob_sweep",
    "collisions": "rmm_bench.collisions",
}


def build_parser():
    return _args.run_parser(__doc__)


def build_report_parser():
    return _args.report_parser()


def build_replay_parser():
    return _args.replay_parser()


def build_sweep_parser():
    return _args.sweep_parser()


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        # module:Class, module:Id and an option's module:Name are found here, after the installed packages
        with user_folders([os.getcwd()]):
            return _command(argv)
    except KeyboardInterrupt:  # a run says what it saved and returns 130 itself; anywhere else, one line
        what = argv[0] if argv and (argv[0] in SUBCOMMANDS or argv[0] in _OWN) else "run"
        print(f"rmm-bench: interrupted (Ctrl-C) during {what}; rerun the same command to finish", file=sys.stderr)
        return 130


#: the subcommands this module dispatches itself (besides SUBCOMMANDS')
_OWN = ("report", "replay", "riskmap", "quadrisk", "sweep", "run")


def _command(argv: list[str]) -> int:
    try:
        if argv and argv[0] == "report":
            from rmm_bench.report import cmd_report

            return cmd_report(_args.parse_report(argv[1:]))
        if argv and argv[0] == "replay":
            from rmm_bench.replay import cmd_replay

            return cmd_replay(_args.parse_replay(argv[1:]))
        if argv and argv[0] in SUBCOMMANDS:
            import importlib

            return int(importlib.import_module(SUBCOMMANDS[argv[0]]).cmd(argv[1:]))
        if argv and argv[0] in ("riskmap", "quadrisk"):
            from rmm_bench.figures import main as figure

            return figure(argv)
        if argv and argv[0] == "sweep":
            return cmd_sweep(_args.parse_sweep(argv[1:]), argv)
        if argv and argv[0] == "run":
            argv = argv[1:]
        return cmd_run(_args.parse_run(argv, __doc__), argv)
    except RunFailed as e:
        print(f"rmm-bench: error: {e}", file=sys.stderr)
        return 1
    except ResultsDatabaseError as e:  # one line, the cause told apart; 2 or 1 as the cause says
        print(f"rmm-bench: error: {e}", file=sys.stderr)
        return e.status
    except OSError as e:  # a full disk, a file-size limit, an unwritable --out, an unreachable Ray cluster
        message, status = describe_os_error(e)
        print(f"rmm-bench: error: {message}", file=sys.stderr)
        return status
    except (ValueError, RuntimeError, LookupError) as e:
        print(f"rmm-bench: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
