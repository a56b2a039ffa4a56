"""The maze ``cbf`` guardian turns away from the wall it approaches (``guardians/cbf/maze.py``).

In the three-cell corridor of ``tests/test_maze_guardians.py`` (wall surfaces at y = 68.75 and
181.25), a car heading toward the upper wall at ``psi`` (up and right for ``0 < psi < pi/2``)
must turn right (``u < 0``) to turn away, and left for ``pi/2 < psi < pi``; toward the lower wall
the other way round.  So whenever the guardian takes control its turn has the sign
``-sign(sin psi cos psi)`` (or is zero: a QP row active at ``u = 0``), and inside the turning
barrier (``B < 0``: even a full turn away cannot keep ``B' + p1 B >= 0``, the QP is infeasible) it
is the full turn away, the fallback.  Head-on (within 0.15 rad of the wall's normal) either
turn is right and is not checked."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import rmm_envs  # noqa: F401
from guardians.cbf.maze import MazeCBFGuardian
from rmm_envs.envs.dubins3d_maze_parallel import Dubins3DMazeGuardedEnv
from tests.test_maze_guardians import reset_at

U_MAX, R, MARGIN = 0.2, 50.0, 2.0  # the maze car's turn bound, its turning radius s / u_max, the guardian's margin


@pytest.fixture(scope="module")
def guardian():
    env = Dubins3DMazeGuardedEnv()
    g = MazeCBFGuardian()
    reset_at(env, g, [250.0, 125.0, 0.0])
    yield g
    env.close()


def _away(psi: float) -> float:
    return -math.copysign(1.0, math.sin(psi) * math.cos(psi))


def _turning_barrier(y: float, psi: float) -> float:
    """``B`` of the wall the car heads to: ``b - R (1 - |cos psi|)``, ``b`` its distance to the wall's
    surface less the margin."""
    b = (181.25 - y if math.sin(psi) > 0 else y - 68.75) - MARGIN
    return b - R * (1.0 - abs(math.cos(psi)))


approach = st.floats(0.15, math.pi / 2 - 0.15) | st.floats(math.pi / 2 + 0.15, math.pi - 0.15)


@settings(max_examples=150, deadline=None)
@given(x=st.floats(200.0, 300.0), gap=st.floats(3.0, 60.0), psi=approach, lower=st.booleans())
def test_a_turn_taken_is_away_from_the_wall_and_full_inside_the_barrier(guardian, x, gap, psi, lower):
    """``gap``: px from the car to the surface of the wall it heads to (the upper one, or mirrored
    to the lower one)."""
    if lower:
        y, psi = 68.75 + gap, -psi
    else:
        y = 181.25 - gap
    before = guardian.stats()["qp_fallbacks"]
    a = guardian.decide(np.array([x, y, psi]))
    fell_back = guardian.stats()["qp_fallbacks"] > before
    B = _turning_barrier(y, psi)
    if B < -1e-3:  # no turn keeps the barrier condition: the full turn away
        assert a["active_ctrl"] == 1 and fell_back
        assert float(a["turnrate_ctrl"][0]) == pytest.approx(_away(psi) * U_MAX)
    elif a["active_ctrl"] == 1:
        u = float(a["turnrate_ctrl"][0])
        assert u == 0.0 or math.copysign(1.0, u) == _away(psi)
        assert abs(u) <= U_MAX
    if B > 1e-3:
        assert not fell_back


def test_hand_computed_full_turns_away():
    """Two poses 10 px from the upper wall's surface at 45 degrees: ``B = 8 - 50 (1 - cos 45deg) =
    -6.6``: full right turn heading up-right, full left turn heading up-left; mirrored at the
    lower wall, the reverse."""
    env = Dubins3DMazeGuardedEnv()
    g = MazeCBFGuardian()
    reset_at(env, g, [250.0, 125.0, 0.0])
    q = math.pi / 4
    for pose, u in (([250.0, 171.25, q], -U_MAX), ([250.0, 171.25, math.pi - q], U_MAX),
                    ([250.0, 78.75, -q], U_MAX), ([250.0, 78.75, -math.pi + q], -U_MAX)):
        a = g.decide(np.array(pose))
        assert a["active_ctrl"] == 1 and float(a["turnrate_ctrl"][0]) == np.float32(u), pose
    assert g.stats()["qp_fallbacks"] == 4
    env.close()


# ------------------------------------------------------------------ arguments
@pytest.mark.parametrize("kw, message", [
    ({"barrier": "circle"}, "barrier must be one of ('turning', 'distance'), got 'circle'"),
    ({"p1": 0.0}, "p1 (class-K gain) must be a finite number > 0.0, got 0.0"),
    ({"p2": -1.0}, "p2 (class-K gain) must be a finite number > 0.0, got -1.0"),
    ({"margin": -0.5}, "margin must be a finite number >= 0.0, got -0.5"),
    ({"n_walls": 0}, "n_walls must be an integer >= 1, got 0"),
    ({"active_atol": math.nan}, "active_atol must be a finite number >= 0.0, got nan"),
    ({"lap_guess": 0.0}, "lap_guess must be a finite number > 0.0, got 0.0"),
    ({"eps": math.inf}, "eps must be a finite number > 0.0, got inf"),
    ({"solver": "nope"}, None),
])
def test_arguments_are_refused_by_exact_message(kw, message):
    with pytest.raises(ValueError) as e:
        MazeCBFGuardian(**kw)
    if message is not None:
        assert str(e.value) == message
    else:
        assert "'nope'" in str(e.value)


def test_defaults_and_the_barrier_dependent_gain():
    g = MazeCBFGuardian()
    assert (g.barrier, g.p1, g.p2, g.margin, g.n_walls, g.active_atol, g.predict_latency, g.lap_guess, g.eps, g.solver) == \
        ("turning", 1.0, 0.1, 2.0, 8, 1e-3, True, 0.1, 1e-6, "osqp")
    assert MazeCBFGuardian(barrier="distance").p1 == 0.1 and MazeCBFGuardian(barrier="distance", p1=0.5).p1 == 0.5
    assert MazeCBFGuardian(p1=3).p1 == 3.0 and MazeCBFGuardian(margin=0).margin == 0.0
    assert MazeCBFGuardian(predict_latency=0).predict_latency is False
    assert g.stats() == {"qp_fallbacks": 0, "nan_states": 0, "qp_solves": 0}
    assert (g.name, g.observation_type, g.privileged) == ("cbf", "global", True)


def test_reset_reads_the_maze_the_speed_and_the_bound(guardian):
    """After ``reset`` in the corridor: its four walls, half-thickness 6.25 px, the car's 10 px/s and
    0.2 rad/s; the nearest ``min(n_walls, walls)`` rows, smallest barrier first."""
    assert guardian.walls.shape == (4, 4) and guardian.half == 6.25 and guardian.speed == 10.0
    assert guardian.u_max == float(np.float32(U_MAX)) and guardian.K == 4  # the action space bound, float32
    b, G, h = guardian.rows(np.array([250.0, 100.0, 0.0]))  # 31.25 px above the lower wall's surface
    assert G.shape == (4, 1) and np.all(np.diff(b) >= 0)
    assert b[0] == pytest.approx(100.0 - 68.75 - MARGIN)


def test_a_pose_with_nan_applies_the_safe_default_and_is_counted():
    """The env's safe default (the full turn away from the nearer wall, read on the rays), counted."""
    env = Dubins3DMazeGuardedEnv()
    g = MazeCBFGuardian()
    obs, info = reset_at(env, g, [250.0, 160.0, 0.0])  # the upper wall is the nearer: turn right
    env.unwrapped._state[:] = np.nan
    a = g.act(obs, info)
    assert a["active_ctrl"] == 1 and float(a["turnrate_ctrl"][0]) == np.float32(-U_MAX)
    assert g.stats()["nan_states"] == 1 and g.stats()["qp_solves"] == 0
    env.close()
