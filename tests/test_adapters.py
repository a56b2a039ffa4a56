"""Risk adapters for simulators the project did not write (rmm_envs.adapters): the batched
dynamics pinned to the envs' own step, failure pinned to their termination, labels as
properties (range, order, determinism), the snapshot protocol and every refusal."""

from __future__ import annotations

from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_envs.adapters import SimulatorScene, SnapshotScene, adapt, snapshot_of, step_by_step
from rmm_envs.risk import RiskEstimator
from rmm_envs.wrappers import RiskLabel


def needs_mujoco(env_id: str) -> None:
    """The MuJoCo envs need the optional extra (in the test extra); the rest runs without it."""
    if env_id.endswith("-v5"):
        pytest.importorskip("mujoco")


SPEED_BOUND = 6.0


def speed_failure(states):
    return np.abs(states[:, 1]) > SPEED_BOUND


def made(env_id, failure=None, **kwargs):
    needs_mujoco(env_id)
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    return env, adapt(env, failure)


finite = st.floats(-3, 3, allow_nan=False)


# -- batched dynamics == the env's own step ---------------------------------------------------
@settings(max_examples=60, deadline=None)
@given(
    x=finite,
    xd=finite,
    th=st.floats(-0.5, 0.5),
    thd=finite,
    action=st.integers(0, 1),
    integrator=st.sampled_from(["euler", "semi-implicit"]),
)
def test_cartpole_batched_step_is_the_envs_step_bit_for_bit(x, xd, th, thd, action, integrator):
    env, ad = made("CartPole-v1")
    env.unwrapped.kinematics_integrator = integrator
    scene = type(ad.scene)(env)
    env.unwrapped.state = np.array([x, xd, th, thd])
    env.unwrapped.step(action)
    ours = scene.step(np.array([[x, xd, th, thd]]), np.array([[action]]))[0]
    assert np.array_equal(ours, env.unwrapped.state)


@settings(max_examples=60, deadline=None)
@given(th=st.floats(-7, 7), thd=st.floats(-8, 8), u=st.floats(-3, 3, width=32))
def test_pendulum_batched_step_is_the_envs_step_bit_for_bit(th, thd, u):
    env, ad = made("Pendulum-v1", speed_failure, g=9.81)
    env.unwrapped.state = np.array([th, thd])
    env.unwrapped.step(np.array([u], dtype=np.float32))
    ours = ad.scene.step(np.array([[th, thd]]), np.array([[u]]))[0]
    assert ad.scene.p["g"] == 9.81 and np.array_equal(ours, env.unwrapped.state)


@pytest.mark.parametrize(
    "env_id, failure, tol",
    [
        ("CartPole-v1", None, 0.0),
        ("Pendulum-v1", speed_failure, 0.0),
        ("InvertedPendulum-v5", None, 0.0),
        ("InvertedDoublePendulum-v5", None, 0.0),
        ("Hopper-v5", None, 1e-9),
    ],
)
def test_batched_paths_equal_the_step_by_step_paths_through_the_envs_own_step(env_id, failure, tol):
    """The same held controls from the same sampled states: the batched scene's paths (NaN from
    the first failed env step on) are the step-by-step scene's, which calls env.step."""
    env, ad = made(env_id, failure)
    rng = np.random.default_rng(3)
    states = ad.sample_states(rng, 24)
    controls = rng.uniform(ad.scene.control_low, ad.scene.control_high, size=(24, len(ad.scene.control_low)))
    t = 4 * ad.scene.dt
    fast = ad.scene.propagate(states, controls, t, 5)
    slow = step_by_step(ad).propagate(states, controls, t, 5)
    assert fast.shape == (24, 5, ad.scene.state_dim)
    assert np.array_equal(np.isnan(fast), np.isnan(slow))
    assert np.nanmax(np.abs(fast - slow)) <= tol
    assert np.array_equal(fast[:, 0], states)
    # the step-by-step scene leaves the env where it found it
    assert np.array_equal(snapshot_of(ad).get_state(), ad.true_state)


