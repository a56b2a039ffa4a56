"""``rmm-envs``: the driver-only demo, read off the env's action space."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from rmm_envs.autonomy import GuardianActionSpace
from rmm_envs.cli import driver_only_action, main


def test_driver_only_action_is_read_off_the_action_space():
    env = gym.make("Dubins4DGuarded-v0")
    a = driver_only_action(env.action_space, "Dubins4DGuarded-v0")
    env.close()
    assert set(a) == {"active_ctrl", "turnrate_ctrl", "accel_ctrl"} and a["active_ctrl"] == 0
    for k in ("turnrate_ctrl", "accel_ctrl"):
        assert a[k].dtype == np.float64 and a[k].shape == (1,) and not a[k].any()
    other = GuardianActionSpace(("thrust", "roll"), [0.0, -1.0], [2.0, 1.0])
    b = driver_only_action(other, "Other-v0")
    assert b["active_ctrl"] == 0 and set(b) == {"active_ctrl", "thrust", "roll"} and not b["thrust"].any()
    plain = spaces.Dict({"active_ctrl": spaces.Discrete(2), "thrust": spaces.Box(-1.0, 1.0, (3,), dtype=np.float64)})
    with pytest.raises(ValueError, match="env Plain-v0 has no guardian action .* not a GuardianActionSpace"):
        driver_only_action(plain, "Plain-v0")
    with pytest.raises(
        ValueError,
        match=r"env Box-v0 has no guardian action .* its action space is Box\(-1\.0, 1\.0, \(2,\), float32\)",
    ):
        driver_only_action(spaces.Box(-1.0, 1.0, (2,), dtype=np.float32), "Box-v0")


def test_demo_prints_what_the_driver_alone_does(capsys):
    assert main(["demo", "--env", "Dubins4DGuarded-v0", "--episodes", "1", "--seed", "4"]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    env = gym.make("Dubins4DGuarded-v0")
    env.reset(seed=4)
    action = {"active_ctrl": 0, "turnrate_ctrl": np.zeros(1, np.float32), "accel_ctrl": np.zeros(1, np.float32)}
    while True:
        _, _, term, trunc, info = env.step(action)
        if term or trunc:
            break
    st = info["episode_stats"]
    assert line == (
        f"episode   0 seed     4: {info['outcome']:9s} after {st['n_env_steps']:4d} steps, "
        f"{st['cum_sim_time']:6.1f} s simulated, final speed {st['final_speed']:.2f} m/s"
    )


def test_demo_refuses_an_env_without_a_guardian_action_and_bad_counts(capsys):
    # --env offers only the envs with a built-in driver: a plain-control env is refused by argparse
    with pytest.raises(SystemExit) as e:
        main(["demo", "--env", "Dubins3DMaze-v0", "--episodes", "1"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'Dubins3DMaze-v0'" in err and "QuadrotorRoomGuarded-v0" in err
    assert main(["demo", "--episodes", "0"]) == 2
    assert "--episodes must be >= 1, got 0" in capsys.readouterr().err
