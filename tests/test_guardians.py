import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest

import rmm_envs  # noqa: F401
from rmm_envs.autonomy import GuardianActionSpace, ObservationBox, ObservationLayout
from rmm_envs.systems.dubins4d.dynamics import Dubins4D, FullBraking
from rmm_envs.systems.dubins4d.env import CONTROLS, observation_layout
from rmm_guardians import CallableGuardian, SB3Guardian, available_guardians, make_guardian
from rmm_guardians.baselines import BrakesGuardian, InactiveGuardian, RandomGuardian
from rmm_guardians.wrapped import to_guardian_action

SPACE = GuardianActionSpace.for_dynamics(Dubins4D(), CONTROLS, safe_default=FullBraking())


def spaces(action_space=SPACE, n_rays=12):
    lay = observation_layout(n_rays)
    return {
        "action_space": action_space,
        "observation_space": ObservationBox(np.full(lay.size, -np.inf), np.full(lay.size, np.inf), lay),
    }


def run(guardian, seed=0, env_id="Dubins4DGuarded-v0", max_steps=2000):
    env = gym.make(env_id)
    obs, info = env.reset(seed=seed)
    guardian.reset(
        seed=seed,
        observation_space=env.observation_space,
        action_space=env.action_space,
        privileged=env.unwrapped.privileged,
    )
    actions, infos = [], []
    for _ in range(max_steps):
        a = guardian.act(obs, info)
        assert env.action_space.contains(
            {k: (np.asarray(v, np.float32) if k != "active_ctrl" else int(v)) for k, v in a.items()}
        ), a
        actions.append(a)
        obs, r, te, tr, info = env.step(a)
        infos.append(info)
        if te or tr:
            break
    return actions, infos


@pytest.mark.parametrize("name", [n for n in ["inactive", "random", "brakes", "lrmm"]])
def test_every_registered_guardian_conforms_over_an_episode(name):
    assert name in available_guardians()
    g = make_guardian(name)
    acts, infos = run(g, seed=3)
    assert "outcome" in infos[-1]


def test_inactive_never_takes_control():
    acts, infos = run(make_guardian("inactive"))
    assert all(a["active_ctrl"] == 0 for a in acts)
    assert infos[-1]["episode_stats"]["n_active_ctrl_env_steps"] == 0


def test_random_is_seeded_and_half_active():
    g = RandomGuardian()
    g.reset(seed=4, **spaces())
    a = [g.act(None, {}) for _ in range(4000)]
    g.reset(seed=4, **spaces())
    b = [g.act(None, {}) for _ in range(4000)]
    assert [x["active_ctrl"] for x in a] == [x["active_ctrl"] for x in b]
    frac = np.mean([x["active_ctrl"] for x in a])
    assert 0.47 < frac < 0.53
    u = np.array([x["turnrate_ctrl"][0] for x in a])
    assert u.min() >= -0.25 and u.max() <= 0.25 and u.std() > 0.1
    with pytest.raises(ValueError, match="p_active"):
        RandomGuardian(p_active=1.5)


def test_brakes_constant_turn_per_episode():
    g = BrakesGuardian()
    g.reset(seed=1, **spaces())
    acts = [g.act(None, {}) for _ in range(5)]
    assert all(a["active_ctrl"] == 1 and a["accel_ctrl"][0] == -0.5 for a in acts)
    turns = {float(a["turnrate_ctrl"][0]) for a in acts}
    assert len(turns) == 1 and turns != {0.0} and abs(turns.pop()) <= 0.25
    g.reset(seed=2, **spaces())
    assert float(g.act(None, {})["turnrate_ctrl"][0]) != float(acts[0]["turnrate_ctrl"][0])
    z = BrakesGuardian(turn="zero")
    z.reset(seed=1, **spaces())
    assert z.act(None, {})["turnrate_ctrl"][0] == 0.0
    with pytest.raises(ValueError, match="turn"):
        BrakesGuardian(turn="left")