@pytest.mark.parametrize("env_id", ["CartPole-v1", "InvertedPendulum-v5", "InvertedDoublePendulum-v5", "Hopper-v5"])
def test_failure_is_the_envs_termination(env_id):
    """Random actions until the env terminates, several episodes: after every step the scene's
    failure test of the true state says what the env's ``terminated`` says."""
    env, ad = made(env_id)
    env.action_space.seed(0)
    seen = {True: 0, False: 0}
    for episode in range(4):
        env.reset(seed=episode)
        for _ in range(300):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            assert bool(ad.scene.state_failed(ad.true_state[None])[0]) == terminated
            seen[terminated] += 1
            if terminated or truncated:
                break
    assert seen[True] >= 1 and seen[False] >= 1, seen


def test_observe_states_is_the_envs_own_observation():
    for env_id in ("CartPole-v1", "Pendulum-v1", "InvertedDoublePendulum-v5", "Hopper-v5"):
        env, ad = made(env_id, speed_failure if env_id == "Pendulum-v1" else None)
        for _ in range(5):
            obs = env.step(env.action_space.sample())[0]
            assert np.allclose(ad.observe_states(ad.true_state[None])[0], obs, atol=1e-6, rtol=0), env_id


# -- hand-computed labels ---------------------------------------------------------------------
def test_cartpole_hand_computed_risks():
    """t = 0.08 s (4 steps), m = 2: two full pushes the same way tip a pole upright at rest to
    9.5 deg (< 12), so no branch fails: risk exactly 0; a pole at 11.5 deg turning outwards at
    2 rad/s passes 12 deg on the first step whatever the push: risk exactly 1."""
    _, ad = made("CartPole-v1")
    assert ad.scene.default_horizon == pytest.approx(0.08) and ad.scene.env_steps(0.08) == 4
    est = RiskEstimator(ad.scene, horizon=0.08)
    r = est.estimate(np.array([[0, 0, 0, 0], [0, 0, np.radians(11.5), 2.0]], float), np.random.default_rng(0))
    assert r.risk.tolist() == [0.0, 1.0]
    eight = np.zeros((1, 4))
    for _ in range(8):
        eight = ad.scene.step(eight, np.array([[0]]))
    assert np.degrees(eight[0, 2]) == pytest.approx(9.534, abs=1e-3)
    assert not ad.scene.state_failed(eight)[0] and ad.scene.state_failed(ad.scene.step(eight, np.array([[0]])))[0]


def test_discrete_controls_map_to_actions_uniformly():
    _, ad = made("CartPole-v1")
    assert ad.scene.control_low.tolist() == [0.0] and ad.scene.control_high.tolist() == [2.0]
    assert ad.scene.to_actions(np.array([[0.0], [0.999], [1.0], [1.999], [2.0]]))[:, 0].tolist() == [0, 0, 1, 1, 1]


def test_paths_are_nan_from_the_first_failed_step_and_hold_whole_env_steps():
    _, ad = made("CartPole-v1")
    start = np.array([[0, 0, np.radians(11.5), 2.0], [0, 0, 0, 0]])
    paths = ad.scene.propagate(start, np.array([[1.5], [1.5]]), 0.1, 6)  # 5 env steps, one point each
    assert np.isnan(paths[0, 1:]).all() and np.isfinite(paths[1]).all()
    assert ad.scene.path_failed(paths).tolist() == [True, False]
    one = np.zeros((1, 4))
    for k in range(1, 6):
        one = ad.scene.step(one, np.array([[1]]))
        assert np.array_equal(paths[1, k], one[0])


# -- labels as properties -------------------------------------------------------------------
ORDERED = [  # env, failure, (near failure, moving away), (upright at rest)
    ("CartPole-v1", None, [0, 0, 0.19, 0.8], [0, 0, 0, 0]),
    ("Pendulum-v1", speed_failure, [0.6, 5.0], [0.0, 0.0]),
    ("InvertedPendulum-v5", None, "qpos1=0.18, qvel1=1.0", "rest"),
    ("InvertedDoublePendulum-v5", None, "qpos1=0.25, qvel1=2.0", "rest"),
    ("Hopper-v5", None, "qpos2=0.18, qvel2=1.5", "rest"),
]


def _state(ad, spec):
    if not isinstance(spec, str):
        return np.asarray(spec, float)
    sc = ad.scene
    s = np.zeros(sc.state_dim)
    s[sc.qpos0 : sc.qpos0 + sc.nq] = ad.unwrapped.init_qpos
    for item in [] if spec == "rest" else spec.split(", "):
        key, value = item.split("=")
        base = sc.qpos0 if key.startswith("qpos") else sc.qvel0
        s[base + int(key[4:])] = float(value)
    return s


