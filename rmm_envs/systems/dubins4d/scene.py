"""A Dubins4D vehicle among fixed circles: :class:`Dubins4DScene` and its observation."""

from __future__ import annotations

import math

import numpy as np

from rmm_envs.autonomy import ObservationLayout
from rmm_envs.scenes.base import SceneBase, branch_inputs
from rmm_envs.scenes.branch_kernels import dubins4d_circle_branches
from rmm_envs.systems.dubins4d.circles import CircleWorld, paths_hit_circles, points_in_circles, ray_cast
from rmm_envs.systems.dubins4d.dynamics import Dubins4D, wrap_angle

__all__ = ["Dubins4DScene", "observation", "observation_layout"]


def observation(states: np.ndarray, sim_time, goals: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """The observation table of :mod:`rmm_envs.systems.dubins4d.env` for ``N`` states ``(N, 4)``:
    ``sim_time`` scalar or ``(N,)``, goal centres ``(N, 2)`` (or ``(1, 2)`` for all), ray
    lengths ``(N, n_rays)``; float32."""
    obs = np.empty((states.shape[0], 5 + rays.shape[1]), dtype=np.float32)
    obs[:, 0] = sim_time
    obs[:, 1] = goals[:, 0] - states[:, 0]
    obs[:, 2] = goals[:, 1] - states[:, 1]
    obs[:, 3] = wrap_angle(states[:, 2])
    obs[:, 4] = states[:, 3]
    obs[:, 5:] = rays
    return obs


class Dubins4DScene(SceneBase):
    """A Dubins4D vehicle among fixed circles: the :class:`rmm_envs.risk.RiskScene` of
    ``Dubins4DGuarded-v0``.

    Batched exact propagation, path failure (any point or segment touching an obstacle), the
    17-dim observation (:meth:`observe`) and the stopping-distance leaf heuristic.  The
    environment uses the very same object, so labels and the env agree by construction.
    """

    state_dim = 4
    dynamics: Dubins4D

    def __init__(
        self,
        obstacles: np.ndarray,
        goal: np.ndarray,
        dynamics: Dubins4D | None = None,
        n_rays: int = 12,
        ray_length: float = 10.0,
    ) -> None:
        self.dynamics = dynamics or Dubins4D()
        self.world = CircleWorld(obstacles, goal)
        self.n_rays = int(n_rays)
        self.ray_length = float(ray_length)
        self.obs_dim = 5 + self.n_rays

    @property
    def obstacles(self) -> np.ndarray:
        return self.world.obstacles

    @property
    def goal(self) -> np.ndarray:
        return self.world.goal

    def state_failed(self, states: np.ndarray) -> np.ndarray:
        return points_in_circles(np.asarray(states)[:, :2], self.world.obstacles)

    def path_failed(self, paths: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: a path ``(N, S, 4)`` touches an obstacle at a point or segment."""
        return paths_hit_circles(paths, self.world.obstacles)

    def propagate_failed(self, states, controls, duration: float, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
        """``path_failed(propagate(...))`` and the paths' last states, one branch at a time in a
        compiled loop (:func:`~rmm_envs.scenes.branch_kernels.dubins4d_circle_branches`, the same
        bits); a subclass that changes the dynamics, ``propagate`` or ``path_failed`` gets the
        composition of its own."""
        if (
            type(self.dynamics) is not Dubins4D
            or type(self).propagate is not SceneBase.propagate
            or type(self).path_failed is not Dubins4DScene.path_failed
        ):
            return super().propagate_failed(states, controls, duration, n_steps)
        states, controls, times = branch_inputs(states, controls, duration, n_steps, 4, 2)
        failed, ends = np.empty(states.shape[0], dtype=bool), np.empty((states.shape[0], 4))
        dyn = self.dynamics
        circles = np.ascontiguousarray(self.world.obstacles, dtype=float)
        dubins4d_circle_branches(states, controls, times, dyn._lo, dyn._hi, circles, failed, ends)
        return failed, ends

    def observe(self, states: np.ndarray, sim_time=0.0) -> np.ndarray:
        """``(N, 17)`` float32 observations for states ``(N, 4)`` at ``sim_time`` (scalar or ``(N,)``)."""
        states = np.asarray(states, dtype=float)
        return observation(states, sim_time, self.goal[None, :2], self.rays(states, self.n_rays))

    def rays(self, states: np.ndarray, n_rays: int) -> np.ndarray:
        """``(N, n_rays)`` ray lengths from states ``(N, 4)``, ray ``i`` at ``theta + 2 pi i / n_rays``,
        capped at ``ray_length`` (the world's question; a scene on another world overrides it)."""
        return ray_cast(states[:, :2], states[:, 2], self.world.obstacles, n_rays, self.ray_length)

    def leaf_estimate(self, states: np.ndarray) -> np.ndarray:
        """pyrmm's Dubins4D stopping-distance leaf heuristic (docs/original-code.md, item 24), ``(N,)``.

        Braking at 0.5 m/s^2 from speed ``v`` covers ``v^2`` m; the risk is that distance over
        the forward ray, capped at 1 (1 when the ray reads 0).  Speeds are never negative here,
        and ``v = 0`` gives 0 (the original asserted on it).
        """
        states = np.asarray(states, dtype=float)
        v = np.clip(states[:, 3], self.dynamics.v_min, self.dynamics.v_max)
        a = abs(self.dynamics.u2_min)
        d_stop = v * v / (2.0 * a)
        fwd = self.rays(states, 1)[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            risk = np.where(fwd <= 0, 1.0, np.minimum(d_stop / fwd, 1.0))
        return np.where(v <= 0, np.where(fwd <= 0, 1.0, 0.0), risk)


def observation_layout(n_rays: int = 12) -> ObservationLayout:
    """The named slices of the observation table above; ray ``i`` points ``2 pi i / n_rays`` left of the heading."""
    return ObservationLayout.of(
        ("time", 1),
        ("goal_offset", 2),
        ("heading", 1),
        ("speed", 1),
        ("rays", n_rays),
        ray_angles=[2.0 * math.pi * i / n_rays for i in range(n_rays)],
    )
