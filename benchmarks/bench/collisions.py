"""``rmm-bench collisions DIR --agent NAME [--versus OTHER]``: why a guardian collides, measured.

Every collision of ``--agent``'s stored run (with ``--versus``: only those the other agent's
run of the same episodes avoided, paired as ``rmm-bench compare`` pairs them: same world,
clock, episode and start fingerprint) is replayed through :mod:`rmm_bench.replay` (the
runner's own episode code, verified against the stored row; an episode that does not verify
is reported as such and the command exits 1), recording after every step who was in control
and the guardian's own alarm (:meth:`rmm_guardians.base.Guardian.alarm`: ``(value,
threshold)``, up when ``value > threshold``).  Each collision falls in one class, the first
that applies:

* ``doomed``: the start was doomed (the results' ``starts`` table): no guardian could avoid it;
* ``unseen``: the alarm never went up before the last ``--last-steps`` steps before impact;
* ``failed manoeuvre``: it went up in time and the guardian was in control at impact;
* ``released``: it went up in time, the guardian took control after it and had handed control
  back to the driver at impact;
* ``alarm ignored``: it went up in time and the guardian never took control after it (a rule
  beyond the alarm held it back).

A guardian without an alarm (``alarm()`` absent or ``None``: a third-party guardian, a
baseline) is classified by who was in control alone: its first step in control stands for its
alarm.  Each episode also gets the simulated time from the first crossing to impact (measured
from the start of the step whose decision first raised the alarm) and the highest alarm value
before the last steps; with ``--versus``, the other agent's outcome and its first alarm
(simulated time) in its replay of the same episode, which is verified too.

The database is opened read-only; bad input (a missing directory, an agent not stored, no
collision to classify, a ``--versus`` agent that ran none of the episodes) is one line naming
the value, exit 2.  ``docs/cli.md`` describes the output.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import asdict
from pathlib import Path

from rmm_bench.collision_classes import (
    AVOIDED,
    CLASSES,
    UNVERIFIED,
    AlarmLog,
    Selection,
    Verdict,
    _verdict,
    classify,
    versus_lead,
)
from rmm_bench.collision_tables import to_csv, to_json, to_markdown
from rmm_bench.consent import check_inputs, consented_imports
from rmm_bench.names import did_you_mean
from rmm_bench.outputs import check_output, write_output
from rmm_bench.replay_env import build_env, check_guardian
from rmm_bench.replay_plan import ReplayRequest, _select_run, plan_replay
from rmm_bench.replay_verify import replay_episode
from rmm_bench.store import ResultsStore, results_database
from rmm_envs.starts import world_key

__all__ = ["CLASSES", "AlarmLog", "Verdict", "build_parser", "classify", "classify_collisions", "cmd"]


def _request(dir: Path, agent: str, episodes, args):
    return ReplayRequest(
        dir=dir,
        agent=agent,
        episodes=tuple(episodes),
        where=None,
        limit=None,
        allow_errors=False,
        trust_modules=args.trust_modules,
        env=None,
        invocation=None,
        progress=False,
        trusted=tuple(args.trust_module),
    )


def _group(config: dict) -> tuple[str, str, str]:
    """The episodes a run ran, as ``rmm-bench compare`` pairs them: its world, its clock and its
    disturbances."""
    kwargs = config.get("env_kwargs", {})
    world = world_key(config["env_id"], kwargs, int(config.get("seed", 0)))
    return world, str(kwargs.get("clock", "wall")), "; ".join(kwargs.get("disturbances", []) or [])


def _describe(config: dict) -> str:
    return f"{config.get('env_id')} seed {config.get('seed')} clock {_group(config)[1]}"


def _select(db: Path, args) -> Selection:
    """The agent's run (the newest, as ``replay`` picks it) and its collisions to classify; with
    ``--versus``, those the other agent's newest run of the same episodes avoided."""
    store = ResultsStore(db, read_only=True)
    try:
        run_key, config = _select_run(store, _request(db.parent, args.agent, (), args))
        rows = {int(r["episode"]): r for r in store.episodes(run_key)}
        world = _group(config)[0]
        doomed = {e: s["doomed"] for e, s in store.starts(world).items()}
        collided = sorted(e for e, row in rows.items() if row["outcome"] == "collision")
        sel = Selection(args.agent, run_key, _describe(config), collided, doomed, len(collided))
        if not collided:
            raise ValueError(
                f"--agent {args.agent}: none of the {len(rows)} episodes of its run {run_key} ({sel.describe}) "
                "collided; expected a run with a collision to classify"
            )
        if args.versus is None:
            return sel
        return _versus(store, db, args, sel, rows, config)
    finally:
        store.close()


