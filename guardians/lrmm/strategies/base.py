"""What every strategy is: :class:`DecisionContext` (what one decision computed, handed to each strategy)
and :class:`Strategy` (the base class), with the checks the built-ins share."""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from rmm_guardians._checks import finite

__all__ = ["DecisionContext", "Strategy"]

_PACKAGE = __name__.rpartition(".")[0]  # rmm_guardians.lrmm.strategies


class DecisionContext:
    """What one decision has computed, handed from the core to each strategy: ``observation``
    (the whole observation), ``x`` (the model's input), ``out`` (the model's outputs: the risk,
    then one per head candidate), ``risk``, ``info``, ``nominal`` (the driver's control, when a
    strategy reads it, else ``None``), ``threshold`` and ``active`` (whether the guardian was in
    control at the previous decision; set to this one's verdict once the *when* strategies ran)."""

    __slots__ = ("active", "info", "nominal", "observation", "out", "risk", "threshold", "x")

    def __init__(self, threshold: float) -> None:
        self.threshold: float = threshold
        self.active: bool = False
        self.observation: Any = None
        self.x: Any = None
        self.out: Any = None
        self.info: Any = None
        self.nominal: list | None = None
        self.risk: float = math.nan


class Strategy:
    """A named rule of the ``lrmm`` guardian.  Subclasses set ``PARAMS`` (their constructor's
    keyword arguments, in order) and override what they change:

    - :meth:`check_model` (at construction) and :meth:`check` (for each env, before any episode):
      raise ``ValueError`` naming what the strategy needs and the model or env lacks;
    - :meth:`reset` (each episode): bind to the guardian (``model``, ``threshold``, ``inputs``,
      ``observation_space``, ``action_space``, ``candidates``) and clear per-episode state;
    - :meth:`take` (*when*): the verdict (in control or not) from the one before it;
    - :meth:`act` (*what*): the control from the one before it (``None``: the env's safe default,
      applied if no strategy chooses another);
    - :meth:`signals`: numbers a replay draws (``risk_driver``).

    ``reads_driver``: the strategy reads the driver's control (``info["nominal_control"]``);
    ``chooses``: its :meth:`act` always returns a control (the env then needs no safe default)."""

    PARAMS: ClassVar[tuple[str, ...]] = ()
    #: parameters left out of :meth:`spec` while at these values (added after specs were stored,
    #: so a stored spec, and the run keys made from it, stay as they were)
    SPEC_DEFAULTS: ClassVar[dict[str, Any]] = {}
    reads_driver: ClassVar[bool] = False
    chooses: ClassVar[bool] = False

    @property
    def name(self) -> str:
        return type(self).__name__

    def params(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.PARAMS}

    def spec(self) -> str:
        """This strategy as a spec :func:`parse_strategies` reads back (stored in model files)."""
        params = {k: v for k, v in self.params().items() if k not in self.SPEC_DEFAULTS or v != self.SPEC_DEFAULTS[k]}
        args = ", ".join(f"{k}={v!r}" for k, v in params.items())
        mod = type(self).__module__
        built_in = mod.startswith(_PACKAGE + ".")  # the built-ins, known by name (spec.STRATEGIES)
        return f"{'' if built_in else mod + ':'}{self.name}({args})"

    def clone(self) -> Strategy:
        """A fresh copy (same parameters, no episode state): each guardian holds its own."""
        return type(self)(**self.params())

    def __eq__(self, other) -> bool:
        return type(other) is type(self) and other.params() == self.params()

    def __hash__(self) -> int:
        return hash((type(self), tuple(self.params().items())))

    def __repr__(self) -> str:
        return self.spec()

    def check_model(self, model, inputs: str | None) -> None:
        """Refuse a model this strategy cannot use (default: any will do)."""

    def check(self, guardian, observation_space, action_space) -> None:
        """Refuse an env this strategy cannot serve (default: any will do)."""

    def reset(self, guardian) -> None:
        """Bind to ``guardian`` for an episode (default: nothing to bind)."""

    def take(self, step: DecisionContext, take: bool) -> bool:
        return take

    def act(self, step: DecisionContext, control):
        return control

    def signals(self) -> dict[str, float]:
        return {}


def _number(name: str, value, lo: float | None = None, lo_open: bool = False) -> float:
    """``value`` as a float: a finite number (not a bool or a string) within the bound."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    return finite(name, value, lo, lo_open)


def _needs_head(strategy: Strategy, model) -> None:
    if model.candidates is None:
        raise ValueError(
            f"strategy {strategy.name} reads the model's action-conditioned head ('candidates'), and "
            f"{getattr(model, 'path', 'the model')} has none"
        )


def _candidate_risks(step: DecisionContext) -> list[float]:
    cand = step.out[1:].tolist()
    if not all(map(math.isfinite, cand)):
        raise ValueError(f"the LRMM model returned non-finite candidate risks {cand}")
    return cand


def _needs_rays(strategy: Strategy, guardian, observation_space, actions) -> Any:
    """The observation's layout with a ``rays`` field, or a ``ValueError`` saying what to use instead."""
    if getattr(observation_space, "layout", None) is None and actions.safe_default is not None:
        raise ValueError(
            f"guardian {guardian.name!r}: strategy {strategy.name} reads the observation field 'rays' by name, "
            f"and this env's observation names no fields (an env of your own, e.g. made by "
            f"rmm_envs.envs.any_env.guarded or parallel); the core alone takes the env's safe default "
            f"({actions.safe_default.description}): rmm-bench --agent-opt {guardian.name}.strategies='\"\"' "
            f'(in Python: strategies="")'
        )
    return guardian.require_layout("rays", observation_space=observation_space)
