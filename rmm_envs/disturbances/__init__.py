"""Disturbances: a system outside a perfect world, drawn so that every agent meets the same one.

A :class:`Disturbance` is one kind at one level, with a shape and the components it acts on,
written ``KIND[.COMPONENT+COMPONENT]=LEVEL[@SHAPE]`` (``obs-noise.rays=0.1``, ``act-delay=2``);
:func:`parse_disturbances` reads a list of them and refuses bad input in one line.  Kinds:
``obs-noise``, ``obs-bias``, ``ray-dropout`` (the observation); ``act-noise``, ``act-gain``,
``act-delay`` (the applied control); ``dyn-rate``, ``impulse`` (the state's rates); ``mismatch``
(the plant's parameters).  Shapes: ``white``, ``uniform``, ``step``, ``periodic``, ``impulse``
(:mod:`rmm_envs.disturbances.spec` gives each kind's level, components and shapes).  A
:class:`Realisation` draws one episode from its seed on streams of its own, every value a
function of the sim-time step, so agents on one episode meet the same draws; a :class:`Plan` is
what an env works out once.  Concepts and commands: docs/disturbances.md; the design: decision
record 0030.
"""

from rmm_envs.disturbances.realisation import BLOCK, Plan, Realisation
from rmm_envs.disturbances.spec import (
    KINDS,
    SHAPES,
    Disturbance,
    DisturbanceError,
    SystemSupport,
    parse_disturbances,
)

__all__ = [
    "BLOCK",
    "KINDS",
    "Plan",
    "SHAPES",
    "Disturbance",
    "DisturbanceError",
    "Realisation",
    "SystemSupport",
    "parse_disturbances",
]
