"""``hj.disturbance`` beyond Dubins4D (issue 52, item 3): the maze car's HJ part takes the same bound
``d_max`` on the position rates (or ``"env"``: the run's own ``dyn-rate`` bound), spelt
``--agent-opt hj.disturbance=...`` as on Dubins4D; 0 is today's value bit for bit under today's cache
key; the quadrotor's part models none and refuses one rather than ignoring it.

The maze value is the corridor's of ``tests/test_maze_hj_props.py`` (car at 10 px/s, ``|u| <= 0.2``,
horizon 12 s).  Hand-checkable: the same open-loop turn rates give the same headings with or
without the disturbance (the heading does not depend on the position), and the disturbance moves
the position by at most ``sqrt(2) d t`` in ``t``; the target is 1-Lipschitz in position, so
``V_0 - sqrt(2) d T <= V_d <= V_0`` (to the scheme's dissipation, which grows with ``d``)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import rmm_envs  # noqa: F401  (registers the envs)
from rmm_bench.run_checks import parse_agent_opts
from rmm_envs.systems.maze.guarded import Dubins3DMazeGuardedEnv
from rmm_envs.systems.quadrotor.guarded import QuadrotorRoomGuardedEnv
from rmm_guardians.hj.cache import ValueCache
from rmm_guardians.hj.guardian import HJGuardian
from rmm_guardians.hj.maze import MazeHJGuardian
from rmm_guardians.hj.quadrotor import QuadrotorHJGuardian
from rmm_guardians.registry import make_guardian
from tests.test_maze_guardians import corridor

MAZE = "Dubins3DMazeGuarded-v0"
SETTINGS = dict(spacing=10.0, n_heading=16, horizon=12.0, region="maze", threads=1, cache=False)
D = 2.0  # px/s, a fifth of the car's speed
#: the corridor value's cache key before the option existed (the dynamics' key held d_max = 0.0 already)
TODAYS_KEY = "a1d49e9aa908734870743d79a6b6ac1a466906b2ae058216e3412937b1cfb6d8"
#: what the scheme's Lax-Friedrichs dissipation (it grows with d) may raise a value by (px; a cell is 10)
DISSIPATION = 0.1


@pytest.fixture(scope="module")
def values():
    """name -> the reset corridor guardian: ``today`` (no argument), ``zero`` (0) and ``d`` (:data:`D`)."""
    space = Dubins3DMazeGuardedEnv().action_space
    priv = {
        "state": np.array([250.0, 125.0, 0.0]),
        "maze": corridor(),
        "goal": np.array([375.0, 125.0, 10.0]),
        "speed": 10.0,
        "sim_time": 0.0,
    }
    out = {}
    for name, kw in (("today", {}), ("zero", {"disturbance": 0}), ("d", {"disturbance": D})):
        g = MazeHJGuardian(**SETTINGS, **kw)
        g.reset(seed=0, action_space=space, privileged=lambda: priv)
        out[name] = (g, priv)
    return out


def test_zero_is_today_s_value_bit_for_bit_under_today_s_cache_key(values):
    (today, priv), (zero, _) = values["today"], values["zero"]
    assert zero.V.dtype == today.V.dtype and np.array_equal(zero.V, today.V)
    assert zero.dynamics == today.dynamics and zero.dynamics.d_max == 0.0
    for g in (today, zero):
        assert ValueCache.key(g.spec(priv["maze"], g.grid)) == TODAYS_KEY


def test_a_bound_grows_the_unsafe_set_within_the_hand_checked_bound(values):
    (zero, _), (d, priv) = values["zero"], values["d"]
    assert d.dynamics.d_max == D and d.dynamics.key()["d_max"] == D
    assert ValueCache.key(d.spec(priv["maze"], d.grid)) != TODAYS_KEY  # its own cache entry
    loss = zero.V.astype(float) - d.V
    assert loss.min() >= -DISSIPATION  # lower or equal everywhere
    assert loss.max() > 5.0 and (loss > 1.0).mean() > 0.5  # strictly, and over most of the grid
    assert loss.max() <= math.sqrt(2) * D * SETTINGS["horizon"] + DISSIPATION
    assert np.all(d.V[zero.V <= 0.0] <= 0.0) and (d.V <= 0.0).sum() > (zero.V <= 0.0).sum()
    # mid-corridor, heading along it, 56.25 px from both walls: the drift costs it distance
    assert d.evaluate((250.0, 125.0, 0.0))[0] < zero.evaluate((250.0, 125.0, 0.0))[0] - 5.0


def test_env_reads_the_bound_from_a_disturbed_maze_env_spelt_as_on_dubins4d():
    opts = parse_agent_opts(["hj.disturbance=env"], ["hj"])
    assert opts == {"hj": {"disturbance": "env"}}
    small = dict(spacing=25.0, n_heading=8, horizon=2.0, cache=False, threads=1)
    for spec, privileged, bound in (
        ("dyn-rate=3", ["dyn-rate=3.0"], 3.0),
        ("dyn-rate.x=1.5; impulse=4", ["dyn-rate.x=1.5", "impulse=4.0"], 1.5),  # a push is no bounded rate
        ("obs-noise.rays=0.2", ["obs-noise.rays=0.2"], 0.0),
        (None, None, 0.0),
    ):
        env = gym.make(MAZE, disturbances=spec).unwrapped
        env.reset(seed=3)
        assert env.privileged().get("disturbances") == privileged  # absent when undisturbed, as before
        g = make_guardian("hj", env_id=MAZE, maze=small, **opts["hj"])
        g.reset(seed=0, observation_space=env.observation_space, action_space=env.action_space,
                privileged=env.privileged)  # fmt: skip
        assert isinstance(g.delegate, MazeHJGuardian) and g.delegate.dynamics.d_max == bound
        env.close()
    # a number reaches the part too, and the part's own dict may set it; unset, its arguments are today's
    assert HJGuardian(disturbance=1.5)._dynamics_args["dubins3d"]["disturbance"] == 1.5
    assert HJGuardian(maze={"disturbance": "env"})._dynamics_args["dubins3d"]["disturbance"] == "env"
    assert "disturbance" not in HJGuardian()._dynamics_args["dubins3d"]


@pytest.mark.parametrize(
    "value, message",
    [
        (-1.0, "disturbance must be a finite number >= 0.0, got -1.0"),
        (float("nan"), "disturbance must be a finite number >= 0.0, got nan"),
        (float("inf"), "disturbance must be a finite number >= 0.0, got inf"),
        ("wind", "disturbance must be a finite number >= 0.0 or \"env\", got 'wind'"),
        ([0.1], "disturbance must be a number, got [0.1]"),
    ],
)
def test_bad_input_is_refused_naming_the_value(value, message):
    for build in (
        lambda: MazeHJGuardian(disturbance=value),
        lambda: QuadrotorHJGuardian(disturbance=value),
        lambda: HJGuardian(disturbance=value),
        lambda: HJGuardian(maze={"disturbance": value}),
    ):
        with pytest.raises(ValueError) as e:
            build()
        assert message in str(e.value)


def test_the_quadrotor_refuses_a_disturbance_in_one_line_naming_why():
    space = QuadrotorRoomGuardedEnv().action_space
    QuadrotorHJGuardian().check_spaces(None, space)
    QuadrotorHJGuardian(disturbance=0).check_spaces(None, space)
    for value in ("env", 0.3):
        g = HJGuardian(disturbance=value)  # a Dubins4D run is unaffected: refused only on the quadrotor's env
        with pytest.raises(ValueError) as e:
            g.check_spaces(None, space)
        text = str(e.value)
        assert "\n" not in text and f"disturbance={value!r}" in text and "force on its velocities" in text
