"""Mistakes in a user's own code, each said in one line that names where it is and what to do:
an env whose constructor raises (rmm-datagen and rmm-bench alike, exit 2), an env or driver that
raises while a dataset is labelled, a simulator without ``render`` (its render modes), a parent
package that fails to import, a policy function given as ``--agent module:fn``, and ``lrmm`` on
an env of one's own (its advice on the command line, its warnings' location)."""

from __future__ import annotations

import os
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import rmm_envs  # noqa: F401
from rmm_envs.env_plugins import describe_env_error
from rmm_envs.envs.any_env import guarded, parallel

HERE = os.path.relpath(__file__) if not os.path.relpath(__file__).startswith("..") else __file__
ERRORS = {e.__name__: e for e in (AttributeError, KeyError, IndexError, ZeroDivisionError, ValueError, RuntimeError)}
ERRORS["TypeError"] = TypeError


# -- 1. an env that cannot be built -----------------------------------------------------------------
def broken_env(kind="AttributeError", size=1, clock=None):
    if size < 0:
        raise ValueError(f"size must be >= 0, got {size}")
    raise ERRORS[kind]("the simulator's table is empty")


for _id in ("BrokenCtor-v0",):
    if _id not in gym.registry:
        gym.register(_id, entry_point=broken_env)


def _said(kind: str) -> str:
    shown = str(KeyError("the simulator's table is empty")) if kind == "KeyError" else "the simulator's table is empty"
    return f"--env BrokenCtor-v0: {kind}: {shown}"


@pytest.mark.parametrize("kind", list(ERRORS))
def test_describe_env_error_is_one_line_with_the_type_for_any_exception(kind):
    try:
        gym.make("BrokenCtor-v0", kind=kind)
    except Exception as e:  # noqa: BLE001 - each kind in turn
        said = describe_env_error(e, "BrokenCtor-v0", {"kind": kind})
    assert said == _said(kind)
    assert "was raised from the environment creator" not in said and "\n" not in said


def test_describe_env_error_names_the_option_its_message_names():
    try:
        gym.make("BrokenCtor-v0", size=-1)
    except ValueError as e:
        assert describe_env_error(e, "BrokenCtor-v0", {"size": -1}) == "--size -1: size must be >= 0, got -1"
        named = describe_env_error(e, "BrokenCtor-v0", {"size": -1}, lambda k, v: f"--env-kwargs {k}={v}")
        assert named == "--env-kwargs size=-1: size must be >= 0, got -1"


@pytest.mark.parametrize("kind", list(ERRORS))
def test_rmm_datagen_says_an_env_that_cannot_be_built_in_one_line_and_exits_2(kind, tmp_path, capsys):
    from rmm_envs.risk.datagen import main

    status = main(["--env", "BrokenCtor-v0", "--env-opt", f'kind="{kind}"', "--out", str(tmp_path / "d")])
    assert (status, capsys.readouterr().err) == (2, f"rmm-datagen: error: {_said(kind)}\n")
    assert not (tmp_path / "d").exists()


def test_rmm_datagen_names_the_env_option_the_constructor_names(tmp_path, capsys):
    from rmm_envs.risk.datagen import main

    status = main(["--env", "BrokenCtor-v0", "--env-opt", "size=-1", "--out", str(tmp_path / "d")])
    assert (status, capsys.readouterr().err) == (
        2,
        "rmm-datagen: error: --env-opt size=-1: size must be >= 0, got -1\n",
    )


@pytest.mark.parametrize(
    "argv, message",
    [
        (
            ["--env-kwargs", '{"size": 1}'],
            "--env-kwargs is no longer accepted; use --env-opt KEY=JSON, once per argument",
        ),
        (["--env-opt", "size"], "--env-opt 'size': expected KEY=JSON, e.g. maze_kind='\"mixed\"'"),
        (["--env-opt", "=1"], "--env-opt '=1': expected KEY=JSON, e.g. maze_kind='\"mixed\"'"),
        (["--env-opt", "kind=mixed"], "--env-opt 'kind=mixed': the value 'mixed' is not JSON (a string needs quotes)"),
        (
            ["--env-opt", "size=1", "--env-opt", "size=2"],
            "--env-opt 'size=2': size is given twice; give each argument once",
        ),
    ],
)
def test_rmm_datagen_refuses_bad_env_options_in_one_line(argv, message, tmp_path, capsys):
    from rmm_envs.risk.datagen import main

    assert main(["--env", "BrokenCtor-v0", *argv, "--out", str(tmp_path / "d")]) == 2
    assert capsys.readouterr().err == f"rmm-datagen: error: {message}\n"
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize("kind", ["AttributeError", "TypeError"])
def test_rmm_bench_says_it_in_the_same_line(kind, tmp_path, capsys, monkeypatch):
    from rmm_bench.cli import main

    env_id = f"BrokenCtor{kind}-v0"
    if env_id not in gym.registry:
        gym.register(env_id, entry_point=lambda clock=None, kind=kind: broken_env(kind, clock=clock))
    argv = ["--env", env_id, "--agent", "inactive", "--clock", "fixed:1", "--episodes", "1", "--no-progress"]
    assert main([*argv, "--no-figure", "--out", str(tmp_path)]) == 2
    said = _said(kind).replace("BrokenCtor-v0", env_id)
    assert capsys.readouterr().err == f"rmm-bench: error: {said}\n"


