"""Which view shows an env: :func:`view_for`, the table :data:`VIEWS` and :func:`register_view`."""

from __future__ import annotations

from collections.abc import Callable

from rmm_envs.views.base import View
from rmm_envs.views.planar import Dubins4DView, MapView, MazeView
from rmm_envs.views.pole import CARTPOLE, PENDULUM, CartPoleView, EnvFrameView
from rmm_envs.views.quadrotor import QuadrotorView

__all__ = ["VIEWS", "driver_target", "register_view", "view_for"]

#: env class name (of ``env.unwrapped`` or of a guarded env's simulator, any class in its MRO)
#: -> ``factory(env, size) -> View``; matched by name so that listing them imports no simulator
VIEWS: dict[str, Callable[..., View]] = {
    "Dubins4DMapEnv": lambda env, size: MapView(size),
    "Dubins4DCirclesEnv": lambda env, size: Dubins4DView(size),
    "Dubins3DMazeGuardedEnv": lambda env, size: MazeView(size),
    "QuadrotorRoomGuardedEnv": lambda env, size: QuadrotorView(size),
    "CartPoleEnv": lambda env, size: CartPoleView(CARTPOLE, size, driver_target(env)),
    "InvertedPendulumEnv": lambda env, size: CartPoleView(PENDULUM, size, driver_target(env)),
}


def driver_target(env) -> Callable[[], float] | None:
    """The goal a pole view draws: the guarded env's driver's ``target`` (a number, read at each
    episode's start, as the built-in ``CartPoleGuarded-v0`` / ``InvertedPendulumGuarded-v0``
    drivers pick a cart position per episode); ``None`` when the driver has none."""
    driver = getattr(env.unwrapped, "driver", None)
    if driver is None or not isinstance(getattr(driver, "target", None), int | float):
        return None
    return lambda: float(driver.target)


def register_view(class_name: str, factory: Callable[..., View]) -> None:
    """Show envs whose class (or a base class) is named ``class_name`` with ``factory(env, size)``."""
    VIEWS[class_name] = factory


def _factory(obj) -> Callable[..., View] | None:
    for cls in type(obj).__mro__:
        if cls.__name__ in VIEWS:
            return VIEWS[cls.__name__]
    return None


def view_for(env, size: int = 512) -> View:
    """The view of ``env`` (a gym env, wrapped or not): the table's systems by their env class; a
    guarded env of :mod:`rmm_envs.envs.driven` by its simulator's class; otherwise the env's own
    ``rgb_array`` frame (:class:`EnvFrameView`, a ``ValueError`` when it does not render)."""
    u = env.unwrapped
    factory = _factory(u)
    if factory is None:
        inner = getattr(u, "env", None)  # DrivenGuardedEnv.env: the simulator (a Gymnasium env)
        if inner is not None and getattr(u, "simulator", None) is None:
            factory = _factory(inner.unwrapped)
    if factory is not None:
        return factory(env, size)
    return EnvFrameView(env, size)
