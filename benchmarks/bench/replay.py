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
(:class:`rmm_bench.video.EpisodeDrawing`) to the episode loop; the env it builds is the one the
episode runs on.  Frames draw the rays the guardian sensed (:mod:`rmm_bench.sensed`).

Side by side (``--agent lrmm,cbf``): each agent's episode is planned, re-simulated and verified
as above (one line each), and one video holds them side by side on a shared simulated-time axis
(:mod:`rmm_bench.side_by_side`).  The agents must have run the episode from the same start (the
same env, seed and start fingerprint, as ``compare`` pairs them); ``--where`` selects by the
first agent's rows.

The parts: :mod:`rmm_bench.replay_plan` (the request, the episodes selected),
:mod:`rmm_bench.replay_env` (the env and the guardian), :mod:`rmm_bench.replay_verify` (the
re-simulation and the comparison with the row); this module is the command.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

from rmm_bench.consent import check_inputs, consented_imports
from rmm_bench.replay_env import build_env, check_guardian, drawable_env
from rmm_bench.replay_plan import ReplayRequest, ReplayTarget, _module_of, plan_replay, replay_agents
from rmm_bench.replay_verify import _same as _same  # its tests import it from here
from rmm_bench.replay_verify import compare_rows, replay_episode
from rmm_bench.side_by_side import frame_size, shared_times, side_by_side_frames
from rmm_bench.store import ResultsStore
from rmm_bench.video import EpisodeDrawing, check_outputs, episode_path, write_frames, write_video

__all__ = [
    "ReplayRequest",
    "ReplayTarget",
    "build_env",
    "check_guardian",
    "cmd_replay",
    "compare_rows",
    "drawable_env",
    "plan_replay",
    "replay_agents",
    "replay_episode",
]


def _pace(times: list[float]) -> float:
    """Frames per second that play ``times`` (one frame each) at their simulated pace (1 to 60)."""
    if not times or not times[-1] > 0:
        return 10.0
    return float(min(60.0, max(1.0, len(times) / times[-1])))


def cmd_replay(req: ReplayRequest) -> int:
    """Replay the request's episodes; 0 if every one is verified, 1 if one differs (2 is raised as
    ValueError); only the modules the command line consents to are imported."""
    agents = replay_agents(req)
    if len(agents) == 1:
        req = replace(req, agent=agents[0])
        with consented_imports(req):
            return _replay(req)
    named = tuple(m for a in agents if (m := _module_of(a)))  # every agent the command line names
    with consented_imports(replace(req, agent=agents[0], trusted=tuple(req.trusted) + named)):
        return _replay_side_by_side(req, agents)


def _database(req: ReplayRequest) -> Path:
    if not req.dir.is_dir():
        what = "is not a directory" if req.dir.exists() else "does not exist"
        raise ValueError(f"replay {req.dir}: it {what}; expected the --out directory of an rmm-bench run")
    db = req.dir / "results.db"
    if not db.is_file():
        raise ValueError(f"replay {req.dir}: it holds no results.db; expected the --out directory of an rmm-bench run")
    return db


def _prepare(targets: list[ReplayTarget], req: ReplayRequest, drawn: bool):
    """The env of ``targets``' run, drawable when ``drawn``; its guardian checked."""
    env = build_env(targets[0])
    try:
        if drawn:
            env = drawable_env(targets[0], env, req.size)
        check_guardian(targets[0])
    except BaseException:
        env.close()
        raise
    return env


def _replay(req: ReplayRequest) -> int:
    db = _database(req)
    store = ResultsStore(db, read_only=True)
    try:
        targets = plan_replay(store, req)
    finally:
        store.close()
    check_inputs(targets[0].run.as_dict())
    check_outputs(req.video, req.frames, req.every, reads=[db])  # before anything is simulated or written
    drawn = bool(req.video or req.frames)
    env = _prepare(targets, req, drawn)
    drawing = EpisodeDrawing(req.size) if drawn else None
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
                fps = req.fps or _pace(drawing.times)
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


def _check_same_starts(agents: tuple[str, ...], plans: list[list[ReplayTarget]]) -> None:
    """Refuse agents whose episode did not start from the same state (one line)."""
    for j, first in enumerate(plans[0]):
        i = int(first.row["episode"])
        for agent, targets in zip(agents[1:], plans[1:], strict=True):
            other = targets[j]
            same = (
                other.run.env_id == first.run.env_id
                and other.row["seed"] == first.row["seed"]
                and (other.row.get("start") is None or first.row.get("start") is None
                     or other.row["start"] == first.row["start"])
            )  # fmt: skip
            if not same:
                raise ValueError(
                    f"--agent {','.join(agents)}: episode {i} of {agent} did not start as {agents[0]}'s did "
                    f"(env {other.run.env_id} vs {first.run.env_id}, seed {other.row['seed']} vs "
                    f"{first.row['seed']}, or its start differs); expected runs of the same env and seed, as "
                    "rmm-bench compare pairs them"
                )


def _write_side_by_side(agents, drawings, req: ReplayRequest, episode: int, several: bool) -> list[str]:
    shown = [(a, d) for a, d in zip(agents, drawings, strict=True) if d.recorder is not None and d.times]
    if not shown or all(d.recorder.n_steps == 0 for _, d in shown):
        return []
    names, ds = [a for a, _ in shown], [d for _, d in shown]
    fps = req.fps or _pace(shared_times([d.times for d in ds]))
    h, w = frame_size(ds)
    out = []
    if req.video is not None:
        video = episode_path(req.video, episode, several)
        n = write_video(side_by_side_frames(names, ds, req.every), video, fps / req.every)
        out.append(f"wrote {video} ({n} frames, {w} x {h}: {', '.join(names)} side by side)")
    if req.frames is not None:
        folder = episode_path(req.frames, episode, several)
        n = write_frames(side_by_side_frames(names, ds, req.every), folder)
        out.append(f"wrote {n} frames to {folder}")
    return out


def _replay_side_by_side(req: ReplayRequest, agents: tuple[str, ...]) -> int:
    """Replay one episode selection of several agents; with --video/--frames, each episode's
    agents side by side in one video."""
    db = _database(req)
    store = ResultsStore(db, read_only=True)
    try:
        first = plan_replay(store, replace(req, agent=agents[0]))
        episodes = tuple(int(t.row["episode"]) for t in first)
        plans = [first] + [
            plan_replay(store, replace(req, agent=a, episodes=episodes, where=None, limit=None)) for a in agents[1:]
        ]
    finally:
        store.close()
    _check_same_starts(agents, plans)
    for targets in plans:
        check_inputs(targets[0].run.as_dict())
    check_outputs(req.video, req.frames, req.every, reads=[db])  # before anything is simulated or written
    drawn = bool(req.video or req.frames)
    envs: list = []
    try:
        for targets in plans:
            envs.append(_prepare(targets, req, drawn))
        drawings = [EpisodeDrawing(req.size) for _ in agents] if drawn else [None] * len(agents)
        verified = True
        for j, i in enumerate(episodes):
            for agent, targets, env, drawing in zip(agents, plans, envs, drawings, strict=True):
                message, ok = replay_episode(targets[j], env, drawing)
                verified &= ok
                print(f"{agent}: {message}")
            if drawn:
                for line in _write_side_by_side(agents, drawings, req, i, len(episodes) > 1):
                    print(line)
    finally:
        for env in envs:
            env.close()
    n = len(episodes) * len(agents)
    print(f"{'verified' if verified else 'not verified'}: {n} episodes of {', '.join(agents)}")
    return 0 if verified else 1
