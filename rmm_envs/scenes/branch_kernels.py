"""Fused branch loops of the risk labeller: propagate one branch, test it, keep its end state.

:class:`rmm_envs.risk.RiskEstimator` needs of each branch of a tree level only whether its path
fails and, if not, its last state.  The scenes' ``propagate`` and ``path_failed`` build every
path of a level as an ``(N, S, d)`` array and test the arrays; the loops here do both for one
branch at a time in compiled code, with no path array, and give the same bits: each repeats its
numpy twin's floating-point operations in the same order (the closed forms of
:class:`rmm_envs.systems.dubins4d.dynamics.Dubins4D` and :class:`rmm_envs.systems.maze.dynamics.Dubins3D`, the path tests of
:mod:`rmm_envs.worlds.path_kernels`); ``tests/test_fused_labels.py`` pins each to its twin.
"""

from __future__ import annotations

# * :func:`dubins4d_circle_branches`: :class:`rmm_envs.scenes.Dubins4DScene`;
# * :func:`dubins3d_maze_branches`: :class:`rmm_envs.scenes.MazeScene`;
# * :func:`quadrotor_command_branches`: :class:`rmm_envs.scenes.QuadrotorCommandScene` (the
#   controller and body of ``ClosedLoopQuadrotor.propagate``, the room test of
#   :mod:`rmm_envs.systems.quadrotor.room_kernels` at each path point as it is reached; a branch stops at its
#   first failing point, since the estimator reads no later state of a failed branch).
#
# Two shortcuts skip work whose result is known without changing a bit: the sine and cosine of a
# branch's start heading are computed once per branch (numpy's ``_displace`` computes them per
# point, the same values), and in a branch whose speed saturates the point after the saturation
# time reuses the saturation point (the same for every later point), while a point before it,
# whose second phase lasts exactly 0 s, is the first phase's point (``x + c * (+0) - s * (+-0)``
# is ``x`` for any ``x != 0``; the full arithmetic runs when a coordinate is 0).
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from rmm_envs.systems.dubins4d.dynamics import SERIES_COEFFICIENTS
from rmm_envs.systems.quadrotor.control import body_step, command_wrench
from rmm_envs.systems.quadrotor.room_kernels import room_state_failed
from rmm_envs.worlds.path_kernels import circle_path_hit, maze_path_hit_near

njit: Callable[..., Any] | None
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency; plain Python still works
    njit = None

__all__ = ["dubins3d_maze_branches", "dubins4d_circle_branches", "quadrotor_command_branches"]

_SERIES_MAX = 0.6  # rmm_envs.systems.dubins4d.dynamics._SERIES_MAX: a test holds the two equal
_C = tuple(tuple(float(c) for c in row) for row in SERIES_COEFFICIENTS)  # constants in the compiled code
_C1R, _C1I, _C2R, _C2I = _C


def _horner7(p, c):
    """``rmm_envs.systems.dubins4d.dynamics._horner`` of seven coefficients (``acc *= p; acc += c``)."""
    acc = c[6]
    acc *= p
    acc += c[5]
    acc *= p
    acc += c[4]
    acc *= p
    acc += c[3]
    acc *= p
    acc += c[2]
    acc *= p
    acc += c[1]
    acc *= p
    acc += c[0]
    return acc


def _series_position(x0, y0, c0, s0, v0, w, a, t):
    """:func:`_position` where ``|w t| <= 0.6`` (the power series; branch-free, so a loop of it
    vectorises over the points; the same operations, so the same bits)."""
    phi = w * t
    p = phi * phi
    e1r, e1i, e2r, e2i = _horner7(p, _C1R), phi * _horner7(p, _C1I), _horner7(p, _C2R), phi * _horner7(p, _C2I)
    lin = v0 * t
    quad = a * t * t
    re = lin * e1r + quad * e2r
    im = lin * e1i + quad * e2i
    return x0 + c0 * re - s0 * im, y0 + s0 * re + c0 * im


