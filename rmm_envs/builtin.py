"""The systems this package ships: one folder each under ``rmm_envs/systems/``, whose ``system.py``
returns its :class:`~rmm_envs.catalog.SystemSpec`.

:func:`systems` is this package's entry point in the group ``rmm_envs.systems``
(pyproject.toml), the way a package of your own registers its systems (:mod:`rmm_envs.catalog`);
it lists the folders' specs in the order of the table (and of ``rmm_envs.ENV_IDS``).  Nothing
else reads this module.
"""

from __future__ import annotations

from rmm_envs.catalog import SystemSpec
from rmm_envs.systems.cartpole import system as cartpole
from rmm_envs.systems.dubins4d import system as dubins4d
from rmm_envs.systems.dubins4d_map import system as dubins4d_map
from rmm_envs.systems.maze import system as maze
from rmm_envs.systems.pendulum import system as pendulum
from rmm_envs.systems.quadrotor import system as quadrotor

__all__ = ["systems"]


def systems() -> tuple[SystemSpec, ...]:
    """The built-in systems, in the order of the table."""
    return tuple(m.spec() for m in (dubins4d, dubins4d_map, maze, quadrotor, cartpole, pendulum))
