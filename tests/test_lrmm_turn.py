"""The LRMM guardian's maze action (strategy ``RayTurn``) and its refusal texts, pinned on hand-made models.

The turn compares the model's risk of the rays rolled by one ray each way (the heading one ray
further left: ``roll(rays, -1)``, whose forward ray is the old ray 1; right: ``roll(rays, 1)``,
whose forward ray is the old ray 7); on a tie (``numpy.isclose``) the side whose nearest wall is
farther wins (rays 1-3 are the left side, 5-7 the right; ray 0 ahead and ray 4 behind are
neither), left on a second tie.  The models below are plain functions of the rays, so every
expected turn is read off the rays by hand.
"""

import math

import numpy as np
import pytest

from rmm_envs.autonomy import GuardianActionSpace, ObservationBox, ObservationLayout
from rmm_envs.systems.maze.guarded import observation_layout
from rmm_guardians.lrmm.guardian import REMEDY, LRMMGuardian
from rmm_guardians.lrmm.model import LRMMModel
from rmm_guardians.lrmm.strategies import RayTurn
from tests.test_lrmm import SPACES, forward_ray_model

TURN = GuardianActionSpace(("turnrate_ctrl",), [-0.2], [0.2])
U1 = np.float32(0.2)


class RaysModel(LRMMModel):
    """An 8-ray model whose risk is ``fn(rays)`` (the network's weights are never read)."""

    def __init__(self, fn, obs_dim=8):
        meta = {
            "env_id": "Dubins3DMaze-v0",
            "obs_dim": obs_dim,
            "features": list(range(obs_dim)),
            "hidden": [1],
            "activation": "relu",
            "output_bias": True,
        }
        super().__init__(
            [(np.zeros((1, obs_dim)), np.zeros(1)), (np.zeros((1, 1)), np.zeros(1))],
            np.zeros(obs_dim),
            np.ones(obs_dim),
            meta,
        )
        self.fn = fn

    def predict_all(self, obs):
        x = np.asarray(obs, float)
        if x.ndim == 1:
            return np.array([self.fn(x)])
        return np.array([[self.fn(row)] for row in x])


def maze_spaces(layout=None):
    lay = layout or observation_layout()
    return {
        "observation_space": ObservationBox(
            np.full(lay.size, -np.inf, np.float32), np.full(lay.size, np.inf, np.float32), lay
        ),
        "action_space": TURN,
    }


def turner(fn, **kw):
    g = LRMMGuardian(RaysModel(fn), threshold=0.3, strategies=(RayTurn(**kw),), inputs="rays")
    g.reset(seed=0, **maze_spaces())
    return g


def maze_obs(rays):
    return np.r_[np.asarray(rays, float), [1e4, -1e4, 0.5]]  # goal offset and heading: never read


def forward_risk(rays):  # short forward ray: high risk; the turned risks read the old rays 1 and 7
    return math.exp(-rays[0])


@pytest.mark.parametrize(
    "rays, turn",
    [
        # the model rates the left turn safer (ray 1 open, ray 7 short) while the nearest wall is on the left (ray 2)
        ([1.0, 9.0, 0.5, 9.0, 9.0, 3.0, 3.0, 3.0], U1),
        # the mirror: the model rates the right turn safer while the nearest wall is on the right (ray 6)
        ([1.0, 3.0, 3.0, 3.0, 9.0, 9.0, 0.5, 9.0], -U1),
    ],
)
def test_turn_goes_where_the_model_rates_the_turned_rays_safer_even_against_the_nearest_wall(rays, turn):
    g = turner(forward_risk)
    a = g.act(maze_obs(rays), {})
    assert g.last_risk == math.exp(-1.0) and a["active_ctrl"] == 1
    assert a["turnrate_ctrl"].tolist() == [turn]


def test_turn_stays_with_the_driver_at_or_below_the_threshold():
    g = turner(forward_risk)
    a = g.act(maze_obs([2.0, 9.0, 0.5, 9.0, 9.0, 3.0, 3.0, 3.0]), {})  # exp(-2) = 0.135 <= 0.3
    assert a["active_ctrl"] == 0 and g.last_risk == math.exp(-2.0)


def nearest_wall_risk(rays):  # the same for every rotation of the rays: the turned risks always tie
    return math.exp(-min(rays))


