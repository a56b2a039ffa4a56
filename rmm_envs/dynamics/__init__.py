"""Batched dynamics of the kinodynamic systems (one file per system)."""

from rmm_envs.dynamics.dubins4d import Dubins4D

__all__ = ["Dubins4D"]
