"""Tutorial: a new scene gets risk labels without touching the estimator.

    python docs/examples/new_system.py

A planar double integrator (a point mass with bounded acceleration) in a corridor of width 2 m:
state ``(x, y, vx, vy)``, control ``(ax, ay)`` in ``[-1, 1]^2``, failure when ``|y| >= 1``.
All the estimator needs is the :class:`rmm_envs.risk.RiskScene` protocol: the state size, the
control bounds, batched propagation, and which states and paths fail.
"""

import numpy as np

from rmm_envs.risk import RiskEstimator, check_scene


class CorridorDoubleIntegrator:
    state_dim = 4

    def __init__(self, half_width=1.0, a_max=1.0):
        self.half_width = half_width
        self.control_low = np.array([-a_max, -a_max])
        self.control_high = np.array([a_max, a_max])

    def propagate(self, states, controls, duration, n_steps):
        # exact for a constant acceleration: p(t) = p0 + v0 t + a t^2 / 2
        t = np.linspace(0.0, duration, n_steps)[None, :, None]
        p0, v0, a = states[:, None, :2], states[:, None, 2:], controls[:, None, :]
        return np.concatenate([p0 + v0 * t + 0.5 * a * t * t, v0 + a * t], axis=-1)

    def state_failed(self, states):
        return np.abs(states[:, 1]) >= self.half_width

    def path_failed(self, paths):
        # y is quadratic in time between path points, so check the points (and the extremum
        # of each segment would be exact; with short segments the points suffice here)
        return np.any(np.abs(paths[..., 1]) >= self.half_width, axis=1)


def main():
    scene = CorridorDoubleIntegrator()
    check_scene(scene)  # raises TypeError naming anything missing
    est = RiskEstimator(scene, branches=32, depth=2, horizon=1.0, n_steps=8)
    states = np.array(
        [
            [0.0, 0.0, 1.0, 0.0],  # centred, moving along the corridor
            [0.0, 0.8, 1.0, 0.0],  # near the upper wall
            [0.0, 0.8, 1.0, 1.0],  # near the wall and heading into it
            [0.0, -0.5, 0.0, -2.0],  # fast toward the lower wall
        ]
    )
    res = est.estimate(states, np.random.default_rng(0))
    for s, r, u in zip(states, res.risk, res.min_risk_ctrl, strict=True):  # one row per state
        print(f"state {s}: risk {r:.3f}, safest first control {np.round(u, 2)}")
    assert res.risk[0] < res.risk[1] < res.risk[2]
    cvar = RiskEstimator(scene, branches=32, depth=2, horizon=1.0, metric="cvar", alpha=0.1).estimate(
        states, np.random.default_rng(0)
    )
    print("CVaR(0.1) risks:", np.round(cvar.risk, 3))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