@pytest.mark.parametrize("env_id, failure, risky, safe", ORDERED)
def test_near_failure_and_moving_away_is_riskier_than_upright_at_rest(env_id, failure, risky, safe):
    needs_mujoco(env_id)
    env = RiskLabel(gym.make(env_id), failure=failure, seed=0)
    env.reset(seed=0)
    ad = env._hooks
    states = np.stack([_state(ad, risky), _state(ad, safe)])
    est = RiskEstimator(ad.scene, horizon=ad.scene.default_horizon)
    r = est.estimate(states, np.random.default_rng(0)).risk
    assert not ad.scene.state_failed(states).any()
    assert r[0] > r[1] + 0.3, r


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), metric=st.sampled_from(["expected", "cvar", "worst"]))
def test_labels_lie_in_0_1_and_a_seed_fixes_them(seed, metric):
    for env_id, failure in (("CartPole-v1", None), ("Pendulum-v1", speed_failure), ("InvertedPendulum-v5", None)):
        env, ad = made(env_id, failure)
        states = ad.sample_states(np.random.default_rng(seed), 6)
        kw = dict(
            branches=6,
            depth=2,
            horizon=ad.scene.default_horizon,
            metric=metric,
            alpha=0.3 if metric == "cvar" else None,
        )
        a = RiskEstimator(ad.scene, **kw).estimate(states, np.random.default_rng(seed)).risk
        b = RiskEstimator(ad.scene, **kw).estimate(states, np.random.default_rng(seed)).risk
        assert np.all((a >= 0) & (a <= 1)) and np.array_equal(a, b)


def test_risklabel_on_an_adapted_env_is_deterministic_under_a_seed():
    def run(seed):
        env = RiskLabel(gym.make("CartPole-v1"), branches=8, seed=seed)
        out = [env.reset(seed=1)[1]["risk"]]
        for a in (0, 1, 1, 0, 0):
            out.append(env.step(a)[4]["risk"])
        return out

    first = run(7)
    assert first == run(7) and all(0 <= r <= 1 for r in first)


def test_sample_states_are_non_failed_and_fixed_by_the_generator():
    for env_id, failure in (("CartPole-v1", None), ("Pendulum-v1", speed_failure), ("Hopper-v5", None)):
        _, ad = made(env_id, failure)
        a = ad.sample_states(np.random.default_rng(4), 20)
        b = ad.sample_states(np.random.default_rng(4), 20)
        assert a.shape == (20, ad.scene.state_dim) and np.array_equal(a, b)
        assert not ad.scene.state_failed(a).any()


# -- the snapshot protocol on a simulator of one's own --------------------------------------
class Cliff:
    """A point on a line moving at the held speed; a step that ends past x = 1 reports failure
    (the state itself never fails: the failure is the step's)."""

    dt = 0.5
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self):
        self.x = np.zeros(1)

    def get_state(self):
        return self.x.copy()

    def set_state(self, state):
        self.x = np.array(state, float)

    def step(self, action):
        self.x = self.x + self.dt * float(action[0])
        return bool(self.x[0] > 1.0)

    def state_failed(self, states):
        return np.zeros(len(states), dtype=bool)


def test_a_simulator_of_ones_own_is_labelled_through_the_snapshot_protocol():
    scene = SnapshotScene(Cliff(), name="Cliff")
    # from x = 0.75 one step at +1 ends at 1.25: a step failure, the path is NaN from there
    paths = scene.propagate(np.array([[0.75], [0.0]]), np.array([[1.0], [1.0]]), 1.0, 3)
    assert np.isnan(paths[0, 1:]).all() and paths[1, :, 0].tolist() == [0.0, 0.5, 1.0]
    assert scene.path_failed(paths).tolist() == [True, False]
    # one level, t = 0.5 s: exactly the controls above 0.5 from x = 0.75 fail
    est = RiskEstimator(scene, branches=4, depth=1, horizon=0.5)
    controls = [np.array([[[0.9], [0.2], [0.6], [-1.0]]])]
    assert est.estimate(np.array([[0.75]]), controls=controls).risk.tolist() == [0.5]


