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
from hypothesis import example, given, settings
from hypothesis import strategies as st

import rmm_envs  # noqa: F401
from rmm_envs.systems.maze.guarded import Dubins3DMazeGuardedEnv
from rmm_guardians.cbf.maze import MazeCBFGuardian
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
    for pose, u in (
        ([250.0, 171.25, q], -U_MAX),
        ([250.0, 171.25, math.pi - q], U_MAX),
        ([250.0, 78.75, -q], U_MAX),
        ([250.0, 78.75, -math.pi + q], -U_MAX),
    ):
        a = g.decide(np.array(pose))
        assert a["active_ctrl"] == 1 and a["turnrate_ctrl"].dtype == np.float64 and a["turnrate_ctrl"][0] == u, pose
    assert g.stats()["qp_fallbacks"] == 4
    env.close()


# ------------------------------------------------------------------ arguments
@pytest.mark.parametrize(
    "kw, message",
    [
        ({"barrier": "circle"}, "barrier must be one of ('turning', 'distance'), got 'circle'"),
        ({"p1": 0.0}, "p1 (class-K gain) must be a finite number > 0.0, got 0.0"),
        ({"p2": -1.0}, "p2 (class-K gain) must be a finite number > 0.0, got -1.0"),
        ({"margin": -0.5}, "margin must be a finite number >= 0.0, got -0.5"),
        ({"n_walls": 0}, "n_walls must be an integer >= 1, got 0"),
        ({"active_atol": math.nan}, "active_atol must be a finite number >= 0.0, got nan"),
        ({"lap_guess": 0.0}, "lap_guess must be a finite number > 0.0, got 0.0"),
        ({"eps": math.inf}, "eps must be a finite number > 0.0, got inf"),
        ({"solver": "nope"}, None),
    ],
)
def test_arguments_are_refused_by_exact_message(kw, message):
    with pytest.raises(ValueError) as e:
        MazeCBFGuardian(**kw)
    if message is not None:
        assert str(e.value) == message
    else:
        assert "'nope'" in str(e.value)


def test_defaults_and_the_barrier_dependent_gain():
    g = MazeCBFGuardian()
    assert (
        g.barrier,
        g.p1,
        g.p2,
        g.margin,
        g.n_walls,
        g.active_atol,
        g.predict_latency,
        g.lap_guess,
        g.eps,
        g.solver,
    ) == ("turning", 1.0, 0.1, 2.0, 8, 1e-3, True, 0.1, 1e-6, "osqp")
    assert MazeCBFGuardian(barrier="distance").p1 == 0.1 and MazeCBFGuardian(barrier="distance", p1=0.5).p1 == 0.5
    assert MazeCBFGuardian(p1=3).p1 == 3.0 and MazeCBFGuardian(margin=0).margin == 0.0
    assert MazeCBFGuardian(predict_latency=0).predict_latency is False
    assert g.stats() == {"qp_fallbacks": 0, "nan_states": 0, "qp_solves": 0}
    assert (g.name, g.observation_type, g.privileged) == ("cbf", "global", True)


def test_reset_reads_the_maze_the_speed_and_the_bound(guardian):
    """After ``reset`` in the corridor: its four walls, half-thickness 6.25 px, the car's 10 px/s and
    0.2 rad/s; the nearest ``min(n_walls, walls)`` rows, smallest barrier first."""
    assert guardian.walls.shape == (4, 4) and guardian.half == 6.25 and guardian.speed == 10.0
    assert guardian.u_max == U_MAX and guardian.K == 4  # the action space bound, float64: exactly 0.2
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
    assert a["active_ctrl"] == 1 and a["turnrate_ctrl"].dtype == np.float64 and a["turnrate_ctrl"][0] == -U_MAX
    assert g.stats()["nan_states"] == 1 and g.stats()["qp_solves"] == 0
    env.close()


def test_head_on_the_turn_away_is_left_on_a_tie():
    """Heading straight at a flat wall (``n . e_perp = 0`` exactly): the row asks for the left turn
    (``sigma = +1``): ``G = -R sigma (-n . e) = -50``, so a left turn (u > 0) raises the barrier."""
    from rmm_guardians.cbf.maze import wall_rows

    B, G, h = wall_rows([0.0, 0.0, 0.0], 10.0, np.array([[30.0, -100.0, 30.0, 100.0]]), 6.25, 2.0, 1.0, 0.1)
    assert G[0, 0] == -R and B[0] == pytest.approx(30.0 - 6.25 - 2.0 - R)
    assert h[0] == pytest.approx(-10.0 + B[0])


