"""Tiny systems with hand-computable risk, implementing the rmm_envs.risk.System protocol."""

import numpy as np


class Line1D:
    """x' = u on a line, u in [0, 3]; failure when x >= wall."""

    state_dim = 1
    control_dim = 1

    def __init__(self, wall=1.0):
        self.wall = wall
        self.control_low = np.array([0.0])
        self.control_high = np.array([3.0])

    def sample_controls(self, rng, n):
        return rng.uniform(self.control_low, self.control_high, size=(n, 1))

    def propagate(self, states, controls, duration, n_steps):
        t = np.linspace(0, duration, n_steps)
        return states[:, None, :] + controls[:, None, :] * t[None, :, None]

    def path_failed(self, paths):
        return np.any(paths[..., 0] >= self.wall, axis=1)

    def state_failed(self, states):
        return states[:, 0] >= self.wall

    def observe(self, states):
        return self.wall - states

    def leaf_estimate(self, states):
        return np.full(states.shape[0], 0.5)
