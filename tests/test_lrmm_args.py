"""The LRMM guardian's arguments, decision file, space checks and moving average, pinned at their edges
(where a full mutation run of guardians/lrmm/guardian.py found them loose)."""

import math
import warnings

import numpy as np
import pytest

from rmm_envs.autonomy import GuardianActionSpace, ObservationBox, ObservationLayout
from rmm_guardians.lrmm.guardian import LRMMGuardian, LRMMPaperGuardian
from rmm_guardians.lrmm.model import LRMMModel
from rmm_guardians.lrmm.strategies import STRATEGIES, BrakeTurn, Commit, MovingAverage, RayTurn
from tests.test_lrmm import SPACES, env_spaces, forward_ray_model, head_model_by_hand, obs_with
from tests.test_lrmm_turn import TURN, U1, RaysModel, forward_risk, maze_obs, maze_spaces, nearest_wall_risk


def test_bounds_of_the_threshold_and_window_are_accepted_and_their_neighbours_refused():
    for t in (0.0, 1.0):
        assert LRMMGuardian(forward_ray_model(), threshold=t, strategies="BrakeTurn").threshold == t
        assert LRMMGuardian(head_model_by_hand(decision={"threshold": t})).threshold == t  # stored
    for t in (-1e-12, 1.0 + 1e-12):
        with pytest.raises(ValueError) as e:
            LRMMGuardian(forward_ray_model(), threshold=t, strategies="BrakeTurn")
        assert str(e.value) == f"threshold must be in [0, 1], got {t}"
        with pytest.raises(ValueError) as e:
            m = head_model_by_hand(decision={"threshold": t})
            LRMMGuardian(m)
        assert (
            str(e.value)
            == f"{m.path.with_suffix('').with_suffix('.decision.toml')}: threshold must be in [0, 1], got {t}"
        )
    g = LRMMGuardian(forward_ray_model(), threshold=0.5, strategies="BrakeTurn, MovingAverage(window=1)")
    assert g.strategies == (BrakeTurn(), MovingAverage(window=1)) and g.strategies[1].window == 1
    with pytest.raises(ValueError) as e:
        LRMMGuardian(forward_ray_model(), threshold=0.5, strategies="BrakeTurn, MovingAverage(window=0)")
    assert str(e.value) == "MovingAverage window must be an integer >= 1, got 0"
    with pytest.raises(ValueError) as e:
        MovingAverage(window=0)
    assert str(e.value) == "MovingAverage window must be an integer >= 1, got 0"


def test_stored_decision_without_strategies_is_the_core_alone_and_a_bad_stored_strategy_is_named():
    assert LRMMGuardian(head_model_by_hand(decision={"threshold": 0.5})).strategies == ()
    assert LRMMGuardian(head_model_by_hand(decision={"threshold": 0.5, "strategies": []})).strategies == ()
    with pytest.raises(ValueError) as e:
        m = head_model_by_hand(decision={"threshold": 0.5, "strategies": ["Fly()"]})
        LRMMGuardian(m)
    assert str(e.value) == (
        f"{m.path.parent / m.path.stem}.decision.toml: unknown strategy 'Fly'; the strategies are: "
        f"{', '.join(STRATEGIES)} or 'module:Class'"
    )
    with pytest.raises(ValueError) as e:  # a field of the former format: named, not ignored
        m = head_model_by_hand(decision={"threshold": 0.5, "action": "head"})
        LRMMGuardian(m)
    assert str(e.value) == (
        f"{m.path.parent / m.path.stem}.decision.toml: unknown key(s) ['action']; a decision file holds format, "
        "version, model_sha256, threshold, strategies, chosen_by"
    )
    with pytest.raises(ValueError) as e:
        m = head_model_by_hand(decision={"threshold": 0.5, "strategies": ["Commit(steps=1)", "-Commit"]})
        LRMMGuardian(m)
    assert "either every item edits the stored ones (+/-) or none does" in str(e.value)
    with pytest.raises(ValueError) as e:
        LRMMGuardian(forward_ray_model(), env_id=5)
    assert str(e.value) == "env_id must be a registered env id (str) or None, got 5"


