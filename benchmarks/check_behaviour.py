"""Behaviour fingerprint: prove a refactor changed no result, and that a machine's arithmetic
changes none either.

``python -m benchmarks.check_behaviour record FILE`` writes a JSON fingerprint of what the
project computes; ``compare FILE`` recomputes it and lists every difference (exit 1 if any):
run ``record`` on the commit before a refactor and ``compare`` after it.  ``arith`` computes
it in fresh interpreters under several machines' arithmetic (BLAS kernel, numpy's SIMD
dispatch, numba's target CPU; see :func:`arith_settings`) and compares them.  The
fingerprint holds:

* **worlds**: rooms, mazes, and every env's world and start state at reset (privileged view);
* **envs**: a SHA-256 of the observations, rewards, flags and info of a seeded rollout of each
  of the envs in :data:`ENVS` (every guardian env of the package's vehicles and the two guarded
  Gymnasium simulators) under seeded random actions;
* **labels**: sampled states, observations and sampling-tree risk labels of each labelled env;
* **datasets**: ``rmm-datagen``'s rows for the three vehicles;
* **hj**: HJ value functions solved afresh;
* **bench**: every non-timing column of fixed-clock ``rmm-bench`` episodes of every system
  (Dubins4D's seven agents and HJ, the maze's, the quadrotor's, CartPole's and
  InvertedPendulum's guardians);
* **applied**: the arithmetic the interpreter really ran under (numpy's dispatch target of
  ``exp``, the OpenBLAS kernel), so that a setting which did not take effect is noticed.

Hashes are of exact bytes: a change in the last bit of one float is a difference.  ``--size
full`` takes about five minutes on one core, ``--size quick`` (the test suite's) about 20 s.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.arith import PRE_FMA, applied, arith_settings, describe, run_under
from rmm_envs.catalog import stored_id  # fingerprint keys: the ids results were first recorded under

# Columns that measure time (machine-dependent) or identify a run, never compared.
_MEASURED = {"decision_mean", "decision_std", "decision_max", "precompute_time", "wall_time"}
_TIMING = _MEASURED | {"finished", "run_key", "invocation", "config"}

# Sizes: "full" is the refactor check (about two minutes on one core), "quick" the cheap one the
# default test suite runs under several machines' arithmetic (tests/test_reproducibility.py).
SIZES = {
    "full": {
        "episodes": 32,
        "hj_episodes": 4,
        "other_episodes": 8,
        "steps": 200,
        "states": 16,
        "seeds": 20,
        "configs": 2,
        "samples": 8,
    },
    "quick": {
        "episodes": 3,
        "hj_episodes": 0,
        "other_episodes": 1,
        "steps": 40,
        "states": 4,
        "seeds": 4,
        "configs": 1,
        "samples": 4,
    },
}
AGENTS = ("inactive", "random", "brakes", "lrmm", "lrmm-paper", "cbf", "cbf-paper")
HJ_AGENTS = ("hj", "hj-paper")
# the other systems' parallel-autonomy envs and the guardians that apply to each
OTHER_BENCH = {
    "Dubins3DMazeParallel-v0": ("inactive", "brakes", "lrmm", "cbf", "hj"),
    "QuadrotorRoomParallel-v0": ("inactive", "brakes", "lrmm", "cbf"),
    "CartPoleParallel-v0": ("inactive", "brakes", "lrmm"),
    "InvertedPendulumParallel-v0": ("inactive", "brakes", "lrmm"),
}
QUICK_OTHER_BENCH = {
    "Dubins3DMazeParallel-v0": ("inactive", "lrmm", "cbf"),
    "QuadrotorRoomParallel-v0": ("inactive", "lrmm", "cbf"),
    "CartPoleParallel-v0": ("inactive", "lrmm"),
    "InvertedPendulumParallel-v0": ("inactive", "lrmm"),
}
ENVS = (
    "Dubins4DGuarded-v0",
    "Dubins4DParallel-v0",
    "Dubins4DMapGuarded-v0",
    "Dubins4DMapParallel-v0",
    "Dubins3DMaze-v0",
    "Dubins3DMazeGuarded-v0",
    "Dubins3DMazeParallel-v0",
    "QuadrotorRoom-v0",
    "QuadrotorRoomGuarded-v0",
    "QuadrotorRoomParallel-v0",
    "CartPoleGuarded-v0",
    "InvertedPendulumGuarded-v0",
)
LABELLED = {
    "Dubins4DGuarded-v0": {},
    "Dubins4DMapGuarded-v0": {},
    "Dubins3DMaze-v0": {},
    "Dubins3DMazeGuarded-v0": {},
    "QuadrotorRoom-v0": {},
    "QuadrotorRoomGuarded-v0": {},
    "CartPoleGuarded-v0": {},
    "InvertedPendulumGuarded-v0": {},
}
DATASETS = ("Dubins4DGuarded-v0", "Dubins3DMazeGuarded-v0", "QuadrotorRoomGuarded-v0")


def _is_timing(key: str) -> bool:
    return key.endswith(("_seconds", "_time", "_ms", "_us")) or key in _TIMING


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(np.asarray(a))
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:32]


def _measured(key) -> bool:
    """An info or stats key that holds a measured (wall-clock or CPU) time, not behaviour: the
    blocking envs' ``cum_compute_time`` / ``avg_compute_time``, a guardian's ``solve_seconds``.
    (Exact names: a room's ``walls`` or a maze's ``wall_height`` are behaviour.)"""
    return isinstance(key, str) and (key.endswith(("compute_time", "_seconds")) or key in _MEASURED)


def _flatten(value, out: list) -> None:
    """Every number, string and array of a nested structure, in a fixed order (measured times left out)."""
    if isinstance(value, dict):
        for k in sorted(value, key=str):
            if _measured(k):
                continue
            out.append(np.frombuffer(str(k).encode(), np.uint8))
            _flatten(value[k], out)
    elif isinstance(value, (list, tuple)):
        for v in value:
            _flatten(v, out)
    elif isinstance(value, str):
        out.append(np.frombuffer(value.encode(), np.uint8))
    elif value is None or callable(value):
        out.append(np.zeros(0))
    elif hasattr(value, "__dict__") and not isinstance(value, np.ndarray):
        _flatten({k: v for k, v in vars(value).items() if not k.startswith("_")}, out)
    else:
        out.append(np.asarray(value))


def _plain(v):
    if isinstance(v, float) and math.isnan(v):
        return "nan"
    if isinstance(v, (np.floating,)):
        return _plain(float(v))
    if isinstance(v, np.integer):
        return int(v)
    return v


def _bench(tmp: str, env_id: str, agents, n: int, extra=()) -> None:
    """One fixed-clock ``rmm-bench`` run, in this process (its table is not printed)."""
    import contextlib
    import io

    from rmm_bench.cli import main as bench_main

    argv = [
        "--env",
        env_id,
        "--agent",
        ",".join(agents),
        "--episodes",
        str(n),
        "--seed",
        "0",
        "--clock",
        "fixed:1",
        "--out",
        tmp,
        "--workers",
        "1",
        "--no-progress",
        "--no-figure",
        *extra,
    ]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = bench_main(argv)
        except SystemExit as e:
            rc = e.code
    if rc not in (0, None):
        raise SystemExit(
            f"rmm-bench {' '.join(argv)} failed ({rc}):\n{out.getvalue()[-2000:]}\n{err.getvalue()[-2000:]}"
        )


def bench_fingerprint(episodes: int, hj_episodes: int, other_episodes: int = 0, other=OTHER_BENCH) -> dict:
    """Every stored non-timing column of fixed-clock benchmark episodes, keyed agent/episode
    (Dubins4D, whose keys are kept as before) or env/agent/episode (the other systems)."""
    from rmm_bench import load_results

    out: dict = {}
    runs = [("Dubins4DParallel-v0", AGENTS, episodes, ())]
    if hj_episodes:  # solve afresh: a cached value function would hide a change of the solver
        runs.append(
            (
                "Dubins4DParallel-v0",
                HJ_AGENTS,
                hj_episodes,
                ("--agent-opt", "hj.cache=false", "--agent-opt", "hj-paper.cache=false"),
            )
        )
    if other_episodes:
        runs += [
            (env_id, agents, other_episodes, ("--agent-opt", "hj.cache=false") if "hj" in agents else ())
            for env_id, agents in other.items()
        ]
    for env_id, agents, n, extra in runs:
        with tempfile.TemporaryDirectory() as tmp:
            _bench(tmp, env_id, agents, n, extra)
            df = load_results(tmp)
        cols = [c for c in df.columns if c not in _TIMING]
        prefix = "" if env_id == "Dubins4DParallel-v0" else f"{stored_id(env_id)}/"
        for row in df[cols].to_dict("records"):
            if row.get("guardian_stats"):  # guardians' own timings (e.g. HJ's solve_seconds) are not behaviour
                stats = json.loads(row["guardian_stats"])
                row["guardian_stats"] = json.dumps({k: v for k, v in sorted(stats.items()) if not _is_timing(k)})
            out[f"{prefix}{row['agent']}/{row['episode']}"] = {k: _plain(v) for k, v in sorted(row.items())}
    return out


def _make(env_id: str):
    import gymnasium as gym

    import rmm_envs  # noqa: F401

    kwargs = {"clock": "fixed:1"} if "Parallel" in env_id else {}
    return gym.make(env_id, **kwargs)


def env_fingerprint(steps: int = 200, envs=ENVS) -> dict:
    """Observations, rewards, flags and every numeric info value of a seeded rollout of each env."""
    out = {}
    for env_id in envs:
        env = _make(env_id)
        env.action_space.seed(7)
        obs, info = env.reset(seed=7)
        record = [obs]
        _flatten(info, record)
        for _ in range(steps):
            obs, r, term, trunc, info = env.step(env.action_space.sample())
            record += [obs, np.array([r, term, trunc], dtype=float)]
            _flatten(info, record)
            if term or trunc:
                obs, _ = env.reset()
                record.append(obs)
        env.close()
        out[stored_id(env_id)] = _digest(*record)
    return out


def world_fingerprint(seeds: int) -> dict:
    """The generated worlds: rooms, mazes, and every env's world and start state at reset
    (circle sets, map starts, goals and waypoints), through the privileged accessor."""
    from rmm_envs.systems.maze.mazes import generate_maze
    from rmm_envs.systems.quadrotor.rooms import generate_room

    out = {}
    rooms, mazes = [], []
    for seed in range(seeds):
        _flatten(generate_room(np.random.default_rng(seed)), rooms)
        for kind in ("rectangular", "honeycomb"):
            _flatten(generate_maze(np.random.default_rng(seed), kind, rows=6, cols=6), mazes)
    out["generate_room"], out["generate_maze"] = _digest(*rooms), _digest(*mazes)
    for env_id in ENVS:
        env = _make(env_id)
        record = []
        for seed in range(seeds):
            obs, _ = env.reset(seed=seed)
            record.append(obs)
            _flatten(env.unwrapped.privileged(), record)
        env.close()
        out[stored_id(env_id)] = _digest(*record)
    return out


def label_fingerprint(n_states: int = 16) -> dict:
    import gymnasium as gym

    import rmm_envs  # noqa: F401
    from rmm_envs.risk.estimator import RiskEstimator

    out = {}
    for env_id, kwargs in LABELLED.items():
        env = gym.make(env_id, **kwargs).unwrapped
        env.reset(seed=3)
        rng = np.random.default_rng(3)
        states = env.sample_states(rng, n_states)
        obs = env.observe_states(states, rng)
        # a simulator's own step fixes its horizons (the guarded envs around Gymnasium's simulators)
        horizon = env.default_horizon if env_id in ("CartPoleGuarded-v0", "InvertedPendulumGuarded-v0") else 0.5
        est = RiskEstimator(env.risk_scene(), branches=4, depth=2, horizon=horizon, n_steps=4)
        res = est.estimate(states, np.random.default_rng(5))
        env.close()
        out[stored_id(env_id)] = _digest(states, obs, res.risk, res.min_risk_ctrl, res.min_risk_ctrl_dur, res.n_leaves)
    return out


def dataset_fingerprint(configs: int, samples: int) -> dict:
    """What ``rmm-datagen`` writes, per system: every value of every shard (read back, so not the
    Parquet bytes, which carry pyarrow's version) and the row count of its manifest."""
    from rmm_envs.risk.datagen import DatagenConfig, generate

    out = {}
    for env_id in DATASETS:
        cfg = DatagenConfig(
            env_id=env_id,
            configs=configs,
            samples_per_config=samples,
            seed=11,
            branches=4,
            depth=2,
            horizon=0.5,
            n_steps=4,
            configs_per_shard=1,
        )
        with tempfile.TemporaryDirectory() as tmp:
            manifest = generate(cfg, tmp, workers=1, progress=False)
            shards = sorted(Path(tmp).glob("shard-*.parquet"))
            import pyarrow.parquet as pq

            cols = [pq.read_table(p).to_pydict() for p in shards]
        out[stored_id(env_id)] = {
            "content": _digest(*[np.asarray(v, dtype=object).astype(str) for c in cols for v in c.values()]),
            "rows": manifest.get("n_rows"),
        }
    return out


def hj_fingerprint() -> dict:
    """HJ value functions solved afresh on a small Dubins4D grid, second and first order (the maze's
    are solved in the benchmark episodes of ``hj`` on the maze)."""
    from rmm_guardians.hj.guardian import HJGuardian

    obstacles = np.array([[3.0, 1.0, 1.5], [-4.0, -2.0, 2.0]])
    out = {}
    for order, rk in ((2, 3), (1, 2)):
        g = HJGuardian(grid_n=(21, 21, 9, 9), horizon=1.0, order=order, rk=rk, cache=False, threads=1)
        out[f"dubins4d/order{order}"] = _digest(g.value_function(obstacles))
    return out


def fingerprint(episodes: int, hj_episodes: int, size: str | None = None) -> dict:
    sz = dict(SIZES[size or "full"], episodes=episodes, hj_episodes=hj_episodes)
    other = QUICK_OTHER_BENCH if size == "quick" else OTHER_BENCH
    return {
        "bench": bench_fingerprint(sz["episodes"], sz["hj_episodes"], sz["other_episodes"], other),
        "envs": env_fingerprint(sz["steps"]),
        "worlds": world_fingerprint(sz["seeds"]),
        "labels": label_fingerprint(sz["states"]),
        "datasets": dataset_fingerprint(sz["configs"], sz["samples"]),
        "hj": hj_fingerprint(),
        "sizes": {**sz, "size": size or "full"},
        "versions": versions(),
        "applied": applied(),
    }


def versions() -> dict:
    """What the bits are promised for: the versions of the packages that compute them."""
    import platform
    from importlib.metadata import version

    out = {"python": ".".join(map(str, sys.version_info[:3])), "libc": " ".join(platform.libc_ver())}
    for pkg in ("numpy", "numba", "scipy", "osqp", "pybullet", "pymunk", "pyarrow"):
        try:
            out[pkg] = version(pkg)
        except Exception:  # noqa: BLE001 - an optional extra that is not installed
            out[pkg] = None
    return out


SECTIONS = ("worlds", "envs", "labels", "datasets", "hj", "bench")


def compare(old: dict, new: dict) -> list[str]:
    diffs = []
    for section in SECTIONS:
        if section not in old or section not in new:
            continue  # a record made before the section existed
        a, b = old[section], new[section]
        for key in sorted(set(a) | set(b)):
            if key not in b:
                diffs.append(f"{section}: {key} missing now")
            elif key not in a:
                diffs.append(f"{section}: {key} new (not in the record)")
            elif a[key] != b[key]:
                if isinstance(a[key], dict):
                    fields = sorted(k for k in set(a[key]) | set(b[key]) if a[key].get(k) != b[key].get(k))
                    diffs.append(
                        f"{section}: {key}: " + ", ".join(f"{f} {a[key].get(f)!r} -> {b[key].get(f)!r}" for f in fields)
                    )
                else:
                    diffs.append(f"{section}: {key}: {a[key]} -> {b[key]}")
    return diffs


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "mode",
        choices=["record", "compare", "print", "arith"],
        help="record FILE, compare FILE, print (JSON to stdout), or arith: the same fingerprint under "
        "several machines' arithmetic (BLAS kernel, numba CPU, numpy SIMD dispatch), compared",
    )
    p.add_argument("file", type=Path, nargs="?")
    p.add_argument("--size", choices=sorted(SIZES), default="full", help="what to compute (default: %(default)s)")
    p.add_argument("--episodes", type=int, default=None, help="Dubins4D benchmark episodes per agent")
    p.add_argument("--hj-episodes", type=int, default=None, help="episodes per HJ agent, 0 to skip")
    p.add_argument(
        "--pre-fma",
        action="store_true",
        help="arith: also a CPU without FMA (the C library's other code; known to differ, for measuring)",
    )
    p.add_argument("--show", type=int, default=1, help="arith: differences listed per setting (default: %(default)s)")
    args = p.parse_args(argv)
    sz = SIZES[args.size]
    episodes = sz["episodes"] if args.episodes is None else args.episodes
    hj_episodes = sz["hj_episodes"] if args.hj_episodes is None else args.hj_episodes
    if args.mode in ("record", "compare") and args.file is None:
        p.error(f"{args.mode} needs a FILE")
    if args.mode == "print":
        print(json.dumps(fingerprint(episodes, hj_episodes, args.size), sort_keys=True))
        return 0
    if args.mode == "arith":
        settings = arith_settings() + ([PRE_FMA] if args.pre_fma else [])
        ref = run_under(settings[0], args.size)
        print(f"reference: {describe(settings[0])} (ran under {ref['applied']})")
        bad = 0
        for s in settings[1:]:
            fp = run_under(s, args.size)
            diffs = compare(ref, fp)
            print(
                f"{describe(s)} (ran under {fp['applied']}): "
                + ("same bits" if not diffs else f"{len(diffs)} DIFFER, first: {diffs[0]}")
            )
            for d in diffs[1 : args.show]:
                print(f"    {d}")
            bad += bool(diffs)
        return 1 if bad else 0
    if args.mode == "record":
        fp = fingerprint(episodes, hj_episodes, args.size)
        args.file.write_text(json.dumps(fp, indent=1, sort_keys=True))
        print(
            f"recorded {len(fp['bench'])} episodes, {len(fp['envs'])} env rollouts, {len(fp['labels'])} label sets, "
            f"{len(fp['worlds'])} world sets, {len(fp['datasets'])} datasets -> {args.file}"
        )
        return 0
    old = json.loads(args.file.read_text())
    sizes = old.get("sizes", {})
    new = fingerprint(sizes.get("episodes", episodes), sizes.get("hj_episodes", hj_episodes), sizes.get("size", "full"))
    diffs = compare(old, new)
    for d in diffs:
        print(d)
    print(
        f"{len(diffs)} differences in {len(new['bench'])} episodes, {len(new['envs'])} env rollouts, "
        f"{len(new['labels'])} label sets"
    )
    return 1 if diffs else 0


if __name__ == "__main__":
    sys.exit(main())
