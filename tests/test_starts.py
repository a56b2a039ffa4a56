"""An episode's start (rmm_envs.starts): its fingerprint is the same whatever the agent or the
clock and differs between seeds and worlds; a world's key ignores the clock's options; every
row of a run carries its start, and a run stores a world's starts once, shared by its agents."""

from __future__ import annotations

import sqlite3

import gymnasium as gym
import numpy as np
import pytest

import rmm_envs  # noqa: F401
from rmm_bench.cli import main
from rmm_envs.starts import StartAssessment, assess_start, start_fingerprint, world_key

FAST = ["--workers", "1", "--no-progress", "--no-figure"]


@pytest.mark.parametrize("env_id", ["Dubins4DParallel-v0", "Dubins3DMazeParallel-v0", "CartPoleParallel-v0"])
def test_a_start_fingerprint_depends_on_the_seed_not_on_the_clock(env_id):
    prints = {}
    for clock in ("fixed:1", "fixed:7", "wall"):
        env = gym.make(env_id, clock=clock)
        for seed in (3, 4):
            obs, _ = env.reset(seed=seed)
            prints[clock, seed] = start_fingerprint(env, obs)
        env.close()
    assert len({prints[c, 3] for c in ("fixed:1", "fixed:7", "wall")}) == 1
    assert prints["fixed:1", 3] != prints["fixed:1", 4]
    assert all(len(p) == 16 and int(p, 16) >= 0 for p in prints.values())


def test_the_fingerprint_reads_the_world_not_only_the_observation():
    env = gym.make("Dubins4DParallel-v0", clock="fixed:1")
    obs, _ = env.reset(seed=5)
    before = start_fingerprint(env, obs)
    u = env.unwrapped
    moved = u.privileged()["obstacles"].copy()
    u.scene.obstacles[-1, 0] += 1e-9  # a world one nanometre apart, the same observation: another start
    assert not np.array_equal(moved, u.privileged()["obstacles"])
    assert start_fingerprint(env, obs) != before
    env.close()


def test_a_world_key_ignores_the_clock_and_its_acceleration_but_not_the_seed_or_shape():
    base = {"base_step": 0.1, "clock": "fixed:1", "time_accel": 10.0}
    k = world_key("Dubins4DParallel-v0", base, 0)
    assert k == world_key("Dubins4DParallel-v0", base | {"clock": "wall", "time_accel": 3.0}, 0)
    assert k != world_key("Dubins4DParallel-v0", base, 1)
    assert k != world_key("Dubins4DParallel-v0", base | {"base_step": 0.05}, 0)
    assert k != world_key("Dubins3DMazeParallel-v0", base, 0)


def test_an_env_without_a_doomed_test_is_not_assessed():
    env = gym.make("CartPoleParallel-v0", clock="fixed:1")
    env.reset(seed=0)
    assert assess_start(env) == StartAssessment(None, "")
    env.close()


def test_every_row_carries_its_start_and_agents_share_it(tmp_path):
    out = tmp_path / "res"
    argv = ["--agent", "brakes,inactive", "--clock", "fixed:1", "--episodes", "3", "--out", str(out)]
    assert main([*argv, *FAST]) == 0
    con = sqlite3.connect(out / "results.db")
    rows = con.execute("SELECT agent, episode, start FROM episodes ORDER BY agent, episode").fetchall()
    con.close()
    by_agent: dict[str, list] = {}
    for agent, _, start in rows:
        by_agent.setdefault(agent, []).append(start)
    assert by_agent["brakes"] == by_agent["inactive"] and len(set(by_agent["brakes"])) == 3
    assert all(s and len(s) == 16 for s in by_agent["brakes"])