def _versus(store: ResultsStore, db: Path, args, sel: Selection, rows: dict, config: dict) -> Selection:
    agent = store.run_config(sel.run_key)["agent"]
    stored = sorted({r[0] for r in store.db.execute("SELECT DISTINCT agent FROM runs")})
    if args.versus in (args.agent, agent):
        raise ValueError(f"--versus {args.versus}: the same agent as --agent; expected another agent")
    if args.versus not in stored:
        raise ValueError(
            f"--versus {args.versus}: no run of {args.versus!r} is stored in {db}{did_you_mean(args.versus, stored)} "
            f"(expected one of: {', '.join(s for s in stored if s != agent)})"
        )
    runs = store.runs_of(args.versus)
    same = [r for r in runs if _group(r["config"]) == _group(config)]
    if not same:
        other = "; ".join(sorted({_describe(r["config"]) for r in runs}))
        raise ValueError(
            f"--versus {args.versus}: no run of it ran {args.agent}'s episodes ({sel.describe}; its runs: {other}); "
            "expected a run of the same env, options, seed and clock"
        )
    if same[0]["run_key"] != runs[0]["run_key"]:
        raise ValueError(
            f"--versus {args.versus}: its newest run {runs[0]['run_key']} ran other episodes than {args.agent}'s "
            f"({_describe(runs[0]['config'])}); expected its newest run to be of {sel.describe}"
        )
    key = same[0]["run_key"]
    theirs = {int(r["episode"]): r for r in store.episodes(key)}
    paired = [e for e in sel.episodes if e in theirs and theirs[e]["outcome"] != "error"]
    for e in paired:
        fa, fb = rows[e].get("start"), theirs[e].get("start")
        if fa is not None and fb is not None and fa != fb:
            raise ValueError(
                f"--versus {args.versus}: episode {e} started differently from {args.agent}'s (start fingerprint "
                f"{fb}, not {fa}): the runs come from code that shapes starts differently"
            )
    if not paired:
        raise ValueError(
            f"--versus {args.versus}: its run {key} has a result for none of {args.agent}'s "
            f"{len(sel.episodes)} collision episodes; expected a run of the same episodes"
        )
    avoided = [e for e in paired if theirs[e]["outcome"] in AVOIDED]
    if not avoided:
        raise ValueError(
            f"--versus {args.versus}: it avoided none of {args.agent}'s {len(paired)} paired collisions "
            f"({sel.describe}); nothing to classify"
        )
    sel.episodes, sel.versus, sel.versus_key = avoided, args.versus, key
    sel.versus_outcomes = {e: theirs[e]["outcome"] for e in avoided}
    return sel


# ---------------------------------------------------------------- replaying


def _replay(db: Path, agent: str, episodes: list[int], args, want_key: str) -> tuple[dict, int]:
    """Replay ``agent``'s ``episodes``: episode -> (row, log or None when not verified, message)."""
    from tqdm import tqdm

    req = _request(db.parent, agent, episodes, args)
    out: dict[int, tuple[dict, AlarmLog | None, str]] = {}
    with consented_imports(req):
        store = ResultsStore(db, read_only=True)
        try:
            targets = plan_replay(store, req)
        finally:
            store.close()
        if targets[0].run_key != want_key:
            raise ValueError(
                f"--versus {agent}: its newest run {targets[0].run_key} ran other episodes than the one paired "
                f"({want_key}); expected its newest run to be the paired one"
            )
        check_inputs(targets[0].run.as_dict())
        env = build_env(targets[0])
        check_guardian(targets[0])
        bar = tqdm(total=len(targets), unit="ep", disable=not args.progress, desc=f"replay {agent}", file=sys.stderr)
        try:
            for target in targets:
                log = AlarmLog()
                message, ok = replay_episode(target, env, log)
                out[int(target.row["episode"])] = (target.row, log if ok else None, message)
                bar.update(1)
        finally:
            bar.close()
            env.close()
    return out, len(targets)