@pytest.mark.parametrize(
    "rays, turn",
    [
        ([1.0, 4.0, 4.0, 4.0, 9.0, 2.0, 2.0, 2.0], U1),  # left side's nearest wall (4) farther than the right's (2)
        ([1.0, 2.0, 2.0, 2.0, 9.0, 4.0, 4.0, 4.0], -U1),  # the mirror
        ([0.5, 2.0, 2.0, 2.0, 9.0, 4.0, 4.0, 4.0], -U1),  # ray 0 (ahead, nearest) belongs to neither side
        ([0.5, 3.0, 3.0, 3.0, 9.0, 3.0, 3.0, 3.0], U1),  # sides equal, ray 0 on neither side: left on the second tie
        ([1.0, 3.0, 3.0, 3.0, 0.5, 3.0, 3.0, 3.0], U1),  # ray 4 (behind, nearest) belongs to neither side: left
        ([1.0, 3.0, 2.5, 3.0, 9.0, 3.0, 3.0, 2.6], -U1),  # the side's nearest of its three rays, not its first
    ],
)
def test_a_tie_of_the_turned_risks_goes_to_the_side_whose_nearest_wall_is_farther(rays, turn):
    g = turner(nearest_wall_risk)
    a = g.act(maze_obs(rays), {})
    assert a["active_ctrl"] == 1 and a["turnrate_ctrl"].tolist() == [turn]


def test_a_near_tie_within_isclose_is_a_tie():
    # the turned risks differ by 1e-12 * (ray 1 - ray 7) = 2e-12, in favour of the right: numpy.isclose calls
    # it a tie, so the nearest walls decide (left: 4 against 2)
    g = turner(lambda r: math.exp(-min(r)) + 1e-12 * r[0])
    a = g.act(maze_obs([1.0, 4.0, 4.0, 4.0, 9.0, 2.0, 2.0, 2.0]), {})
    assert a["turnrate_ctrl"].tolist() == [U1]
    # the same rays with a difference isclose does not swallow (1e-3 * 2): the model decides, right
    g = turner(lambda r: math.exp(-min(r)) + 1e-3 * r[0])
    assert g.act(maze_obs([1.0, 4.0, 4.0, 4.0, 9.0, 2.0, 2.0, 2.0]), {})["turnrate_ctrl"].tolist() == [-U1]


def test_turn_rate_is_the_action_spaces_largest_or_the_given_one():
    narrow = GuardianActionSpace(("turnrate_ctrl",), [-0.1], [0.15])
    g = LRMMGuardian(RaysModel(forward_risk), threshold=0.3, strategies="RayTurn", inputs="rays")
    g.reset(seed=0, **(maze_spaces() | {"action_space": narrow}))
    assert g.act(maze_obs([1.0, 9.0, 0.5, 9.0, 9.0, 3.0, 3.0, 3.0]), {})["turnrate_ctrl"].tolist() == [np.float32(0.15)]
    g = turner(forward_risk, rate=0.05)
    assert g.act(maze_obs([1.0, 3.0, 3.0, 3.0, 9.0, 9.0, 0.5, 9.0]), {})["turnrate_ctrl"].tolist() == [
        np.float32(-0.05)
    ]


@pytest.mark.parametrize("bad_ray, where", [(1, 0), (7, 1)])
def test_a_non_finite_turned_risk_is_an_error_not_a_turn(bad_ray, where):
    rays = [1.0, 9.0, 0.5, 9.0, 9.0, 3.0, 3.0, 3.0]
    rays[bad_ray] = 7.0  # read as the forward ray of one turned copy only
    g = turner(lambda r: math.nan if r[0] == 7.0 else math.exp(-r[0]))
    with pytest.raises(ValueError, match=r"^the LRMM model returned non-finite risks \[.*\] for the turned rays$") as e:
        g.act(maze_obs(rays), {})
    shown = str(e.value).split("[")[1].split("]")[0].split(", ")
    assert ["nan" in s for s in shown] == [where == 0, where == 1]
    g = turner(lambda r: math.inf if r[0] == 7.0 else math.exp(-r[0]))
    with pytest.raises(ValueError, match="non-finite risks .*inf.* for the turned rays"):
        g.act(maze_obs(rays), {})


def _turn_refusal(inputs, angles):
    return (
        "guardian 'lrmm': strategy RayTurn judges a turn by the model's risk of the rays rotated by one ray, so the model "
        "must read the 'rays' field, rays evenly spaced over the full circle from the heading; "
        f"got inputs={inputs!r}, ray angles {angles}"
    )


@pytest.mark.parametrize(
    "angles",
    [
        tuple([0.0, 0.7] + [k * math.pi / 4 for k in range(2, 8)]),  # one ray off its place
        tuple(k * math.pi / 4 + math.pi / 8 for k in range(8)),  # even, but not from the heading
        tuple(k * math.pi / 4 for k in range(7, -1, -1)),  # the full circle clockwise
    ],
)
def test_turn_refuses_rays_that_a_roll_does_not_rotate(angles):
    lay = ObservationLayout.of(("rays", 8), ("goal_offset", 2), ("heading", 1), ray_angles=angles)
    g = LRMMGuardian(RaysModel(forward_risk), threshold=0.3, strategies="RayTurn", inputs="rays")
    with pytest.raises(ValueError) as e:
        g.reset(seed=0, **maze_spaces(lay))
    assert str(e.value) == _turn_refusal("rays", lay.ray_angles)
    # the same rays at k * 45 degrees from the heading (angles that differ from those by whole turns too) serve
    for shift in (0.0, 2 * math.pi):
        ok = ObservationLayout.of(
            ("rays", 8), ("goal_offset", 2), ("heading", 1), ray_angles=[k * math.pi / 4 + shift for k in range(8)]
        )
        g.reset(seed=0, **maze_spaces(ok))


