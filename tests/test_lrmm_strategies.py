"""The lrmm guardian's strategies as a surface of their own (``rmm_guardians.lrmm.strategies``): the
spec language (``parse_strategies``, ``strategy_specs``, ``-``/``+`` edits), a strategy of one's own
(``module:Class``), the settings presets, what a stored decision may hold, which strategy needs what
of the model and of the env, and both command lines (``rmm-bench --agent-opt lrmm.strategies=...``
and ``python -m rmm_guardians.lrmm.decision``)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import rmm_envs  # noqa: F401
from rmm_guardians.lrmm.decision import decision_path, read_decision, set_decision
from rmm_guardians.lrmm.guardian import LRMMGuardian, LRMMPaperGuardian
from rmm_guardians.lrmm.model import LRMMModel
from rmm_guardians.lrmm.settings import LRMMSettings
from rmm_guardians.lrmm.strategies import (
    STRATEGIES,
    BrakeTurn,
    Commit,
    MovingAverage,
    RatedDriver,
    RayTurn,
    Restart,
    SafestCandidate,
    Slide,
    Strategy,
    parse_strategies,
    strategy_specs,
)
from tests.test_lrmm import SPACES, decided, forward_ray_model, head_model_by_hand, obs_with

STORED = (SafestCandidate(), Commit(steps=18), Restart(speed=0.3))  # the shipped Dubins4D act model's


# ----------------------------------------------------------------------------- strategies of one's own
class EveryOther(Strategy):
    """When: also in control at every ``period``-th decision of an episode, whatever the risk."""

    PARAMS = ("period",)

    def __init__(self, period: int = 2) -> None:
        self.period = period
        self._n = 0

    def reset(self, guardian) -> None:
        self._n = 0

    def take(self, step, take: bool) -> bool:
        self._n += 1
        return take or self._n % self.period == 0


class Fixed(Strategy):
    """What: a fixed (turn rate, acceleration), whatever the env's safe default."""

    PARAMS = ("turn", "accel")
    chooses = True

    def __init__(self, turn: float = 0.0, accel: float = -0.1) -> None:
        self.turn, self.accel = turn, accel

    def act(self, step, control):
        return (self.turn, self.accel)


class Needy(Strategy):
    """A strategy whose constructor has a required argument."""

    PARAMS = ("level",)

    def __init__(self, level: float) -> None:
        self.level = level


HERE = __name__  # "tests.test_lrmm_strategies": how a spec names the classes above


def test_a_strategy_of_ones_own_serves_as_an_object_and_by_module_class():
    m = head_model_by_hand(decision={"threshold": 0.5})
    mine = (EveryOther(period=3), Fixed(turn=0.1, accel=-0.2))
    spec = f"{HERE}:EveryOther(period=3), {HERE}:Fixed(turn=0.1, accel=-0.2)"
    assert strategy_specs(mine) == [f"{HERE}:EveryOther(period=3)", f"{HERE}:Fixed(turn=0.1, accel=-0.2)"]
    assert parse_strategies(spec) == mine and parse_strategies(strategy_specs(mine)) == mine
    low, high = obs_with(9.0, 5.0, 5.0), obs_with(0.0, 5.0, 5.0)  # risks sigmoid(-7) and sigmoid(2)
    for given_as in (mine, spec):
        g = LRMMGuardian(m, strategies=given_as)  # SPACES states no safe default: Fixed chooses the control
        assert g.strategies == mine and all(a is not b for a, b in zip(g.strategies, mine, strict=True))
        g.reset(seed=0, **SPACES)
        acts = [g.act(o, {}) for o in (low, low, low, high, low, low)]
        assert [a["active_ctrl"] for a in acts] == [0, 0, 1, 1, 0, 1]  # every third decision, and at the risk
        assert all((float(a["turnrate_ctrl"][0]), float(a["accel_ctrl"][0])) == (0.1, -0.2) for a in acts[2:4])
        g.reset(seed=0, **SPACES)  # a new episode counts afresh
        assert [g.act(low, {})["active_ctrl"] for _ in range(3)] == [0, 0, 1]
    assert mine[0]._n == 0  # the guardian ran copies: the objects given are untouched


