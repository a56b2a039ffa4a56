"""InvertedPendulum seen from the front: its spec's ``view``."""

from __future__ import annotations

from rmm_envs.views.pole import CartAndPoleView, PoleGeometry, driver_target

__all__ = ["PENDULUM", "pendulum_view"]

#: InvertedPendulum-v5: the MuJoCo snapshot ``(time, x, theta, x_dot, theta_dot)``, the rail's joint range +-1 m
#: (a stop, not a failure), the pole 0.6 m, fails beyond 0.2 rad
PENDULUM = PoleGeometry(1, 2, 0.6, 1.0, 0.2)


def pendulum_view(env, size: int) -> CartAndPoleView:
    """The ``InvertedPendulum`` system's view (its spec's ``view``)."""
    return CartAndPoleView(PENDULUM, size, driver_target(env))