def test_turn_refuses_a_model_that_reads_more_than_the_rays_and_spaces_without_one_control():
    g = LRMMGuardian(RaysModel(forward_risk, obs_dim=11), threshold=0.3, strategies="RayTurn")  # the whole observation
    with pytest.raises(ValueError) as e:
        g.reset(seed=0, **maze_spaces())
    assert str(e.value) == _turn_refusal(None, observation_layout().ray_angles)
    g = LRMMGuardian(RaysModel(forward_risk), threshold=0.3, strategies="RayTurn", inputs="rays")
    with pytest.raises(ValueError) as e:
        g.reset(seed=0, **(maze_spaces() | {"action_space": SPACES["action_space"]}))
    assert str(e.value) == (
        "guardian 'lrmm' needs an action space with 1 controls, got 2 (('turnrate_ctrl', 'accel_ctrl'))"
    )


# ----------------------------------------------------------------------------- refusal texts, exactly
def test_a_model_without_a_file_is_named_the_model_in_refusals_and_warnings():
    m = forward_ray_model()  # built in memory: no path
    assert not hasattr(m, "path")
    with pytest.raises(ValueError) as e:
        LRMMGuardian(m, threshold=0.5, strategies="SafestCandidate")
    assert str(e.value) == (
        "strategy SafestCandidate reads the model's action-conditioned head ('candidates'), and the model has none"
    )
    with pytest.raises(ValueError) as e:
        LRMMGuardian(m)
    assert str(e.value) == (
        "lrmm: the model (an LRMMModel without a file) has no decision: give a threshold "
        "(--agent-opt lrmm.threshold=0.5; in Python threshold=0.5)"
    )
    assert LRMMGuardian(m, threshold=0.5).strategies == ()  # no head, nothing stored: the core alone


def test_a_wrong_observation_size_is_refused_showing_the_space_or_the_field():
    g = LRMMGuardian(forward_ray_model(), strategies="BrakeTurn", threshold=0.85)
    with pytest.raises(ValueError) as e:
        g.check_spaces("a space without a shape", SPACES["action_space"])
    assert str(e.value) == (
        "guardian 'lrmm': the LRMM model (trained on Dubins4DGuarded-v0) expects observations of "
        "shape (17,), the env's observation space is a space without a shape" + REMEDY
    )
    with pytest.raises(ValueError) as e:
        g.check_spaces(
            ObservationBox(np.zeros(11, np.float32), np.ones(11, np.float32), observation_layout()),
            SPACES["action_space"],
        )
    assert str(e.value) == (
        "guardian 'lrmm': the LRMM model (trained on Dubins4DGuarded-v0) expects observations of "
        "shape (17,), the env's observation space is (11,)" + REMEDY
    )
    t = LRMMGuardian(RaysModel(forward_risk, obs_dim=12), threshold=0.3, strategies="RayTurn", inputs="rays")
    with pytest.raises(ValueError) as e:
        t.reset(seed=0, **maze_spaces())
    assert str(e.value) == (
        "guardian 'lrmm': the LRMM model (trained on Dubins3DMaze-v0) expects observations of "
        "shape (12,), the env's observation field 'rays' has 8 numbers" + REMEDY
    )


def test_the_sides_are_read_from_the_directions_however_the_angles_are_written():
    """The same eight directions with those past the left written negative (ray 4 at -pi, not +pi):
    ray 4, straight behind, still belongs to neither side."""
    angles = [0.0, math.pi / 4, math.pi / 2, 3 * math.pi / 4, -math.pi, -3 * math.pi / 4, -math.pi / 2, -math.pi / 4]
    lay = ObservationLayout.of(("rays", 8), ("goal_offset", 2), ("heading", 1), ray_angles=angles)
    g = LRMMGuardian(RaysModel(nearest_wall_risk), threshold=0.3, strategies="RayTurn", inputs="rays")
    g.reset(seed=0, **maze_spaces(lay))
    # left's nearest wall 2, right's 4: right, whatever the wall behind (0.5) is
    a = g.act(maze_obs([1.0, 2.0, 2.0, 2.0, 0.5, 4.0, 4.0, 4.0]), {})
    assert a["active_ctrl"] == 1 and a["turnrate_ctrl"].tolist() == [-U1]
    a = g.act(maze_obs([1.0, 4.0, 4.0, 4.0, 0.5, 2.0, 2.0, 2.0]), {})
    assert a["turnrate_ctrl"].tolist() == [U1]