# -- refusals -------------------------------------------------------------------------------
def test_pendulum_without_a_failure_is_refused_by_name():
    with pytest.raises(TypeError, match=r"^Pendulum-v1 never terminates.*failure=callable.*--failure"):
        RiskLabel(gym.make("Pendulum-v1"))


def test_an_env_no_adapter_serves_is_refused_listing_what_is_missing():
    with pytest.raises(
        TypeError,
        match=r"Acrobot-v1 \(AcrobotEnv\) is not a LabelledEnv.*risk_scene is missing; "
        r"true_state is missing; no risk adapter serves it either.*SnapshotSimulator",
    ):
        RiskLabel(gym.make("Acrobot-v1"))


def test_a_mujoco_env_without_a_known_failure_needs_one():
    needs_mujoco("Swimmer-v5")
    with pytest.raises(
        TypeError,
        match=r"^Swimmer-v5: no failure test is known.*give one: failure=callable in Python, --failure "
        r"module:callable for rmm-datagen, called as failure\(states\) -> \(N,\) bool on \(N, 11\) full states "
        r"\(column 0 the time, columns 1-5 qpos, columns 6-10 qvel\)$",
    ):
        adapt(gym.make("Swimmer-v5"))
    ad = adapt(gym.make("Swimmer-v5"), failure=lambda s: np.abs(s[:, 3]) > 1.0)
    assert ad.scene.default_horizon == pytest.approx(2 * ad.scene.dt)


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        (
            {"failure": 3},
            TypeError,
            r"CartPole-v1: failure must be a callable failure\(states \(N, d\)\) -> \(N,\) bool, got 3",
        ),
        (
            {"horizon": 0.03},
            ValueError,
            r"CartPole-v1: the horizon t = 0.03 s must be a whole number >= 1 of the env's steps "
            r"of dt = 0.02 s \(for example 0.04\)",
        ),
        ({"horizon": 0.005}, ValueError, r"t = 0.005 s must be a whole number >= 1"),
    ],
)
def test_bad_adapter_arguments_are_refused_by_name(kwargs, error, match):
    with pytest.raises(error, match=match):
        RiskLabel(gym.make("CartPole-v1"), **kwargs)


def test_a_failure_of_the_wrong_shape_is_refused_by_name():
    env = RiskLabel(gym.make("Pendulum-v1"), failure=lambda s: np.abs(s) > 1, seed=0)
    with pytest.raises(
        ValueError,
        match=r"Pendulum-v1: failure\(states\) must return shape \(1,\) for 1 states, got \(1, 2\) "
        r"from failure = tests.test_adapters:test_a_failure_of_the_wrong_shape_is_refused_by_name.<locals>.<lambda>",
    ):
        env.reset(seed=0)


def test_failure_for_a_package_env_is_refused():
    with pytest.raises(TypeError, match=r"failure= is for envs served by a risk adapter"):
        RiskLabel(gym.make("Dubins4DGuarded-v0"), failure=speed_failure)


def test_an_object_that_is_not_a_snapshot_simulator_is_refused_listing_what_it_lacks():
    class Half:
        dt = 0.1
        action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

        def get_state(self):
            return np.zeros(2)

    with pytest.raises(TypeError, match=r"Half is not a SnapshotSimulator.*\['set_state', 'step', 'state_failed'\]"):
        SnapshotScene(Half())


def test_an_unbounded_action_space_is_refused_by_name():
    with pytest.raises(
        TypeError, match=r"Mine: its action space Box\(-inf, inf, \(1,\), float32\) cannot be sampled uniformly"
    ):
        SimulatorScene("Mine", 2, 0.1, gym.spaces.Box(-np.inf, np.inf, (1,), np.float32))
    with pytest.raises(
        ValueError, match=r"Mine: the env's step length dt must be a finite number of seconds > 0, got 0.0"
    ):
        SimulatorScene("Mine", 2, 0.0, gym.spaces.Discrete(3))


