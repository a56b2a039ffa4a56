import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from rmm_envs.systems.dubins4d.dynamics import Dubins4D, wrap_angle

SYS = Dubins4D()


def prop(state, control, duration, n=2):
    return SYS.propagate(np.array([state], float), np.array([control], float), duration, n)[0]


def test_straight_line_closed_form():
    end = prop([1.0, -2.0, math.pi / 3, 1.5], [0.0, 0.0], 2.0)[-1]
    assert end == pytest.approx(
        [1.0 + 3.0 * math.cos(math.pi / 3), -2.0 + 3.0 * math.sin(math.pi / 3), math.pi / 3, 1.5], abs=1e-12
    )


def test_constant_turn_is_a_circle():
    v, w, T = 1.0, 0.25, 3.0
    end = prop([0.0, 0.0, 0.0, v], [w, 0.0], T)[-1]
    R = v / w
    assert end[0] == pytest.approx(R * math.sin(w * T), abs=1e-12)
    assert end[1] == pytest.approx(R * (1 - math.cos(w * T)), abs=1e-12)
    assert end[2] == pytest.approx(w * T)


def test_accelerate_from_unit_speed():
    # the hand case: from (0,0,0,1) with u = (0, 0.1) for 1 s: x = 1.05, v = 1.1
    end = prop([0.0, 0.0, 0.0, 1.0], [0.0, 0.1], 1.0)[-1]
    assert end == pytest.approx([1.05, 0.0, 0.0, 1.1], abs=1e-12)


def test_speed_saturates_at_bounds():
    # from v = 1.9 accelerating 0.5 m/s^2 for 1 s: 0.2 s to reach 2 m/s, then hold
    end = prop([0.0, 0.0, 0.0, 1.9], [0.0, 0.5], 1.0)[-1]
    assert end[3] == pytest.approx(2.0)
    assert end[0] == pytest.approx(1.9 * 0.2 + 0.5 * 0.5 * 0.04 + 2.0 * 0.8, abs=1e-12)
    # braking stops at v = 0 and stays there: distance v^2 / (2 a)
    end = prop([0.0, 0.0, 0.0, 1.0], [0.2, -0.5], 5.0)[-1]
    assert end[3] == 0.0
    path = prop([0.0, 0.0, 0.0, 1.0], [0.0, -0.5], 5.0, n=11)
    assert path[-1, 0] == pytest.approx(1.0, abs=1e-12)
    assert np.all(path[:, 3] >= 0)


def test_controls_are_clipped_to_the_box():
    a = prop([0, 0, 0, 1.0], [5.0, 5.0], 1.0)
    b = prop([0, 0, 0, 1.0], [0.25, 0.5], 1.0)
    np.testing.assert_allclose(a, b)


def _rhs(t, z, u):
    x, y, th, v = z
    dv = u[1]
    if (dv < 0 and v <= 0) or (dv > 0 and v >= 2):
        dv = 0.0
    return [v * math.cos(th), v * math.sin(th), u[0], dv]


@settings(max_examples=40, deadline=None)
@given(
    th=st.floats(-4, 4),
    v=st.floats(0, 2),
    u1=st.floats(-0.25, 0.25),
    u2=st.floats(-0.5, 0.5),
    T=st.floats(0.01, 4.0),
)
def test_matches_an_independent_ode_solution(th, v, u1, u2, T):
    times = np.linspace(0, T, 5)
    z0 = np.array([0.3, -0.7, th, v])
    ref = solve_ivp(_rhs, (0, T), z0, args=((u1, u2),), t_eval=times, rtol=1e-12, atol=1e-12, max_step=0.005)
    ours = SYS.propagate(z0[None], np.array([[u1, u2]]), T, 5)[0]
    # the reference's own error is dominated by the kink at speed saturation
    np.testing.assert_allclose(ours, ref.y.T, atol=1e-6)


@given(w=st.floats(-1e-3, 1e-3))
def test_tiny_turn_rates_are_smooth(w):
    # the Taylor branch and the closed form agree where they meet, no 1/w blow-up
    end = prop([0, 0, 0, 2.0], [w, 0.3], 2.0)[-1]
    straight = prop([0, 0, 0, 2.0], [0.0, 0.3], 2.0)[-1]
    assert np.all(np.abs(end - straight)[:2] < 5e-3)


def test_batched_equals_one_by_one():
    rng = np.random.default_rng(0)
    X = np.c_[rng.uniform(-5, 5, (50, 2)), rng.uniform(-3, 3, 50), rng.uniform(0, 2, 50)]
    U = SYS.sample_controls(rng, 50)
    batch = SYS.propagate(X, U, 2.0, 8)
    for i in range(50):
        np.testing.assert_allclose(batch[i], SYS.propagate(X[i : i + 1], U[i : i + 1], 2.0, 8)[0], atol=1e-13)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(states=np.zeros((3, 3)), controls=np.zeros((3, 2)), duration=1.0, n_steps=4), "shape"),
        (dict(states=np.zeros((3, 4)), controls=np.zeros((2, 2)), duration=1.0, n_steps=4), "controls"),
        (dict(states=np.zeros((3, 4)), controls=np.zeros((3, 2)), duration=-1.0, n_steps=4), "duration"),
        (dict(states=np.zeros((3, 4)), controls=np.zeros((3, 2)), duration=1.0, n_steps=1), "n_steps"),
    ],
)
def test_bad_inputs(kwargs, match):
    with pytest.raises(ValueError, match=match):
        SYS.propagate(**kwargs)


def test_bad_bounds():
    with pytest.raises(ValueError, match="v_min"):
        Dubins4D(v_min=2, v_max=1)


def test_wrap_angle_range():
    a = wrap_angle(np.array([-np.pi, np.pi, 3 * np.pi, -7.0, 0.0]))
    assert np.all(a >= -np.pi) and np.all(a < np.pi)
    assert a[1] == pytest.approx(-np.pi)


@settings(max_examples=60, deadline=None)
@given(
    th=st.floats(-10, 10),
    v=st.floats(-1, 3),
    u1=st.floats(-0.5, 0.5),
    u2=st.floats(-1, 1),
    T=st.floats(0, 9.0),
)
def test_compiled_single_path_equals_the_numpy_path(th, v, u1, u2, T):
    # one state (an env step) runs through the compiled loop, batches through numpy: same
    # formulas in the same order, so the same floats (speeds and controls out of bounds,
    # saturation, series and closed-form turn integrals included)
    z0, u, times = np.array([[1.5, -0.7, th, v]]), np.array([[u1, u2]]), np.linspace(0.0, T, 16)
    np.testing.assert_array_equal(SYS.states_at(z0, u, times), SYS._states_at_numpy(z0, u, times))
