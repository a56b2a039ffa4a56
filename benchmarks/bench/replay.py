"""``rmm-bench replay DIR --agent NAME --episode I``: re-simulate stored episodes and verify them against their rows.

A replay rebuilds the env and the guardian from the stored run (its configuration: env id
and options, the guardian's options, the files it read, checked by their stored SHA-256),
re-simulates the episode with its stored seed through the runner's own episode function
(:func:`rmm_bench.runner.play_episode`, the very code that ran it), and compares every stored
column that is a result with the row: outcome, steps, simulated time, active steps and time,
final speed, cost, reward, the guardian's statistics (its timings aside,
:func:`rmm_bench.runner.is_timing_stat`), and the env clock's compute time when the clock is
reproduced.  It prints ``verified``, or the first column that differs with both values, and
exits 1 on a difference.

Clocks.  A fixed-clock run (``fixed:MS``) replays from its options alone.  A clocked run
(``wall``, ``cpu``) of a non-blocking env replays from the episode's stored clock trace (every
lap the non-blocking wrapper's clock returned), played back by
:class:`rmm_envs.clocks.ReplayClock`; a database written before traces were stored cannot
replay such an episode, and says so.  A blocking env's clock only times the guardian: its run
replays under any clock (its compute time is then not compared).

What cannot be verified: a guardian that reads the time itself (rather than through the env's
clock) or is not deterministic (unseeded randomness, a result depending on thread timing)
decides differently in a replay; the replay then reports the first differing column, or that
the clock trace ran out (the replay went on longer than the run), and says that such a guardian
cannot be verified.

Safety.  The database is opened read-only (never migrated nor written).  Built-in guardians,
envs and strategies replay directly; a module the database names (a ``module:Class`` agent, a
``module:Id`` env, a ``module:Name`` in the agent's or the env's options, such as a strategy of
one's own) is imported only when the command line names the same module (``--agent
module:Class``, ``--env module:Id``, ``--trust-module module``) or with ``--trust-modules``: a
database may come from someone else (:mod:`rmm_bench.consent`).

Bad input (one line naming the value and what was expected, exit 2): a missing directory or
database, an agent or episode not stored, an errored episode without ``--allow-errors``, a
lost worker's episode, a newer schema, a module no longer importable or not consented to, a
file whose SHA-256 differs from the run's (a model, or the source file of a module the run
names: editing it after the run is refused, naming it, never replayed and blamed on
non-determinism).

Rendering (``--video``, ``--frames``, ``--every``): :func:`replay_episode` passes an observer
(:class:`rmm_bench.video.EpisodeDrawing`) to the episode loop; the
env it builds is the one the episode runs on.
"""

from __future__ import annotations

import json
import math
import os
import sqlite3
import sys
from dataclasses import dataclass
from pathlib import Path

from rmm_bench.config import AgentRun, EpisodeTask, changed_inputs
from rmm_bench.consent import check_consent, check_inputs, consented_imports
from rmm_bench.names import did_you_mean
from rmm_bench.runner import CLOCK_COLUMNS, REPRODUCIBLE_CLOCKS, TIMING_COLUMNS, is_timing_stat
from rmm_bench.store import EPISODE_FIELDS, ResultsStore

__all__ = ["ReplayRequest", "ReplayTarget", "cmd_replay", "compare_rows", "plan_replay", "replay_episode"]

#: The columns compared, in this order (the rest of the row follows in the store's order).
_FIRST = ("outcome", "error_kind", "steps", "sim_time", "active_steps", "active_sim_time", "final_speed", "cost")
#: Columns naming the episode, not results of it.
_IDENTITY = ("run_key", "episode", "agent", "seed")
_UNVERIFIABLE = (
    "(a guardian that reads the time itself or is not deterministic cannot be verified: "
    "docs/getting-started.md, Replaying an episode)"
)


