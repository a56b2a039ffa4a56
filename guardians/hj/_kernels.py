"""Compiled (numba) kernels for the Dubins4D Lax-Friedrichs update on a 4-D grid.

Two kernels: ``_stage`` (first-order upwind differences, one ghost cell per side) and
``_stage2`` (ENO2 differences, two ghost cells per side; the default scheme).  On arrays kept
padded with ghost cells, one call of :func:`lf_stage` computes a whole Runge-Kutta stage in
one pass over the interior:

``out = a * V0 + b * (W + dt * min(0, H_LF(W)))``, then ``out = max(out, floor)`` if a floor
is given,

with ``H_LF`` the Lax-Friedrichs numerical Hamiltonian of
:class:`rmm_guardians.hj.dynamics.Dubins4DHJ`.  The numpy path in ``solver.py`` is the reference
(the tests compare the two).  ``out`` must not be ``W``.  The padding, the cost of ENO2 and
aliasing: :class:`Dubins4DStepper`; why compiled and fused: docs/decisions/0010-hj-solver.md.
"""

from __future__ import annotations

import numpy as np

try:  # numba is a dependency, but the solver keeps a numpy path that works without it
    import numba
    from numba import njit, prange

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - exercised only where numba is missing
    HAVE_NUMBA = False

from rmm_guardians.hj.dynamics import Dubins4DHJ

__all__ = ["HAVE_NUMBA", "Dubins4DStepper", "kernel_mismatch", "set_threads"]


def kernel_mismatch(grid, dynamics, order: int = 1) -> str | None:
    """Why the compiled kernel cannot solve this problem, or ``None`` if it can."""
    if not isinstance(dynamics, Dubins4DHJ) or order not in (1, 2):
        return f"the compiled kernel supports only Dubins4DHJ with order 1 or 2, got {type(dynamics).__name__}, order={order}"
    if grid.ndim != 4 or grid.periodic != (False, False, True, False):
        return f"the compiled kernel needs a 4-D grid with only axis 2 periodic, got periodic={grid.periodic}"
    return None


def set_threads(n: int | None) -> None:
    """Limit the kernel's threads (``None``: numba's default, the core count)."""
    if HAVE_NUMBA:
        numba.set_num_threads(
            int(n) if n else numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]  # set at import via globals()
        )


