"""CartPole seen from the front: its spec's ``view``."""

from __future__ import annotations

import numpy as np

from rmm_envs.views.pole import CartAndPoleView, PoleGeometry, driver_target

__all__ = ["CARTPOLE", "cartpole_view"]

#: CartPole-v1: true state ``(x, x_dot, theta, theta_dot)``, fails at 2.4 m or 12 degrees
CARTPOLE = PoleGeometry(0, 2, 1.0, 2.4, 12 * 2 * np.pi / 360)


def cartpole_view(env, size: int) -> CartAndPoleView:
    """The ``CartPole`` system's view (its spec's ``view``)."""
    return CartAndPoleView(CARTPOLE, size, driver_target(env))