def test_a_strategy_from_a_module_on_the_path_is_stored_and_read_back(tmp_path, monkeypatch):
    (tmp_path / "my_lrmm_rules.py").write_text(
        textwrap.dedent(
            """
            from rmm_guardians.lrmm.strategies import Strategy

            class Coast(Strategy):
                PARAMS = ("accel",)
                chooses = True

                def __init__(self, accel=0.0):
                    self.accel = float(accel)

                def act(self, step, control):
                    return (0.0, self.accel)

            class NotOne:
                pass
            """
        )
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    (coast,) = parse_strategies("my_lrmm_rules:Coast(accel=-0.3)")
    assert coast.spec() == "my_lrmm_rules:Coast(accel=-0.3)"
    p = head_model_by_hand().save(tmp_path / "m.npz")
    set_decision(p, 0.5, "my_lrmm_rules:Coast(accel=-0.3), Commit(steps=1)", "a test")
    assert read_decision(decision_path(p)).strategies == "my_lrmm_rules:Coast(accel=-0.3), Commit(steps=1)"
    g = LRMMGuardian(p)
    assert [s.spec() for s in g.strategies] == ["my_lrmm_rules:Coast(accel=-0.3)", "Commit(steps=1)"]
    g.reset(seed=0, **SPACES)
    a = g.act(obs_with(0.0, 5.0, 5.0), {})
    assert (a["active_ctrl"], float(a["turnrate_ctrl"][0]), float(a["accel_ctrl"][0])) == (1, 0.0, -0.3)
    with pytest.raises(ValueError, match=r"strategy 'my_lrmm_rules:NotOne' is not a subclass of .*Strategy"):
        parse_strategies("my_lrmm_rules:NotOne")
    with pytest.raises(ValueError, match=r"unknown strategy 'my_lrmm_rules:Gone': .*has no attribute 'Gone'"):
        parse_strategies("my_lrmm_rules:Gone")
    with pytest.raises(
        ValueError, match=r"unknown strategy 'no_such_lrmm_module:Coast': cannot import module .*: no module"
    ):
        parse_strategies("no_such_lrmm_module:Coast")


# ----------------------------------------------------------------------------- the spec language
def _compositions():
    """Compositions of the built-ins: each at most once, in any order, with any valid parameters."""
    nonneg = st.floats(min_value=0.0, max_value=1e6, allow_nan=False, allow_infinity=False)
    real = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
    makers = {
        "SafestCandidate": st.just(SafestCandidate()),
        "Slide": st.just(Slide()),
        "Restart": st.builds(Restart, speed=nonneg),
        "BrakeTurn": st.builds(BrakeTurn, turn=st.none() | real, brake=st.none() | real),
        "RayTurn": st.builds(RayTurn, rate=st.none() | nonneg.filter(lambda x: x > 0)),
        "RatedDriver": st.builds(RatedDriver, margin=nonneg, still=st.none() | nonneg, stay=st.booleans()),
        "MovingAverage": st.builds(MovingAverage, window=st.integers(1, 10**6)),
        "Commit": st.builds(Commit, steps=st.integers(0, 10**6)),
    }
    assert set(makers) == set(STRATEGIES)
    names = st.lists(st.sampled_from(sorted(makers)), unique=True)
    return names.flatmap(lambda ns: st.tuples(*(makers[n] for n in ns)))


@settings(max_examples=200, deadline=None)
@given(_compositions())
def test_specs_read_back_as_the_same_strategies(composition):
    specs = strategy_specs(composition)
    assert parse_strategies(specs) == composition
    assert parse_strategies(", ".join(specs)) == composition  # one string, as on the command line
    assert [repr(s) for s in composition] == specs
    assert tuple(s.clone() for s in composition) == composition
    assert LRMMSettings(strategies=", ".join(specs)).strategies == composition


def test_specs_take_positional_and_keyword_literals_and_defaults():
    assert parse_strategies("SafestCandidate, Commit(18), Restart(speed=0.3)") == STORED
    assert parse_strategies("Commit") == (Commit(steps=0),) == parse_strategies(" Commit() ,")
    assert parse_strategies("RatedDriver(0.15, 0.05, False)") == (RatedDriver(margin=0.15, still=0.05, stay=False),)
    assert parse_strategies("BrakeTurn(turn=-0.25, brake=None)") == (BrakeTurn(turn=-0.25),)
    assert parse_strategies("") == () == parse_strategies(" , ") == parse_strategies([])
    assert parse_strategies(["Commit(steps=2)", SafestCandidate()]) == (Commit(steps=2), SafestCandidate())


def test_edits_change_the_stored_composition():
    assert parse_strategies("-Commit", STORED) == (SafestCandidate(), Restart(speed=0.3))
    assert parse_strategies("- Commit", STORED) == (SafestCandidate(), Restart(speed=0.3))
    assert parse_strategies("+Commit(steps=5)", STORED) == (SafestCandidate(), Commit(steps=5), Restart(speed=0.3))
    assert parse_strategies("+MovingAverage(window=3)", STORED) == (*STORED, MovingAverage(window=3))
    assert parse_strategies("-Commit, -Restart", STORED) == (SafestCandidate(),)
    assert parse_strategies("-Commit, +Commit(steps=2)", STORED) == (SafestCandidate(), Restart(0.3), Commit(2))
    assert parse_strategies(["-Restart"], STORED) == (SafestCandidate(), Commit(steps=18))
    assert parse_strategies("+Commit(steps=4)") == (Commit(steps=4),)  # nothing stored: appended
    with pytest.raises(ValueError) as e:
        parse_strategies("-Slide", STORED)
    assert str(e.value) == "strategy '-Slide': no Slide to remove (the stored ones: SafestCandidate, Commit, Restart)"
    with pytest.raises(ValueError, match=r"strategy '-Commit': no Commit to remove \(the stored ones: none\)"):
        parse_strategies("-Commit")
    with pytest.raises(ValueError, match="either every item edits the stored ones .+/-. or none does"):
        parse_strategies("-Commit, Restart(speed=0.5)", STORED)
    with pytest.raises(ValueError, match="unknown strategy 'Nope'"):
        parse_strategies("+Nope", STORED)
    # on the guardian: the edits apply to the model's stored decision
    assert LRMMGuardian(strategies="-Commit").strategies == (SafestCandidate(), Restart(speed=0.3))
    assert LRMMGuardian(strategies="+Commit(steps=5)").strategies == (SafestCandidate(), Commit(5), Restart(0.3))


def test_an_unknown_strategy_is_refused_listing_the_built_ins():
    for spec in ("Nope", "SafestCandidate, Nope(1)", "commit"):
        with pytest.raises(ValueError) as e:
            parse_strategies(spec)
        bad = spec.rpartition(", ")[2].partition("(")[0]
        assert str(e.value) == (
            f"unknown strategy {bad!r}; the strategies are: SafestCandidate, Restart, BrakeTurn, RayTurn, "
            "RatedDriver, Slide, MovingAverage, Commit or 'module:Class'"
        )


@pytest.mark.parametrize(
    "spec, words",
    [
        ("Commit(step=3)", ["'Commit(step=3)'", "'step'", "its parameters: steps"]),
        ("Commit(1, 2)", ["'Commit(1, 2)'", "its parameters: steps"]),
        ("BrakeTurn(turn=0.1, extra=1)", ["'extra'", "its parameters: turn, brake"]),
        ("RatedDriver(hold=1)", ["'hold'", "its parameters: margin, still, stay"]),
        ("SafestCandidate(0.5)", ["'SafestCandidate(0.5)'", "its parameters: none"]),
        ("Restart(speed=fast)", ["'Restart(speed=fast)'", "arguments must be literals, as in Commit(steps=18)"]),
        ("Commit(steps=1", ["'Commit(steps=1'", "arguments must be literals"]),
        ("Commit(steps=-1)", ["Commit steps must be an integer >= 0", "got -1"]),
        ("Commit(steps=True)", ["Commit steps must be an integer >= 0", "got True"]),
        ("MovingAverage(window=0)", ["MovingAverage window must be an integer >= 1, got 0"]),
        ("RayTurn(rate=0.0)", ["RayTurn rate must be a finite number > 0.0, got 0.0"]),
        ("Restart(speed=-0.1)", ["Restart speed must be a finite number >= 0.0, got -0.1"]),
        ("BrakeTurn(turn=1e999)", ["BrakeTurn turn must be a finite number, got inf"]),
        ("RatedDriver(stay=1)", ["RatedDriver stay must be True or False, got 1"]),
    ],
)
def test_bad_arguments_are_refused_naming_them(spec, words):
    with pytest.raises(ValueError) as e:
        parse_strategies(spec)
    assert all(w in str(e.value) for w in words), str(e.value)


def test_a_strategy_may_appear_once():
    for spec in ("Commit, Commit(steps=2)", (Commit(1), Commit(2)), ["SafestCandidate", SafestCandidate()]):
        with pytest.raises(ValueError, match="each strategy may appear once"):
            parse_strategies(spec)
    with pytest.raises(ValueError, match="each strategy may appear once"):
        LRMMGuardian(strategies="Commit(1), SafestCandidate, Commit(2)")
    assert parse_strategies((Fixed(), EveryOther(), Commit())) == (Fixed(), EveryOther(), Commit())


def test_strategies_of_the_wrong_kind_are_refused():
    for bad in ((Commit,), (3,), [None]):
        with pytest.raises(ValueError, match="strategies must be Strategy objects or spec strings"):
            parse_strategies(bad)


@pytest.mark.parametrize("spec", ["Commit(**{'steps': 5})", "Commit()(3)"])
def test_spec_forms_beyond_literal_arguments_are_refused(spec):
    with pytest.raises(ValueError, match="Commit"):
        parse_strategies(spec)


def test_an_empty_module_name_is_named():
    with pytest.raises(ValueError, match="':Commit'"):
        parse_strategies(":Commit")


def test_removing_needs_no_arguments():
    assert parse_strategies(f"-{HERE}:Needy", (Needy(1.0), Commit(2))) == (Commit(2),)


def test_no_strategies_at_all_is_a_value_error(tmp_path):
    with pytest.raises(ValueError, match="None"):
        parse_strategies(None)
    with pytest.raises(ValueError, match="None"):
        set_decision(head_model_by_hand().save(tmp_path / "m.npz"), 0.5, None, "x")


# ----------------------------------------------------------------------------- settings and presets
def test_an_unknown_preset_is_refused_listing_the_presets():
    for name in ("nope", "LRMM", "paper"):
        with pytest.raises(ValueError) as e:
            LRMMGuardian(settings=name)
        assert str(e.value) == f"unknown LRMMSettings preset {name!r}; the presets are: ['core', 'lrmm', 'lrmm-paper']"


def test_the_core_preset_applies_the_safe_default_full_braking_while_the_risk_is_high():
    env = gym.make("Dubins4DGuarded-v0")
    space = env.action_space
    g = LRMMGuardian(settings="core")  # the shipped act model with its stored threshold, no strategy
    assert (g.strategies, g.threshold, g.threshold_source) == ((), 0.25, "stored decision")
    g.reset(seed=0, observation_space=env.observation_space, action_space=space)
    safe = space.safe_default.policy(space, np.random.default_rng(0))
    clear = obs_with(10.0, 10.0, 10.0)
    clear[4] = 0.5
    assert g.act(clear, {})["active_ctrl"] == 0 and g.last_risk <= 0.25
    for ray0 in (0.3, 0.5, 0.8):
        o = obs_with(ray0, 8.0, 2.0)
        o[4] = 1.5
        a = g.act(o, {})
        assert g.last_risk > 0.25 and a["active_ctrl"] == 1
        expected = space.active(safe(o))  # full braking with the episode's constant turn rate
        assert float(a["accel_ctrl"][0]) == -0.5 and -0.25 <= float(a["turnrate_ctrl"][0]) <= 0.25
        for k in ("active_ctrl", "turnrate_ctrl", "accel_ctrl"):
            np.testing.assert_array_equal(a[k], expected[k])
    # the same as the edit taking every stored strategy out
    assert LRMMGuardian(strategies="-SafestCandidate, -Commit, -Restart").strategies == ()
    assert LRMMGuardian(settings="core", threshold=0.9).threshold == 0.9


def test_settings_objects_and_their_fields_given_as_arguments():
    s = LRMMSettings(threshold=0.4, strategies="SafestCandidate, Commit(steps=3)")
    g = LRMMGuardian(settings=s)
    assert (g.settings, g.threshold, g.strategies) == (s, 0.4, (SafestCandidate(), Commit(steps=3)))
    g = LRMMGuardian(settings=s, threshold=0.6, strategies="-Commit")  # arguments change the settings' fields
    assert (g.threshold, g.strategies) == (0.6, (SafestCandidate(),))  # edits of the settings' own strategies
    p = LRMMGuardian(settings="lrmm-paper")
    assert (type(p), p.threshold, p.strategies) == (LRMMGuardian, 0.85, (BrakeTurn(),))
    assert decision_path(p.model.path).is_file()  # the lrmm model: presets set the rule, not its decision


def test_edits_on_a_preset_edit_the_presets_strategies():
    assert LRMMPaperGuardian(strategies="+Commit(steps=3)").strategies == (BrakeTurn(), Commit(steps=3))


# ----------------------------------------------------------------------------- stored decisions
@pytest.mark.parametrize(
    "decision, words",
    [
        ({"threshold": 0.3, "strategies": ["Teleport()"], "chosen_by": "x"}, ["unknown strategy 'Teleport'"]),
        ({"threshold": 0.3, "strategies": ["Commit(steps=2)", "Commit()"]}, ["each strategy may appear once"]),
        ({"threshold": 0.3, "commit": 18, "chosen_by": "x"}, ["unknown key(s) ['commit']", "threshold, strat"]),
        ({"threshold": 0.3, "trigger": "driver", "slide": True}, ["['slide', 'trigger']"]),
        ({"threshold": 0.3, "strategies": 3}, ["strategies must be a spec string ('': none), got 3"]),
        ({"threshold": 0.3, "chosen_by": " "}, ["chosen_by.how must say how"]),
        ({"strategies": ["Commit(steps=2)"]}, ["no threshold"]),
    ],
)
def test_a_bad_stored_decision_is_refused_when_the_guardian_is_built(tmp_path, decision, words):
    p = decided(head_model_by_hand(), decision, tmp_path / "m.npz").path
    words = [f"{tmp_path / 'm.decision.toml'}: ", *words]
    for kw in ({}, {"threshold": 0.5}):
        with pytest.raises(ValueError) as e:
            LRMMGuardian(p, **kw)  # at construction: no reset, no env
        assert all(w in str(e.value) for w in words), str(e.value)


def test_set_decision_edits_edit_the_files_stored_strategies(tmp_path):
    p = head_model_by_hand().save(tmp_path / "m.npz")
    set_decision(p, 0.3, "SafestCandidate, Commit(steps=18)", "a test")
    try:
        set_decision(p, 0.3, "+Commit(steps=5)", "a test")
    except ValueError:
        return  # refusing edits is as good
    assert read_decision(decision_path(p)).strategies == "SafestCandidate(), Commit(steps=5)"


# ----------------------------------------------------------------------------- what a strategy needs
@pytest.mark.parametrize("spec", ["SafestCandidate", "BrakeTurn, Restart(speed=0.3)", "RatedDriver, BrakeTurn"])
def test_a_strategy_reading_the_head_is_refused_at_construction_on_a_model_without_one(spec):
    name = next(s.name for s in parse_strategies(spec) if s.name != "BrakeTurn")
    with pytest.raises(ValueError) as e:
        LRMMGuardian(forward_ray_model(), threshold=0.5, strategies=spec)
    assert str(e.value) == (
        f"strategy {name} reads the model's action-conditioned head ('candidates'), and the model has none"
    )


def _maze_head_model():
    """An 8-ray maze model with a two-candidate head (turn left, turn right)."""
    meta = {
        "env_id": "Dubins3DMaze-v0",
        "obs_dim": 8,
        "features": list(range(8)),
        "hidden": [1],
        "activation": "relu",
        "output_bias": True,
        "candidates": [[0.2], [-0.2]],
        "candidate_hold": 1.0,
    }
    return LRMMModel([(np.zeros((1, 8)), np.zeros(1)), (np.zeros((3, 1)), np.zeros(3))], np.zeros(8), np.ones(8), meta)


def test_a_strategy_needing_a_field_or_a_control_the_env_lacks_is_refused_by_check_spaces():
    maze = gym.make("Dubins3DMazeParallel-v0")
    g = LRMMGuardian(_maze_head_model(), threshold=0.5, strategies="RayTurn, Restart(speed=0.3)", inputs="rays")
    with pytest.raises(ValueError) as e:
        g.check_spaces(maze.observation_space, maze.action_space)
    assert str(e.value) == (
        "guardian 'lrmm': strategy Restart needs an 'accel_ctrl' control and a 'speed' observation field, "
        "got controls ('turnrate_ctrl',)"
    )
    LRMMGuardian(_maze_head_model(), threshold=0.5, strategies="RayTurn", inputs="rays").check_spaces(
        maze.observation_space, maze.action_space
    )
    d4 = gym.make("Dubins4DParallel-v0")
    head = head_model_by_hand()
    h = LRMMGuardian(head, threshold=0.5, strategies="RatedDriver, SafestCandidate, Slide")
    with pytest.raises(ValueError) as e:
        h.check_spaces(d4.observation_space, d4.action_space)
    assert str(e.value) == (
        "guardian 'lrmm': strategy Slide bends a velocity command: it needs the controls "
        "('vforward_ctrl', 'vleft_ctrl', 'vup_ctrl'), got ('turnrate_ctrl', 'accel_ctrl')"
    )
    LRMMGuardian(head, threshold=0.5, strategies="RatedDriver, SafestCandidate").check_spaces(
        d4.observation_space, d4.action_space
    )


# ----------------------------------------------------------------------------- the command lines
RUN = ["--episodes", "1", "--workers", "1", "--clock", "fixed:1", "--no-progress", "--no-figure"]


@pytest.mark.parametrize(
    "opt, words",
    [
        ('lrmm.strategies="Nope"', ["'Nope'", "SafestCandidate, Restart, BrakeTurn", "MovingAverage, Commit"]),
        ('lrmm.strategies="Commit(step=2)"', ["'step'", "its parameters: steps"]),
        ('lrmm.strategies="-Slide"', ["no Slide to remove", "SafestCandidate, Commit, Restart"]),
        ('lrmm.settings="nope"', ["'nope'", "['core', 'lrmm', 'lrmm-paper']"]),
    ],
)
def test_rmm_bench_refuses_bad_strategies_and_presets_in_one_line(tmp_path, capsys, opt, words):
    from rmm_bench.cli import main

    out = tmp_path / "r"
    assert main(["--agent", "lrmm", "--agent-opt", opt, "--out", str(out), *RUN]) == 2
    cap = capsys.readouterr()
    lines = cap.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("rmm-bench: error: --agent-opt lrmm."), cap.err
    assert all(w in lines[0] for w in words), lines[0]
    assert not out.exists()


def test_rmm_bench_runs_an_edited_composition_and_a_strategy_of_ones_own(tmp_path, capsys):
    import sqlite3

    from rmm_bench.cli import main

    for i, spec in enumerate(("-Commit", f"SafestCandidate, {HERE}:EveryOther(period=50)")):
        out = tmp_path / f"r{i}"
        opt = f"lrmm.strategies={json.dumps(spec)}"
        assert main(["--agent", "lrmm", "--agent-opt", opt, "--out", str(out), *RUN]) == 0, capsys.readouterr().err
        con = sqlite3.connect(out / "results.db")
        assert [o for (o,) in con.execute("SELECT outcome FROM episodes")] in (["goal"], ["collision"], ["timeout"])
        con.close()
    capsys.readouterr()


def test_the_decision_command_stores_and_refuses(tmp_path, capsys):
    from rmm_guardians.lrmm.decision import main as decision_main

    p = head_model_by_hand().save(tmp_path / "m.npz")
    argv = [str(p), "--threshold", "0.3", "--strategies", "SafestCandidate, Commit(18), Restart(speed=0.3)"]
    assert decision_main([*argv, "--chosen-by", "a test"]) == 0
    assert capsys.readouterr().out == (
        f"{tmp_path / 'm.decision.toml'}: decision threshold 0.3, strategies "
        "[SafestCandidate(), Commit(steps=18), Restart(speed=0.3)]\n"
    )
    stored = read_decision(decision_path(p))
    assert (stored.threshold, stored.strategies, stored.chosen_by) == (
        0.3,
        "SafestCandidate(), Commit(steps=18), Restart(speed=0.3)",
        {"how": "a test"},
    )
    assert (LRMMGuardian(p).threshold, LRMMGuardian(p).strategies) == (0.3, STORED)
    for strategies, words in (
        ("Nope", ["unknown strategy 'Nope'", "SafestCandidate, Restart", "'module:Class'"]),
        ("Commit(step=1)", ["'step'", "its parameters: steps"]),
        ("Commit, Commit", ["each strategy may appear once"]),
    ):
        bad = [str(p), "--threshold", "0.5", "--strategies", strategies, "--chosen-by", "x"]
        assert decision_main(bad) == 2
        err = capsys.readouterr().err
        assert err.startswith("python -m rmm_guardians.lrmm.decision: error: ") and err.count("\n") == 1, err
        assert all(w in err for w in words), err
    assert decision_main([str(p), "--threshold", "1.5", "--strategies", "", "--chosen-by", "x"]) == 2
    assert "threshold must be in [0, 1], got 1.5" in capsys.readouterr().err
    assert read_decision(decision_path(p)) == stored  # every refusal left the file as it was
    assert decision_main([str(p), "--threshold", "0.3", "--chosen-by", "x"]) == 2  # --strategies is required
    assert "give --threshold, --strategies and --chosen-by" in capsys.readouterr().err
    assert decision_main([str(p), "--threshold", "0.3", "--strategies", "", "--chosen-by", "the core alone"]) == 0
    assert read_decision(decision_path(p)).strategies == "" and LRMMGuardian(p).strategies == ()


def test_the_decision_module_runs_as_a_command(tmp_path):
    p = head_model_by_hand().save(tmp_path / "m.npz")
    cmd = [sys.executable, "-m", "rmm_guardians.lrmm.decision", str(p), "--threshold", "0.4", "--chosen-by", "t"]
    ok = subprocess.run([*cmd, "--strategies", "SafestCandidate, Commit(steps=2)"], capture_output=True, text=True)
    assert ok.returncode == 0 and ok.stdout.endswith("strategies [SafestCandidate(), Commit(steps=2)]\n"), ok.stderr
    assert LRMMGuardian(p).strategies == (SafestCandidate(), Commit(steps=2))
    bad = subprocess.run([*cmd, "--strategies", "Nope"], capture_output=True, text=True)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "unknown strategy 'Nope'" in bad.stderr


def test_the_guardian_module_names_no_system_and_takes_at_most_six_parameters():
    import inspect
    from pathlib import Path

    import rmm_guardians.lrmm.guardian as module
    from rmm_envs.catalog import SYSTEMS
    from rmm_guardians.lrmm.guardian import LRMMGuardian

    text = Path(module.__file__).read_text().lower()
    named = [s.name for s in SYSTEMS if s.name.lower() in text] + [w for w in ("maze", "quadrotor") if w in text]
    assert not named, f"the lrmm guardian's module names systems {named}: a system's rules belong in strategies"
    params = [p for p in inspect.signature(LRMMGuardian.__init__).parameters if p != "self"]
    assert params == ["model", "settings", "env_id", "threshold", "strategies", "inputs"]
