"""``info["nominal_control"]`` and ``info["cost"]`` of the guardian envs (the parallel-autonomy contract).

The nominal control is the driver's intended control for the next interval, computed from the
state the returned observation shows.  The contract's test: a guardian that hands it back every
step, ``action_space.active(info["nominal_control"])``, drives exactly as the driver does alone
(``inactive``), bit for bit, under a fixed clock.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import rmm_envs  # noqa: F401
from rmm_envs.envs.guarded import EPISODE_KEY

BLOCKING = [
    ("Dubins4DGuarded-v0", {}, 400),
    ("Dubins4DMapGuarded-v0", {}, 300),
    ("Dubins3DMazeGuarded-v0", {}, 600),
    ("QuadrotorRoomGuarded-v0", {}, 80),
]


def _episode(env, seed: int, policy, max_steps: int):
    """``[(observation, reward, (terminated, truncated), info)]`` of one episode (at most
    ``max_steps`` steps) and the env's episode statistics then."""
    obs, info = env.reset(seed=seed)
    trace = [(obs, 0.0, (False, False), info)]
    for _ in range(max_steps):
        obs, r, term, trunc, info = env.step(policy(env.unwrapped.action_space, info))
        trace.append((obs, r, (term, trunc), info))
        if term or trunc:
            break
    return trace, env.unwrapped.episode_statistics(trace[-1][3].get("outcome"))


def _drive(space, info):
    return space.inactive()


def _hand_back(space, info):
    return space.active(info["nominal_control"])


@pytest.mark.parametrize("env_id,kwargs,max_steps", BLOCKING, ids=[b[0] for b in BLOCKING])
def test_handing_back_the_nominal_control_is_the_driver_bit_for_bit(env_id, kwargs, max_steps):
    env = gym.make(env_id, clock="fixed:1", **kwargs)
    space = env.unwrapped.action_space
    for seed in (3, 11):
        alone, s1 = _episode(env, seed, _drive, max_steps)
        filtered, s2 = _episode(env, seed, _hand_back, max_steps)
        assert len(alone) == len(filtered) > 1
        for k, ((o1, r1, e1, i1), (o2, r2, e2, i2)) in enumerate(zip(alone, filtered, strict=True)):
            assert o1.tobytes() == o2.tobytes(), (env_id, seed, k)
            assert (r1, e1) == (r2, e2)
            assert i1["state"].tobytes() == i2["state"].tobytes()
            assert i1["nominal_control"].tobytes() == i2["nominal_control"].tobytes()
            assert i1["nominal_control"].shape == (space.control_dim,)
            assert np.all(i1["nominal_control"] >= space.control_low) and np.all(
                i1["nominal_control"] <= space.control_high
            )
            if k:
                # the applied control is the nominal control the previous step reported
                assert i1["control"].tobytes() == alone[k - 1][3]["nominal_control"].tobytes()
                assert i2["control"].tobytes() == i1["control"].tobytes()
                assert (i1["active"], i2["active"]) == (False, True)
                assert i1["cost"] == i2["cost"] == (1.0 if i1.get("outcome") == "collision" else 0.0)
        if EPISODE_KEY in alone[-1][3]:
            assert alone[-1][3][EPISODE_KEY] == s1 and filtered[-1][3][EPISODE_KEY] == s2
        assert s1["n_active_ctrl_env_steps"] == 0 and s2["n_active_ctrl_env_steps"] == s2["n_env_steps"]
        for key in (
            "outcome",
            "n_env_steps",
            "cum_sim_time",
            "cum_reward",
            "cum_cost",
            "cum_compute_time",
            "final_speed",
        ):
            assert s1[key] == s2[key], key
    env.close()


def test_the_nominal_control_is_the_drivers_control_at_the_observed_state():
    """Dubins4D's driver is a pure function of the state and the goal: the nominal control is
    the driver's QP at the state the observation shows (``info["state"]``), recomputed here."""
    env = gym.make("Dubins4DGuarded-v0", clock="fixed:1")
    obs, info = env.reset(seed=5)
    u = env.unwrapped
    for _ in range(30):
        expected = u.driver.control(info["state"], u.privileged()["goal"][:2])
        assert info["nominal_control"].tolist() == expected.tolist()
        # the observation shows that same state: its goal offset and heading
        assert obs[1] == np.float32(u.privileged()["goal"][0] - info["state"][0])
        obs, _, term, trunc, info = env.step(u.action_space.active([0.25, -0.5]))
        if term or trunc:
            break


def test_the_maze_driver_follows_its_route_while_the_guardian_drives():
    """The driver is asked once per observed state, whoever controls, so its progress along the
    route follows the car: after the guardian has driven it past the first corner, the nominal
    control aims along a later segment (it did not stay behind on the first one)."""
    env = gym.make("Dubins3DMazeGuarded-v0", clock="fixed:1")
    _, info = env.reset(seed=3)
    u = env.unwrapped
    for _ in range(400):
        _, _, term, trunc, info = env.step(u.action_space.active(info["nominal_control"]))
        if term or trunc:
            break
    assert u.driver._seg > 0
    assert info["nominal_control"].tolist() == [u.driver.control(info["state"])]


def test_cost_is_one_on_the_collision_step_and_summed_per_episode():
    env = gym.make("Dubins4DGuarded-v0", clock="fixed:1")
    obs, info = env.reset(
        seed=0, options={"state": [0.0, 0.0, 0.0, 2.0], "obstacles": [[3.0, 0.0, 1.0]], "goal": [-8.0, 0.0, 0.5]}
    )
    space = env.unwrapped.action_space
    costs = []
    while True:  # full speed straight into the obstacle 2 m ahead
        obs, r, term, trunc, info = env.step(space.active([0.0, 0.5]))
        costs.append(info["cost"])
        if term or trunc:
            break
    assert info["outcome"] == "collision" and r == -1.0
    assert costs == [0.0] * (len(costs) - 1) + [1.0]
    assert info[EPISODE_KEY]["cum_cost"] == 1.0
    assert "episode" not in info  # left to RecordEpisodeStatistics / Monitor


def test_vector_env_reports_the_single_envs_nominal_control_and_cost():
    n = 3
    venv = gym.make_vec("Dubins4DGuarded-v0", num_envs=n, vectorization_mode="vector_entry_point", clock="fixed:1")
    singles = [gym.make("Dubins4DGuarded-v0", clock="fixed:1") for _ in range(n)]
    _, vinfo = venv.reset(seed=7)
    infos = [s.reset(seed=7 + i)[1] for i, s in enumerate(singles)]
    space = singles[0].unwrapped.action_space
    for _ in range(40):
        for i in range(n):
            assert vinfo["nominal_control"][i].tobytes() == infos[i]["nominal_control"].tobytes()
        # hand the nominal control back in sub-env 0, let the driver drive the others
        act = {
            "active_ctrl": np.array([1, 0, 0]),
            "turnrate_ctrl": vinfo["nominal_control"][:, :1],
            "accel_ctrl": vinfo["nominal_control"][:, 1:],
        }
        _, _, term, trunc, vinfo = venv.step(act)
        outs = [
            s.step(space.active(infos[0]["nominal_control"]) if i == 0 else space.inactive())
            for i, s in enumerate(singles)
        ]
        infos = [o[4] for o in outs]
        for i in range(n):
            assert vinfo["cost"][i] == infos[i]["cost"]
            assert vinfo["state"][i].tobytes() == infos[i]["state"].tobytes()
        if (term | trunc).any():
            break
    venv.close()