@dataclass(frozen=True)
class ReplayRequest:
    """``rmm-bench replay``'s arguments, validated (``args.parse_replay``)."""

    dir: Path
    agent: str
    episodes: tuple[int, ...] | None  # --episode (None: --where selects)
    where: str | None
    limit: int | None
    allow_errors: bool
    trust_modules: bool
    env: str | None  # --env: names the env's module for a module:Id env (and must match the stored env)
    invocation: int | None
    progress: bool
    video: Path | None = None  # --video FILE (.mp4 or .gif)
    frames: Path | None = None  # --frames DIR (one PNG per frame)
    every: int = 1  # --every K: every K-th frame (and the last)
    fps: float | None = None  # --fps (default: the episode's own pace, simulated seconds per video second)
    size: int = 512  # --size: the picture's side in pixels (the strip comes under it)
    trusted: tuple[str, ...] = ()  # --trust-module: modules the database names that may be imported


@dataclass(frozen=True)
class ReplayTarget:
    """One episode to replay: the stored run, its row, its clock trace (None: not needed)."""

    run: AgentRun
    run_key: str
    row: dict
    clock_trace: tuple[float, ...] | None
    clock_mode: str  # the run's clock mode (wall, cpu, fixed)
    nonblocking: bool


def _module_of(name: str) -> str | None:
    module, colon, _ = name.rpartition(":")
    return module if colon and module else None


def _select_run(store: ResultsStore, req: ReplayRequest) -> tuple[str, dict]:
    """The run of ``--agent`` to replay: that of ``--invocation``, else the newest stored."""
    runs = store.runs_of(req.agent)
    if not runs:  # a module:Class agent named by its class alone (its module is then not named: see _check_trust)
        stored = [r[0] for r in store.db.execute("SELECT DISTINCT agent FROM runs")]
        same = [a for a in stored if _module_of(a) and a.rpartition(":")[2] == req.agent]
        runs = store.runs_of(same[0]) if len(same) == 1 else []
    if not runs:
        agents = sorted({r[0] for r in store.db.execute("SELECT agent FROM runs")})
        raise ValueError(
            f"--agent {req.agent}: no run of {req.agent!r} is stored in {store.path}{did_you_mean(req.agent, agents)} "
            f"(expected one of its agents: {', '.join(agents) or 'none stored'})"
        )
    if req.invocation is None:
        return runs[0]["run_key"], runs[0]["config"]
    inv = store.invocation(req.invocation)  # LookupError naming the invocation
    key = inv["run_keys"].get(req.agent)
    if key is None:
        raise ValueError(
            f"--invocation {req.invocation}: it ran {', '.join(inv['run_keys']) or 'no agent'}, not {req.agent!r}"
        )
    return key, store.run_config(key)["config"]


def _agent_run(config: dict, run_key: str, store: ResultsStore) -> AgentRun:
    from rmm_envs.catalog import current_id

    try:
        run = AgentRun(
            agent=config["agent"],
            agent_kwargs=config["agent_kwargs"],
            env_id=current_id(config["env_id"]),
            env_kwargs=config["env_kwargs"],
            seed=int(config["seed"]),
            episode_timeout=float(config["episode_timeout"]),
            charge_precompute=bool(config["charge_precompute"]),
            inputs=config.get("inputs") or {},
        )
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"run {run_key} in {store.path}: its stored configuration cannot be read ({e!r})") from None
    if run.key != run_key:
        raise ValueError(
            f"run {run_key} in {store.path}: its stored configuration hashes to {run.key}, expected {run_key}; "
            "the database was edited or written by another version"
        )
    return run


def _episode_numbers(store: ResultsStore, run_key: str, req: ReplayRequest) -> list[int]:
    if req.where is None:
        numbers = list(req.episodes or ())
    else:
        try:
            rows = store.db.execute(
                f"SELECT episode FROM episodes WHERE run_key = ? AND ({req.where}) ORDER BY episode", (run_key,)
            ).fetchall()
        except sqlite3.Error as e:
            columns = [r[1] for r in store.db.execute("PRAGMA table_info(episodes)")]
            raise ValueError(
                f"--where {req.where!r}: {e}; expected an SQL condition on the episodes table's columns "
                f"({', '.join(columns)}), e.g. \"outcome='collision'\""
            ) from None
        numbers = [int(r[0]) for r in rows]
        if req.episodes is not None:
            numbers = [i for i in numbers if i in set(req.episodes)]
        if not numbers:
            raise ValueError(f"--where {req.where!r}: no episode of {req.agent}'s run {run_key} matches")
    return numbers[: req.limit] if req.limit is not None else numbers


