"""Frames that explain an episode: the world, the path coloured by who controlled it, the goal,
the collision point, and a strip over the episode with the guardian's intervals and signals.

Drawn with Pillow's ``ImageDraw``; what does not move is drawn once per episode.  Two parts:

* a **view** per system (:class:`~rmm_envs.views.base.View`, in ``systems/<system>/view.py``):
  reads the env's world and state through public accessors (``privileged()``, ``true_state``);
  :func:`view_for` picks the view of an env;
* the **recorder** (:class:`EpisodeRecorder`): collects per step the state, who controlled
  (driver or guardian) and the guardian's signals (a plain ``dict[str, float]``, e.g.
  ``rmm_guardians``' ``Guardian.signals()``), and composes frames.

Every system of the table has a view, named by its spec (``SystemSpec.view``, a system of
your own states its own there); any other env that renders ``rgb_array`` is shown through its
own frame (:class:`EnvFrameView`).
"""

from __future__ import annotations

from rmm_envs.views.base import View, Window
from rmm_envs.views.planar import CarView, PlanarWorld
from rmm_envs.views.pole import CartAndPoleView, EnvFrameView, PoleGeometry
from rmm_envs.views.recorder import STRIP_HEIGHT, EpisodeRecorder, signal_groups
from rmm_envs.views.select import view_for

__all__ = [
    "STRIP_HEIGHT",
    "CarView",
    "CartAndPoleView",
    "EnvFrameView",
    "EpisodeRecorder",
    "PlanarWorld",
    "PoleGeometry",
    "View",
    "Window",
    "signal_groups",
    "view_for",
]
