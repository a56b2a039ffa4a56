"""Scenes: a system's dynamics placed in one obstacle configuration, the
:class:`rmm_envs.risk.RiskScene` the risk estimator labels.

An env builds its episode's scene at every ``reset`` and uses the very same object for its own
collision checks and observations, so labels and the env agree by construction.  What every
scene shares is :class:`SceneBase`; each system's own scene is ``scene.py`` in its folder
(``rmm_envs/systems/<system>/scene.py``, named by its spec's ``scenes``).
"""

from rmm_envs.scenes.base import SceneBase

__all__ = ["SceneBase"]