def _clock_mode(env_kwargs: dict) -> str:
    from rmm_envs.clocks import make_clock

    return make_clock(env_kwargs.get("clock", "wall")).mode


def plan_replay(store: ResultsStore, req: ReplayRequest) -> list[ReplayTarget]:
    """Every selected episode, checked (ValueError, one line, for any that cannot be replayed)
    before anything is imported or run."""
    run_key, config = _select_run(store, req)
    if req.env is not None and req.env not in (config["env_id"],):
        from rmm_envs.catalog import current_id

        if current_id(req.env) != current_id(config["env_id"]):
            raise ValueError(f"--env {req.env}: {req.agent}'s run {run_key} ran on {config['env_id']!r}, expected it")
    check_consent(config, req)  # before anything is imported
    run = _agent_run(config, run_key, store)
    mode = _clock_mode(run.env_kwargs)
    nonblocking = "time_accel" in run.env_kwargs
    stored = {r["episode"]: r for r in store.episodes(run_key)}
    targets = []
    for i in _episode_numbers(store, run_key, req):
        row = stored.get(i)
        if row is None:
            span = f"0-{max(stored)}" if stored else "none"
            raise ValueError(
                f"--episode {i}: {req.agent}'s run {run_key} in {store.path} has no episode {i} "
                f"(expected one of the {len(stored)} stored: {span})"
            )
        if row["outcome"] == "error":
            kind = row.get("error_kind") or "guardian"
            first = (row.get("error") or "").splitlines()[0][:200] if row.get("error") else "no message"
            if kind == "lost_worker":
                raise ValueError(
                    f"--episode {i}: its worker was lost ({first}), so nothing of it was recorded to replay; "
                    "expected an episode with a result (rerun the run to retry it)"
                )
            if not req.allow_errors:
                raise ValueError(
                    f"--episode {i}: it ended in an error of kind {kind} ({first}); replayed only with --allow-errors"
                )
        trace = None
        if nonblocking and mode not in REPRODUCIBLE_CLOCKS:
            laps = store.clock_trace(run_key, i)
            if laps is None:
                why = (
                    f"{store.path} predates clock traces (schema version {store.version})"
                    if not store.has_traces()
                    else "no clock trace is stored for it"
                )
                raise ValueError(
                    f"--episode {i}: cannot be replayed: its run used the {mode!r} clock, whose decision times "
                    f"passed in the simulated world, and {why}; only its fixed-clock runs (--clock fixed:MS) "
                    "replay without one"
                )
            trace = tuple(laps)
        targets.append(ReplayTarget(run, run_key, row, trace, mode, nonblocking))
    if not targets:
        raise ValueError("--episode: no episode selected; expected an episode number, e.g. --episode 3")
    return targets


def _as_stored(result) -> dict:
    """``result`` as the store would read it back: through an in-memory table of the same columns."""
    con = sqlite3.connect(":memory:")
    try:
        keys = list(EPISODE_FIELDS)
        con.execute(f"CREATE TABLE episodes ({', '.join(f'{k} {v}' for k, v in EPISODE_FIELDS.items())})")
        row = result.as_row()
        con.execute(f"INSERT INTO episodes VALUES ({', '.join('?' * len(keys))})", [row[k] for k in keys])
        cur = con.execute("SELECT * FROM episodes")
        return dict(zip([d[0] for d in cur.description], cur.fetchone(), strict=True))
    finally:
        con.close()


