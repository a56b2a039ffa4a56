"""The doomed-start test of the Dubins4D car on a map (its spec's ``doomed_test``): the search of
:func:`rmm_envs.systems.dubins4d.doomed.dubins4d_escapes` with the map's exact contact test."""

from __future__ import annotations

import numpy as np

from rmm_envs.starts import StartAssessment
from rmm_envs.systems.dubins4d.doomed import DUBINS4D_METHOD, dubins4d_escapes

__all__ = ["dubins4d_map_test"]


def dubins4d_map_test(env) -> StartAssessment:
    """The doomed test of a Dubins4D map env right after ``reset``: the same search as among
    circles, with the map's exact contact test (circles, polygons and walls, by pymunk)."""
    inner = env.unwrapped
    scene = inner.scene

    def first_hit(paths: np.ndarray) -> np.ndarray:
        contact = scene.world.first_contacts(paths)  # j + alpha along segment j; inf: none
        return np.where(np.isfinite(contact), np.ceil(np.nan_to_num(contact, posinf=0.0)), paths.shape[1]).astype(int)

    doomed = not dubins4d_escapes(inner.dynamics, inner.true_state, np.zeros((0, 3)), scene.goal, first_hit=first_hit)
    return StartAssessment(doomed, DUBINS4D_METHOD)