def test_predict_is_the_exact_arc():
    """``lap`` seconds of turn rate ``u`` at 10 px/s from the origin heading +x: the arc of radius
    ``10 / u``; straight for ``u = 0``; the heading wrapped to [-pi, pi)."""
    g = MazeCBFGuardian()
    g.speed = 10.0
    np.testing.assert_allclose(
        g.predict(np.array([0.0, 0.0, 0.0]), 0.1, 1.0),
        [100.0 * math.sin(0.1), 100.0 * (1 - math.cos(0.1)), 0.1],
        atol=1e-12,
    )
    np.testing.assert_allclose(
        g.predict(np.array([5.0, 1.0, 0.5]), 0.0, 2.0),
        [5.0 + 20.0 * math.cos(0.5), 1.0 + 20.0 * math.sin(0.5), 0.5],
        atol=1e-12,
    )
    x, y, psi = g.predict(np.array([0.0, 0.0, 3.1]), 0.2, 1.0)
    assert psi == pytest.approx(3.3 - 2 * math.pi, abs=1e-12)
    assert x == pytest.approx(50.0 * (math.sin(3.3) - math.sin(3.1)), abs=1e-12)
    assert y == pytest.approx(-50.0 * (math.cos(3.3) - math.cos(3.1)), abs=1e-12)


def test_rows_keep_the_nearest_walls_smallest_barrier_first_for_either_barrier():
    """With ``n_walls = 2`` of the corridor's four walls: the two rows of smallest barrier value, in
    that order, of the guardian's own barrier."""
    from rmm_guardians.cbf.maze import wall_rows

    env = Dubins3DMazeGuardedEnv()

    pose = np.array([300.0, 160.0, 0.3])
    for barrier in ("turning", "distance"):
        g = MazeCBFGuardian(barrier=barrier, n_walls=2)
        reset_at(env, g, [250.0, 125.0, 0.0])
        b, G, h = g.rows(pose)
        B, GG, hh = wall_rows(pose, 10.0, g.walls, 6.25, 2.0, g.p1, g.p2, barrier, g.u_max)
        order = np.argsort(B, kind="stable")[:2]
        np.testing.assert_array_equal(b, B[order])
        np.testing.assert_array_equal(G, GG[order])
        np.testing.assert_array_equal(h, hh[order])
    env.close()


@pytest.mark.filterwarnings(
    "ignore:Converted matrix:UserWarning", "ignore:Clarabel.rs terminated with status:UserWarning"
)
def test_a_qpsolvers_backend_decides_as_the_direct_osqp_path():
    """(The fallback poses are infeasible QPs: qpsolvers warns of each; the decision is the same.)"""
    from qpsolvers import available_solvers

    name = next(n for n in ("clarabel", "daqp") if n in available_solvers)
    env = Dubins3DMazeGuardedEnv()
    a, b = MazeCBFGuardian(), MazeCBFGuardian(solver=f"qpsolvers:{name}")
    reset_at(env, a, [250.0, 125.0, 0.0])
    reset_at(env, b, [250.0, 125.0, 0.0])
    assert b._qp.name == name and a._qp.name is None
    for pose in ([300.0, 150.0, 1.0], [250.0, 171.25, math.pi / 4], [250.0, 125.0, 0.0], [200.0, 90.0, -0.7]):
        da, db = a.decide(np.array(pose)), b.decide(np.array(pose))
        assert da["active_ctrl"] == db["active_ctrl"]
        assert float(da["turnrate_ctrl"][0]) == pytest.approx(float(db["turnrate_ctrl"][0]), abs=1e-4)
    env.close()


def test_without_a_safe_default_a_nan_pose_turns_left_at_full_rate():
    from rmm_envs.autonomy import GuardianActionSpace
    from rmm_guardians.cbf.maze import MazeCBFGuardian as G
    from tests.test_maze_guardians import corridor

    space = GuardianActionSpace(("turnrate_ctrl",), [-0.2], [0.2], dynamics_name="dubins3d")
    g = G()
    g.reset(
        seed=0,
        observation_space=None,
        action_space=space,
        privileged=lambda: {"maze": corridor(), "speed": 10.0, "state": [math.nan, 1.0, 0.0], "sim_time": 0.0},
    )
    a = g.act(None)
    assert (
        a["active_ctrl"] == 1
        and a["turnrate_ctrl"].dtype == np.float64
        and a["turnrate_ctrl"][0] == 0.2
        and g.stats()["nan_states"] == 1
    )


def _maze_privileged(**over):
    from tests.test_maze_guardians import corridor

    priv = {"maze": corridor(), "speed": 10.0, "state": [300.0, 150.0, 1.0]} | over
    return lambda: priv


