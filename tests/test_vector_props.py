"""The native vector env never changes an array after returning it (``rmm_envs/systems/dubins4d/vector.py``).

RL libraries keep the observation arrays they are given (rollout buffers, ``final_obs`` of the
previous step, a ``NormalizeObservation`` running statistic): an env that writes into an array
it returned rewrites their past.  Every array returned by ``reset`` and ``step`` (observations,
rewards, flags and every info array, nested ones included) is kept with a copy, and after many
more calls, in every autoreset mode and with partial resets, each must still equal its copy."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_envs.envs.guarded import EPISODE_KEY
from rmm_envs.systems.dubins4d.vector import Dubins4DCirclesVectorEnv

N = 4


def _arrays(tree, path="") -> list[tuple[str, np.ndarray]]:
    """Every numpy array in a (nested) dict/tuple of results, with a path naming it."""
    if isinstance(tree, np.ndarray):
        out = [(path, tree)]
        if tree.dtype == object:
            for i, x in enumerate(tree.ravel()):
                out += _arrays(x, f"{path}[{i}]")
        return out
    if isinstance(tree, dict):
        return [a for k, v in tree.items() for a in _arrays(v, f"{path}.{k}")]
    if isinstance(tree, (tuple, list)):
        return [a for i, v in enumerate(tree) for a in _arrays(v, f"{path}[{i}]")]
    return []


class Keeper:
    """Keeps what the env returned, and a private copy of each array."""

    def __init__(self) -> None:
        self.kept: list[tuple[str, np.ndarray, np.ndarray]] = []

    def keep(self, label: str, result) -> None:
        self.kept += [(label + p, a, a.copy()) for p, a in _arrays(result) if a.dtype != object]

    def check(self) -> None:
        for label, arr, copy in self.kept:
            assert np.array_equal(arr, copy, equal_nan=True), f"{label} changed after it was returned"


def _actions(rng: np.random.Generator, active_p: float) -> dict:
    return {
        "active_ctrl": (rng.random(N) < active_p).astype(np.int64),
        "turnrate_ctrl": rng.uniform(-0.25, 0.25, (N, 1)),
        "accel_ctrl": rng.uniform(-0.5, 0.5, (N, 1)),
    }


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP, AutoresetMode.DISABLED])
def test_returned_arrays_are_never_written_to(mode):
    """Short episodes (5 s, 50 steps) so that every mode resets sub-envs several times within the
    run: autoresets (NEXT_STEP, SAME_STEP), partial resets by ``reset_mask`` (DISABLED)."""
    env = Dubins4DCirclesVectorEnv(N, autoreset_mode=mode, clock="fixed:1", max_episode_sim_time=5.0)
    rng = np.random.default_rng(0)
    k = Keeper()
    k.keep("reset", env.reset(seed=3))
    ended_some = False
    for t in range(140):
        out = env.step(_actions(rng, 0.3))
        k.keep(f"step {t}", out)
        done = out[2] | out[3]
        ended_some |= bool(done.any())
        if mode == AutoresetMode.SAME_STEP:  # final_obs is the ended episode's last observation, not the new first one
            fin = out[4].get("final_info", {})
            for i in np.flatnonzero(done):
                last = out[4]["final_obs"][i]
                assert last[0] == np.float32(fin["sim_time"][i]) and last[4] == np.float32(fin["state"][i, 3])
                assert out[0][i, 0] == 0.0 and not np.array_equal(last, out[0][i])
        if mode == AutoresetMode.DISABLED and done.any():
            k.keep(f"reset_mask {t}", env.reset(options={"reset_mask": done.copy()}))
    assert ended_some
    k.check()
    env.close()


@settings(max_examples=8, deadline=None)
@given(
    seed=st.integers(0, 2**16), masks=st.lists(st.lists(st.booleans(), min_size=N, max_size=N), min_size=1, max_size=4)
)
def test_partial_resets_leave_earlier_observations_alone(seed, masks):
    """A reset of some sub-envs returns fresh observations for them and leaves the array the
    previous call returned as it was (the rows it did not reset are equal in both)."""
    env = Dubins4DCirclesVectorEnv(N, autoreset_mode=AutoresetMode.DISABLED, clock="fixed:1")
    obs, _ = env.reset(seed=seed)
    k = Keeper()
    k.keep("reset", obs)
    rng = np.random.default_rng(seed)
    for m in masks:
        m = np.array(m)
        if m.any():
            new, _ = env.reset(options={"reset_mask": m})
            assert new is not obs
            np.testing.assert_array_equal(new[~m], obs[~m])
            k.keep("partial reset", new)
            obs = new
        obs, _, term, trunc, _ = env.step(_actions(rng, 0.0))
        k.keep("step", obs)
        if (term | trunc).any():
            obs, _ = env.reset(options={"reset_mask": term | trunc})
            k.keep("reset ended", obs)
    k.check()
    env.close()


# ------------------------------------------------------------------ arguments, refused by exact message
@pytest.mark.parametrize(
    "kw, message",
    [
        ({"num_envs": 0}, "num_envs must be an integer >= 1, got 0"),
        ({"num_envs": True}, "num_envs must be an integer >= 1, got True"),
        ({"num_envs": 1.5}, "num_envs must be an integer >= 1, got 1.5"),
        (
            {"num_envs": 2, "autoreset_mode": "sometimes"},
            "autoreset_mode must be one of ['NextStep', 'SameStep', 'Disabled'], got 'sometimes'",
        ),
        (
            {"num_envs": 2, "render_mode": "human"},
            "render_mode must be None for the vector env (render a single env instead), got 'human'",
        ),
        (
            {"num_envs": 2, "driver_solver": "osqp"},
            "driver_solver must be 'closed_form' in the vector env (the batched exact solver), got 'osqp'",
        ),
    ],
)
def test_constructor_arguments_are_refused_by_exact_message(kw, message):
    with pytest.raises(ValueError) as e:
        Dubins4DCirclesVectorEnv(**kw)
    assert str(e.value) == message


def test_accepted_arguments_are_kept():
    env = Dubins4DCirclesVectorEnv(np.int64(3), autoreset_mode="SameStep", driver_solver="closed_form", n_obstacles=2)
    assert env.num_envs == 3 and type(env.num_envs) is int
    assert env.autoreset_mode is AutoresetMode.SAME_STEP and env.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
    assert Dubins4DCirclesVectorEnv.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP  # the class's stays
    assert env.render_mode is None and env.observation_space.shape == (3, 17)
    obs, info = env.reset(seed=0)
    assert obs.shape == (3, 17) and info["state"].shape == (3, 4) and info["_state"].all()
    assert info["sim_time"].tolist() == [0.0] * 3
    env.close()


@pytest.mark.parametrize(
    "call, message",
    [
        ({"seed": [1, 2, 3]}, "seed must be None, an int or a list of 2 ints or None, got [1, 2, 3]"),
        ({"seed": 1.5}, "seed must be None, an int or a list of 2 ints or None, got 1.5"),
        ({"seed": True}, "seed must be None, an int or a list of 2 ints or None, got True"),
        (
            {"options": {"reset_mask": np.array([1, 0])}},
            "options['reset_mask'] must be a numpy bool array of shape (2,), got array([1, 0])",
        ),
        (
            {"options": {"reset_mask": np.zeros(2, bool)}},
            "options['reset_mask'] must select at least one sub-env, got none",
        ),
        (
            {"options": {"reset_mask": np.array([True, False])}},
            "the first reset must reset every sub-env; options['reset_mask'] selects only some",
        ),
        (
            {"seed": 0, "options": {"obstacles": [[0.0, 0.0, 1.0]], "state": [5.0, 5.0, 0.0, 1.0]}},
            "option 'obstacles' must hold n_obstacles = 5 circles in the vector env (every world of a batch has as many), got 1",
        ),
    ],
)
def test_bad_resets_are_refused_by_exact_message(call, message):
    env = Dubins4DCirclesVectorEnv(2)
    with pytest.raises(ValueError) as e:
        env.reset(**call)
    assert str(e.value) == message


def test_stepping_an_ended_sub_env_without_autoreset_names_it():
    env = Dubins4DCirclesVectorEnv(2, autoreset_mode=AutoresetMode.DISABLED, max_episode_sim_time=0.1)
    env.reset(seed=0)
    a = {"active_ctrl": np.zeros(2, np.int64), "turnrate_ctrl": np.zeros((2, 1)), "accel_ctrl": np.zeros((2, 1))}
    _, _, term, trunc, info = env.step(a)
    assert trunc.tolist() == [True, True] and info["outcome"].tolist() == ["timeout", "timeout"]
    with pytest.raises(RuntimeError) as e:
        env.step(a)
    assert str(e.value) == (
        "sub-env 0's episode has ended and autoreset_mode is DISABLED: reset it first "
        "with reset(options={'reset_mask': mask})"
    )
    env.reset(options={"reset_mask": np.array([True, False])})
    with pytest.raises(RuntimeError, match="^sub-env 1's episode has ended"):
        env.step(a)


def test_an_obstacle_and_the_goal_reached_at_the_same_instant_is_a_collision():
    """Mirror images about the car's path (same radius, same distance): both circles are entered at
    the same time; the collision counts, in the vector env as in the single env."""
    import gymnasium as gym

    import rmm_envs  # noqa: F401

    opts = {"state": [0.0, 0.0, 0.0, 1.0], "obstacles": [[2.0, 0.6, 0.7]], "goal": [2.0, -0.6, 0.7]}
    a = {"active_ctrl": np.ones(1, np.int64), "turnrate_ctrl": np.zeros((1, 1)), "accel_ctrl": np.zeros((1, 1))}
    vec = Dubins4DCirclesVectorEnv(1, n_obstacles=1)
    vec.reset(seed=0, options=opts)
    single = gym.make("Dubins4DGuarded-v0", n_obstacles=1)
    single.reset(seed=0, options=opts)
    for _ in range(40):
        _, r, term, trunc, info = vec.step(a)
        _, r1, term1, _, info1 = single.step(single.action_space.active([0.0, 0.0]))
        assert term[0] == term1
        if term[0]:
            break
    assert info["outcome"][0] == info1["outcome"] == "collision" and r[0] == r1 == -1.0


def test_ended_info_masks_are_independent_arrays():
    """Each info key has its own mask array (a caller may edit one without changing another)."""
    env = Dubins4DCirclesVectorEnv(2, max_episode_sim_time=0.1)
    env.reset(seed=0)
    a = {"active_ctrl": np.zeros(2, np.int64), "turnrate_ctrl": np.zeros((2, 1)), "accel_ctrl": np.zeros((2, 1))}
    _, _, _, trunc, info = env.step(a)
    assert trunc.all()
    masks = [v for k, v in info.items() if k.startswith("_")] + [
        v for k, v in info[EPISODE_KEY].items() if k.startswith("_")
    ]
    assert "episode" not in info  # Gymnasium's RecordEpisodeStatistics owns that key
    assert len(masks) >= 10 and all(m.all() for m in masks)
    for i, m in enumerate(masks):
        for other in masks[i + 1 :]:
            assert not np.shares_memory(m, other)


def test_the_time_limit_holds_with_its_tolerance_inclusive():
    """With ``max_episode_sim_time = step_dt + 1e-9`` (``step_dt = 0.25``: ``max - 1e-9`` is exactly
    0.25), the first step reaches the limit: truncated, as the single env."""
    import gymnasium as gym

    import rmm_envs  # noqa: F401

    kw = dict(step_dt=0.25, max_episode_sim_time=0.25 + 1e-9)
    vec = Dubins4DCirclesVectorEnv(2, **kw)
    vec.reset(seed=0)
    a = {"active_ctrl": np.zeros(2, np.int64), "turnrate_ctrl": np.zeros((2, 1)), "accel_ctrl": np.zeros((2, 1))}
    _, _, term, trunc, info = vec.step(a)
    assert trunc.tolist() == [True, True] and not term.any() and info["outcome"].tolist() == ["timeout"] * 2
    single = gym.make("Dubins4DGuarded-v0", **kw)
    single.reset(seed=0)
    assert single.step(single.action_space.inactive())[3]