def classify_collisions(dir: str | Path, args) -> tuple[Selection, list[Verdict], float]:
    """Classify ``args.agent``'s collisions in ``dir`` (see the module): the selection, one
    verdict per episode, and the seconds the replays took.  ``ValueError`` for bad input."""
    if args.last_steps < 0:
        raise ValueError(f"--last-steps {args.last_steps}: expected a whole number of steps >= 0")
    if args.window is not None and not (args.window > 0 and math.isfinite(args.window)):
        raise ValueError(f"--window {args.window}: expected a number of seconds > 0 (or 'all')")
    db = results_database(dir, "collisions")
    sel = _select(db, args)
    t0 = time.perf_counter()
    mine, _ = _replay(db, args.agent, sel.episodes, args, sel.run_key)
    theirs: dict = {}
    if sel.versus is not None:
        assert sel.versus_key is not None
        theirs, _ = _replay(db, sel.versus, sel.episodes, args, sel.versus_key)
    seconds = time.perf_counter() - t0
    verdicts = []
    for e in sel.episodes:
        row, log, message = mine[e]
        doomed = sel.doomed.get(e)
        if log is None:
            v = Verdict(
                e,
                int(row["seed"]),
                UNVERIFIED,
                doomed,
                int(row["steps"]),
                math.nan,
                False,
                math.nan,
                math.nan,
                False,
                math.nan,
                math.nan,
                verified=False,
                note=message,
            )
        else:
            v = _verdict(row, log, doomed, args.last_steps, args.window)
        if sel.versus is not None:
            _, vlog, vmessage = theirs[e]
            lead = math.nan
            if vlog is not None and not math.isnan(v.impact_s):
                lead = versus_lead(vlog, v.impact_s, args.window)
            note = v.note if vlog is not None else f"{sel.versus}: {vmessage}"
            v = Verdict(
                **{
                    **asdict(v),
                    "versus_outcome": (sel.versus_outcomes or {}).get(e),
                    "versus_control_lead_s": lead,
                    "verified": v.verified and vlog is not None,
                    "note": note,
                }
            )
        verdicts.append(v)
    return sel, verdicts, seconds


# ---------------------------------------------------------------- output


def _window(text: str) -> float | None:
    if text == "all":
        return None
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds or 'all', got {text!r}") from None


def build_parser() -> argparse.ArgumentParser:
    """The ``rmm-bench collisions`` command line."""
    p = argparse.ArgumentParser(
        prog="rmm-bench collisions",
        description="Classify an agent's collisions by replaying them (verified against the stored rows): "
        "doomed start, unseen (its alarm never up before the last steps), failed manoeuvre (in control at "
        "impact), released (control handed back before impact) or alarm ignored, with the time from the "
        "first alarm to impact.  The alarm is the guardian's own (Guardian.alarm(), docs/guardians.md); one "
        "without it is classified by who was in control.  Opens the database read-only.",
    )
    p.add_argument("results_dir", metavar="DIR", help="a results directory (a run's --out) or its results.db")
    p.add_argument("--agent", required=True, help="the stored agent whose collisions to classify (its newest run)")
    p.add_argument(
        "--versus",
        default=None,
        metavar="AGENT",
        help="only the collisions this agent's run of the same episodes avoided (goal or timeout); replayed too",
    )
    p.add_argument(
        "--last-steps",
        type=int,
        default=3,
        metavar="N",
        help="an alarm first up within the last N steps before impact is too late: unseen (default 3)",
    )
    p.add_argument(
        "--window",
        type=_window,
        default=3.0,
        metavar="SECONDS",
        help="the alarm that counts is the first one up within this many simulated seconds before impact, "
        "traced back to where it began; 'all': the whole episode (default 3)",
    )
    p.add_argument("--format", default="md", choices=("md", "csv", "json"), help="md (default), csv or json")
    p.add_argument("--table", type=Path, default=None, metavar="FILE", help="write the table there (default: stdout)")
    p.add_argument("--trust-modules", action="store_true", help="import any module the database names (as replay)")
    p.add_argument(
        "--trust-module", action="append", default=[], metavar="MODULE", help="import this module the database names"
    )
    p.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")
    return p


def cmd(argv: list[str]) -> int:
    """Run ``rmm-bench collisions``: 0, or 1 when an episode's replay did not verify; bad input
    raises ``ValueError`` (exit 2 through the CLI)."""
    args = build_parser().parse_args(argv)
    existed = args.table is not None and args.table.exists()
    if args.table is not None:  # before anything is read: never over the database it reads (or any other)
        check_output(args.table, "--table", reads=[results_database(args.results_dir, "collisions")])
    sel, verdicts, seconds = classify_collisions(args.results_dir, args)
    replays = len(verdicts) * (2 if sel.versus else 1)
    print(f"rmm-bench collisions: replayed {replays} episodes in {seconds:.1f} s", file=sys.stderr)
    if args.format == "md":
        text = to_markdown(sel, verdicts, args.last_steps, args.window)
    elif args.format == "csv":
        text = to_csv(verdicts)
    else:
        text = to_json(sel, verdicts, args.last_steps, args.window)
    if args.table is None:
        sys.stdout.write(text)
    else:
        write_output(args.table, lambda tmp: tmp.write_text(text), existed=existed)
        print(f"wrote {args.table}", file=sys.stderr)
    return 0 if all(v.verified for v in verdicts) else 1