def _position(x0, y0, c0, s0, v0, w, a, t):
    """``_segment`` of :mod:`rmm_envs.systems.dubins4d.dynamics` for one time ``t``, given the start
    heading's cosine ``c0`` and sine ``s0``: the turn integrals, then ``_displace``."""
    phi = w * t
    if abs(phi) <= _SERIES_MAX:
        p = phi * phi
        e1r, e1i, e2r, e2i = _horner7(p, _C1R), phi * _horner7(p, _C1I), _horner7(p, _C2R), phi * _horner7(p, _C2I)
    else:  # _closed_turn_integrals
        sn, cs = math.sin(phi), math.cos(phi)
        h = math.sin(0.5 * phi)
        one_m_cos = 2.0 * h * h
        inv = 1.0 / phi
        e1r, e1i = sn * inv, one_m_cos * inv
        e2r, e2i = (phi * sn - one_m_cos) * inv * inv, (sn - phi * cs) * inv * inv
    lin = v0 * t
    quad = a * t * t
    re = lin * e1r + quad * e2r
    im = lin * e1i + quad * e2i
    return x0 + c0 * re - s0 * im, y0 + s0 * re + c0 * im


def _dubins4d_path(x0, y0, th0, v, u1, u2, times, lo, hi, px, py):
    """The positions ``px, py`` of :meth:`Dubins4D.states_at <rmm_envs.systems.dubins4d.dynamics.Dubins4D.states_at>`
    at ``times`` and the last point's heading and speed; ``lo``/``hi``: (v, u1, u2) bounds."""
    s = times.shape[0]
    t_end = 0.0
    for k in range(s):
        t_end = max(t_end, times[k])
    # numpy's clips, ties included (numba's min and max return their first argument on a tie, numpy's
    # minimum and maximum their second; np.clip keeps x with scalar bounds and takes the bound with arrays)
    v0 = min(max(v, lo[0]), hi[0])
    w = min(hi[1], max(lo[1], u1))
    a = min(hi[2], max(lo[2], u2))
    v_end = v0 + a * t_end
    c0, s0 = math.cos(th0), math.sin(th0)
    t_last = times[s - 1]
    if not (v_end > hi[0] or v_end < lo[0]):
        if abs(w * t_end) <= _SERIES_MAX:  # every point's |w t| too (rounding is monotone): one loop, no branch
            for k in range(s):
                px[k], py[k] = _series_position(x0, y0, c0, s0, v0, w, a, times[k])
        else:
            for k in range(s):
                px[k], py[k] = _position(x0, y0, c0, s0, v0, w, a, times[k])
        return th0 + w * t_last, v0 + a * t_last
    # the speed saturates: accelerate until t_sat, then hold the speed (numpy's two-phase block)
    t_sat = (hi[0] - v0) / a if a > 0 else (lo[0] - v0) / a
    ts = max(0.0, t_sat)  # np.maximum(t_sat, 0.0): +0 for a t_sat of -0
    xs, ys = _position(x0, y0, c0, s0, v0, w, a, ts)
    vs = min(max(v0 + a * ts, lo[0]), hi[0])
    ths = th0 + w * ts
    cs, ss = math.cos(ths), math.sin(ths)
    for k in range(s):
        t = times[k]
        if t > ts:  # t1 = ts: the second phase from the saturation point
            px[k], py[k] = _position(xs, ys, cs, ss, vs, w, 0.0, t - ts)
            continue
        x1, y1 = _position(x0, y0, c0, s0, v0, w, a, t)  # t1 = t, a second phase of 0 s
        if x1 != 0.0 and y1 != 0.0:
            px[k], py[k] = x1, y1
        else:
            th1 = th0 + w * t
            v1 = min(max(v0 + a * t, lo[0]), hi[0])
            px[k], py[k] = _position(x1, y1, math.cos(th1), math.sin(th1), v1, w, 0.0, t - t)
    t1 = min(ts, t_last)  # np.minimum(t, ts)
    return th0 + w * t_last, min(max(v0 + a * t1, lo[0]), hi[0])