# -- 1. an env or its driver raising while a dataset is labelled ------------------------------------
class Line:
    """A point on a line, with the two controls of a car (neither observation layout nor render)."""

    dt = 0.25
    action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    def __init__(self):
        self.x = 0.0

    def get_state(self):
        return np.array([self.x, 0.0])

    def set_state(self, state):
        self.x = float(state[0])

    def step(self, action):
        self.x += self.dt * float(action[0])
        return self.x >= 1.0

    def state_failed(self, states):
        return np.asarray(states)[:, 0] >= 1.0

    def sample_states(self, rng, n):
        return np.column_stack([rng.uniform(-1.0, 1.0, n), np.zeros(n)])


class Mismatched(Line):
    def step(self, action):
        self.x += float(np.sum(np.zeros(2) + np.zeros(0)))  # MISMATCH
        return False


class Drawn(Line):
    def render(self, state):
        return np.zeros((4, 8, 3), dtype=np.uint8)


def forward(obs):
    return np.array([1.0, 0.0], np.float32)


def brake(obs):
    return np.array([-1.0, 0.0], np.float32)


def never(obs):
    return False


def _own(cls, maker=guarded):
    def entry(clock=None, render_mode=None):
        return maker(
            cls(),
            driver=forward,
            safe_default=brake,
            success=never,
            max_episode_sim_time=5.0,
            clock=clock,
            render_mode=render_mode,
        )

    return entry


for _name, _cls in (("Line", Line), ("Mismatched", Mismatched), ("Drawn", Drawn)):
    for _maker, _kind in ((guarded, "Guarded"), (parallel, "Parallel")):
        if f"Own{_name}{_kind}-v0" not in gym.registry:
            gym.register(f"Own{_name}{_kind}-v0", entry_point=_own(_cls, _maker))


def test_an_error_while_labelling_names_the_env_the_type_and_the_line(tmp_path, capsys):
    from rmm_envs.risk.datagen import main

    try:
        np.zeros(2) + np.zeros(0)
    except ValueError as e:
        numpy_says = str(e).strip()  # numpy's message ends in a space
    line = next(i for i, text in enumerate(Path(__file__).read_text().splitlines(), 1) if text.endswith("# MISMATCH"))
    argv = ["--env", "OwnMismatchedGuarded-v0", "--configs", "1", "--samples-per-config", "4", "--branches", "2"]
    status = main([*argv, "--depth", "1", "--workers", "1", "--no-progress", "--out", str(tmp_path / "d")])
    assert (status, capsys.readouterr().err) == (
        2,
        "rmm-datagen: error: --env OwnMismatchedGuarded-v0: labelling configuration 0 (--seed 0) raised "
        f"ValueError: {numpy_says} (at {HERE}:{line} in step)\n",
    )


# -- 2. render modes: only what the simulator can render ---------------------------------------------
@pytest.mark.filterwarnings("ignore:.*WARN:")  # check_env's advice (infinite bounds, a wrapped env)
def test_a_simulator_without_render_advertises_no_render_mode_and_passes_check_env():
    env = gym.make("OwnLineGuarded-v0")
    assert env.unwrapped.metadata["render_modes"] == []
    check_env(env.unwrapped)  # the render check included: no mode to make
    twin = gym.make("OwnLineParallel-v0", clock="fixed:1")
    assert twin.metadata["render_modes"] == []
    check_env(twin)


@pytest.mark.filterwarnings("ignore:.*WARN:")
def test_a_simulator_with_render_and_a_gymnasium_env_advertise_what_they_render():
    env = gym.make("OwnDrawnGuarded-v0")
    assert env.unwrapped.metadata["render_modes"] == ["rgb_array", "human"]
    drawn = gym.make("OwnDrawnGuarded-v0", render_mode="rgb_array")
    drawn.reset(seed=0)
    assert drawn.render().shape == (4, 8, 3)
    cart = guarded("CartPole-v1", driver=lambda obs: 0, safe_default=0, success=never)
    assert cart.metadata["render_modes"] == ["rgb_array", "human"]


