"""Walker2d-v5 through the MuJoCo risk adapter: it has no failure test of its own, so it is
labelled with the one the package ships (``--failure rmm_envs.adapters.mujoco_envs:walker2d_unhealthy``,
Gymnasium's unhealthy termination of the walker); the states a failure test receives start with
the time column; ``rmm-datagen`` makes a small dataset with it and refuses every bad ``--failure``
with one message naming the value and what was expected (exit 2, nothing written)."""

from __future__ import annotations

import re

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("mujoco")

from rmm_envs.adapters import adapt  # noqa: E402
from rmm_envs.adapters.mujoco_envs import state_columns, walker2d_unhealthy  # noqa: E402

WALKER = "rmm_envs.adapters.mujoco_envs:walker2d_unhealthy"


def test_walker2d_unhealthy_is_the_envs_own_health_test_on_its_boundaries_and_between():
    env = gym.make("Walker2d-v5")
    env.reset(seed=0)
    ad = adapt(env, walker2d_unhealthy)
    u = env.unwrapped
    rng = np.random.default_rng(0)
    zs = np.concatenate([[0.8, 2.0, np.nextafter(0.8, 1), np.nextafter(2.0, 1)], rng.uniform(0.5, 2.3, 60)])
    angles = np.concatenate([[-1.0, 1.0, np.nextafter(-1.0, 0), np.nextafter(1.0, 0)], rng.uniform(-1.5, 1.5, 60)])
    states = np.repeat(ad.true_state[None], zs.size, axis=0)
    states[:, 2], states[:, 3] = zs, rng.permutation(angles)
    expected = []
    for s in states:
        u.set_state(s[1:10], s[10:19])
        expected.append(not u.is_healthy)
    got = walker2d_unhealthy(states)
    assert got.dtype == bool and got.tolist() == expected
    assert 0 < sum(expected) < len(expected)  # both kinds of state were tried
    with pytest.raises(ValueError, match=r"states must be \(N, 19\) full states of Walker2d-v5 .*got shape \(3, 18\)"):
        walker2d_unhealthy(np.zeros((3, 18)))


def test_column_0_of_the_state_a_failure_test_receives_is_the_time():
    env = gym.make("Walker2d-v5")
    env.reset(seed=1)
    seen = []

    def failure(states):
        seen.append(np.array(states))
        return walker2d_unhealthy(states)

    ad = adapt(env, failure)
    assert state_columns(env.unwrapped.model) == [("time", 0, 1), ("qpos", 1, 10), ("qvel", 10, 19)]
    for _ in range(3):
        env.step(np.zeros(6, dtype=np.float32))
    state = ad.true_state
    assert state[0] == pytest.approx(3 * env.unwrapped.dt) == pytest.approx(env.unwrapped.data.time)
    assert np.array_equal(state[1:10], env.unwrapped.data.qpos) and np.array_equal(
        state[10:19], env.unwrapped.data.qvel
    )
    seen.clear()
    ad.scene.propagate(state[None], np.zeros((1, 6)), 2 * ad.scene.dt, 3)
    assert np.allclose(seen[-1][:, 0], [state[0] + ad.scene.dt, state[0] + 2 * ad.scene.dt])


def test_the_missing_failure_message_names_the_time_column_and_the_shipped_test():
    with pytest.raises(TypeError) as e:
        adapt(gym.make("Walker2d-v5"))
    assert str(e.value) == (
        "Walker2d-v5: no failure test is known for this MuJoCo env (the adapters know InvertedPendulum-v5, "
        "InvertedDoublePendulum-v5, Hopper-v5); give one: failure=callable in Python, --failure module:callable "
        "for rmm-datagen, called as failure(states) -> (N,) bool on (N, 19) full states (column 0 the time, "
        f"columns 1-9 qpos, columns 10-18 qvel); for Walker2d-v5 the package ships one: --failure {WALKER}"
    )


def _datagen(out, *extra):
    from rmm_envs.risk.datagen import main

    args = ["--env", "Walker2d-v5", "--configs", "2", "--samples-per-config", "3", "--branches", "2"]
    return main([*args, "--horizon", "0.04", "--workers", "1", "--no-progress", "--out", str(out), *extra])


def test_datagen_makes_a_walker2d_dataset_with_the_documented_failure_test(tmp_path, capsys):
    from rmm_envs.risk.datagen import load_dataset

    assert _datagen(tmp_path / "d", "--failure", WALKER) == 0
    data = load_dataset(tmp_path / "d")
    assert data.meta["failure"] == WALKER and data.meta["estimator"]["horizon"] == 0.04
    assert (data.meta["state_dim"], data.meta["obs_dim"], data.meta["control_dim"]) == (19, 17, 6)
    assert len(data.risk) == 6 and np.all((data.risk >= 0) & (data.risk <= 1))
    assert not walker2d_unhealthy(data.state).any()  # the sampler keeps healthy states only
    assert np.all(data.state[:, 0] >= 0)  # column 0: the time since the seeded reset
    # the observation stored is the env's own in that state (qpos without x, qvel clipped to 10)
    expected = np.concatenate([data.state[:, 2:10], np.clip(data.state[:, 10:19], -10, 10)], axis=1)
    assert np.allclose(data.obs, expected.astype(np.float32))


PREFIX = "failure (--failure) must be 'module:callable' naming a function failure(states) -> (N,) bool, got "


@pytest.mark.parametrize(
    "spec, why",
    [
        ("no_colon", "not of the form module:callable"),
        ("a:b:c", "not of the form module:callable"),
        (":walker2d_unhealthy", "not of the form module:callable"),
        ("rmm_envs.adapters.mujoco_envs:", "not of the form module:callable"),
        ("no_such_module_26:f", "it cannot be imported (cannot import module 'no_such_module_26': no module named"),
        ("rmm_envs.adapters.mujoco_envs:walker3d", "it cannot be imported (module 'rmm_envs.adapters.mujoco_envs' "),
        (
            "rmm_envs.adapters.mujoco_envs:WALKER2D_STATE_DIM",
            "rmm_envs.adapters.mujoco_envs.WALKER2D_STATE_DIM is 19, ",
        ),
    ],
)
def test_datagen_refuses_a_bad_failure_with_one_message_naming_it(spec, why, tmp_path, capsys):
    assert _datagen(tmp_path / "d", "--failure", spec) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"rmm-datagen: error: {PREFIX}{spec!r}: {why}"), err
    assert not (tmp_path / "d" / "metadata.json").exists()


def test_datagen_refuses_a_missing_or_wrong_shaped_failure_naming_what_is_expected(tmp_path, capsys):
    assert _datagen(tmp_path / "a") == 2
    err = capsys.readouterr().err
    assert re.search(r"Walker2d-v5: no failure test is known.*--failure module:callable.*column 0 the time", err)
    assert f"--failure {WALKER}" in err
    assert _datagen(tmp_path / "b", "--failure", "numpy:isnan") == 2
    err = capsys.readouterr().err
    assert (
        "Walker2d-v5: failure(states) must return shape (1,) for 1 states, got (1, 19) from failure = numpy:isnan"
        in err
    )
    assert not any((tmp_path / d / "metadata.json").exists() for d in "ab")


def test_the_reproduction_report_uses_the_documented_failure_test():
    from pathlib import Path

    page = (Path(__file__).resolve().parents[1] / "docs" / "reproduction.md").read_text()
    section = page[page.index("## Risk labels and a model for Walker2d-v5") :]
    assert f"--env Walker2d-v5 --failure {WALKER} --horizon 0.04" in section