def test_brakes_stops_the_car():
    acts, infos = run(make_guardian("brakes", turn="zero"), seed=5)
    ep = infos[-1]["episode_stats"]
    if infos[-1]["outcome"] == "timeout":
        assert ep["final_speed"] == 0.0
    assert ep["n_active_ctrl_env_steps"] == ep["n_env_steps"] - 0  # blocking env: every step is the guardian's


def test_callable_adapter_with_dict_and_flat_actions():
    g = CallableGuardian(lambda obs: [1.0, 0.1, -0.2], name="flat")
    g.reset(seed=0, **spaces())
    a = g.act(np.zeros(17), {})
    assert a["active_ctrl"] == 1 and a["turnrate_ctrl"][0] == pytest.approx(0.1)
    assert a["accel_ctrl"][0] == pytest.approx(-0.2)
    g.reset(seed=0)  # no action space: a flat action cannot become a dict
    with pytest.raises(ValueError, match="flat action"):
        g.act(np.zeros(17), {})
    acts, infos = run(CallableGuardian(lambda obs: {"active_ctrl": 0, "turnrate_ctrl": [0.0], "accel_ctrl": [0.0]}))
    assert infos[-1]["episode_stats"]["n_active_ctrl_env_steps"] == 0
    with pytest.raises(TypeError, match="callable"):
        CallableGuardian(3)
    with pytest.raises(ValueError, match="active, turnrate_ctrl, accel_ctrl"):
        to_guardian_action([1, 2], SPACE)
    assert to_guardian_action([0.2, 9.0, 9.0], SPACE) == {**SPACE.inactive(), "active_ctrl": 0}
    d = {"active_ctrl": 0}
    assert to_guardian_action(d, None) is d  # a dict passes through


def test_sb3_style_adapter():
    class Model:
        def predict(self, obs, deterministic=True):
            assert deterministic
            return np.array([1.0, -0.25, -0.5]), None

    g = SB3Guardian(Model())
    g.reset(seed=0, **spaces())
    a = g.act(np.zeros(17), {})
    # the unit box of FlattenGuardianAction: -0.25 -> a quarter of the way up [-0.25, 0.25]
    assert a["active_ctrl"] == 1 and a["turnrate_ctrl"][0] == -0.0625 and a["accel_ctrl"][0] == -0.25
    raw = SB3Guardian(Model(), flat="raw")
    raw.reset(seed=0, **spaces())
    a = raw.act(np.zeros(17), {})
    assert a["active_ctrl"] == 1 and a["turnrate_ctrl"][0] == -0.25 and a["accel_ctrl"][0] == -0.5
    with pytest.raises(TypeError, match="predict"):
        SB3Guardian(object())
    with pytest.raises(ValueError, match=r"flat must be one of \('unit', 'raw'\).*'scaled'"):
        SB3Guardian(Model(), flat="scaled")


def test_module_class_spec_and_entry_point(tmp_path, monkeypatch):
    pkg = tmp_path / "myguard"
    pkg.mkdir()
    (pkg / "__init__.py").write_text(
        textwrap.dedent("""
        from rmm_guardians.base import Guardian
        class Swerve(Guardian):
            name = "swerve"
            def act(self, obs, info):
                return self.action_space.active([0.25, 0.0])
    """)
    )
    dist = tmp_path / "myguard-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: myguard\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[rmm_envs.guardians]\nswerve = myguard:Swerve\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    g = make_guardian("myguard:Swerve")
    assert g.name == "swerve"
    assert "swerve" in available_guardians()
    g2 = make_guardian("swerve")
    g2.reset(seed=0, **spaces())
    assert g2.act(None, {})["turnrate_ctrl"][0] == 0.25
    sys.modules.pop("myguard", None)


def test_unknown_guardian_names():
    with pytest.raises(ValueError, match="available"):
        make_guardian("teleport")
    with pytest.raises(ValueError, match="cannot import"):
        make_guardian("no_such_module_xyz:Thing")
    with pytest.raises(ValueError, match="no attribute"):
        make_guardian("rmm_guardians.baselines:Nope")
    with pytest.raises(TypeError, match="guardian"):
        make_guardian("collections:OrderedDict")