def _same(a, b) -> bool:
    """Equal as stored: floats bit for bit (``nan`` equal to ``nan``)."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def compare_rows(stored: dict, replayed: dict, clock_reproduced: bool) -> tuple[str, object, object] | None:
    """The first result column where ``replayed`` differs from ``stored`` (both as the store
    reads them): ``(column, stored value, replayed value)``, or None when every one is equal.
    Only columns the stored row has are compared (an older layout lacks some); timing columns
    never, the clock columns only when ``clock_reproduced``; ``guardian_stats`` key by key
    (``guardian_stats.KEY``), its timings aside; an error by its first line."""
    skip = set(_IDENTITY) | TIMING_COLUMNS | (set() if clock_reproduced else CLOCK_COLUMNS)
    order = [c for c in _FIRST if c in stored] + [c for c in stored if c not in _FIRST]
    for col in order:
        if col in skip:
            continue
        a, b = stored[col], replayed.get(col)
        if col == "start" and a is None:  # a row stored before starts were fingerprinted
            continue
        if col == "guardian_stats":
            sa, sb = json.loads(a or "{}"), json.loads(b or "{}")
            for k in sorted(set(sa) | set(sb)):
                if not is_timing_stat(k) and not _same(sa.get(k), sb.get(k)):
                    return f"guardian_stats.{k}", sa.get(k), sb.get(k)
            continue
        if col == "error":
            a = (a or "").splitlines()[0] if a else a
            b = (b or "").splitlines()[0] if b else b
        if not _same(a, b):
            return col, a, b
    return None


def replay_episode(target: ReplayTarget, env=None, drawing=None) -> tuple[str, bool]:
    """Re-simulate ``target``'s episode and compare it with its row: ``(message, verified)``.

    ``env``: one built for the run by :func:`build_env` (reused across episodes of one run);
    ``drawing``: a :class:`rmm_bench.video.EpisodeDrawing` that records the episode's frames."""
    from rmm_bench.runner import play_episode
    from rmm_envs.clocks import TraceExhausted

    row = target.row
    i = row["episode"]
    label = f"episode {i} of {target.run.agent}'s run {target.run_key}"
    clock = None
    if target.clock_trace is not None:
        clock = env.get_wrapper_attr("clock")
        clock.load(target.clock_trace, label)
    task = EpisodeTask(
        run=target.run, run_key=target.run_key, episode=i, seed=int(row["seed"]), import_path=(os.getcwd(),)
    )
    record = play_episode(task, env, observer=drawing)
    replayed = _as_stored(record.result)
    error = replayed.get("error") or ""
    first = error.splitlines()[0] if error else ""
    if first.startswith(TraceExhausted.__name__):
        return (f"episode {i}: differs: {first} {_UNVERIFIABLE}", False)
    reproduced = target.clock_mode in REPRODUCIBLE_CLOCKS or target.clock_trace is not None
    diff = compare_rows(row, replayed, reproduced)
    where = ""
    if replayed["outcome"] == "error":
        where = "; the replay raised: " + " | ".join(line.strip() for line in error.splitlines()[-3:] if line.strip())
    if diff is not None:
        col, a, b = diff
        return (f"episode {i}: differs in {col}: stored {a!r}, replayed {b!r} {_UNVERIFIABLE}{where}", False)
    if clock is not None and clock.used != len(clock.laps):
        return (
            f"episode {i}: differs in the clock trace: the replay read {clock.used} of its {len(clock.laps)} laps "
            f"{_UNVERIFIABLE}",
            False,
        )
    return (f"episode {i}: verified{where}", True)


def build_env(target: ReplayTarget, render_mode: str | None = None):
    """The env the run's episodes ran on, built with the run's options; a clocked run's clock is a
    :class:`~rmm_envs.clocks.ReplayClock` (loaded per episode).  ``render_mode``: also passed to
    the env (to draw it).  ValueError when it cannot be made."""
    import gymnasium as gym

    from rmm_envs.clocks import ReplayClock
    from rmm_envs.env_plugins import EnvUnavailable, resolve_env_id
    from rmm_envs.user_modules import search_user_folders

    search_user_folders((os.getcwd(),))  # a module:Id env's module, after the installed packages
    kwargs = dict(target.run.env_kwargs)
    if target.clock_trace is not None:
        kwargs["clock"] = ReplayClock((), "no episode yet")
    if render_mode is not None:
        kwargs["render_mode"] = render_mode
    try:
        return gym.make(resolve_env_id(target.run.env_id), **kwargs)
    except EnvUnavailable as e:
        raise ValueError(f"{e}; expected the env the run used to be importable") from None
    except Exception as e:  # noqa: BLE001 - its constructor failed: the stored options no longer build it
        raise ValueError(
            f"--env {target.run.env_id}: the run's env cannot be made with its stored options {target.run.env_kwargs}: "
            f"{type(e).__name__}: {e}"
        ) from None


