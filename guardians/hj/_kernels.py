"""Compiled (numba) kernel for the Dubins4D Lax-Friedrichs update on a 4-D grid.

The arrays are kept **padded** with one ghost cell on each side of every axis (heading:
periodic copies; the other axes: linear extrapolation, so that the outer one-sided difference
equals the inner one, as in the numpy path).  One call of :func:`lf_stage` then computes a
whole Runge-Kutta stage in a single branch-free, vectorisable pass over the interior:

``out = a * V0 + b * (W + dt * min(0, H_LF(W)))``, then ``out = max(out, floor)`` if a floor
is given,

where ``H_LF`` is the first-order upwind Lax-Friedrichs numerical Hamiltonian of
:class:`guardians.hj.dynamics.Dubins4DHJ` on axes ``(x, y, theta, v)``.  The numpy path in
``solver.py`` is the reference; the tests compare the two.  Fusing the differences, the
Hamiltonian, the dissipation and the stage combination avoids the dozen full-size
temporaries of the numpy path (each 17 MB on the default grid) and lets the compiler use
SIMD; it is what makes 2,048-episode HJ benchmarks feasible.

``out`` must not be ``W`` (the stencil reads ``W``'s neighbours) and should not be ``V0``
either: that would be correct (each output point reads ``V0`` only at itself) but LLVM's
run-time alias check then falls back to scalar code, 3x slower.
"""

from __future__ import annotations

import numpy as np

try:  # numba is a dependency, but the solver keeps a numpy path that works without it
    import numba
    from numba import njit, prange

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - exercised only where numba is missing
    HAVE_NUMBA = False

__all__ = ["HAVE_NUMBA", "Dubins4DStepper", "kernel_mismatch", "set_threads"]


def kernel_mismatch(grid, dynamics, order: int = 1) -> str | None:
    """Why the compiled kernel cannot solve this problem, or ``None`` if it can."""
    from guardians.hj.dynamics import Dubins4DHJ

    if not isinstance(dynamics, Dubins4DHJ) or order != 1:
        return f"the compiled kernel supports only Dubins4DHJ with order=1, got {type(dynamics).__name__}, order={order}"
    if grid.ndim != 4 or grid.periodic != (False, False, True, False):
        return f"the compiled kernel needs a 4-D grid with only axis 2 periodic, got periodic={grid.periodic}"
    return None


def set_threads(n: int | None) -> None:
    """Limit the kernel's threads (``None``: numba's default, the core count)."""
    if HAVE_NUMBA:
        numba.set_num_threads(int(n) if n else numba.config.NUMBA_NUM_THREADS)


if HAVE_NUMBA:

    @njit(cache=True, parallel=True, boundscheck=False)
    def _stage(V0, W, out, floor, has_floor, a, b, dt, inv_dx, alpha, C, S, up, down, sign, u1max, u2max, d_max):
        # For fixed (i, j) the padded (theta, v) plane is contiguous: one long, branch-free,
        # vectorisable loop over it (its ghost entries get junk, then the ghosts are refilled).
        #
        # With central differences d_a = w[+a] - w[-a] and sums s_a = w[+a] + w[-a], the LF
        # terms simplify: p_a = d_a / (2 dx_a) and alpha_a (p+_a - p-_a) / 2 =
        # alpha_a (s_a - 2 w) / (2 dx_a), so the kernel needs no one-sided differences.
        n0, n1, n2, n3 = W.shape
        plane = n2 * n3
        Wf, Of, Vf, Ff = W.reshape(-1), out.reshape(-1), V0.reshape(-1), floor.reshape(-1)
        sx, sy, st = n1 * plane, plane, n3
        half = np.float32(0.5)
        zero = np.float32(0.0)
        two = np.float32(2.0)
        k0, k1, k2, k3 = half * inv_dx[0], half * inv_dx[1], half * inv_dx[2], half * inv_dx[3]
        g0, g1, g2, g3 = alpha[0] * k0, alpha[1] * k1, alpha[2] * k2, alpha[3] * k3  # dissipation weights
        gw = two * (g0 + g1 + g2 + g3)
        K1 = sign * u1max * k2  # heading-rate term: K1 |d_theta|
        K3 = sign * u2max * k3  # acceleration term: K3 max(sign d_v up, -sign d_v down)
        KD0, KD1 = sign * d_max * k0, sign * d_max * k1  # disturbance
        bdt = b * dt
        q_lo = n3 + 1  # the first interior entry of a (theta, v) plane
        count = plane - 2 * n3 - 2  # up to the last interior entry
        Cq, Sq = C[q_lo:q_lo + count] * k0, S[q_lo:q_lo + count] * k1
        Aq, Bq = sign * up[q_lo:q_lo + count], -sign * down[q_lo:q_lo + count]
        for i in prange(1, n0 - 1):
            for j in range(1, n1 - 1):
                base = i * sx + j * sy + q_lo
                # shifted views starting at the first interior entry, so that every load below
                # is indexed by a counter from 0 (numba then knows it is non-negative, skips the
                # negative-index wrap-around and the loop vectorises)
                wc = Wf[base:base + count]
                wxm, wxp = Wf[base - sx:base - sx + count], Wf[base + sx:base + sx + count]
                wym, wyp = Wf[base - sy:base - sy + count], Wf[base + sy:base + sy + count]
                wtm, wtp = Wf[base - st:base - st + count], Wf[base + st:base + st + count]
                wvm, wvp = Wf[base - 1:base - 1 + count], Wf[base + 1:base + 1 + count]
                o = Of[base:base + count]
                v0 = Vf[base:base + count] if a != zero else wc  # a = 0: no second stream to read
                fr = Ff[base:base + count] if has_floor else Ff[0:count]
                for q in range(count):
                    w = wc[q]
                    dx_, dy_, dv_ = wxp[q] - wxm[q], wyp[q] - wym[q], wvp[q] - wvm[q]
                    hv, hd = dv_ * Aq[q], dv_ * Bq[q]
                    H = Cq[q] * dx_ + Sq[q] * dy_ + K1 * abs(wtp[q] - wtm[q]) + K3 * (hv if hv > hd else hd)
                    H -= KD0 * abs(dx_) + KD1 * abs(dy_)
                    H += g0 * (wxp[q] + wxm[q]) + g1 * (wyp[q] + wym[q]) + g2 * (wtp[q] + wtm[q]) + g3 * (wvp[q] + wvm[q]) - gw * w
                    H = H if H < zero else zero
                    val = a * v0[q] + b * w + bdt * H
                    if has_floor:
                        fl = fr[q]
                        val = val if val > fl else fl
                    o[q] = val
                # this plane's own ghosts, while it is in cache: heading periodic, speed extrapolated
                _fill_plane_ghosts(Of[i * sx + j * sy:i * sx + j * sy + plane], n2, n3)
        _fill_xy_ghosts(out)

    @njit(cache=True, boundscheck=False)
    def _fill_plane_ghosts(pl, n2, n3):
        """Ghosts of one flattened (theta, v) plane: heading periodic, then speed extrapolated."""
        two = np.float32(2.0)
        for m in range(n3):
            pl[m] = pl[(n2 - 2) * n3 + m]
            pl[(n2 - 1) * n3 + m] = pl[n3 + m]
        for k in range(n2):
            pl[k * n3] = two * pl[k * n3 + 1] - pl[k * n3 + 2]
            pl[k * n3 + n3 - 1] = two * pl[k * n3 + n3 - 2] - pl[k * n3 + n3 - 3]

    @njit(cache=True, boundscheck=False)
    def _fill_xy_ghosts(P):
        """Ghost faces of the two position axes (linear extrapolation), whole (theta, v) planes."""
        n0, n1 = P.shape[0], P.shape[1]
        two = np.float32(2.0)
        P[0] = two * P[1] - P[2]
        P[n0 - 1] = two * P[n0 - 2] - P[n0 - 3]
        for i in range(n0):
            P[i, 0] = two * P[i, 1] - P[i, 2]
            P[i, n1 - 1] = two * P[i, n1 - 2] - P[i, n1 - 3]

    @njit(cache=True, boundscheck=False)
    def _fill_ghosts(P):
        """All ghost cells: every (theta, v) plane's, then the position faces."""
        n0, n1, n2, n3 = P.shape
        plane = n2 * n3
        Pf = P.reshape(-1)
        for i in range(n0):
            for j in range(n1):
                _fill_plane_ghosts(Pf[(i * n1 + j) * plane:(i * n1 + j + 1) * plane], n2, n3)
        _fill_xy_ghosts(P)