def dubins4d_circle_branches(states, controls, times, lo, hi, circles, failed, ends):
    """For each row of ``states`` ``(N, 4)`` and ``controls`` ``(N, 2)``: whether its path at
    ``times`` touches a circle (``failed``, ``(N,)`` bool) and its last state (``ends``, ``(N, 4)``;
    written for every row).  The same bits as ``Dubins4DScene.path_failed(propagate(...))`` and
    the path's last point."""
    s = times.shape[0]
    px, py, scratch = np.empty(s), np.empty(s), np.empty(max(s - 1, 1))
    for i in range(states.shape[0]):
        th, v = _dubins4d_path(
            states[i, 0],
            states[i, 1],
            states[i, 2],
            states[i, 3],
            controls[i, 0],
            controls[i, 1],
            times,
            lo,
            hi,
            px,
            py,
        )
        failed[i] = circle_path_hit(px, py, s, circles, scratch)
        ends[i, 0], ends[i, 1], ends[i, 2], ends[i, 3] = px[s - 1], py[s - 1], th, v
    return failed


def dubins3d_maze_branches(states, controls, times, speed, u_max, walls, cand, half, width, height, failed, ends):
    """For each row of ``states`` ``(N, 3)`` and ``controls`` ``(N, 1)``: whether the car's path at
    ``times`` fails in the maze (``failed``) and its last pose (``ends``), the same bits as
    ``MazeScene.path_failed(propagate(...))``; ``cand`` ``(N, K)``: each start's candidate walls."""
    s = times.shape[0]
    px, py, d2 = np.empty(s), np.empty(s), np.empty(s * cand.shape[1])
    t_last = times[s - 1]
    for i in range(states.shape[0]):
        x0, y0, th0 = states[i, 0], states[i, 1], states[i, 2]
        w = min(max(controls[i, 0], -u_max), u_max)
        c0, s0 = math.cos(th0), math.sin(th0)
        for k in range(s):
            px[k], py[k] = _position(x0, y0, c0, s0, speed, w, 0.0, times[k])
        failed[i] = maze_path_hit_near(px, py, s, walls, cand[i], half, width, height, d2)
        ends[i, 0], ends[i, 1], ends[i, 2] = px[s - 1], py[s - 1], th0 + w * t_last
    return failed


def quadrotor_command_branches(states, cmds, k, b, per_segment, n_points, room, failed, ends):
    """For each row of ``states`` ``(N, 13)`` and commands ``cmds`` ``(N, 4)`` (clipped): whether
    a path point of ``ClosedLoopQuadrotor.propagate`` (``n_points`` points, ``per_segment``
    physics steps apart; ``k``, ``b``: the packed controller and body) fails in the room
    (``failed``), and the last state (``ends``; for a failed branch, the first failing point's).
    ``room``: ``RoomCollision.kernel_args()``."""
    points, walls, shapes, pos, rots, sizes, radii, geom = room
    u, cur, nxt, rot = np.empty(4), np.empty(13), np.empty(13), np.empty(9)
    for i in range(states.shape[0]):
        for j in range(13):
            cur[j] = states[i, j]
        fail = room_state_failed(cur, rot, points, walls, shapes, pos, rots, sizes, radii, geom)
        p = 1
        while not fail and p < n_points:
            for _ in range(per_segment):
                command_wrench(cur, cmds[i], k, u)
                body_step(cur, u, b, nxt)
                cur, nxt = nxt, cur
            fail = room_state_failed(cur, rot, points, walls, shapes, pos, rots, sizes, radii, geom)
            p += 1
        failed[i] = fail
        for j in range(13):
            ends[i, j] = cur[j]
    return failed


if njit is not None:  # one source: the compiled loops are these functions
    _horner7 = njit(cache=True, inline="always")(_horner7)
    _series_position = njit(cache=True, inline="always")(_series_position)
    _position = njit(cache=True, inline="always")(_position)
    _dubins4d_path = njit(cache=True)(_dubins4d_path)
    dubins4d_circle_branches = njit(cache=True)(dubins4d_circle_branches)
    dubins3d_maze_branches = njit(cache=True)(dubins3d_maze_branches)
    quadrotor_command_branches = njit(cache=True)(quadrotor_command_branches)