# -- 3. a parent package that fails to import --------------------------------------------------------
def test_the_file_that_raised_is_named_when_a_parent_package_fails(tmp_path, monkeypatch):
    from rmm_envs.user_modules import UserModuleError, import_user_module

    pkg = tmp_path / "userpkg26"
    pkg.mkdir()
    (pkg / "__init__.py").write_text(
        "import pathlib\npathlib.Path(__file__).with_name('runs').open('a').write('x')\n"
        "raise ImportError('cannot import name Helper from elsewhere')\n"
    )
    (pkg / "foo.py").write_text("class X:\n    pass\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [str(tmp_path), *sys.path])
    for name in ("userpkg26", "userpkg26.foo", "userpkg26.nope"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    with pytest.raises(UserModuleError) as e:
        import_user_module("userpkg26.foo", "guardian 'userpkg26.foo:X'")
    assert str(e.value) == (
        "guardian 'userpkg26.foo:X': cannot import module 'userpkg26.foo' (from userpkg26/foo.py): "
        "userpkg26/__init__.py:3 raised ImportError: cannot import name Helper from elsewhere"
    )
    assert (pkg / "runs").read_text() == "x"  # the failing __init__.py ran once: naming it ran nothing
    with pytest.raises(UserModuleError) as e:
        import_user_module("userpkg26.nope", "--env 'userpkg26.nope:E-v0'")
    assert str(e.value) == (
        "--env 'userpkg26.nope:E-v0': cannot import module 'userpkg26.nope': "
        "userpkg26/__init__.py:3 raised ImportError: cannot import name Helper from elsewhere"
    )


# -- 4. a policy function as --agent module:fn -------------------------------------------------------
POLICY = """
import numpy as np
from rmm_guardians import CallableGuardian


def fn(obs):
    return np.array([1.0, 0.0, 0.0])


def guardian():
    return CallableGuardian(fn)
"""
SAYS = (
    "odd26:fn(obs) is a function, not a Guardian class, and calling it with the guardian's options (none) fails: "
    "missing a required argument: 'obs'; a module:Class must name a Guardian subclass (or a factory taking the "
    "guardian's options as keywords and returning a guardian), and a policy function fn(obs) -> action is wrapped "
    "with rmm_guardians.CallableGuardian, e.g. `def guardian(): return CallableGuardian(fn)` in odd26, named "
    "odd26:guardian"
)


@pytest.fixture
def odd(tmp_path, monkeypatch):
    (tmp_path / "odd26.py").write_text(POLICY)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [str(tmp_path), *sys.path])
    monkeypatch.delitem(sys.modules, "odd26", raising=False)
    return tmp_path


def test_a_policy_function_is_told_to_be_wrapped(odd):
    from rmm_guardians import CallableGuardian, make_guardian

    with pytest.raises(TypeError) as e:
        make_guardian("odd26:fn")
    assert str(e.value) == SAYS
    assert isinstance(make_guardian("odd26:guardian"), CallableGuardian)  # the factory it suggests works


def test_rmm_bench_says_it_in_one_line(odd, capsys):
    from rmm_bench.cli import main

    argv = ["--agent", "odd26:fn", "--clock", "fixed:1", "--episodes", "1", "--no-progress", "--no-figure"]
    assert main([*argv, "--out", str(odd / "r")]) == 2
    assert capsys.readouterr().err == (
        "rmm-bench: error: --agent odd26:fn: the guardian cannot be built for --env Dubins4DParallel-v0: "
        f"TypeError: {SAYS}\n"
    )


# -- 5. lrmm on an env of one's own ------------------------------------------------------------------
def _model(obs_dim: int):
    from rmm_guardians.lrmm.model import LRMMModel

    meta = {
        "env_id": "OwnLineGuarded-v0",
        "obs_dim": obs_dim,
        "features": list(range(obs_dim)),
        "hidden": [1],
        "activation": "sigmoid",
        "output_bias": True,
    }
    return LRMMModel(
        [(np.ones((1, obs_dim)), np.zeros(1)), (np.ones((1, 1)), np.zeros(1))],
        np.zeros(obs_dim),
        np.ones(obs_dim),
        meta,
    )


def test_lrmm_on_an_own_simulator_says_what_to_give_on_the_command_line():
    from rmm_guardians.lrmm.guardian import LRMMGuardian

    env = gym.make("OwnLineParallel-v0", clock="fixed:1")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # everything given: no fallback to warn of
        g = LRMMGuardian(_model(2), threshold=0.3, strategies="BrakeTurn")
    with pytest.raises(ValueError) as e:
        g.check_spaces(env.observation_space, env.action_space)
    assert str(e.value) == (
        "guardian 'lrmm': strategy BrakeTurn reads the observation field 'rays' by name, and this env's observation "
        "names no fields (an env of your own, e.g. made by rmm_envs.envs.any_env.guarded or parallel); the core alone "
        "takes the env's safe default (the policy brake): rmm-bench --agent-opt lrmm.strategies='\"\"' "
        '(in Python: strategies="")'
    )
    LRMMGuardian(_model(2), threshold=0.3, strategies="").check_spaces(env.observation_space, env.action_space)
    # a model without a head and without a stored decision: the core alone, which serves this env as it is
    LRMMGuardian(_model(2), threshold=0.3).check_spaces(env.observation_space, env.action_space)


def test_lrmm_refuses_a_model_without_a_decision_in_one_line_directly_and_by_name():
    from rmm_guardians import make_guardian
    from rmm_guardians.lrmm.guardian import LRMMGuardian

    for build in (LRMMGuardian, lambda m: make_guardian("lrmm", model=m)):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # refused, not warned of
            with pytest.raises(ValueError) as e:
                build(_model(2))
        assert str(e.value) == (
            "lrmm: the model (an LRMMModel without a file) has no decision: give a threshold "
            "(--agent-opt lrmm.threshold=0.5; in Python threshold=0.5)"
        )