class Dubins4DStepper:
    """Runge-Kutta stages of the Dubins4D LF scheme on padded float32 arrays.

    ``padded(V)`` returns a padded copy; ``stage(V0, W, out, a, b, dt)`` writes one stage into
    ``out`` (interior and ghosts); ``interior(P)`` is a view of the unpadded values.
    """

    def __init__(self, grid, dynamics, alphas, control: str = "max", floor: np.ndarray | None = None) -> None:
        if not HAVE_NUMBA:
            raise RuntimeError("the compiled HJ kernel needs numba (pip install numba)")
        problem = kernel_mismatch(grid, dynamics)
        if problem:
            raise ValueError(problem)
        th, v = grid.axes[2], grid.axes[3]
        vv = np.minimum(v, dynamics.v_max)

        def plane(a):  # a (theta, v) table on the padded plane, flattened; ghosts get 0
            P = np.zeros((len(th) + 2, len(v) + 2), np.float32)
            P[1:-1, 1:-1] = a
            return P.reshape(-1)

        self.C = plane(np.cos(th)[:, None] * vv[None, :])
        self.S = plane(np.sin(th)[:, None] * vv[None, :])
        self.up = plane(np.broadcast_to(v < dynamics.v_max, (len(th), len(v))))
        self.down = plane(np.broadcast_to(v > dynamics.v_min, (len(th), len(v))))
        self.inv_dx = (1.0 / np.asarray(grid.dx)).astype(np.float32)
        self.alpha = np.asarray(alphas, dtype=np.float32)
        f32 = np.float32
        self.consts = (f32(1.0 if control == "max" else -1.0), f32(dynamics.u1_max), f32(dynamics.u2_max), f32(dynamics.d_max))
        self.floor = None if floor is None else self.padded(np.asarray(floor, dtype=np.float32))
        self._dummy_floor = np.zeros((1, 1, 1, 1), np.float32)

    @staticmethod
    def padded(V: np.ndarray) -> np.ndarray:
        P = np.empty(tuple(n + 2 for n in V.shape), np.float32)
        P[1:-1, 1:-1, 1:-1, 1:-1] = V
        _fill_ghosts(P)
        return P

    @staticmethod
    def interior(P: np.ndarray) -> np.ndarray:
        return P[1:-1, 1:-1, 1:-1, 1:-1]

    def stage(self, V0, W, out, a: float, b: float, dt: float) -> None:
        f32 = np.float32
        has_floor = self.floor is not None
        _stage(V0, W, out, self.floor if has_floor else self._dummy_floor, has_floor, f32(a), f32(b), f32(dt),
               self.inv_dx, self.alpha, self.C, self.S, self.up, self.down, *self.consts)
