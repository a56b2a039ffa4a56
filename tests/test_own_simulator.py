"""A simulator of one's own, end to end (:mod:`rmm_envs.envs.any_env`, ``docs/tutorials/own-simulator.md``):
a simulator written only against the snapshot protocol made a guarded env, its hooks and every
refusal, labels and a dataset of it, ``step_dt`` without a ``dt``, rendering, and the tutorial's
script ``docs/examples/own_simulator_wall.py``."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import rmm_envs  # noqa: F401
from rmm_envs.envs.any_env import SIMULATOR_HOOKS, guarded, hooks_table, parallel
from rmm_envs.envs.target_driver import TargetDriver
from rmm_envs.systems.cartpole.guarded import CARTPOLE_K

ROOT = Path(__file__).resolve().parent.parent
TUTORIAL = ROOT / "docs" / "tutorials" / "own-simulator.md"
SCRIPT = ROOT / "docs" / "examples" / "own_simulator_wall.py"
HOOK_DOCS = "(every hook: rmm_envs.envs.any_env.SIMULATOR_HOOKS, docs/tutorials/own-simulator.md)"
GUARDED = "guarded()/parallel() (every env they make: rmm-bench, rmm-datagen)"


class Line:
    """A point on a line moved by its held speed in [-1, 1] for 0.25 s steps; it fails at x >= 1."""

    dt = 0.25
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self, x=0.0):
        self.x = float(x)

    def get_state(self):
        return np.array([self.x])

    def set_state(self, state):
        self.x = float(state[0])

    def step(self, action):
        self.x += self.dt * float(action[0])
        return self.x >= 1.0

    def state_failed(self, states):
        return np.asarray(states)[:, 0] >= 1.0

    def sample_states(self, rng, n):
        return rng.uniform(-1.0, 1.0, (n, 1))

    def render(self, state):
        frame = np.zeros((4, 8, 3), dtype=np.uint8)
        frame[:, int(np.clip((state[0] + 1.0) * 3.5, 0, 7))] = 255
        return frame


def forward(obs):
    return np.array([1.0], np.float32)


def stop(obs):
    return np.array([0.0], np.float32)


def never(obs):
    return False


def steps_until_end(env, seed=0):
    obs, info = env.reset(seed=seed)
    out = [(obs, info)]
    while True:
        obs, _, term, trunc, info = env.step(env.action_space.inactive())
        out.append((obs, info))
        if term or trunc:
            return out


def line_env(sim=None, **kw):
    return guarded(
        Line() if sim is None else sim,
        driver=forward,
        safe_default=np.array([-1.0], np.float32),
        success=never,
        **({"max_episode_sim_time": 10.0} | kw),
    )


# -- a simulator as a guarded env -----------------------------------------------------------------
def test_a_simulator_steps_as_written_and_a_failed_step_is_a_collision():
    env = line_env()
    assert env.dt == env.step_dt == 0.25
    assert env.observation_space == gym.spaces.Box(-np.inf, np.inf, (1,), np.float32)  # observe's default
    steps = steps_until_end(env)
    assert [o.tolist() for o, _ in steps] == [[0.0], [0.25], [0.5], [0.75], [1.0]]
    assert steps[0][0].dtype == np.float32  # the state itself, as float32
    stats = steps[-1][1]["episode_stats"]
    assert steps[-1][1]["outcome"] == "collision" and stats["n_env_steps"] == 4 and stats["cum_sim_time"] == 1.0
    assert [i["cost"] for _, i in steps[1:]] == [0.0, 0.0, 0.0, 1.0]
    # the guardian's control is applied: back 0.25 a step, never failing, until the time is up
    env = line_env(max_episode_sim_time=0.5)
    env.reset(seed=0)
    obs = [env.step(env.action_space.active([-1.0]))[0].tolist() for _ in range(2)]
    assert obs == [[-0.25], [-0.5]]


def test_an_episode_starts_where_the_simulator_was_handed_over_or_at_initial_state():
    env = line_env(Line(0.5))
    assert [o.tolist() for o, _ in steps_until_end(env)] == [[0.5], [0.75], [1.0]]
    assert env.reset(seed=1)[0].tolist() == [0.5]  # the start is restored, not the failed state

    class Drawn(Line):
        def initial_state(self, rng):
            assert isinstance(rng, np.random.Generator)
            return np.array([rng.uniform(-1.0, 0.0)])

    env = line_env(Drawn())
    a, b, c = (env.reset(seed=s)[0][0] for s in (3, 3, 4))
    assert a == b != c and -1.0 <= a <= 0.0


def test_observe_and_observation_space_hooks_make_the_envs_observation():
    class Seen(Line):
        observation_space = gym.spaces.Box(-5.0, 5.0, (2,), np.float64)

        def observe(self, state):
            return np.array([1.0 - state[0], 2.0 * state[0]])

    env = line_env(Seen(0.25))
    obs, _ = env.reset(seed=0)
    assert env.observation_space == Seen.observation_space and obs.tolist() == [0.75, 0.5]
    assert env.step(env.action_space.inactive())[0].tolist() == [0.5, 1.0]
    assert env.privileged() == {"state": pytest.approx(np.array([0.5]))}


# -- the step from step_dt ------------------------------------------------------------------------
class NoDt(Line):
    dt = None

    def step(self, action):  # 0.25 m at full speed, whatever the time
        self.x += 0.25 * float(action[0])
        return self.x >= 1.0


def test_step_dt_is_the_step_of_a_simulator_or_env_without_dt():
    env = line_env(NoDt(), step_dt=0.5, max_episode_sim_time=1.0)
    assert env.dt == env.step_dt == 0.5
    steps = steps_until_end(env)
    assert [o.tolist() for o, _ in steps] == [[0.0], [0.25], [0.5]]  # the simulator's own step, once per 0.5 s
    assert steps[-1][1]["outcome"] == "timeout" and steps[-1][1]["episode_stats"]["cum_sim_time"] == 1.0

    class Counter(gym.Env):  # a Gymnasium env with neither dt nor tau
        observation_space = gym.spaces.Box(0.0, 100.0, (1,), np.float32)
        action_space = gym.spaces.Discrete(2)

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            self.n = 0
            return np.array([0.0], np.float32), {}

        def step(self, action):
            self.n += 1
            return np.array([self.n], np.float32), 0.0, False, False, {}

    kw = dict(driver=lambda obs: 1, safe_default=0, success=never, failure="terminated", max_episode_sim_time=2.0)
    env = guarded(Counter(), step_dt=0.5, **kw)
    steps = steps_until_end(env)
    assert [o.tolist() for o, _ in steps] == [[0.0], [1.0], [2.0], [3.0], [4.0]]
    with pytest.raises(
        ValueError,
        match=r"^Counter states no step length \(an attribute dt or tau on the unwrapped env\); give step_dt "
        r"\(the seconds one env step advances\)$",
    ):
        guarded(Counter(), **kw)
    nb = parallel(Counter(), step_dt=0.5, clock="fixed:0", **kw)
    assert nb.base_step == 0.5
    nb.reset(seed=0)
    assert nb.step(nb.action_space.inactive())[0].tolist() == [1.0]


def balance(obs):
    return TargetDriver(CARTPOLE_K, 0, 2, 0.02, 0.5, 1.0, 1.0, 1.0, 0.2, 1.0, True).balance(obs)


def test_parallel_steps_step_dt_per_base_step():
    env = parallel("CartPole-v1", driver=balance, safe_default=0, success=never, step_dt=0.1, clock="fixed:0")
    assert env.base_step == 0.1 and env.unwrapped.step_dt == 0.1 and env.unwrapped.dt == 0.02
    obs0, _ = env.reset(seed=0)
    raw = gym.make("CartPole-v1").unwrapped
    raw.reset(seed=0)
    raw.state = np.array(env.unwrapped.env.unwrapped.state, dtype=float)
    held = balance(obs0)  # the driver's action at the observed state, held for the whole interval
    for _ in range(5):  # 0.1 s of CartPole's 0.02 s steps
        expected = raw.step(held)[0]
    assert np.array_equal(env.step(env.action_space.inactive())[0], expected)
    assert env.unwrapped._sim_time == 0.1
    # without step_dt, the env's own step, as before
    assert parallel("CartPole-v1", driver=balance, safe_default=0, success=never).base_step == 0.02
    with pytest.raises(
        ValueError, match=r"^parallel\(\): base_step=0.1 and step_dt=0.5 both set the seconds of a base step"
    ):
        parallel("CartPole-v1", driver=balance, safe_default=0, success=never, step_dt=0.5, base_step=0.1)


# -- every refusal ----------------------------------------------------------------------------------
def _without(name):
    return type(f"LineWithout_{name}", (Line,), {name: None})


@pytest.mark.parametrize("name", ["action_space", "get_state", "set_state", "step"])
def test_a_simulator_missing_a_hook_guarded_needs_is_refused_with_what_it_is_for(name):
    hook = SIMULATOR_HOOKS[name]
    cls = _without(name)
    with pytest.raises(TypeError) as e:
        line_env(cls())
    assert (
        str(e.value)
        == f"{cls.__name__} lacks the hook {hook.signature}, which {GUARDED} needs: {hook.purpose} {HOOK_DOCS}"
    )


def test_the_messages_say_what_each_hook_is_for():
    with pytest.raises(TypeError) as e:
        line_env(_without("step")())
    assert str(e.value) == (
        "LineWithout_step lacks the hook step(action) -> bool, which guarded()/parallel() (every env they make: "
        "rmm-bench, rmm-datagen) needs: advance dt seconds under the action and return True when this step failed "
        f"(the episode ends as a collision) {HOOK_DOCS}"
    )
    with pytest.raises(TypeError) as e:
        line_env(NoDt())
    assert str(e.value) == (
        f"NoDt lacks the hook dt (float, seconds), which {GUARDED} without step_dt needs: the simulated seconds "
        f"one step advances {HOOK_DOCS}"
    )


def test_bad_values_are_named():
    class Backwards(Line):
        dt = -1.0

    with pytest.raises(ValueError, match=r"^Backwards: dt must be a finite number of seconds > 0, got -1.0$"):
        line_env(Backwards())
    with pytest.raises(ValueError, match=r"^step_dt must be a finite number of seconds > 0, got 'fast'$"):
        line_env(step_dt="fast")
    with pytest.raises(ValueError, match=r"^failure: the simulator Line reports its failures itself"):
        line_env(failure=lambda obs: False)
    with pytest.raises(ValueError, match=r"^render_mode must be None, 'rgb_array' or 'human', got 'ansi'$"):
        line_env(render_mode="ansi")
    with pytest.raises(
        ValueError, match=r"^Wide: sample_states\(rng, (\d+)\) must return shape \(\1, 1\), got \(\1, 2\)$"
    ):

        class Wide(Line):
            def sample_states(self, rng, n):
                return np.zeros((n, 2))

        env = line_env(Wide())
        env.reset(seed=0)
        env.sample_states(np.random.default_rng(0), 8)
    with pytest.raises(ValueError, match=r"^Point: initial_state\(rng\) must be a \(d,\) float array, got shape \(\)$"):

        class Point(Line):
            def initial_state(self, rng):
                return 0.0

        line_env(Point()).reset(seed=0)


def _register(env_id, cls):
    def entry(clock=None, render_mode=None):
        return guarded(
            cls(),
            driver=forward,
            safe_default=stop,
            success=never,
            max_episode_sim_time=5.0,
            clock=clock,
            render_mode=render_mode,
        )

    if env_id not in gym.registry:
        gym.register(env_id, entry_point=entry)
    return env_id


@pytest.mark.parametrize("name", ["state_failed", "sample_states"])
def test_rmm_datagen_names_the_hook_it_lacks_in_one_line_and_exits_2(name, tmp_path, capsys):
    from rmm_envs.risk.datagen import main

    cls = _without(name)
    env_id = _register(f"OwnLineWithout{name.title().replace('_', '')}-v0", cls)
    status = main(["--env", env_id, "--configs", "1", "--samples-per-config", "4", "--out", str(tmp_path / "d")])
    err = capsys.readouterr().err
    hook = SIMULATOR_HOOKS[name]
    assert status == 2 and err == (
        f"rmm-datagen: error: {cls.__name__} lacks the hook {hook.signature}, which rmm-datagen needs: "
        f"{hook.purpose} {HOOK_DOCS}\n"
    )


def test_rmm_bench_names_the_hook_it_lacks_in_one_line_and_exits_2(tmp_path, capsys):
    from rmm_bench.cli import main

    env_id = _register("OwnLineWithoutStep-v0", _without("step"))
    status = main(
        ["--env", env_id, "--agent", "inactive", "--clock", "fixed:1", "--episodes", "1"] + ["--out", str(tmp_path)]
    )
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and err.startswith("rmm-bench: error: ")
    assert (
        "LineWithout_step lacks the hook step(action) -> bool, which guarded()/parallel()" in err and "rmm-bench" in err
    )


# -- labels and a dataset ---------------------------------------------------------------------------
def test_rmm_datagen_labels_a_simulator_half_from_its_sampler_half_from_the_drivers_states(tmp_path):
    from rmm_envs.risk.datagen import DatagenConfig, generate, load_dataset

    env_id = _register("OwnLine-v0", Line)
    cfg = DatagenConfig(env_id=env_id, configs=2, samples_per_config=8, branches=400, depth=1, seed=0)
    generate(cfg, tmp_path / "d", workers=1, progress=False)
    ds = load_dataset(tmp_path / "d")
    assert ds.meta["estimator"]["horizon"] == 2.5  # no default_horizon: 10 steps
    assert ds.meta["obs_dim"] == ds.meta["state_dim"] == ds.meta["control_dim"] == 1
    assert ds.meta["obs_time_feature"] is None
    np.testing.assert_array_equal(ds.obs, ds.state.astype(np.float32))  # observe's default: the state
    for c in (0, 1):
        x = ds.state[ds.config_id == c, 0]
        assert np.all((-1.0 <= x[:4]) & (x[:4] <= 1.0))  # Line.sample_states
        assert set(x[4:].tolist()) <= {0.0, 0.25, 0.5, 0.75}  # the driver's, from 0 at full speed; 1.0 failed
    # one level of 2.5 s at a held speed a uniform on [-1, 1]: x fails iff a >= (1 - x) / 2.5
    exact = (1.0 - (1.0 - ds.state[:, 0]) / 2.5) / 2.0
    assert np.max(np.abs(ds.risk - exact)) < 0.1  # 400 branches: a standard error of 0.025 at most


def test_a_simulators_hooks_are_the_labelled_envs():
    class Own(Line):
        default_horizon = 0.5

        def privileged(self):
            return {"x": self.x}

        def dataset_notes(self):
            return {"obs_time_feature": "none here"}

    env = line_env(Own(0.75))
    env.reset(seed=0)
    assert env.default_horizon == 0.5 and env.privileged() == {"x": 0.75}
    assert env.dataset_notes() == {"obs_time_feature": "none here"}
    assert env.true_state.tolist() == [0.75] and env.risk_scene().name == "Own"
    from rmm_envs.risk import RiskEstimator

    # from 0.75 in 0.5 s (two steps) it fails iff a >= 0.5; at 1.0 it has failed; from -1 it cannot
    est = RiskEstimator(env.risk_scene(), branches=2000, depth=1, horizon=0.5)
    risk = est.estimate(np.array([[0.75], [1.0], [-1.0]]), np.random.default_rng(0)).risk
    assert abs(risk[0] - 0.25) < 0.04 and risk[1:].tolist() == [1.0, 0.0]
    assert env.true_state.tolist() == [0.75]  # labelling restores the simulator's state


# -- rendering ----------------------------------------------------------------------------------------
def test_a_guarded_simulator_renders_its_rgb_array():
    env_id = _register("OwnLine-v0", Line)
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    assert env.unwrapped.metadata["render_fps"] == 4  # one frame per 0.25 s step
    np.testing.assert_array_equal(env.render(), Line().render(np.array([0.0])))
    env.step(env.action_space.inactive())
    frame = env.render()
    assert frame.shape == (4, 8, 3) and frame.dtype == np.uint8 and frame[0, 4].tolist() == [255, 255, 255]
    with pytest.raises(TypeError, match=r"^LineWithout_render lacks the hook render\(state\) -> \(H, W, 3\) uint8 "):
        line_env(_without("render")(), render_mode="rgb_array")


def test_human_is_the_base_envs_own_window_where_it_has_one():
    class Lamp(gym.Env):
        metadata = {"render_modes": ["human", "rgb_array"]}
        observation_space = gym.spaces.Box(0.0, 1.0, (1,), np.float32)
        action_space = gym.spaces.Discrete(2)
        dt = 0.5

        def __init__(self, render_mode=None):
            self.render_mode, self.shown = render_mode, 0

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            return np.zeros(1, np.float32), {}

        def step(self, action):
            return np.zeros(1, np.float32), 0.0, False, False, {}

        def render(self):
            self.shown += 1

    if "OwnLamp-v0" not in gym.registry:
        gym.register("OwnLamp-v0", entry_point=Lamp)
    kw = dict(driver=lambda obs: 0, safe_default=0, success=never, failure="terminated", max_episode_sim_time=1.0)
    env = guarded("OwnLamp-v0", render_mode="human", **kw)
    env.reset(seed=0)
    assert env.env.unwrapped.render_mode == "human" and env.render() is None and env.env.unwrapped.shown == 1
    with pytest.raises(
        ValueError, match=r"^render_mode='human' needs an env made with it; got an env with render_mode=None"
    ):
        guarded(Lamp(), render_mode="human", **kw)


def test_human_on_a_simulator_shows_its_frames_with_pygame():
    env = line_env(render_mode="human")
    assert env.env.render_mode == "rgb_array"  # the frames come from the simulator's render
    try:
        import pygame  # noqa: F401
    except ImportError:  # shown from reset on, as Gymnasium's own envs do
        with pytest.raises(gym.error.DependencyNotInstalled, match="render_mode='human' needs pygame"):
            env.reset(seed=0)
    else:  # pragma: no cover - needs a display
        pytest.skip("pygame is installed: a window would open")


def test_the_packages_guarded_envs_take_a_render_mode():
    pytest.importorskip("pygame")  # CartPole draws with pygame
    env = gym.make("CartPoleParallel-v0", render_mode="rgb_array", clock="fixed:0")
    env.reset(seed=0)
    assert env.render().shape == (400, 600, 3)


# -- the tutorial and its script ------------------------------------------------------------------------
def test_the_tutorial_lists_every_hook_in_one_table():
    assert hooks_table() in TUTORIAL.read_text()


def _run_script(tmp_path, *args):
    env = dict(os.environ, MPLBACKEND="Agg", TMPDIR=str(tmp_path))
    res = subprocess.run(
        [sys.executable, str(SCRIPT), "--out", str(tmp_path / "work"), *args],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
        env=env,
    )
    assert res.returncode == 0, res.stderr[-3000:]
    with open(tmp_path / "work" / "bench" / "table_I.csv") as f:
        return res.stdout, {r["agent"]: r for r in csv.DictReader(f)}


def test_the_script_goes_from_a_simulator_to_a_table_where_lrmm_fails_less_often(tmp_path):
    out, rows = _run_script(tmp_path, "--configs", "4", "--samples", "32", "--epochs", "100", "--episodes", "16")
    assert list(rows) == ["lrmm", "inactive", "random"] and all(r["episodes"] == "16" for r in rows.values())
    assert float(rows["lrmm"]["collision_mean"]) < float(rows["inactive"]["collision_mean"])
    assert "$ rmm-bench --env own_simulator_wall:CartWall-v0 --agent lrmm,inactive,random" in out
