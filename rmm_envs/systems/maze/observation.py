"""What the maze car senses and does when it cannot see a way: the observation's layout and the
safe default that turns away from the nearer wall."""

from __future__ import annotations

import math

import numpy as np

from rmm_envs.autonomy import GuardianActionSpace, ObservationLayout, SafeDefault
from rmm_envs.machine_independent import wrap_angle

__all__ = ["N_RAYS", "TurnFromNearerWall", "observation_layout"]

N_RAYS = 8


def observation_layout() -> ObservationLayout:
    """The named slices of the observation table above."""
    return ObservationLayout.of(
        ("rays", N_RAYS), ("goal_offset", 2), ("heading", 1), ray_angles=[k * math.pi / 4 for k in range(N_RAYS)]
    )


class TurnFromNearerWall(SafeDefault):
    """The maze car's safe default: the maximum turn rate away from the nearer wall.

    "Nearer wall" compares the shortest ray on the left (rays strictly between 0 and pi from
    the heading) with the shortest on the right; the car turns toward the side whose shortest
    ray is longer, left on a tie.  The car cannot stop, so turning is all it can do."""

    description = "maximum turn rate away from the nearer wall"

    def __init__(self, layout: ObservationLayout) -> None:
        rays = layout["rays"]
        ang = wrap_angle(layout.ray_angles)
        self._left = [rays.start + i for i, a in enumerate(ang) if 1e-9 < a < math.pi - 1e-9]
        self._right = [rays.start + i for i, a in enumerate(ang) if -math.pi + 1e-9 < a < -1e-9]

    def policy(self, space: GuardianActionSpace, rng: np.random.Generator, **options):
        self.check_options(options)
        left, right = self._left, self._right
        turn_left, turn_right = space.control_high.copy(), space.control_low.copy()

        def control(observation) -> np.ndarray:
            obs = np.asarray(observation, dtype=float)
            return turn_right if min(obs[left]) < min(obs[right]) else turn_left

        return control