# -- datasets of adapted envs (rmm-datagen) -------------------------------------------------
def test_datagen_labels_cartpole_with_the_adapters_sampler_and_horizon(tmp_path):
    from rmm_envs.risk.datagen import DatagenConfig, generate, load_dataset

    tiny = dict(env_id="CartPole-v1", configs=2, samples_per_config=8, branches=4, configs_per_shard=1, seed=3)
    one = generate(DatagenConfig(**tiny), tmp_path / "a", workers=1, progress=False)
    two = generate(DatagenConfig(**tiny), tmp_path / "b", workers=2, progress=False)
    assert one["dataset_sha256"] == two["dataset_sha256"]
    data = load_dataset(tmp_path / "a")
    assert data.meta["estimator"]["horizon"] == 0.08 and data.meta["failure"] is None
    assert (data.meta["obs_dim"], data.meta["state_dim"], data.meta["control_dim"]) == (4, 4, 1)
    assert np.array_equal(data.obs, data.state.astype(np.float32))
    assert np.all((data.risk >= 0) & (data.risk <= 1))
    # the labels are the estimator's on the sampled states, with the configuration's generator
    from rmm_envs.risk.labelling import config_seeds

    env, ad = made("CartPole-v1")
    _, rng = config_seeds(3, 0)
    states = ad.sample_states(rng, 8)
    risk = RiskEstimator(ad.scene, branches=4, horizon=0.08).estimate(states, rng).risk
    assert np.array_equal(data.state[:8], states) and np.array_equal(data.risk[:8], risk)


