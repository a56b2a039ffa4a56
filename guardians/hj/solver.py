"""A small level-set solver for backward reachable tubes (BRTs).

Solves ``V_tau = min(0, H(x, grad V))``, ``V(x, 0) = l(x)``, from ``tau = 0`` to the
horizon, where ``l <= 0`` on the target (obstacle) set and ``H = max_u min_d grad V . f``.
The result ``V(x, T)`` is ``<= 0`` exactly on the states from which the target cannot be
avoided within ``T`` seconds.  Lax-Friedrichs with first-order upwind (``order=1``) or ENO2
(``order=2``, default) differences, TVD Runge-Kutta in time (:data:`TVD_RK`, ``rk=3`` default),
optional reach-avoid, float32 arrays.  Two implementations of the same scheme: a generic numpy
one (any dimension and dynamics; the reference) and, for the Dubins4D dynamics, compiled numba
kernels (``guardians/hj/_kernels.py``); ``backend="auto"`` takes the compiled one where it
applies, and both agree to float32 rounding (tested).  ``threads`` sets the compiled kernel's
thread count without changing the result.  The numerics: :func:`solve_brt`; why:
docs/decisions/0010-hj-solver.md.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from fractions import Fraction
from typing import Protocol, cast

import numpy as np

from rmm_envs.environment_variables import HJ_THREADS, hj_threads
from rmm_guardians._checks import finite, integer
from rmm_guardians.hj import _kernels
from rmm_guardians.hj.dynamics import HJDynamics, check_dynamics
from rmm_guardians.hj.grid import Grid

__all__ = ["BACKENDS", "TVD_RK", "default_threads", "select_backend", "solve_brt", "spatial_derivatives"]

BACKENDS = ("auto", "numpy", "numba")

_F = Fraction
#: TVD Runge-Kutta schemes in Shu-Osher form, by order: ``(a_k, b_k)`` per stage, and stage
#: ``k`` computes ``V_{k+1} = a_k V_0 + b_k (V_k + dt L(V_k))`` from ``V_0 = V(t)``; the last
#: stage is ``V(t + dt)``.  Exact fractions: each backend rounds a coefficient once, its own way.
TVD_RK = {
    1: ((_F(0), _F(1)),),  # forward Euler
    2: ((_F(0), _F(1)), (_F(1, 2), _F(1, 2))),  # Heun
    3: ((_F(0), _F(1)), (_F(3, 4), _F(1, 4)), (_F(1, 3), _F(2, 3))),  # Shu-Osher
}


def _scaled(X: np.ndarray, c: Fraction) -> np.ndarray:
    """``c X`` in float32, correctly rounded: ``X / n`` for ``c = 1/n`` (``1/3`` has no exact
    binary form, so multiplying by it would round twice)."""
    if c == 1:
        return X
    if c.numerator == 1:
        return X / float(c.denominator)
    return float(c) * X


def _combine(V0: np.ndarray, E: np.ndarray, a: Fraction, b: Fraction) -> np.ndarray:
    """``a V0 + b E`` (one Runge-Kutta stage of :data:`TVD_RK`, ``E`` its Euler step)."""
    return _scaled(E, b) if a == 0 else _scaled(V0, a) + _scaled(E, b)


THREADS_VARIABLE = HJ_THREADS


def default_threads() -> int | None:
    """The HJ guardians' ``threads`` when none is given: ``$RMM_HJ_THREADS`` (an integer >= 1)
    if set, else ``None`` (numba's default, the core count); read by :mod:`rmm_envs.environment_variables`."""
    return hj_threads()


def check_scheme(order, rk, cfl) -> tuple[int, int, float]:
    """The numerical scheme's settings checked (``ValueError`` naming the bad one): spatial
    ``order`` 1 or 2, ``rk`` stages 1-3 (:data:`TVD_RK`), ``cfl`` in (0, 1]; returned as
    ``(order, rk, cfl)``.  The one check the solver and every HJ guardian use."""
    if isinstance(order, bool) or order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order!r}")
    if isinstance(rk, bool) or rk not in TVD_RK:
        raise ValueError(f"rk must be one of {sorted(TVD_RK)}, got {rk!r}")
    cfl = finite("cfl", cfl, 0.0, lo_open=True)
    if cfl > 1:
        raise ValueError(f"cfl must be in (0, 1], got {cfl!r}")
    return int(order), int(rk), cfl


