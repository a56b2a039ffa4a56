"""The native vector env never changes an array after returning it (``rmm_envs/envs/dubins4d_vector.py``).

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

from rmm_envs.envs.dubins4d_vector import Dubins4DCirclesVectorEnv

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
    return {"active_ctrl": (rng.random(N) < active_p).astype(np.int64),
            "turnrate_ctrl": rng.uniform(-0.25, 0.25, (N, 1)), "accel_ctrl": rng.uniform(-0.5, 0.5, (N, 1))}


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
@given(seed=st.integers(0, 2 ** 16), masks=st.lists(st.lists(st.booleans(), min_size=N, max_size=N), min_size=1, max_size=4))
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