def test_datagen_failure_is_imported_by_name_and_recorded(tmp_path, monkeypatch):
    from rmm_envs.risk.datagen import main

    (tmp_path / "pendulum_failure.py").write_text(
        "import numpy as np\n\ndef too_fast(s):\n    return np.abs(s[:, 1]) > 6.0\n\nnot_callable = 3\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    args = ["--env", "Pendulum-v1", "--configs", "1", "--samples-per-config", "4", "--branches", "2", "--no-progress"]
    assert main(args + ["--out", str(tmp_path / "ok"), "--failure", "pendulum_failure:too_fast"]) == 0
    import json

    assert json.loads((tmp_path / "ok" / "metadata.json").read_text())["failure"] == "pendulum_failure:too_fast"


@pytest.mark.parametrize(
    "extra, match",
    [
        ([], r"Pendulum-v1 never terminates.*--failure module:callable"),
        (["--failure", "no_colon"], r"failure \(--failure\) must be 'module:callable'.*, got 'no_colon': not of"),
        (
            ["--failure", "no_such_module_26:f"],
            r"failure \(--failure\) must be 'module:callable'.*, got 'no_such_module_26:f': it cannot be imported "
            r"\(cannot import module .no_such_module_26.: no module named",
        ),
        (
            ["--failure", "numpy:pi"],
            r"failure \(--failure\) must be 'module:callable'.*, got 'numpy:pi': numpy.pi is 3.14",
        ),
    ],
)
def test_datagen_refuses_a_missing_or_bad_failure_by_name(extra, match, tmp_path, capsys):
    from rmm_envs.risk.datagen import main

    out = tmp_path / "d"
    assert main(["--env", "Pendulum-v1", "--configs", "1", "--out", str(out), "--no-progress", *extra]) == 2
    import re

    assert re.search(match, capsys.readouterr().err) and not (out / "metadata.json").exists()


def test_datagen_refuses_a_failure_for_a_package_env(tmp_path, capsys):
    from rmm_envs.risk.datagen import main

    assert (
        main(
            [
                "--env",
                "Dubins4DGuarded-v0",
                "--configs",
                "1",
                "--out",
                str(tmp_path / "d"),
                "--no-progress",
                "--failure",
                "numpy:isnan",
            ]
        )
        == 2
    )
    assert (
        "failure (--failure) is for envs served by a risk adapter; Dubins4DGuarded-v0 defines its own"
        in capsys.readouterr().err
    )


def test_adapted_envs_follow_the_labelled_env_protocol_and_sampling_leaves_the_episode_alone():
    from rmm_envs.risk import check_labelled_env

    for env_id, failure in (("CartPole-v1", None), ("Pendulum-v1", speed_failure), ("Hopper-v5", None)):
        env, ad = made(env_id, failure)
        check_labelled_env(SimpleNamespace(unwrapped=ad))  # the hooks are the adapter's (its .unwrapped is the env's)
        before = ad.true_state
        ad.sample_states(np.random.default_rng(0), 5)
        assert np.array_equal(ad.true_state, before)
        assert ad.privileged()["state"].tolist() == before.tolist() and ad.dataset_notes() == {"obs_time_feature": None}
    # the env's generator is untouched by the MuJoCo sampler's resets
    a, b = made("Hopper-v5")[0], made("Hopper-v5")
    adapt(b[0]).sample_states(np.random.default_rng(0), 3)
    assert np.array_equal(a.reset()[0], b[0].reset()[0])


def test_true_state_before_reset_is_refused():
    with pytest.raises(RuntimeError, match=r"CartPole-v1 has no state before its first reset"):
        _ = adapt(gym.make("CartPole-v1")).true_state


MY_MODULE = """import gymnasium as gym

if "MyCartPole-v0" not in gym.registry:
    gym.register("MyCartPole-v0", entry_point="gymnasium.envs.classic_control:CartPoleEnv", max_episode_steps=200)
"""


def test_the_two_commands_the_lrmm_refusal_names_make_a_model_for_a_module_env(tmp_path, monkeypatch):
    """An env of one's own (``module:Id``, the module in the current directory) has no shipped
    model; the refusal names two commands, and running exactly those (sized down) makes one."""
    import re
    import shlex

    from rmm_envs.risk.datagen import main as datagen_main
    from rmm_guardians.lrmm.model import LRMMModel, default_model_path
    from rmm_guardians.lrmm.train import main as train_main

    (tmp_path / "mycartpole.py").write_text(MY_MODULE)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("sys.path", list(__import__("sys").path))  # datagen puts the cwd first
    with pytest.raises(ValueError) as e:
        default_model_path("mycartpole:MyCartPole-v0")
    msg = str(e.value)
    m = re.search(
        r"two commands: rmm-datagen (.*) and rmm-train (.*); then give it: --agent-opt lrmm\.model='\"(.*)\"'", msg
    )
    assert m and msg.startswith("no shipped LRMM model for 'mycartpole:MyCartPole-v0' (shipped for ['"), msg
    assert (
        datagen_main(
            shlex.split(m.group(1))
            + ["--configs", "3", "--samples-per-config", "8", "--branches", "4", "--workers", "2", "--no-progress"]
        )
        == 0
    )
    assert train_main(shlex.split(m.group(2)) + ["--epochs", "2", "--quiet"]) == 0
    model = LRMMModel.load(tmp_path / m.group(3))
    assert model.env_id == "mycartpole:MyCartPole-v0" and model.obs_dim == 4


def test_datagen_names_a_module_that_fails_to_import_and_the_nearest_id_of_a_typo(tmp_path, monkeypatch, capsys):
    from rmm_envs.risk.datagen import main

    (tmp_path / "brokenmod26.py").write_text("undefined_name_in_module\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("sys.path", list(__import__("sys").path))
    assert main(["--env", "brokenmod26:X-v0", "--out", str(tmp_path / "d"), "--no-progress"]) == 2
    assert (
        "cannot import module 'brokenmod26' (from brokenmod26.py): "
        "NameError: name 'undefined_name_in_module' is not defined"
    ) in capsys.readouterr().err
    assert main(["--env", "CartPoleGuardd-v0", "--out", str(tmp_path / "d"), "--no-progress"]) == 2
    assert "is not a registered Gymnasium env (did you mean 'CartPoleGuarded-v0'?)" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize(
    "env, match",
    [
        ("no_such_module_26:X-v0", r"env 'no_such_module_26:X-v0': cannot import module 'no_such_module_26'"),
        (
            "mycartpole:Other-v0",
            r"env 'mycartpole:Other-v0': importing 'mycartpole' \(from .*mycartpole\.py\) registered no env 'Other-v0'",
        ),
    ],
)
def test_datagen_refuses_a_module_env_that_does_not_register_by_name(env, match, tmp_path, monkeypatch, capsys):
    import re

    from rmm_envs.risk.datagen import main

    (tmp_path / "mycartpole.py").write_text(MY_MODULE)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("sys.path", list(__import__("sys").path))
    assert main(["--env", env, "--out", str(tmp_path / "d"), "--no-progress"]) == 2
    assert re.search(match, capsys.readouterr().err)