def test_every_registered_name_makes_a_guardian_of_that_name():
    """Each name of both sets builds a guardian whose table name is the registered name, and a
    -paper preset is its default's class with other defaults (so options carry over)."""
    from rmm_guardians.registry import DEFAULT_SET, PAPER_SET, load_guardian_class

    for name in set(DEFAULT_SET) | set(PAPER_SET):
        assert name in available_guardians()
        assert load_guardian_class(name).name == name
    for name in ("lrmm", "cbf", "hj"):
        assert issubclass(load_guardian_class(f"{name}-paper"), load_guardian_class(name))


# ---------------------------------------------------------------- the contract: any action space
def test_baselines_build_actions_through_any_action_space():
    """The same baseline code on a three-control space with other bounds: actions have that
    space's fields, respect its bounds, and brakes holds every control but the first at its low."""
    space = GuardianActionSpace(("a", "b", "c"), [-1.0, -2.0, 0.5], [1.0, -1.0, 4.0], safe_default=FullBraking())
    r = RandomGuardian(p_active=1.0)
    r.reset(seed=0, action_space=space)
    for _ in range(200):
        act = r.act(None, {})
        assert space.contains(act)
    b = BrakesGuardian()
    b.reset(seed=3, action_space=space)
    active, u = space.parse(b.act(None, {}))
    assert active and -1.0 <= u[0] <= 1.0 and u[1:].tolist() == [-2.0, 0.5]
    z = BrakesGuardian(turn="zero")
    z.reset(seed=3, action_space=GuardianActionSpace(("t", "s"), [0.1, -1.0], [0.2, 1.0], safe_default=FullBraking()))
    assert z.act(None, {})["t"][0] == 0.1  # zero clipped into the bounds
    i = InactiveGuardian()
    i.reset(seed=0, action_space=space)
    assert i.act(None, {}) == {**space.inactive(), "active_ctrl": 0}


def test_random_draws_exactly_as_before_on_dubins4d():
    """Pinned: one draw for the flag, then one uniform per control over the space's bounds."""
    g = RandomGuardian()
    g.reset(seed=11, **spaces())
    ref = np.random.default_rng(11)
    for _ in range(50):
        flag = ref.random() < 0.5
        u1, u2 = ref.uniform(-0.25, 0.25), ref.uniform(-0.5, 0.5)
        a = g.act(None, {})
        assert a["active_ctrl"] == int(flag)
        if flag:
            assert (a["turnrate_ctrl"][0], a["accel_ctrl"][0]) == (u1, u2)  # float64: unrounded


@pytest.mark.parametrize("cls", [InactiveGuardian, RandomGuardian, BrakesGuardian])
def test_a_baseline_without_an_action_space_refuses_at_reset(cls):
    g = cls()
    with pytest.raises(ValueError, match=f"guardian '{g.name}'.*action space"):
        g.reset(seed=0)
    with pytest.raises(ValueError, match=f"guardian '{g.name}'.*action space"):
        g.reset(seed=0, action_space=gym.spaces.Dict({"active_ctrl": gym.spaces.Discrete(2)}))


def test_require_layout_names_the_guardian_and_the_missing_field():
    g = InactiveGuardian()
    g.reset(seed=0, action_space=SPACE, observation_space=gym.spaces.Box(-1, 1, (17,)))
    with pytest.raises(ValueError, match="guardian 'inactive'.*layout"):
        g.require_layout("rays")
    lay = ObservationLayout.of(("time", 1), ("speed", 1))
    g.reset(seed=0, action_space=SPACE, observation_space=ObservationBox(np.zeros(2), np.ones(2), lay))
    with pytest.raises(ValueError, match=r"guardian 'inactive'.*\['rays'\]"):
        g.require_layout("speed", "rays")
    assert g.require_layout("speed") is lay
    with pytest.raises(ValueError, match="guardian 'inactive'.*3 controls"):
        g.require_action_space(controls=3)
