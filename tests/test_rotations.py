import math

import numpy as np
import pybullet as p
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_envs.systems.quadrotor.rotations import quat_from_euler, quat_mul, quat_to_rot

S = math.sin(math.pi / 4)  # sin and cos of half a right angle

# 90 degrees about each axis: the columns are the rotated body axes
HAND = [
    ((0, 0, 0, 1), np.eye(3)),
    ((S, 0, 0, S), [[1, 0, 0], [0, 0, -1], [0, 1, 0]]),
    ((0, S, 0, S), [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]),
    ((0, 0, S, S), [[0, -1, 0], [1, 0, 0], [0, 0, 1]]),
    ((1, 0, 0, 0), [[1, 0, 0], [0, -1, 0], [0, 0, -1]]),  # 180 degrees about x
]


def unit_quats(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


@pytest.mark.parametrize("q, R", HAND)
def test_quat_to_rot_hand_computed(q, R):
    np.testing.assert_allclose(quat_to_rot(q), R, atol=1e-15)
    # the same rotation from -q
    np.testing.assert_allclose(quat_to_rot(-np.asarray(q, float)), R, atol=1e-15)


def test_quat_to_rot_matches_pybullet():
    rng = np.random.default_rng(0)
    for q in unit_quats(rng, 200):
        ref = np.reshape(p.getMatrixFromQuaternion(q.tolist()), (3, 3))
        np.testing.assert_allclose(quat_to_rot(q), ref, atol=1e-14)


def test_batched_forms_equal_the_single_forms_bit_for_bit():
    rng = np.random.default_rng(1)
    Q, P = unit_quats(rng, 50), unit_quats(rng, 50)
    angles = rng.uniform(-np.pi, np.pi, (50, 3))
    R, M, E = quat_to_rot(Q), quat_mul(Q, P), quat_from_euler(*angles.T)
    assert R.shape == (50, 3, 3) and M.shape == (50, 4) and E.shape == (50, 4)
    for i in range(50):
        np.testing.assert_array_equal(R[i], quat_to_rot(Q[i]))
        np.testing.assert_array_equal(M[i], quat_mul(Q[i], P[i]))
        np.testing.assert_allclose(
            E[i], quat_from_euler(*angles[i]), rtol=0, atol=1e-15
        )  # numpy's sin/cos may vectorise
    # any leading shape
    np.testing.assert_array_equal(quat_to_rot(Q.reshape(5, 10, 4)), R.reshape(5, 10, 3, 3))
    assert quat_to_rot(np.zeros((0, 4))).shape == (0, 3, 3)


def test_quat_mul_hand_computed():
    i, j, k, one = (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1)
    np.testing.assert_array_equal(quat_mul(i, j), k)
    np.testing.assert_array_equal(quat_mul(j, i), np.negative(k))
    np.testing.assert_array_equal(quat_mul(j, k), i)
    np.testing.assert_array_equal(quat_mul(i, i), np.negative(one))
    np.testing.assert_array_equal(quat_mul(one, (0.1, 0.2, 0.3, 0.4)), [0.1, 0.2, 0.3, 0.4])
    # two quarter turns about z make a half turn about z
    np.testing.assert_allclose(quat_mul((0, 0, S, S), (0, 0, S, S)), [0, 0, 1, 0], atol=1e-15)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-1, 1), min_size=8, max_size=8).filter(
        lambda v: np.linalg.norm(v[:4]) > 0.1 and np.linalg.norm(v[4:]) > 0.1
    )
)
def test_product_composes_rotations(v):
    a, b = np.array(v[:4]) / np.linalg.norm(v[:4]), np.array(v[4:]) / np.linalg.norm(v[4:])
    np.testing.assert_allclose(quat_to_rot(quat_mul(a, b)), quat_to_rot(a) @ quat_to_rot(b), atol=1e-13)
    R = quat_to_rot(a)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-13)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-13)


def test_quat_from_euler_matches_pybullet_and_the_axis_rotations():
    np.testing.assert_allclose(quat_from_euler(math.pi / 2, 0, 0), [S, 0, 0, S], atol=1e-16)
    np.testing.assert_allclose(quat_from_euler(0, 0, math.pi / 2), [0, 0, S, S], atol=1e-16)

    def rx(a):
        return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])

    def ry(a):
        return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])

    def rz(a):
        return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])

    rng = np.random.default_rng(2)
    for r, pt, y in rng.uniform(-np.pi, np.pi, (100, 3)):
        q = quat_from_euler(r, pt, y)
        np.testing.assert_allclose(q, p.getQuaternionFromEuler([r, pt, y]), atol=1e-14)
        np.testing.assert_allclose(quat_to_rot(q), rz(y) @ ry(pt) @ rx(r), atol=1e-14)


@pytest.mark.parametrize("bad", [np.zeros(3), np.zeros((2, 5)), 1.0])
def test_bad_shapes_are_refused(bad):
    with pytest.raises(ValueError, match=r"shape \(4,\)"):
        quat_to_rot(bad)
    with pytest.raises(ValueError, match="got shape"):
        quat_mul(bad, (0, 0, 0, 1))
    with pytest.raises(ValueError, match="b must"):
        quat_mul((0, 0, 0, 1), bad)
