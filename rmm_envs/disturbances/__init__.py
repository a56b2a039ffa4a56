"""Disturbances: a system outside a perfect world, drawn so that every agent meets the same one.

A :class:`Disturbance` is one kind at one level, with a temporal shape and the components it acts
on; its string form is ``KIND[.COMPONENT+COMPONENT]=LEVEL[@SHAPE]``, e.g. ``obs-noise.rays=0.1``,
``dyn-rate=0.2@periodic``, ``act-delay=2``.  :func:`parse_disturbances` reads a list of them (or
one string with ``;`` between them) and refuses bad input in one line naming the value.

Kinds, what they act on, their level, and their shapes (the default first):

- ``obs-noise``: observation fields (default: all but time); a standard deviation in the
  field's units; white, uniform, step, periodic, impulse.
- ``obs-bias``: observation fields (default: the rays); an offset added; uniform.
- ``ray-dropout``: the rays; the probability a ray reads its maximum range; white.
- ``act-noise``: the applied control; a standard deviation as a fraction of each control's half
  range; white, uniform, step, periodic, impulse.
- ``act-gain``: the applied control; a gain drawn in ``[1 - level, 1 + level]`` per episode and
  control; uniform.
- ``act-delay``: the applied control; a whole number of steps.
- ``dyn-rate``: the state's rate components (position rates by default); each bounded by
  ``abs(d) <= level`` (the HJ model's disturbance); uniform, white, step, periodic.
- ``impulse``: the rate components; one push of the given size (state units) in a random
  direction, over one step at a random time; impulse.
- ``mismatch``: the plant's parameters; each drawn in ``nominal * [1 - level, 1 + level]`` per
  episode; uniform.

**Shapes.**  ``white``: a fresh draw every step.  ``uniform``: one draw per episode, held.
``step``: zero until an onset drawn uniformly in the first half of the horizon, then a held draw.
``periodic``: a held amplitude times ``sin(2 pi t / P + phi)``, ``P`` drawn in ``[2, 10]`` s and
``phi`` uniformly.  ``impulse``: one step, at a time drawn uniformly in the first half of the
horizon.  Gaussian kinds (``obs-noise``, ``act-noise``) draw ``N(0, level^2)``; bounded kinds
(``dyn-rate``) draw uniformly in ``[-level, level]``.

**Pairing.**  A :class:`Realisation` draws from its own random streams, derived from the
episode's seed and the disturbance's kind and components, never from the env's generator: a
disturbance does not shift the start, the world or the driver's randomness, and every value is
a function of the step index ``k = floor(t / dt)`` of sim time ``t``, drawn in blocks of
:data:`BLOCK` steps, so two agents on one episode meet the same realisation whatever they do and
however often they act.
"""

from rmm_envs.disturbances.realisation import BLOCK, Realisation
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
    "SHAPES",
    "Disturbance",
    "DisturbanceError",
    "Realisation",
    "SystemSupport",
    "parse_disturbances",
]