def test_a_model_of_ones_own_on_an_env_with_a_shipped_model_gets_no_shipped_decision():
    # the maze's shipped model has threshold 0.7 and Commit(steps=5) beside it: a model of one's own
    # (without a decision file) is refused in one line naming rmm-bench tune, never given those numbers
    with pytest.raises(ValueError) as e:
        LRMMGuardian(RaysModel(forward_risk), env_id="Dubins3DMazeParallel-v0")
    assert str(e.value).startswith("lrmm: the model (an LRMMModel without a file) has no decision: give a threshold")
    g = LRMMGuardian(RaysModel(forward_risk), env_id="Dubins3DMazeParallel-v0", threshold=0.85, strategies="RayTurn")
    assert (g.threshold, g.strategies, g.inputs) == (0.85, (RayTurn(),), "rays")  # the table's input field applies
    g = LRMMGuardian(RaysModel(forward_risk), env_id="Dubins3DMazeParallel-v0", threshold=0.85)
    assert (g.threshold, g.strategies) == (0.85, ())  # not the shipped model's Commit: the core alone
    # an env id without an entry in the table: the whole observation
    g = LRMMGuardian(forward_ray_model(), threshold=0.5, strategies="BrakeTurn", env_id="SomeOtherEnv-v0")
    assert (g.env_id, g.inputs, g.strategies) == ("SomeOtherEnv-v0", None, (BrakeTurn(),))


def test_no_warning_without_a_decision_a_refusal():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match="has no decision"):
            LRMMGuardian(forward_ray_model())
        LRMMGuardian(forward_ray_model(), threshold=0.85)  # given: nothing to warn about


def test_last_risk_is_nan_until_the_first_decision_and_after_each_reset():
    g = LRMMGuardian(forward_ray_model(), threshold=0.5, strategies="BrakeTurn")
    assert isinstance(g.last_risk, float) and math.isnan(g.last_risk)
    g.reset(seed=0, **SPACES)
    g.act(obs_with(1.0, 8.0, 2.0), {})
    assert g.last_risk > 0.9
    g.reset(seed=0, **SPACES)
    assert isinstance(g.last_risk, float) and math.isnan(g.last_risk)
    o = obs_with(1.0, 8.0, 2.0)
    assert g.risk(o) == g.model.predict(o) == pytest.approx(g.model.predict_all(o)[0])


def test_the_paper_preset_passes_its_other_arguments_on():
    spec = "BrakeTurn(turn=0.1), MovingAverage(window=5), Commit(steps=3)"
    g = LRMMPaperGuardian(head_model_by_hand(), strategies=spec)
    assert (g.threshold, g.strategies) == (0.85, (BrakeTurn(turn=0.1), MovingAverage(window=5), Commit(steps=3)))
    g.reset(seed=0, **SPACES)
    a = g.act(obs_with(0.0, 8.0, 2.0), {})  # risk sigmoid(2) = 0.88 > 0.85
    assert (a["active_ctrl"], float(a["turnrate_ctrl"][0]), float(a["accel_ctrl"][0])) == (1, 0.1, -0.5)
    p = LRMMPaperGuardian(head_model_by_hand(), threshold=0.3)
    assert (p.threshold, p.strategies) == (0.3, (BrakeTurn(),))  # the threshold changed, the rule kept


def test_moving_average_is_strictly_above_the_threshold_and_over_the_last_window_only():
    m = head_model_by_hand()
    at = obs_with(2.0, 5.0, 5.0)  # risk sigmoid(0) = 0.5: the threshold exactly
    g = LRMMGuardian(m, threshold=0.5, strategies="MovingAverage(window=3), SafestCandidate")
    g.reset(seed=0, **SPACES)
    assert [g.act(at, {})["active_ctrl"] for _ in range(4)] == [0, 0, 0, 0]  # mean 0.5 is not above 0.5
    high, low = obs_with(0.0, 5.0, 5.0), obs_with(9.0, 5.0, 5.0)  # risks sigmoid(2) = 0.88, sigmoid(-7) = 0.0009
    g = LRMMGuardian(m, threshold=0.5, strategies="MovingAverage(window=2), SafestCandidate")
    g.reset(seed=0, **SPACES)
    assert [g.act(high, {})["active_ctrl"] for _ in range(4)] == [1] * 4
    # the last two risks (0.88, 0.0009) average 0.44: released at once; the whole history (two 0.5s at
    # reset, four 0.88s, one 0.0009) would average 0.64 and hold control
    assert g.act(low, {})["active_ctrl"] == 0


def test_non_finite_candidate_risks_are_an_error_naming_them():
    class NanHead(LRMMModel):
        def predict_all(self, obs):
            return np.array([0.9, np.nan, 0.1, 0.2])

    src = head_model_by_hand()
    m = NanHead(src.weights, src.scaler_min, src.scaler_scale, src.meta)
    g = LRMMGuardian(m, threshold=0.5, strategies="SafestCandidate")
    g.reset(seed=0, **SPACES)
    with pytest.raises(ValueError) as e:
        g.act(obs_with(1.0, 5.0, 5.0), {})
    assert str(e.value) == "the LRMM model returned non-finite candidate risks [nan, 0.1, 0.2]"


ONE = GuardianActionSpace(("turnrate_ctrl",), [-0.2], [0.2])


