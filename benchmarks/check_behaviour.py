"""Behaviour fingerprint: prove a refactor changed no result.

``python benchmarks/check_behaviour.py record FILE`` writes a JSON fingerprint of what the
project computes; ``python benchmarks/check_behaviour.py compare FILE`` recomputes it and
lists every difference (exit 1 if any).  Run ``record`` on the commit before a refactor and
``compare`` after it.  The fingerprint holds:

* **benchmark episodes**: every non-timing column of every episode ``rmm-bench`` stores for
  the agents below on ``Dubins4DParallel-v0`` under a fixed 1 ms clock (so timing and machine
  load cannot change them), seed 0: outcome, steps, simulated and intervention time, final
  speed, reward, guardian counters;
* **environments**: a SHA-256 of the observations, rewards and flags of a seeded rollout of
  each registered environment under seeded random actions;
* **risk labels**: a SHA-256 of the sampled states, observations and sampling-tree risk labels
  of each labelled environment (small trees, a fixed seed).

Hashes are of exact bytes: a change in the last bit of one float is a difference.  The
default sizes take about two minutes on one core (``--episodes`` and ``--hj-episodes`` set
the benchmark's share; HJ is slow because each episode solves a PDE).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

# Columns that measure time (machine-dependent) or identify a run, never compared.
_TIMING = {"decision_mean", "decision_std", "decision_max", "precompute_time", "wall_time", "finished", "run_key",
           "invocation", "config"}

AGENTS = ("inactive", "random", "brakes", "lrmm", "lrmm-paper", "cbf", "cbf-paper")
HJ_AGENTS = ("hj", "hj-paper")
ENVS = ("Dubins4DCircles-v0", "Dubins4DParallel-v0", "Dubins3DMaze-v0", "QuadrotorRoom-v0")
LABELLED = {"Dubins4DCircles-v0": {}, "Dubins3DMaze-v0": {}, "QuadrotorRoom-v0": {}}


def _is_timing(key: str) -> bool:
    return key.endswith(("_seconds", "_time", "_ms", "_us")) or key in _TIMING


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(np.asarray(a))
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:32]


def _plain(v):
    if isinstance(v, float) and math.isnan(v):
        return "nan"
    if isinstance(v, (np.floating,)):
        return _plain(float(v))
    if isinstance(v, np.integer):
        return int(v)
    return v


def bench_fingerprint(episodes: int, hj_episodes: int) -> dict:
    from benchmarks import load_results

    out: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        runs = [(AGENTS, episodes)] + ([(HJ_AGENTS, hj_episodes)] if hj_episodes else [])
        for agents, n in runs:
            cmd = [sys.executable, "-m", "benchmarks.bench.cli", "--agent", ",".join(agents), "--episodes", str(n),
                   "--seed", "0", "--clock", "fixed:1", "--out", tmp, "--workers", "1", "--no-progress"]
            if agents == HJ_AGENTS:  # solve afresh: a cached value function would hide a change of the solver
                cmd += ["--agent-opt", "hj.cache=false", "--agent-opt", "hj-paper.cache=false"]
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if proc.returncode != 0:
                raise SystemExit(f"rmm-bench failed ({proc.returncode}):\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")
        df = load_results(tmp)
        cols = [c for c in df.columns if c not in _TIMING]
        for row in df[cols].to_dict("records"):
            if row.get("guardian_stats"):  # guardians' own timings (e.g. HJ's solve_seconds) are not behaviour
                stats = json.loads(row["guardian_stats"])
                row["guardian_stats"] = json.dumps({k: v for k, v in sorted(stats.items()) if not _is_timing(k)})
            out[f"{row['agent']}/{row['episode']}"] = {k: _plain(v) for k, v in sorted(row.items())}
    return out


def env_fingerprint(steps: int = 200) -> dict:
    import gymnasium as gym

    import rmm_envs  # noqa: F401

    out = {}
    for env_id in ENVS:
        kwargs = {"clock": "fixed:1"} if env_id == "Dubins4DParallel-v0" else {}
        env = gym.make(env_id, **kwargs)
        env.action_space.seed(7)
        obs, _ = env.reset(seed=7)
        record = [obs]
        for _ in range(steps):
            obs, r, term, trunc, _ = env.step(env.action_space.sample())
            record += [obs, np.array([r, term, trunc], dtype=float)]
            if term or trunc:
                obs, _ = env.reset()
                record.append(obs)
        env.close()
        out[env_id] = _digest(*record)
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
        est = RiskEstimator(env.risk_scene(), branches=4, depth=2, horizon=0.5, n_steps=4)
        res = est.estimate(states, np.random.default_rng(5))
        env.close()
        out[env_id] = _digest(states, obs, res.risk, res.min_risk_ctrl, res.min_risk_ctrl_dur, res.n_leaves)
    return out


def fingerprint(episodes: int, hj_episodes: int) -> dict:
    return {"bench": bench_fingerprint(episodes, hj_episodes), "envs": env_fingerprint(),
            "labels": label_fingerprint(), "sizes": {"episodes": episodes, "hj_episodes": hj_episodes}}


def compare(old: dict, new: dict) -> list[str]:
    diffs = []
    for section in ("envs", "labels", "bench"):
        a, b = old.get(section, {}), new.get(section, {})
        for key in sorted(set(a) | set(b)):
            if key not in b:
                diffs.append(f"{section}: {key} missing now")
            elif key not in a:
                diffs.append(f"{section}: {key} new (not in the record)")
            elif a[key] != b[key]:
                if isinstance(a[key], dict):
                    fields = sorted(k for k in set(a[key]) | set(b[key]) if a[key].get(k) != b[key].get(k))
                    diffs.append(f"{section}: {key}: " + ", ".join(f"{f} {a[key].get(f)!r} -> {b[key].get(f)!r}" for f in fields))
                else:
                    diffs.append(f"{section}: {key}: {a[key]} -> {b[key]}")
    return diffs


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mode", choices=["record", "compare"])
    p.add_argument("file", type=Path)
    p.add_argument("--episodes", type=int, default=32, help="benchmark episodes per agent (default: %(default)s)")
    p.add_argument("--hj-episodes", type=int, default=4, help="episodes per HJ agent, 0 to skip (default: %(default)s)")
    args = p.parse_args(argv)
    if args.mode == "record":
        fp = fingerprint(args.episodes, args.hj_episodes)
        args.file.write_text(json.dumps(fp, indent=1, sort_keys=True))
        print(f"recorded {len(fp['bench'])} episodes, {len(fp['envs'])} env rollouts, {len(fp['labels'])} label sets -> {args.file}")
        return 0
    old = json.loads(args.file.read_text())
    sizes = old.get("sizes", {})
    new = fingerprint(sizes.get("episodes", args.episodes), sizes.get("hj_episodes", args.hj_episodes))
    diffs = compare(old, new)
    for d in diffs:
        print(d)
    print(f"{len(diffs)} differences in {len(new['bench'])} episodes, {len(new['envs'])} env rollouts, "
          f"{len(new['labels'])} label sets")
    return 1 if diffs else 0


if __name__ == "__main__":
    sys.exit(main())
