"""The car the world moves under a model mismatch (issue 52): the nominal car's parameters scaled
by an episode's draw (:mod:`rmm_envs.disturbances`), shared by the single and the vector env."""

from __future__ import annotations

import dataclasses

import numpy as np

from rmm_envs.systems.dubins4d.dynamics import Dubins4D

__all__ = ["plant_model"]


def plant_model(nominal: Dubins4D, parameters: dict[str, float] | None) -> tuple[Dubins4D, np.ndarray]:
    """The car the world moves and the gains on its controls: ``nominal`` and ones, or under a
    mismatch a car whose turn rate and acceleration are the commanded ones times their gains
    (bounds scaled alike) and whose top speed is ``parameters["v_max"]``."""
    if parameters is None:
        return nominal, np.ones(2)
    g = np.array([parameters["turn_gain"], parameters["accel_gain"]])
    plant = dataclasses.replace(
        nominal,
        v_max=parameters["v_max"],
        u1_min=nominal.u1_min * g[0],
        u1_max=nominal.u1_max * g[0],
        u2_min=nominal.u2_min * g[1],
        u2_max=nominal.u2_max * g[1],
    )
    return plant, g
