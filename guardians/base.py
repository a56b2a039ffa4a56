"""The Guardian protocol: what a guardian is to the benchmark and to users.

A guardian watches a driver and decides, each step, whether to take control and with which
control.  :class:`Guardian` is the base class: ``name``, ``observation_type`` (``"local"``,
``"global"`` or ``"none"``), ``privileged``; :meth:`~Guardian.reset` each episode with the
seed, the env's spaces and, for privileged guardians, the env's ``privileged()`` accessor;
:meth:`~Guardian.act` ``(observation, info) -> action``, built through the env's
:class:`rmm_envs.autonomy.GuardianActionSpace`; :meth:`~Guardian.stats`, :meth:`~Guardian.signals`
(what the last decision saw, for frames), :meth:`~Guardian.alarm` (its own alarm, for
``rmm-bench collisions``), :meth:`~Guardian.warm_up` (run once, untimed) and :meth:`~Guardian.input_files`
(files whose digests join the run's identity).  :meth:`~Guardian.check_spaces`,
:meth:`~Guardian.require_action_space` and :meth:`~Guardian.require_layout` refuse an env that
lacks what the guardian needs (``ValueError`` naming the guardian and the piece) before any
episode.  Guardians never read an env's private attributes.  The protocol in full:
``docs/guardians.md``; privileged guardians share :mod:`rmm_guardians.privileged`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from rmm_envs.autonomy import GuardianActionSpace, ObservationLayout

if TYPE_CHECKING:
    import gymnasium as gym

__all__ = ["Guardian"]


class Guardian:
    """Base class; subclasses override :meth:`act` (and :meth:`reset` when they keep state)."""

    name: str = "guardian"
    observation_type: str = "local"
    privileged: bool = False

    def __init__(self) -> None:
        # the spaces given at reset (None before): a guardian checks them (check_spaces) before use
        self.observation_space: gym.Space[Any] | None = None
        self.action_space: GuardianActionSpace | None = None
        self.rng = np.random.default_rng()
        self._privileged: Callable[[], dict[str, Any]] | None = None

    def reset(
        self,
        *,
        seed: int | None = None,
        observation_space=None,
        action_space=None,
        privileged: Callable[[], dict[str, Any]] | None = None,
    ) -> None:
        self.observation_space = observation_space
        self.action_space = action_space
        self.rng = np.random.default_rng(seed)
        if self.privileged and privileged is None:
            raise ValueError(
                f"guardian {self.name!r} needs privileged information: pass reset(privileged=env.unwrapped.privileged)"
            )
        self._privileged = privileged

    def input_files(self) -> dict[str, str]:
        """The files this guardian read when it was built: path -> SHA-256 (hex) of the bytes it
        read.  A guardian that reads a file its arguments do not name (a shipped model, a
        default data file) must list it here; files named by a string argument are hashed by
        ``rmm-bench`` anyway.  ``rmm-bench`` makes them part of the run's identity, so a run
        resumed after a model file changed is a new run, never a mix of two models.  Default: none."""
        return {}

    def check_spaces(self, observation_space, action_space) -> None:
        """Raise ``ValueError`` (naming this guardian and what is missing) if it cannot serve an
        env with these spaces.  Cheap, so ``rmm-bench`` calls it before any episode; guardians
        that need more than a ``GuardianActionSpace`` override it (and call it from ``reset``)."""
        self.require_action_space(space=action_space)

    def require_action_space(self, controls: int | None = None, space=None) -> GuardianActionSpace:
        """The action space given at :meth:`reset` (or ``space``), checked to be a ``GuardianActionSpace``
        (with ``controls`` components when given); a ``ValueError`` naming this guardian otherwise."""
        space = self.action_space if space is None else space
        if not isinstance(space, GuardianActionSpace):
            raise ValueError(
                f"guardian {self.name!r} builds its actions through the env's action space: pass "
                f"reset(action_space=env.action_space) with a rmm_envs.autonomy.GuardianActionSpace, "
                f"got {space!r}"
            )
        if controls is not None and space.control_dim != controls:
            raise ValueError(
                f"guardian {self.name!r} needs an action space with {controls} controls, "
                f"got {space.control_dim} ({space.controls})"
            )
        return space

    def require_layout(self, *fields: str, observation_space=None) -> ObservationLayout:
        """The layout of the observation space given at :meth:`reset` (or ``observation_space``),
        checked to have ``fields`` (``"rays"`` also needs the rays' directions); a ``ValueError``
        naming this guardian otherwise."""
        space = self.observation_space if observation_space is None else observation_space
        lay = getattr(space, "layout", None)
        if not isinstance(lay, ObservationLayout):
            raise ValueError(
                f"guardian {self.name!r} reads the observation by name: pass reset(observation_space="
                f"env.observation_space) with a layout (rmm_envs.autonomy.ObservationBox), "
                f"got {space!r}"
            )
        missing = [f for f in fields if f not in lay]
        if missing:
            raise ValueError(
                f"guardian {self.name!r} needs the observation field(s) {missing}; "
                f"the observation has {list(lay.names)}"
            )
        return lay

    def act(self, observation: np.ndarray, info: dict[str, Any]) -> dict:  # pragma: no cover - abstract
        raise NotImplementedError

    def warm_up(self, observation: np.ndarray, info: dict[str, Any]) -> None:
        """Run the decision's compiled paths once, untimed, so that compiling or loading compiled
        code is never charged to a timed decision: one :meth:`act` (a guardian whose first
        decision skips some compiled path, a QP solved only near an obstacle, runs it here too).
        ``rmm-bench`` calls it once per worker and resets the guardian afterwards."""
        self.act(observation, info)

    def stats(self) -> dict[str, float]:
        return {}

    def signals(self) -> dict[str, float]:
        """The guardian's own signal at its last decision, for pictures of an episode
        (:class:`rmm_envs.views.EpisodeRecorder` draws each in the strip under the frame): names
        -> plain floats (``nan`` where a value is not known at this decision).  Keys sharing the
        part of their name before the first ``_`` are drawn on one scale (``risk`` and
        ``risk_threshold``); a key containing ``threshold`` is drawn as the line to compare with.

        Read only from what the last :meth:`act` computed anyway: calling it never changes a
        decision and costs next to nothing, so it may be called after every step.  Default: none
        (``{}``).  Built-in: ``lrmm`` ``risk``, ``risk_threshold``; ``cbf`` ``barrier_min``,
        ``qp_fallbacks``; ``hj`` ``value``, ``value_threshold`` (docs/guardians.md)."""
        return {}

    def alarm(self) -> tuple[float, float] | None:
        """The guardian's own alarm at its last decision, as a pair ``(value, threshold)``: the
        alarm is up when ``value > threshold`` (``nan``: not up).  A guardian whose signal
        falls as danger grows (a value function, a barrier) returns both negated.  Read by
        ``rmm-bench collisions`` after every step to date when the guardian first saw the
        danger it collided with.  Like :meth:`signals`, read only from what the last
        :meth:`act` computed: calling it never changes a decision.  Default ``None``: no alarm,
        so its collisions are classified by who was in control alone.  Built-in: ``lrmm``
        ``(risk, threshold)``; ``cbf`` ``(-barrier_min, 0)``; ``hj`` ``(-value,
        -value_threshold)`` (docs/guardians.md)."""
        return None

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"
