"""The shared env skeleton (rmm_envs.envs.base) and the LabelledEnv protocol checker."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import rmm_envs  # noqa: F401
from rmm_envs.envs.base import check_arguments, draw_until, option_vector, rejection_sample
from rmm_envs.risk import LabelledEnv, RiskScene, check_labelled_env, check_scene
from rmm_envs.systems.dubins4d.env import Dubins4DGuardedEnv
from rmm_envs.systems.dubins4d.scene import Dubins4DScene
from rmm_envs.systems.maze.env import Dubins3DMazeEnv
from rmm_envs.systems.maze.scene import MazeScene
from rmm_envs.systems.quadrotor.env import QuadrotorRoomEnv


@pytest.mark.parametrize("env_id", ["Dubins4DGuarded-v0", "Dubins4DParallel-v0", "Dubins3DMaze-v0", "QuadrotorRoom-v0"])
def test_every_registered_env_is_a_labelled_env_before_and_after_reset(env_id):
    env = gym.make(env_id)
    check_labelled_env(env)  # on the class: no reset needed
    with pytest.raises(RuntimeError, match=r"call reset\(\) first"):
        env.unwrapped.risk_scene()
    env.reset(seed=0)
    base = env.unwrapped
    assert isinstance(base, LabelledEnv)
    scene = base.risk_scene()
    assert isinstance(scene, RiskScene) and not hasattr(base, "risk_system")  # no former names
    rng = np.random.default_rng(0)
    states = base.sample_states(rng, 5)
    assert states.shape == (5, scene.state_dim) and not scene.state_failed(states).any()
    obs = base.observe_states(states, rng)
    assert obs.shape == (5,) + env.observation_space.shape and obs.dtype == np.float32
    assert base.true_state.shape == (scene.state_dim,)
    assert set(base.dataset_notes()) == {"obs_time_feature"}
    assert "state" in base.privileged()
    env.close()


class _Bad(gym.Env):
    def risk_scene(self, episode):  # an extra required argument
        return None

    def true_state(self):  # a method, not a property
        return None

    sample_states = 3  # not callable

    def observe_states(self, states, rng=None):
        return states

    def privileged(self):
        return {}

    def dataset_notes(self):
        return {}


def test_the_checker_names_the_env_and_each_ill_formed_hook():
    with pytest.raises(TypeError) as e:
        check_labelled_env(_Bad())
    assert str(e.value) == (
        "_Bad is not a LabelledEnv (see rmm_envs.risk.protocol): risk_scene(self, episode) cannot be called as "
        "risk_scene(); true_state must be a property or attribute, not a method; "
        "sample_states must be a method taking (rng, n)"
    )
    check_labelled_env(_Bad(), needs=("observe_states", "privileged"))  # only what is asked for


def test_scene_protocol_asks_only_for_what_the_estimator_uses():
    import rmm_envs.risk as risk
    import rmm_envs.risk.protocol as protocol
    import rmm_envs.systems.dubins4d.env as d4

    for module, old in (
        (risk, "System"),
        (risk, "check_system"),
        (protocol, "System"),
        (protocol, "check_system"),
        (d4, "parse_guardian_action"),
    ):  # no former names kept alive
        assert not hasattr(module, old)

    class Minimal:
        state_dim = 1
        control_low = np.zeros(1)
        control_high = np.ones(1)

        def propagate(self, s, u, d, n): ...

        def path_failed(self, p): ...

        def state_failed(self, s): ...

    check_scene(Minimal())  # no sample_controls, observe or control_dim needed
    with pytest.raises(TypeError, match=r"Minimal2 is not a RiskScene: it lacks \['state_failed'\]"):
        check_scene(_without(Minimal, "state_failed"))
    scene = Dubins4DScene(np.array([[0.0, 0.0, 1.0]]), np.array([5.0, 5.0, 1.0]))
    assert scene.control_dim == 2 and isinstance(scene, RiskScene)


def _without(cls, name):
    attrs = {k: v for k, v in vars(cls).items() if not k.startswith("__") and k != name}
    return type("Minimal2", (), attrs)()


def test_rejection_sample_is_seeded_ordered_and_bounded():
    def draw(r, k):
        return r.uniform(0, 1, (k, 2))

    def rejected(c):
        return c[:, 0] < 0.5

    a = rejection_sample(np.random.default_rng(3), 40, 2, draw, rejected, "points")
    b = rejection_sample(np.random.default_rng(3), 40, 2, draw, rejected, "points")
    np.testing.assert_array_equal(a, b)
    # exactly the accepted rows of the first rounds, in order: round 1 draws 80, round 2 twice the missing
    r = np.random.default_rng(3)
    first = draw(r, 80)
    kept = first[first[:, 0] >= 0.5]
    np.testing.assert_array_equal(a[: min(40, len(kept))], kept[:40])
    assert rejection_sample(np.random.default_rng(0), 0, 2, draw, rejected, "points").shape == (0, 2)
    with pytest.raises(
        RuntimeError, match=r"could not draw 5 points: only 0 of 48 candidates were accepted in 3 rounds"
    ):
        rejection_sample(np.random.default_rng(0), 5, 2, draw, lambda c: np.ones(len(c), bool), "points", max_rounds=3)


def test_draw_until_and_argument_checks():
    it = iter(range(10))
    assert draw_until(lambda: next(it), lambda x: x == 3, 10) == 3
    assert draw_until(lambda: 1, lambda x: False, 5) is None
    with pytest.raises(ValueError, match=r"^n must be an integer >= 1, got 0$"):
        check_arguments([(True, "a", 1, "x"), (False, "n", 0, "an integer >= 1")])
    np.testing.assert_array_equal(option_vector([1, 2], 2, "goal"), [1.0, 2.0])
    for bad in ([1.0], [1.0, np.nan], "ab", {"x": 1}):
        with pytest.raises(ValueError, match=r"option 'goal' must be 2 finite numbers \[x, y\], got"):
            option_vector(bad, 2, "goal", " [x, y]")


@pytest.mark.parametrize("make", [Dubins4DGuardedEnv, Dubins3DMazeEnv, QuadrotorRoomEnv])
def test_running_state_guards_options_and_render_warning(make):
    env = make()
    with pytest.raises(RuntimeError, match=r"call reset\(\) before step\(\)"):
        env.step(env.action_space.sample())
    with pytest.raises(RuntimeError, match=r"call reset\(\) first"):
        env.sample_states(np.random.default_rng(0), 1)
    with pytest.raises(ValueError, match=r"unknown reset options \['bogus'\]; expected any of 'state', "):
        env.reset(seed=0, options={"bogus": 1})
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None
    with pytest.raises(ValueError, match="render_mode must be one of"):
        make(render_mode="nope")
    env.close()


def test_dubins4d_observe_states_needs_its_generator():
    env = Dubins4DGuardedEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="observe_states needs rng, a numpy.random.Generator"):
        env.observe_states(env.sample_states(np.random.default_rng(0), 2))


def test_maze_scene_is_the_env_scene_and_observations_are_named():
    env = gym.make("Dubins3DMaze-v0").unwrapped
    env.reset(seed=1)
    assert isinstance(env.risk_scene(), MazeScene)
    assert env.observation_space.layout["rays"] == slice(0, 8)
    q = gym.make("QuadrotorRoom-v0").unwrapped
    lay = q.observation_space.layout
    assert [lay[n] for n in lay.names] == [slice(0, 4), slice(4, 6), slice(6, 10), slice(10, 13), slice(13, 16)]
    assert lay.ray_index(np.pi / 2) == 1 and lay.names[1] == "rays_vertical"
    q.close()


@pytest.mark.parametrize(
    "env_id", ["Dubins4DParallel-v0", "Dubins3DMazeParallel-v0", "QuadrotorRoomParallel-v0", "Dubins4DMapParallel-v0"]
)
def test_parallel_envs_refuse_step_dt_which_non_blocking_stepping_would_ignore(env_id):
    import gymnasium as gym

    with pytest.raises(ValueError) as e:
        gym.make(env_id, step_dt=5.0)
    assert str(e.value) == (
        f"{env_id} steps by elapsed * time_accel + base_step, so step_dt (the fixed step of the "
        "blocking env) does not apply; set base_step and time_accel instead, got step_dt=5.0"
    )
    env = gym.make(env_id, base_step=0.2, clock="fixed:0")
    env.reset(seed=0)
    _, _, _, _, info = env.step(
        env.action_space.inactive() if hasattr(env.action_space, "inactive") else env.unwrapped.action_space.inactive()
    )
    assert abs(info["sim_time"] - 0.2) < 1e-9  # the first interval: base_step, the driver's
    env.close()