def drawable_env(target: ReplayTarget, env, size: int):
    """``env`` ready to be drawn: as it is when a view of the package draws it, else rebuilt with
    ``render_mode="rgb_array"`` (its own frames: a simulator of your own, a Gymnasium env);
    ``ValueError`` naming the env, never the guardian, when it cannot draw at all."""
    from rmm_envs.views import view_for

    try:
        view_for(env, size)
        return env
    except ValueError:
        pass
    try:
        drawn = build_env(target, render_mode="rgb_array")
        view_for(drawn, size)
    except Exception as e:  # noqa: BLE001 - the env cannot render: it is the cause, not the guardian
        raise ValueError(
            f"--video/--frames: {target.run.env_id} cannot draw its episodes: it has no view in this package "
            f"and does not render with render_mode='rgb_array' ({e}); replay without --video/--frames "
            "verifies it"
        ) from None
    env.close()
    return drawn


def _check_guardian(target: ReplayTarget) -> None:
    """Import and build the run's guardian (as the episode will), refused in one line if it cannot be."""
    from rmm_bench.config import InputChanged, run_input_digests
    from rmm_bench.runner import guardian_for

    task = EpisodeTask(run=target.run, run_key=target.run_key, episode=0, seed=0, import_path=(os.getcwd(),))
    try:
        guardian = guardian_for(task)
    except InputChanged as e:
        raise ValueError(f"{e}".split(": a file changed")[0] + ": expected the file the run read") from None
    except Exception as e:  # noqa: BLE001 - an import or a constructor that fails now
        raise ValueError(
            f"--agent {target.run.agent}: the run's guardian cannot be imported or built now: {type(e).__name__}: {e}"
        ) from None
    changed = changed_inputs(target.run.inputs, run_input_digests(guardian, target.run))
    if changed:
        raise ValueError(f"{changed}: expected the files the run read")


def _pace(drawing) -> float:
    """Frames per second that play the episode at its simulated pace (1 to 60)."""
    rec = drawing.recorder
    times = [] if rec is None else list(rec.times)
    if not times or not times[-1] > 0:
        return 10.0
    return float(min(60.0, max(1.0, len(times) / times[-1])))


def cmd_replay(req: ReplayRequest) -> int:
    """Replay the request's episodes; 0 if every one is verified, 1 if one differs (2 is raised as
    ValueError); only the modules the command line consents to are imported."""
    with consented_imports(req):
        return _replay(req)


def _replay(req: ReplayRequest) -> int:
    if not req.dir.is_dir():
        what = "is not a directory" if req.dir.exists() else "does not exist"
        raise ValueError(f"replay {req.dir}: it {what}; expected the --out directory of an rmm-bench run")
    db = req.dir / "results.db"
    if not db.is_file():
        raise ValueError(f"replay {req.dir}: it holds no results.db; expected the --out directory of an rmm-bench run")
    store = ResultsStore(db, read_only=True)
    try:
        targets = plan_replay(store, req)
    finally:
        store.close()
    check_inputs(targets[0].run.as_dict())
    from rmm_bench.video import EpisodeDrawing, check_outputs, episode_path

    check_outputs(req.video, req.frames, req.every, reads=[db])  # before anything is simulated or written
    env = build_env(targets[0])
    if req.video or req.frames:
        env = drawable_env(targets[0], env, req.size)
    _check_guardian(targets[0])
    drawing = EpisodeDrawing(req.size) if (req.video or req.frames) else None
    several = len(targets) > 1
    from tqdm import tqdm

    verified = True
    show = req.progress and len(targets) > 1
    bar = tqdm(total=len(targets), unit="ep", disable=not show, dynamic_ncols=True, desc="replay", file=sys.stderr)
    try:
        for target in targets:
            message, ok = replay_episode(target, env, drawing)
            verified &= ok
            (tqdm.write if show else print)(message)
            if drawing is not None:
                i = int(target.row["episode"])
                fps = req.fps or _pace(drawing)
                video = None if req.video is None else episode_path(req.video, i, several)
                frames = None if req.frames is None else episode_path(req.frames, i, several)
                for line in drawing.write(video, frames, req.every, fps):
                    (tqdm.write if show else print)(line)
            bar.update(1)
    finally:
        bar.close()
        env.close()
    if len(targets) > 1:
        print(f"{'verified' if verified else 'not verified'}: {len(targets)} episodes of {req.agent}")
    return 0 if verified else 1