if HAVE_NUMBA:
    from rmm_guardians.hj._ghosts import (
        _fill_ghosts,
        _fill_plane_ghosts,
        _fill_plane_ghosts2,
        _fill_xy_ghosts,
        _fill_xy_ghosts2,
    )

    @njit(cache=True)
    def _setup(V0, W, out, floor, b, dt, inv_dx, alpha, C, S, up, down, sign, u1max, u2max, d_max, ghosts):
        # What both stages derive from their arguments: flat views, strides, the LF weights, the
        # Hamiltonian's coefficients, the per-plane coefficient rows over the interior entries of
        # a plane and the weight of the rate in the stage combination.
        n0, n1, n2, n3 = W.shape
        plane = n2 * n3
        half = np.float32(0.5)
        k0, k1, k2, k3 = half * inv_dx[0], half * inv_dx[1], half * inv_dx[2], half * inv_dx[3]
        g = (alpha[0] * k0, alpha[1] * k1, alpha[2] * k2, alpha[3] * k3)  # dissipation weights
        K1 = sign * u1max * k2  # heading-rate term: K1 |d_theta|
        K3 = sign * u2max * k3  # acceleration term: K3 max(sign d_v up, -sign d_v down)
        KD0, KD1 = sign * d_max * k0, sign * d_max * k1  # disturbance
        q_lo = ghosts * n3 + ghosts  # the first interior entry of a (theta, v) plane
        count = plane - 2 * ghosts * n3 - 2 * ghosts  # up to the last interior entry
        Cq, Sq = C[q_lo : q_lo + count] * k0, S[q_lo : q_lo + count] * k1
        Aq, Bq = sign * up[q_lo : q_lo + count], -sign * down[q_lo : q_lo + count]
        flat = (W.reshape(-1), out.reshape(-1), V0.reshape(-1), floor.reshape(-1))
        return flat, plane, n1 * plane, plane, n3, g, K1, K3, KD0, KD1, q_lo, count, Cq, Sq, Aq, Bq, b * dt

    @njit(inline="always", boundscheck=False)
    def _point(q, dx_, dy_, dth, dv_, diss, w, v0, fr, has_floor, a, b, bdt, Cq, Sq, Aq, Bq, K1, K3, KD0, KD1):
        # One grid point of a stage, shared by both kernels (inlined into their loops): the
        # Hamiltonian from the (scaled) central differences, plus the dissipation ``diss``,
        # capped at 0, then the stage combination and the floor.
        hv, hd = dv_ * Aq[q], dv_ * Bq[q]
        H = Cq[q] * dx_ + Sq[q] * dy_ + K1 * abs(dth) + K3 * (hv if hv > hd else hd)
        H -= KD0 * abs(dx_) + KD1 * abs(dy_)
        H += diss
        H = H if H < np.float32(0.0) else np.float32(0.0)
        val = a * v0[q] + b * w + bdt * H
        if has_floor:
            fl = fr[q]
            val = val if val > fl else fl
        return val

    @njit(cache=True, parallel=True, boundscheck=False)
    def _stage(V0, W, out, floor, has_floor, a, b, dt, inv_dx, alpha, C, S, up, down, sign, u1max, u2max, d_max):
        # For fixed (i, j) the padded (theta, v) plane is contiguous: one long, branch-free,
        # vectorisable loop over it (its ghost entries get junk, then the ghosts are refilled).
        #
        # With central differences d_a = w[+a] - w[-a] and sums s_a = w[+a] + w[-a], the LF
        # terms simplify: p_a = d_a / (2 dx_a) and alpha_a (p+_a - p-_a) / 2 =
        # alpha_a (s_a - 2 w) / (2 dx_a), so the kernel needs no one-sided differences.
        n0, n1, n2, n3 = W.shape
        zero = np.float32(0.0)
        two = np.float32(2.0)
        (Wf, Of, Vf, Ff), plane, sx, sy, st, (g0, g1, g2, g3), K1, K3, KD0, KD1, q_lo, count, Cq, Sq, Aq, Bq, bdt = (
            _setup(V0, W, out, floor, b, dt, inv_dx, alpha, C, S, up, down, sign, u1max, u2max, d_max, 1)
        )
        gw = two * (g0 + g1 + g2 + g3)
        for i in prange(1, n0 - 1):
            for j in range(1, n1 - 1):
                base = i * sx + j * sy + q_lo
                # shifted views starting at the first interior entry, so that every load below
                # is indexed by a counter from 0 (numba then knows it is non-negative, skips the
                # negative-index wrap-around and the loop vectorises)
                wc = Wf[base : base + count]
                wxm, wxp = Wf[base - sx : base - sx + count], Wf[base + sx : base + sx + count]
                wym, wyp = Wf[base - sy : base - sy + count], Wf[base + sy : base + sy + count]
                wtm, wtp = Wf[base - st : base - st + count], Wf[base + st : base + st + count]
                wvm, wvp = Wf[base - 1 : base - 1 + count], Wf[base + 1 : base + 1 + count]
                o = Of[base : base + count]
                v0 = Vf[base : base + count] if a != zero else wc  # a = 0: no second stream to read
                fr = Ff[base : base + count] if has_floor else Ff[0:count]
                for q in range(count):
                    w = wc[q]
                    dx_, dy_, dv_ = wxp[q] - wxm[q], wyp[q] - wym[q], wvp[q] - wvm[q]
                    diss = (
                        g0 * (wxp[q] + wxm[q])
                        + g1 * (wyp[q] + wym[q])
                        + g2 * (wtp[q] + wtm[q])
                        + g3 * (wvp[q] + wvm[q])
                        - gw * w
                    )
                    o[q] = _point(
                        q,
                        dx_,
                        dy_,
                        wtp[q] - wtm[q],
                        dv_,
                        diss,
                        w,
                        v0,
                        fr,
                        has_floor,
                        a,
                        b,
                        bdt,
                        Cq,
                        Sq,
                        Aq,
                        Bq,
                        K1,
                        K3,
                        KD0,
                        KD1,
                    )
                # this plane's own ghosts, while it is in cache: heading periodic, speed extrapolated
                _fill_plane_ghosts(Of[i * sx + j * sy : i * sx + j * sy + plane], n2, n3)
        _fill_xy_ghosts(out)

    @njit(cache=True, parallel=True, boundscheck=False)
    def _stage2(V0, W, out, floor, has_floor, a, b, dt, inv_dx, alpha, C, S, up, down, sign, u1max, u2max, d_max):
        # The ENO2 version of _stage on arrays padded with two ghosts per side.  Along an axis
        # with neighbours w-2, w-1, w, w+1, w+2 and undivided second differences
        # c_m = w-2 - 2 w-1 + w, c_0 = w-1 - 2 w + w+1, c_p = w - 2 w+1 + w+2:
        #   p- = (w - w-1 + minabs(c_m, c_0) / 2) / dx,  p+ = (w+1 - w - minabs(c_0, c_p) / 2) / dx
        # (minabs: the argument of smaller magnitude, the left one on a tie, as the numpy path).
        # Then, with e = (minabs(c_m, c_0) + minabs(c_0, c_p)) / 2 and the central difference d:
        # with lm = minabs(c_m, c_0) and rm = minabs(c_0, c_p):
        #   (p- + p+) / 2 = (w+1 - w-1 + (lm - rm) / 2) / (2 dx)   (``d*_`` below, times 2 dx)
        #   (p+ - p-) / 2 = (c_0 - (lm + rm) / 2) / (2 dx)          (``j*`` below, times 2 dx)
        # so the LF dissipation alpha (p+ - p-) / 2 is alpha / (2 dx) * j, as in _stage.
        n0, n1, n2, n3 = W.shape
        half = np.float32(0.5)
        zero = np.float32(0.0)
        two = np.float32(2.0)
        (Wf, Of, Vf, Ff), plane, sx, sy, st, (g0, g1, g2, g3), K1, K3, KD0, KD1, q_lo, count, Cq, Sq, Aq, Bq, bdt = (
            _setup(V0, W, out, floor, b, dt, inv_dx, alpha, C, S, up, down, sign, u1max, u2max, d_max, 2)
        )
        for i in prange(2, n0 - 2):
            for j in range(2, n1 - 2):
                base = i * sx + j * sy + q_lo
                wc = Wf[base : base + count]
                xm2, xm, xp, xp2 = (
                    Wf[base - 2 * sx : base - 2 * sx + count],
                    Wf[base - sx : base - sx + count],
                    Wf[base + sx : base + sx + count],
                    Wf[base + 2 * sx : base + 2 * sx + count],
                )
                ym2, ym, yp, yp2 = (
                    Wf[base - 2 * sy : base - 2 * sy + count],
                    Wf[base - sy : base - sy + count],
                    Wf[base + sy : base + sy + count],
                    Wf[base + 2 * sy : base + 2 * sy + count],
                )
                tm2, tm, tp, tp2 = (
                    Wf[base - 2 * st : base - 2 * st + count],
                    Wf[base - st : base - st + count],
                    Wf[base + st : base + st + count],
                    Wf[base + 2 * st : base + 2 * st + count],
                )
                vm2, vm, vp, vp2 = (
                    Wf[base - 2 : base - 2 + count],
                    Wf[base - 1 : base - 1 + count],
                    Wf[base + 1 : base + 1 + count],
                    Wf[base + 2 : base + 2 + count],
                )
                o = Of[base : base + count]
                v0 = Vf[base : base + count] if a != zero else wc
                fr = Ff[base : base + count] if has_floor else Ff[0:count]
                for q in range(count):
                    w = wc[q]
                    w2 = two * w
                    # x
                    cm, c0, cp = xm2[q] - two * xm[q] + w, xm[q] - w2 + xp[q], w - two * xp[q] + xp2[q]
                    lm = cm if abs(cm) <= abs(c0) else c0
                    rm = c0 if abs(c0) <= abs(cp) else cp
                    dx_ = xp[q] - xm[q] + half * (lm - rm)  # 2 dx (p- + p+) / 2
                    jx = c0 - half * (lm + rm)  # dx (p+ - p-)
                    # y
                    cm, c0, cp = ym2[q] - two * ym[q] + w, ym[q] - w2 + yp[q], w - two * yp[q] + yp2[q]
                    lm = cm if abs(cm) <= abs(c0) else c0
                    rm = c0 if abs(c0) <= abs(cp) else cp
                    dy_ = yp[q] - ym[q] + half * (lm - rm)
                    jy = c0 - half * (lm + rm)
                    # theta
                    cm, c0, cp = tm2[q] - two * tm[q] + w, tm[q] - w2 + tp[q], w - two * tp[q] + tp2[q]
                    lm = cm if abs(cm) <= abs(c0) else c0
                    rm = c0 if abs(c0) <= abs(cp) else cp
                    dt_ = tp[q] - tm[q] + half * (lm - rm)
                    jt = c0 - half * (lm + rm)
                    # v
                    cm, c0, cp = vm2[q] - two * vm[q] + w, vm[q] - w2 + vp[q], w - two * vp[q] + vp2[q]
                    lm = cm if abs(cm) <= abs(c0) else c0
                    rm = c0 if abs(c0) <= abs(cp) else cp
                    dv_ = vp[q] - vm[q] + half * (lm - rm)
                    jv = c0 - half * (lm + rm)
                    o[q] = _point(
                        q,
                        dx_,
                        dy_,
                        dt_,
                        dv_,
                        g0 * jx + g1 * jy + g2 * jt + g3 * jv,
                        w,
                        v0,
                        fr,
                        has_floor,
                        a,
                        b,
                        bdt,
                        Cq,
                        Sq,
                        Aq,
                        Bq,
                        K1,
                        K3,
                        KD0,
                        KD1,
                    )
                _fill_plane_ghosts2(Of[i * sx + j * sy : i * sx + j * sy + plane], n2, n3)
        _fill_xy_ghosts2(out)


