"""``rmm-bench``: run guardians over seeded episodes, compare and reproduce the results.

    rmm-bench --agent lrmm --episodes 2048                 # a run: rmm-bench run, the default command
    rmm-bench --agent all --episodes 64                    # every guardian at its defaults
    rmm-bench --agent lrmm,cbf --clock fixed:2             # reproducible: every decision takes 2 ms
    rmm-bench --agent lrmm --env-opt n_obstacles=3         # an argument of the env's constructor
    rmm-bench report results/                              # rebuild Table I: every agent of the newest configuration
    rmm-bench replay results/ --agent lrmm --episode 17    # re-simulate a stored episode and verify its row
    rmm-bench compare results/ --agent lrmm,cbf            # paired comparison on the episodes both ran
    rmm-bench --agent lrmm --shard 1/2 --out part1         # one machine's share; then: rmm-bench merge part1 part2 --out all
    rmm-bench export results/ --format parquet             # the episodes in a documented, versioned schema
    rmm-bench reproduce --quick --check                    # rerun small versions of the published tables
    rmm-bench sweep --agent lrmm,cbf --latency 0,1,5,20,50 # collision rate against decision latency
    rmm-bench riskmap --world-seed 3                       # the paper's Fig. 1 (a maze, by inferred risk)

``rmm-bench COMMAND --help`` tells each command's options; ``rmm-bench run --help`` tells where
results go, the envs and clocks, your own guardians and envs, and what each exit status means
(2: bad input, 1: a run that could not finish, 130: Ctrl-C).  In every command ``DIR`` is a
results directory (a run's ``--out``), ``--agent`` chooses agents (one or a comma list),
``--out`` is a directory written into, and ``--seed`` the master seed the episodes' seeds derive from.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from rmm_bench.run_execute import RunFailed
from rmm_bench.store import ResultsDatabaseError
from rmm_envs.os_errors import describe_os_error
from rmm_envs.user_modules import user_folders

__all__ = ["DEFAULT_COMMAND", "SUBCOMMANDS", "build_parser", "command_parser", "main"]

#: Every subcommand, registered in one line: name -> (where it lives, its line in ``rmm-bench --help``).
#: ``"module"`` offers ``build_parser()`` (its argparse parser, standalone) and ``cmd(argv) -> int``
#: (the exit status); ``"module:stem"`` offers ``stem_parser()`` and ``stem_cmd(argv)`` instead.
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "run": ("rmm_bench.run_args:run", "run guardians over seeded episodes (the default)"),
    "sweep": ("rmm_bench.run_args:sweep", "collision rate against added decision latency"),
    "report": ("rmm_bench.results_args:report", "rebuild Table I and the figures of a results DIR"),
    "replay": ("rmm_bench.results_args:replay", "re-simulate stored episodes and verify their rows"),
    "compare": ("rmm_bench.compare_command", "agents compared on the episodes they all ran"),
    "merge": ("rmm_bench.merge", "join the results of several machines into one"),
    "export": ("rmm_bench.export", "the stored episodes as one versioned table"),
    "reproduce": ("rmm_bench.reproduce_command", "rerun the commands behind the published tables"),
    "check-system": ("rmm_bench.check_system", "pre-flight check of a system before labelling"),
    "tune": ("rmm_bench.tune", "choose lrmm's decision for a model of yours"),
    "calibrate": ("rmm_bench.calibration", "a model's risk against fresh labels of new worlds"),
    "knob-sweep": ("rmm_bench.knob_sweep", "collisions against interventions over one knob"),
    "collisions": ("rmm_bench.collisions", "why an agent collides: its collisions replayed and classified"),
    "ablation": ("rmm_bench.ablation", "what each of lrmm's strategies adds, on one env"),
    "model-spread": ("rmm_bench.model_spread", "lrmm's rates with models trained under other seeds"),
    "riskmap": ("rmm_bench.paper_figures:riskmap", "the paper's Fig. 1: a maze by inferred risk"),
    "quadrisk": ("rmm_bench.paper_figures:quadrisk", "the paper's Fig. 3: the quadrotor by inferred risk"),
}

#: what ``rmm-bench`` runs when its first argument is a flag, or when it has none
DEFAULT_COMMAND = "run"


def _functions(name: str):
    """The subcommand ``name``'s parser factory and command function."""
    where = SUBCOMMANDS[name][0]
    module_name, _, stem = where.partition(":")
    module = importlib.import_module(module_name)
    if stem:
        return getattr(module, f"{stem}_parser"), getattr(module, f"{stem}_cmd")
    return module.build_parser, module.cmd


def command_parser(name: str) -> argparse.ArgumentParser:
    """The subcommand ``name``'s own parser (``prog`` ``rmm-bench NAME``), as its module builds it."""
    return _functions(name)[0]()


class _TopFormatter(argparse.RawDescriptionHelpFormatter):
    """``rmm-bench --help``: every subcommand's name and its line on one line (argparse measures the
    names at one indent less than it prints them, and would wrap the longest, ``check-system``)."""

    def add_argument(self, action):
        super().add_argument(action)
        self._action_max_length = max(self._action_max_length, 4 + max(map(len, SUBCOMMANDS)) + 2)


def build_parser() -> argparse.ArgumentParser:
    """``rmm-bench``: one subparser per subcommand, each made of its module's parser (its options,
    and the parent parsers of :mod:`rmm_bench.options` that subcommands share)."""
    p = argparse.ArgumentParser(
        prog="rmm-bench",
        description=__doc__,
        formatter_class=_TopFormatter,
        usage="rmm-bench [COMMAND] [OPTIONS]   (no COMMAND: rmm-bench run)",
    )
    sub = p.add_subparsers(dest="subcommand", metavar="COMMAND", title="commands", prog="rmm-bench")
    for name, (_, summary) in SUBCOMMANDS.items():
        own = command_parser(name)
        sub.add_parser(
            name,
            help=summary,
            parents=[own],
            add_help=False,
            description=own.description,
            formatter_class=own.formatter_class,
        )
    return p


def _with_command(argv: list[str]) -> list[str]:
    """``argv`` with the default command put first when it names none: no arguments, or a flag
    first (``rmm-bench --agent lrmm`` is ``rmm-bench run --agent lrmm``); help stays the top's."""
    if not argv or (argv[0].startswith("-") and argv[0] not in ("-h", "--help")):
        return [DEFAULT_COMMAND, *argv]
    return argv


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        # module:Class, module:Id and an option's module:Name are found here, after the installed packages
        with user_folders([os.getcwd()]):
            return _command(argv)
    except KeyboardInterrupt:  # a run says what it saved and returns 130 itself; anywhere else, one line
        what = _with_command(argv)[0]
        what = what if what in SUBCOMMANDS else DEFAULT_COMMAND
        print(f"rmm-bench: interrupted (Ctrl-C) during {what}; rerun the same command to finish", file=sys.stderr)
        return 130


def _command(argv: list[str]) -> int:
    try:
        full = _with_command(argv)
        name = build_parser().parse_args(full).subcommand  # --help, a bad command or option: argparse, exit 0 or 2
        # the command parses its own arguments again, as it does run on its own (python -m)
        return int(_functions(name)[1](full[1:]))
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
    except (ValueError, RuntimeError, LookupError) as e:  # a renamed flag (rmm_bench.options) among them
        print(f"rmm-bench: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