@pytest.mark.parametrize("speed", [0.0, -1.0, math.nan])
def test_a_non_positive_speed_in_the_privileged_data_is_refused_by_name(speed):
    from rmm_envs.autonomy import GuardianActionSpace

    g = MazeCBFGuardian()
    with pytest.raises(ValueError) as e:
        g.reset(
            seed=0,
            action_space=GuardianActionSpace(("turnrate_ctrl",), [-0.2], [0.2], dynamics_name="dubins3d"),
            privileged=_maze_privileged(speed=speed),
        )
    assert str(e.value) == f"privileged speed must be a finite number > 0.0, got {speed!r}"


def test_the_next_decision_is_for_the_pose_after_the_turn_it_emitted():
    """Latency prediction: the second ``act`` (no simulated time passed: the guessed lap, 0.1 s)
    decides for the pose reached by holding the first decision's turn over that lap; no
    ``sim_time`` in the privileged data is read as no time passing."""
    from rmm_envs.autonomy import GuardianActionSpace

    space = GuardianActionSpace(("turnrate_ctrl",), [-0.2], [0.2], dynamics_name="dubins3d")
    g, ref = MazeCBFGuardian(), MazeCBFGuardian()
    for x in (g, ref):
        x.reset(seed=0, action_space=space, privileged=_maze_privileged())
    first = g.act(None)
    u1 = float(first["turnrate_ctrl"][0])
    assert first["active_ctrl"] == 1 and u1 != 0.0
    second = g.act(None)
    expect = ref.decide(ref.predict(np.array([300.0, 150.0, 1.0]), u1, 0.1))
    assert second["active_ctrl"] == expect["active_ctrl"]
    assert float(second["turnrate_ctrl"][0]) == pytest.approx(float(expect["turnrate_ctrl"][0]), abs=1e-6)


@settings(max_examples=60, deadline=None)
@given(px=st.floats(5.0, 40.0), py=st.floats(-40.0, 40.0), psi=st.floats(-math.pi, math.pi), u=st.floats(-0.2, 0.2))
def test_at_a_walls_end_the_row_is_the_barriers_rate(px, py, psi, u):
    """Past the end of a wall (the segment from (-100, 0) to (0, 0), the car at x > 0, so the
    nearest point is the end): ``B' = (h - p1 B) - G u`` is the barrier's rate along the exact
    arc (central difference over 1e-4 s), while approaching and not head-on."""
    from rmm_guardians.cbf.maze import wall_rows

    wall = np.array([[-100.0, 0.0, 0.0, 0.0]])
    g = MazeCBFGuardian()
    g.speed = 10.0

    def rows(pose):
        return wall_rows(pose, 10.0, wall, 6.25, 2.0, 1.0, 0.1, "turning", 0.2)

    s = np.array([px, py, psi])
    d = math.hypot(px, py)
    ne = (px * math.cos(psi) + py * math.sin(psi)) / d
    nperp = (-px * math.sin(psi) + py * math.cos(psi)) / d
    if d < 7.0 or ne > -0.05 or abs(nperp) < 0.05:
        return
    B, G, h = rows(s)
    rate = (h[0] - 1.0 * B[0]) - G[0, 0] * u
    dt = 1e-4
    fwd, back = rows(g.predict(s, u, dt))[0][0], rows(g.predict(s, u, -dt))[0][0]
    assert rate == pytest.approx((fwd - back) / (2 * dt), rel=1e-4, abs=1e-5)


@settings(max_examples=60, deadline=None)
@given(psi=st.floats(-math.pi, math.pi), u=st.floats(-0.2, 0.2), lap=st.floats(-0.2, 0.2))
@example(psi=-2.5, u=5.960464477539063e-08, lap=1e-4)  # the arc form lost 6e-6 of the chord here (found by hypothesis)
def test_the_predicted_pose_is_the_arc_to_rounding_at_every_turn_rate(psi, u, lap):
    """``predict`` against the arc's displacement summed as its Taylor series in ``u lap``
    (40 terms, no cancellation at any turn rate): equal to 1e-12 px, tiny ``u lap`` included."""
    g = MazeCBFGuardian()
    g.speed = 10.0
    x1, y1, _ = g.predict(np.array([5.0, 5.0, psi]), u, lap)
    # displacement = s lap * sum_k (i u lap)^k / (k+1)! * e^{i psi}, summed in complex arithmetic
    w, term, total = complex(0.0, u * lap), 1.0 + 0j, 0j
    for k in range(40):
        total += term
        term *= w / (k + 2)
    z = 10.0 * lap * total * complex(math.cos(psi), math.sin(psi))
    assert x1 - 5.0 == pytest.approx(z.real, abs=1e-12) and y1 - 5.0 == pytest.approx(z.imag, abs=1e-12)