class Dubins4DStepper:
    """Runge-Kutta stages of the Dubins4D LF scheme on padded float32 arrays.

    ``order`` 1 (upwind, one ghost cell per side) or 2 (ENO2, two).  ``padded(V)`` returns a
    padded copy; ``stage(V0, W, out, a, b, dt)`` writes one stage into ``out`` (interior and
    ghosts); ``interior(P)`` is a view of the unpadded values.

    Padding: heading ghosts are periodic copies; the other axes' are linear extrapolations, so
    the outer one-sided difference equals the inner one, as in the numpy path.  Fusing the
    differences, the Hamiltonian, the dissipation and the stage combination avoids the dozen
    full-size temporaries of the numpy path (each 17 MB on the default grid) and lets the compiler
    use SIMD.  ENO2 reads two neighbours per side and chooses the smaller second difference,
    about 2.2x the work of a first-order stage; with RK3 a default-grid solve costs about 3.3x the
    first-order RK2 one.  ``out`` must not be ``W`` (the stencil reads its neighbours) and should
    not be ``V0`` either: that would be correct, but LLVM's run-time alias check then falls back
    to scalar code, 3x slower.  The position axes' ghosts are filled by scalar loops over the
    flattened array, not whole-face array expressions, which numba took about 6 s each to
    compile for a 4-D array.
    """

    def __init__(
        self, grid, dynamics, alphas, control: str = "max", floor: np.ndarray | None = None, order: int = 1
    ) -> None:
        if not HAVE_NUMBA:
            raise RuntimeError("the compiled HJ kernel needs numba (pip install numba)")
        problem = kernel_mismatch(grid, dynamics, order)
        if problem:
            raise ValueError(problem)
        self.order = g = int(order)
        self._kernel = _stage if g == 1 else _stage2
        self._inner = (slice(g, -g),) * 4
        th, v = grid.axes[2], grid.axes[3]
        vv = np.minimum(v, dynamics.v_max)

        def plane(a):  # a (theta, v) table on the padded plane, flattened; ghosts get 0
            P = np.zeros((len(th) + 2 * g, len(v) + 2 * g), np.float32)
            P[g:-g, g:-g] = a
            return P.reshape(-1)

        self.C = plane(np.cos(th)[:, None] * vv[None, :])
        self.S = plane(np.sin(th)[:, None] * vv[None, :])
        self.up = plane(np.broadcast_to(v < dynamics.v_max, (len(th), len(v))))
        self.down = plane(np.broadcast_to(v > dynamics.v_min, (len(th), len(v))))
        self.inv_dx = (1.0 / np.asarray(grid.dx)).astype(np.float32)
        self.alpha = np.asarray(alphas, dtype=np.float32)
        f32 = np.float32
        self.consts = (
            f32(1.0 if control == "max" else -1.0),
            f32(dynamics.u1_max),
            f32(dynamics.u2_max),
            f32(dynamics.d_max),
        )
        self.floor = None if floor is None else self.padded(np.asarray(floor, dtype=np.float32))
        self._dummy_floor = np.zeros((1, 1, 1, 1), np.float32)

    def padded(self, V: np.ndarray) -> np.ndarray:
        g = self.order
        P = np.empty(tuple(n + 2 * g for n in V.shape), np.float32)
        P[self._inner] = V
        _fill_ghosts(P, g)
        return P

    def interior(self, P: np.ndarray) -> np.ndarray:
        return P[self._inner]

    def stage(self, V0, W, out, a: float, b: float, dt: float) -> None:
        f32 = np.float32
        has_floor = self.floor is not None
        self._kernel(
            V0,
            W,
            out,
            self.floor if has_floor else self._dummy_floor,
            has_floor,
            f32(a),
            f32(b),
            f32(dt),
            self.inv_dx,
            self.alpha,
            self.C,
            self.S,
            self.up,
            self.down,
            *self.consts,
        )
