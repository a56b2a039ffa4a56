"""Scenes: a system's dynamics placed in one obstacle configuration, the
:class:`rmm_envs.risk.RiskScene` the risk estimator labels.

An env builds its episode's scene at every ``reset`` and uses the very same object for its own
collision checks and observations, so labels and the env agree by construction:

* :class:`Dubins4DScene`: :class:`rmm_envs.dynamics.Dubins4D` among circles (with a goal);
* :class:`MazeScene`: :class:`rmm_envs.dynamics.Dubins3D` in a maze;
* :class:`QuadrotorScene`: the numpy :class:`rmm_envs.dynamics.Quadrotor` in a room;
* :class:`QuadrotorCommandScene`: the same body flown through its cascaded controller (the
  control is a velocity command).
"""

from rmm_envs.scenes.base import SceneBase
from rmm_envs.scenes.dubins4d import Dubins4DScene
from rmm_envs.scenes.maze import MazeScene
from rmm_envs.scenes.quadrotor import QuadrotorCommandScene, QuadrotorScene

__all__ = ["Dubins4DScene", "MazeScene", "QuadrotorCommandScene", "QuadrotorScene", "SceneBase"]