def select_backend(grid: Grid, dynamics: HJDynamics, order: int, backend: str = "auto") -> str:
    """The implementation ``solve_brt`` will use: ``"numba"`` or ``"numpy"``."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    problem = _kernels.kernel_mismatch(grid, dynamics, order)
    if backend == "numba":
        if not _kernels.HAVE_NUMBA:
            raise RuntimeError("backend='numba' needs numba installed (pip install numba)")
        if problem:
            raise ValueError(f"backend='numba': {problem}")
        return "numba"
    if backend == "numpy":
        return "numpy"
    return "numba" if (problem is None and _kernels.HAVE_NUMBA) else "numpy"


def _pad(V: np.ndarray, axis: int, periodic: bool, g: int) -> np.ndarray:
    if periodic:
        return np.concatenate([V.take(range(-g, 0), axis=axis), V, V.take(range(g), axis=axis)], axis=axis)
    n = V.shape[axis]
    lo = [V.take([0], axis=axis) + (V.take([0], axis=axis) - V.take([1], axis=axis)) * k for k in range(g, 0, -1)]
    hi = [
        V.take([n - 1], axis=axis) + (V.take([n - 1], axis=axis) - V.take([n - 2], axis=axis)) * k
        for k in range(1, g + 1)
    ]
    return np.concatenate(lo + [V] + hi, axis=axis)


def spatial_derivatives(V: np.ndarray, grid: Grid, axis: int, order: int = 1):
    """Left and right one-sided derivatives ``(p-, p+)`` of ``V`` along ``axis``."""
    dx = np.float32(grid.dx[axis])
    n = V.shape[axis]
    if order == 1:
        P = _pad(V, axis, grid.periodic[axis], 1)
        D = np.diff(P, axis=axis) / dx  # n + 1 differences; D[i] = (V_i - V_{i-1}) / dx
        index = [slice(None)] * V.ndim
        index[axis] = slice(0, n)
        left = D[tuple(index)]
        index[axis] = slice(1, n + 1)
        return left, D[tuple(index)]
    if order == 2:
        P = _pad(V, axis, grid.periodic[axis], 2)
        D1 = np.diff(P, axis=axis) / dx  # n + 3
        D2 = np.diff(D1, axis=axis) / dx  # n + 2; D2[j] is the second difference at padded j + 1

        def sl(a, b):
            s = [slice(None)] * V.ndim
            s[axis] = slice(a, b)
            return tuple(s)

        d2_im1, d2_i, d2_ip1 = D2[sl(0, n)], D2[sl(1, n + 1)], D2[sl(2, n + 2)]
        c_left = np.where(np.abs(d2_im1) <= np.abs(d2_i), d2_im1, d2_i)
        c_right = np.where(np.abs(d2_i) <= np.abs(d2_ip1), d2_i, d2_ip1)
        left = D1[sl(1, n + 1)] + 0.5 * dx * c_left
        right = D1[sl(2, n + 2)] - 0.5 * dx * c_right
        return left, right
    raise ValueError(f"order must be 1 or 2, got {order}")


class _ReachDynamics(HJDynamics, Protocol):
    """Dynamics used for reach-avoid: their Hamiltonian also takes ``control="min"``."""

    def hamiltonian(self, grid, p: Sequence[np.ndarray], control: str = "max") -> np.ndarray: ...


def _rate(V: np.ndarray, grid: Grid, dynamics: HJDynamics, alphas, order: int, control: str = "max") -> np.ndarray:
    p_mean, diss = [], None
    for ax in range(grid.ndim):
        left, right = spatial_derivatives(V, grid, ax, order)
        p_mean.append(0.5 * (left + right))
        term = (0.5 * np.float32(alphas[ax])) * (right - left)
        diss = term if diss is None else diss + term
        del left, right
    if control == "max":
        H = dynamics.hamiltonian(grid, p_mean)
    else:  # reach-avoid (solve_brt with a constraint): the caller's dynamics take control="min"
        H = cast(_ReachDynamics, dynamics).hamiltonian(grid, p_mean, control="min")
    H += diss
    return np.minimum(H, 0.0, out=H)


def solve_brt(
    grid: Grid,
    dynamics: HJDynamics,
    target: np.ndarray,
    horizon: float,
    order: int = 2,
    rk: int = 3,
    cfl: float = 0.8,
    progress=None,
    constraint: np.ndarray | None = None,
    backend: str = "auto",
    threads: int | None = None,
) -> tuple[np.ndarray, dict]:
    """Backward reachable tube of ``target`` (``l``: <= 0 inside) over ``horizon`` seconds.

    Avoid mode (``constraint=None``): the control *avoids* the target (maximises); ``V <= 0``
    marks the states that cannot avoid it.  Reach-avoid mode (``constraint`` given, ``g``:
    <= 0 inside the obstacles): the control *reaches* the target (minimises) while
    ``V >= -g`` is enforced after every stage, so ``V <= 0`` marks the states that can reach
    the target within the horizon without entering an obstacle.

    Numerics (Osher-Fedkiw, Mitchell's toolbox conventions): one-sided differences, first-order
    upwind or ENO2, periodic axes wrapped and the others extrapolated linearly; the
    Lax-Friedrichs numerical Hamiltonian ``H(x, (p- + p+)/2) + sum_i alpha_i (p+_i - p-_i) / 2``
    (plus sign: the equation is ``V_tau = +H``), ``alpha_i >= max |dH/dp_i|`` from the dynamics;
    TVD Runge-Kutta (``rk=1`` forward Euler, ``2`` Heun, ``3`` Shu-Osher; one tableau,
    :data:`TVD_RK`, that both implementations step through) with
    ``dt = cfl / sum_i (alpha_i / dx_i)``.  ``order=2, rk=3`` is second order in space (away from
    kinks) and third in time; ``order=1, rk=2`` (the paper's) is diffusive and under-estimates the
    unsafe set.  Float32 arrays (the default Dubins4D grid has 4.2 M points, 17 MB per array).

    ``backend``: ``"auto"`` (compiled kernel where it applies, 10-20x faster on the default
    grid), ``"numpy"`` or ``"numba"``.  ``threads``: threads of the compiled kernel (``None``:
    leave numba's setting as it is); every grid point is computed by exactly one thread.

    Returns ``V(x, horizon)`` (float32, the grid's shape) and a dict of solver statistics.
    """
    check_dynamics(dynamics)
    if target.shape != grid.shape:
        raise ValueError(f"target has shape {target.shape}, the grid {grid.shape}")
    if not horizon >= 0:
        raise ValueError(f"horizon must be >= 0, got {horizon}")
    if threads is not None:
        integer("threads", threads, 1, "or None")
    check_scheme(order, rk, cfl)
    impl = select_backend(grid, dynamics, order, backend)
    control = "max" if constraint is None else "min"
    if constraint is not None:
        if constraint.shape != grid.shape:
            raise ValueError(f"constraint has shape {constraint.shape}, the grid {grid.shape}")
        floor = (-constraint).astype(np.float32)
    alphas = [float(np.max(a)) for a in dynamics.alphas(grid)]
    rate_bound = sum(a / d for a, d in zip(alphas, grid.dx, strict=True))
    dt_max = cfl / rate_bound if rate_bound > 0 else horizon
    V = target.astype(np.float32, copy=True)
    if constraint is not None:
        V = np.maximum(V, floor)

    if impl == "numba":
        return _solve_compiled(
            grid,
            dynamics,
            alphas,
            V,
            dt_max,
            horizon,
            rk,
            control,
            None if constraint is None else floor,
            progress,
            cfl,
            order,
            threads,
        )

    def L(W):
        return _rate(W, grid, dynamics, alphas, order, control)

    def clamp(W):
        return W if constraint is None else np.maximum(W, floor)

    t, steps = 0.0, 0
    t0 = time.perf_counter()
    while t < horizon - 1e-12:
        dt = np.float32(min(dt_max, horizon - t))
        W = V
        for a, b in TVD_RK[rk]:
            W = clamp(_combine(V, W + dt * L(W), a, b))
        V = W.astype(np.float32, copy=False)
        t += float(dt)
        steps += 1
        if progress is not None:
            progress(t, horizon)
    return V, {
        "steps": steps,
        "dt": dt_max,
        "seconds": time.perf_counter() - t0,
        "order": order,
        "rk": rk,
        "cfl": cfl,
        "mode": "avoid" if constraint is None else "reach_avoid",
        "backend": "numpy",
    }


def _solve_compiled(grid, dynamics, alphas, V, dt_max, horizon, rk, control, floor, progress, cfl, order, threads):
    if threads is not None:
        _kernels.set_threads(threads)
    stepper = _kernels.Dubins4DStepper(grid, dynamics, alphas, control=control, floor=floor, order=order)
    P = stepper.padded(V)
    tableau = [(float(a), float(b)) for a, b in TVD_RK[rk]]
    # one output buffer per stage: an output aliasing an input defeats the kernel's vectorisation
    bufs = [np.empty_like(P) for _ in tableau]
    t, steps = 0.0, 0
    t0 = time.perf_counter()
    while t < horizon - 1e-12:
        dt = float(np.float32(min(dt_max, horizon - t)))
        W = P
        for (a, b), out in zip(tableau, bufs, strict=True):
            stepper.stage(P, W, out, a, b, dt)
            W = out
        P, bufs[-1] = bufs[-1], P
        t += dt
        steps += 1
        if progress is not None:
            progress(t, horizon)
    V = np.ascontiguousarray(stepper.interior(P))
    return V, {
        "steps": steps,
        "dt": dt_max,
        "seconds": time.perf_counter() - t0,
        "order": order,
        "rk": rk,
        "cfl": cfl,
        "mode": "avoid" if floor is None else "reach_avoid",
        "backend": "numba",
    }