def test_check_spaces_judges_the_spaces_it_is_given_before_any_reset():
    """check_spaces() is public: it must read its arguments, not the spaces of a reset that has not happened."""
    no_rays = ObservationLayout.of(("time", 1), ("goal_offset", 2), ("heading", 1), ("speed", 1), ("ranges", 12))
    no_rays_space = env_spaces(layout=no_rays)["observation_space"]
    heur = LRMMGuardian(forward_ray_model(), threshold=0.5, strategies="BrakeTurn")
    with pytest.raises(ValueError) as e:
        heur.check_spaces(SPACES["observation_space"], ONE)
    assert str(e.value) == "guardian 'lrmm' needs an action space with 2 controls, got 1 (('turnrate_ctrl',))"
    with pytest.raises(ValueError) as e:
        heur.check_spaces(no_rays_space, SPACES["action_space"])
    assert str(e.value) == (
        "guardian 'lrmm' needs the observation field(s) ['rays']; the observation has "
        "['time', 'goal_offset', 'heading', 'speed', 'ranges']"
    )
    heur.check_spaces(SPACES["observation_space"], SPACES["action_space"])  # and what it needs passes
    turn = LRMMGuardian(RaysModel(forward_risk), threshold=0.3, strategies="RayTurn", inputs="rays")
    with pytest.raises(ValueError) as e:
        turn.check_spaces(maze_spaces()["observation_space"], SPACES["action_space"])
    assert (
        str(e.value) == "guardian 'lrmm' needs an action space with 1 controls, got 2 (('turnrate_ctrl', 'accel_ctrl'))"
    )
    bare = ObservationLayout.of(("goal_offset", 2), ("heading", 1), ("ranges", 8))
    bare_space = ObservationBox(np.zeros(11, np.float32), np.ones(11, np.float32), bare)
    with pytest.raises(ValueError) as e:
        turn.check_spaces(bare_space, TURN)
    assert (
        str(e.value)
        == "guardian 'lrmm' needs the observation field(s) ['rays']; the observation has ['goal_offset', 'heading', 'ranges']"
    )
    turn.check_spaces(maze_spaces()["observation_space"], TURN)
    whole = LRMMGuardian(RaysModel(forward_risk, obs_dim=11), threshold=0.3, strategies="RayTurn")  # all 11 numbers
    with pytest.raises(ValueError) as e:
        whole.check_spaces(bare_space, TURN)
    assert (
        str(e.value)
        == "guardian 'lrmm' needs the observation field(s) ['rays']; the observation has ['goal_offset', 'heading', 'ranges']"
    )


@pytest.mark.parametrize(
    "angles",
    [
        [k * math.pi / 4 + (5e-9 if k == 1 else 0.0) for k in range(8)],  # one ray 5e-9 rad off
        [k * math.pi / 4 + math.pi for k in range(8)],  # evenly spaced from straight behind
    ],
)
def test_turn_needs_rays_from_the_heading_to_1e_9_rad(angles):
    lay = ObservationLayout.of(("rays", 8), ("goal_offset", 2), ("heading", 1), ray_angles=angles)
    g = LRMMGuardian(RaysModel(forward_risk), threshold=0.3, strategies="RayTurn", inputs="rays")
    with pytest.raises(ValueError, match="rays evenly spaced over the full circle from the heading"):
        g.reset(seed=0, **maze_spaces(lay))
    ok = [k * math.pi / 4 + (5e-10 if k == 1 else 0.0) for k in range(8)]  # within 1e-9
    g.reset(seed=0, **maze_spaces(ObservationLayout.of(("rays", 8), ("goal_offset", 2), ("heading", 1), ray_angles=ok)))


@pytest.mark.parametrize("shift", [0.0, 2 * math.pi, -2 * math.pi])
def test_the_sides_hold_for_angles_written_whole_turns_away(shift):
    lay = ObservationLayout.of(
        ("rays", 8), ("goal_offset", 2), ("heading", 1), ray_angles=[k * math.pi / 4 + shift for k in range(8)]
    )
    g = LRMMGuardian(RaysModel(nearest_wall_risk), threshold=0.3, strategies="RayTurn", inputs="rays")
    g.reset(seed=0, **maze_spaces(lay))
    # the left side's nearest wall is ray 1 (45 degrees, 2), the right side's 3: turn right
    assert g.act(maze_obs([1.0, 2.0, 4.0, 4.0, 9.0, 3.0, 3.0, 3.0]), {})["turnrate_ctrl"].tolist() == [-U1]
    assert g.act(maze_obs([1.0, 3.0, 3.0, 3.0, 9.0, 4.0, 4.0, 2.0]), {})["turnrate_ctrl"].tolist() == [U1]


def test_no_fallback_warning_when_everything_is_given():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        LRMMGuardian(forward_ray_model(), threshold=0.5, strategies="BrakeTurn")
        LRMMGuardian(head_model_by_hand(), threshold=0.5, strategies="")  # the core alone: given, no fallback
