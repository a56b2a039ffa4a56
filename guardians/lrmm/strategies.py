"""The ``lrmm`` guardian's strategies: named rules composed around its core.

The core (:class:`rmm_guardians.lrmm.guardian.LRMMGuardian`) takes control while the model's risk
of the observation is above the threshold and applies the env's safe default.  A strategy changes
*when* it is in control (:meth:`Strategy.take`) or *what* it applies (:meth:`Strategy.act`);
strategies run in the order given, each seeing the verdict or action of those before it.
Built in (:data:`STRATEGIES`): :class:`SafestCandidate`, :class:`BrakeTurn`, :class:`RayTurn`,
:class:`Restart`, :class:`Slide` (what), :class:`RatedDriver`, :class:`MovingAverage`,
:class:`Commit` (when).  A strategy of one's own subclasses :class:`Strategy`; it is given as an
object in Python, or as ``module:Class(args)`` in a spec (:func:`parse_strategies`, e.g.
``"SafestCandidate, Commit(steps=18)"``; items starting with ``-``/``+`` edit the stored
composition).  Why each built-in exists and what it adds: docs/decisions/0024-lrmm-core-and-strategies.md.
"""

from __future__ import annotations

import ast
import importlib
import math
from collections import deque
from typing import Any, ClassVar

import numpy as np

from rmm_envs.portable import wrap_angle
from rmm_guardians._checks import finite, integer
from rmm_guardians.lrmm.nominal import VELOCITY_CONTROLS, driver_at_risk, make_rater

__all__ = [
    "STRATEGIES",
    "BrakeTurn",
    "Commit",
    "MovingAverage",
    "RatedDriver",
    "RayTurn",
    "Restart",
    "SafestCandidate",
    "Slide",
    "Step",
    "Strategy",
    "parse_strategies",
    "strategy_specs",
]


class Step:
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
    reads_driver: ClassVar[bool] = False
    chooses: ClassVar[bool] = False

    @property
    def name(self) -> str:
        return type(self).__name__

    def params(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.PARAMS}

    def spec(self) -> str:
        """This strategy as a spec :func:`parse_strategies` reads back (stored in model files)."""
        args = ", ".join(f"{k}={v!r}" for k, v in self.params().items())
        mod = type(self).__module__
        return f"{'' if mod == __name__ else mod + ':'}{self.name}({args})"

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

    def take(self, step: Step, take: bool) -> bool:
        return take

    def act(self, step: Step, control):
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


def _candidate_risks(step: Step) -> list[float]:
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
            f"rmm_envs.envs.driven.guarded or parallel); the core alone takes the env's safe default "
            f"({actions.safe_default.description}): rmm-bench --agent-opt {guardian.name}.strategies='\"\"' "
            f'(in Python: strategies="")'
        )
    return guardian.require_layout("rays", observation_space=observation_space)


class SafestCandidate(Strategy):
    """Apply the head candidate the model rates safest (the first of the lowest).

    The action-conditioned head rates each of a few candidate controls by the risk after
    holding it; in control, the guardian applies the one rated lowest instead of the env's fixed
    safe default.  Why: on Dubins4D full braking straight on often ends in the obstacle ahead,
    while a rated turn clears it."""

    chooses = True

    def check_model(self, model, inputs) -> None:
        _needs_head(self, model)

    def check(self, guardian, observation_space, actions) -> None:
        cands = guardian.model.candidates
        if cands.shape[1] != actions.control_dim:
            k = cands.shape[1]
            raise ValueError(
                f"guardian {guardian.name!r} needs an action space with {k} controls (the model's candidate "
                f"controls have {k} components), got {actions.control_dim} ({actions.controls})"
            )
        low, high = np.asarray(actions.control_low, float), np.asarray(actions.control_high, float)
        outside = [c.tolist() for c in cands if np.any(c < low) or np.any(c > high)]
        if outside:
            raise ValueError(
                f"guardian {guardian.name!r}: candidate controls {outside} of "
                f"{getattr(guardian.model, 'path', 'the model')} lie outside the env's control bounds "
                f"[{low.tolist()}, {high.tolist()}] ({actions.controls})"
            )

    def reset(self, guardian) -> None:
        self._cands = guardian.candidates

    def act(self, step: Step, control):
        cand = _candidate_risks(step)
        return self._cands[cand.index(min(cand))]


class Restart(Strategy):
    """A car in control below ``speed`` (m/s) applies the safest head candidate that accelerates,
    when one is rated at or below the threshold; else the control before it is kept.

    Why: a car the guardian braked to a stop is never at risk again and never reaches its goal,
    so a guardian that only brakes turns collisions into timeouts."""

    PARAMS = ("speed",)

    def __init__(self, speed: float = 0.3) -> None:
        self.speed = _number("Restart speed", speed, 0.0)

    def check_model(self, model, inputs) -> None:
        _needs_head(self, model)

    def check(self, guardian, observation_space, actions) -> None:
        if "accel_ctrl" not in actions.controls or "speed" not in getattr(observation_space, "layout", ()):
            raise ValueError(
                f"guardian {guardian.name!r}: strategy Restart needs an 'accel_ctrl' control and a 'speed' "
                f"observation field, got controls {actions.controls}"
            )

    def reset(self, guardian) -> None:
        self._cands = guardian.candidates
        self._speed = guardian.observation_space.layout.index("speed")
        self._accel = guardian.action_space.controls.index("accel_ctrl")

    def act(self, step: Step, control):
        if not step.observation[self._speed] < self.speed:
            return control
        cand = _candidate_risks(step)
        go = [(r, i) for i, r in enumerate(cand) if self._cands[i][self._accel] > 0 and r <= step.threshold]
        return self._cands[min(go)[1]] if go else control


_SIDE_RAY = math.pi / 6  # BrakeTurn compares the rays 30 degrees left and right of the heading


class BrakeTurn(Strategy):
    """The paper's avoidance: the strongest braking and the largest turn toward the more open of
    the rays 30 degrees left and right (none on a tie).  ``turn``, ``brake``: the turn rate and
    acceleration (``None``: the action space's largest turn rate and strongest braking).

    Why: the paper's rule, kept to reproduce it (``lrmm-paper``) and as the Dubins car's
    avoidance for a model without a head."""

    chooses = True

    PARAMS = ("turn", "brake")

    def __init__(self, turn: float | None = None, brake: float | None = None) -> None:
        self.turn = None if turn is None else _number("BrakeTurn turn", turn)
        self.brake = None if brake is None else _number("BrakeTurn brake", brake)

    def check(self, guardian, observation_space, actions) -> None:
        if actions.control_dim != 2 and actions.safe_default is not None:
            raise ValueError(
                f"guardian {guardian.name!r}: strategy BrakeTurn needs the Dubins car's two controls, got "
                f"{actions.control_dim} ({actions.controls}); this env states a safe default "
                f"({actions.safe_default.description}), which the core alone applies"
            )
        guardian.require_action_space(controls=2, space=actions)  # (turn rate, acceleration)
        _needs_rays(self, guardian, observation_space, actions)

    def reset(self, guardian) -> None:
        lay, actions = guardian.observation_space.layout, guardian.action_space
        self._left, self._right = lay.ray_index(_SIDE_RAY), lay.ray_index(-_SIDE_RAY)
        self._u1 = float(actions.control_high[0]) if self.turn is None else self.turn
        self._u2 = float(actions.control_low[1]) if self.brake is None else self.brake

    def act(self, step: Step, control):
        left, right = step.observation[self._left], step.observation[self._right]
        turn = 0.0 if np.isclose(left, right) else (self._u1 if left > right else -self._u1)
        return (turn, self._u2)


class RayTurn(Strategy):
    """Turn at the largest rate (or ``rate``) toward the side the model rates lower: its risk of
    the rays as they would read with the heading one ray further left or right; on a tie
    (``numpy.isclose``), toward the side whose nearest wall is farther, left on a second tie.

    Why: the maze car cannot stop, so its safe default is a turn; the model's own view of
    which side is safer avoids turning into a wall the nearest-wall rule cannot see."""

    chooses = True

    PARAMS = ("rate",)

    def __init__(self, rate: float | None = None) -> None:
        self.rate = None if rate is None else _number("RayTurn rate", rate, 0.0, lo_open=True)

    def check(self, guardian, observation_space, actions) -> None:
        guardian.require_action_space(controls=1, space=actions)  # the turn rate
        lay = _needs_rays(self, guardian, observation_space, actions)
        n = lay.size_of("rays")
        even = np.allclose(wrap_angle(np.asarray(lay.ray_angles) - 2 * np.pi * np.arange(n) / n), 0, atol=1e-9)
        if guardian.inputs != "rays" or not even:
            raise ValueError(
                f"guardian {guardian.name!r}: strategy RayTurn judges a turn by the model's risk of the rays "
                "rotated by one ray, so the model must read the 'rays' field, rays evenly spaced over the "
                f"full circle from the heading; got inputs={guardian.inputs!r}, ray angles {lay.ray_angles}"
            )

    def reset(self, guardian) -> None:
        lay = guardian.observation_space.layout
        rays = lay["rays"]
        angles = [math.remainder(a, 2 * math.pi) for a in lay.ray_angles]
        self._lside = [rays.start + i for i, a in enumerate(angles) if 0 < a < math.pi]
        self._rside = [rays.start + i for i, a in enumerate(angles) if -math.pi < a < 0]
        self._u1 = float(guardian.action_space.control_high[0]) if self.rate is None else self.rate
        self._model = guardian.model

    def act(self, step: Step, control):
        rays, observation = step.x, step.observation
        r_left, r_right = self._model.predict_all(np.stack([np.roll(rays, -1), np.roll(rays, 1)]))[:, 0]
        if not (math.isfinite(r_left) and math.isfinite(r_right)):
            raise ValueError(f"the LRMM model returned non-finite risks {[r_left, r_right]} for the turned rays")
        if np.isclose(r_left, r_right):
            left = min(observation[i] for i in self._lside) >= min(observation[i] for i in self._rside)
        else:
            left = r_left < r_right
        return (self._u1 if left else -self._u1,)


def _rater(strategy: Strategy, guardian, observation_space, actions):
    """The :class:`~rmm_guardians.lrmm.nominal.PredictRater` of this env, or a ``ValueError``."""
    rater = None
    if guardian.inputs is None:  # a model reading one field cannot be given a predicted whole observation
        rater = make_rater(
            actions.controls,
            getattr(observation_space, "layout", None),
            guardian.model.candidate_hold,
            observation_space.low,
            observation_space.high,
        )
    if rater is None:
        raise ValueError(
            f"guardian {guardian.name!r}: strategy {strategy.name} rates the driver's control, so it needs the "
            "model reading the whole observation and a field the controls move ('velocity', 'speed', or "
            f"'heading' with evenly spaced rays; rmm_guardians.lrmm.nominal); got controls {actions.controls}, "
            f"inputs={guardian.inputs!r}"
        )
    return rater


class RatedDriver(Strategy):
    """Take control on the driver's next control rated, not on the state risk: the model's risk
    of the observation predicted after holding it (:mod:`rmm_guardians.lrmm.nominal`).  In control
    when that rating is above the threshold and the best head candidate is rated more than
    ``margin`` lower, or (``still``) holding still more than ``still`` lower; with ``stay``, it
    stays while the rating is above the threshold.  A step without the driver's control falls
    back on the state risk.

    Why: the quadrotor's state risk stays high near walls the driver is flying away from; the
    driver's own control rated tells a safe pass from a collision course."""

    PARAMS = ("margin", "still", "stay")
    reads_driver = True

    def __init__(self, margin: float = 0.0, still: float | None = None, stay: bool = True) -> None:
        self.margin = _number("RatedDriver margin", margin, 0.0)
        self.still = None if still is None else _number("RatedDriver still", still, 0.0)
        if not isinstance(stay, (bool, np.bool_)):
            raise ValueError(f"RatedDriver stay must be True or False, got {stay!r}")
        self.stay = bool(stay)
        self.last = math.nan

    def check_model(self, model, inputs) -> None:
        _needs_head(self, model)

    def check(self, guardian, observation_space, actions) -> None:
        _rater(self, guardian, observation_space, actions)

    def reset(self, guardian) -> None:
        self._rater = _rater(self, guardian, guardian.observation_space, guardian.action_space)
        self._model = guardian.model
        self._cands = guardian.candidates
        self._zero = [0.0] * guardian.action_space.control_dim
        self.last = math.nan

    def take(self, step: Step, take: bool) -> bool:
        nominal = step.nominal
        if nominal is None:
            return take
        rated = self._rater.rate_many([nominal, self._zero, *self._cands], self._model, step.x)
        self.last = rated[0]
        return driver_at_risk(rated, step.threshold, self.margin, self.still, step.active and self.stay)

    def signals(self) -> dict[str, float]:
        return {"risk_driver": float(self.last)}


#: Slide's variants of the driver's velocity command: (cos, sin) of the turn of its horizontal
#: velocity, the fraction of that velocity kept, and the vertical velocity (``"climb"``: the
#: box's largest, or the fraction of the driver's kept)
SLIDE_MOVES = (((1.0, 0.0), 1.0, "climb"), ((1.0, 0.0), 0.5, "climb"), ((1.0, 0.0), 0.0, "climb"))


class Slide(Strategy):
    """In control, apply the variant of the driver's velocity command nearest to it that the model
    rates at or below the threshold (climbing at its horizontal velocity, half of it or none,
    :data:`SLIDE_MOVES`; other controls kept), else keep the control before it.

    Why: the quadrotor's driver mostly flies toward its goal; bending its command keeps that
    progress where replacing it with a fixed manoeuvre would throw it away."""

    reads_driver = True

    def check(self, guardian, observation_space, actions) -> None:
        if any(c not in actions.controls for c in VELOCITY_CONTROLS):
            raise ValueError(
                f"guardian {guardian.name!r}: strategy Slide bends a velocity command: it needs the controls "
                f"{tuple(VELOCITY_CONTROLS)}, got {actions.controls}"
            )
        _rater(self, guardian, observation_space, actions)

    def reset(self, guardian) -> None:
        actions = guardian.action_space
        self._rater = _rater(self, guardian, guardian.observation_space, actions)
        self._model = guardian.model
        self.f, self.l, self.up = (actions.controls.index(c) for c in VELOCITY_CONTROLS)
        self._low, self._high = [float(v) for v in actions.control_low], [float(v) for v in actions.control_high]

    def variants(self, u) -> list[list[float]]:
        """The variants of ``u``, nearest first (Euclidean over the velocities; ties in
        :data:`SLIDE_MOVES` order), ``u`` itself and repeats left out."""
        u = [float(v) for v in u]
        out = []
        for (c, s), k, z in SLIDE_MOVES:
            v = list(u)
            v[self.f] = k * (c * u[self.f] - s * u[self.l])
            v[self.l] = k * (s * u[self.f] + c * u[self.l])
            v[self.up] = self._high[self.up] if z == "climb" else z * u[self.up]
            v = [min(max(a, lo), hi) for a, lo, hi in zip(v, self._low, self._high, strict=True)]
            if v != u and v not in out:
                out.append(v)
        gap = [math.sqrt(sum((v[j] - u[j]) ** 2 for j in (self.f, self.l, self.up))) for v in out]
        return [out[i] for i in sorted(range(len(out)), key=lambda i: gap[i])]

    def act(self, step: Step, control):
        if not step.nominal:
            return control
        options = self.variants(step.nominal)
        if not options:
            return control
        rated = self._rater.rate_many(options, self._model, step.x)
        return next((v for v, r in zip(options, rated, strict=True) if r <= step.threshold), control)


class MovingAverage(Strategy):
    """Also in control while the mean risk of the last ``window`` decisions is above the
    threshold (the window starts full of the threshold).  Why: the original code's release rule,
    kept to reproduce it."""

    PARAMS = ("window",)

    def __init__(self, window: int = 20) -> None:
        self.window = integer("MovingAverage window", window, 1)

    def reset(self, guardian) -> None:
        self._history = deque([guardian.threshold] * self.window, maxlen=self.window)

    def take(self, step: Step, take: bool) -> bool:
        self._history.append(step.risk)
        return take or sum(self._history) / len(self._history) > step.threshold


class Commit(Strategy):
    """Stay in control ``steps`` decisions after the verdict before it turns to "not in control".

    Why: a risk hovering at the threshold hands control back and forth every step, and the
    driver, handed a car half way through an avoidance, steers it back into danger."""

    PARAMS = ("steps",)

    def __init__(self, steps: int = 0) -> None:
        self.steps = integer("Commit steps", steps, 0, "decisions to stay in control")
        self._left = 0

    def reset(self, guardian) -> None:
        self._left = 0

    def take(self, step: Step, take: bool) -> bool:
        if take:
            self._left = self.steps
        elif self._left > 0:
            self._left -= 1
            return True
        return take


#: The built-in strategies by name.
STRATEGIES: dict[str, type[Strategy]] = {
    c.__name__: c for c in (SafestCandidate, Restart, BrakeTurn, RayTurn, RatedDriver, Slide, MovingAverage, Commit)
}


def _strategy_class(name: str) -> type[Strategy]:
    if ":" in name:
        module, _, attr = name.partition(":")
        if not module or not attr:
            raise ValueError(f"strategy {name!r} must look like 'package.module:Class'")
        try:
            cls = getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError) as e:
            raise ValueError(f"unknown strategy {name!r}: {e}") from None
        if not (isinstance(cls, type) and issubclass(cls, Strategy)):
            raise ValueError(f"strategy {name!r} is not a subclass of rmm_guardians.lrmm.strategies.Strategy")
        return cls
    if name not in STRATEGIES:
        raise ValueError(f"unknown strategy {name!r}; the strategies are: {', '.join(STRATEGIES)} or 'module:Class'")
    return STRATEGIES[name]


def _split(text: str) -> list[str]:
    """``text`` split at the commas outside parentheses, items stripped, empty ones dropped."""
    items, depth, start = [], 0, 0
    for i, ch in enumerate(text):
        depth += {"(": 1, ")": -1}.get(ch, 0)
        if ch == "," and depth == 0:
            items.append(text[start:i])
            start = i + 1
    items.append(text[start:])
    return [s.strip() for s in items if s.strip()]


def _parse_one(item: str) -> Strategy:
    name, paren, rest = item.partition("(")
    name = name.strip()
    if not paren:
        return _strategy_class(name)()
    try:
        call = ast.parse(f"f({rest}", mode="eval").body
        if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Name) and call.func.id == "f"):
            raise ValueError  # e.g. Commit()(3): a call of a call
        if any(isinstance(a, ast.Starred) for a in call.args) or any(k.arg is None for k in call.keywords):
            raise ValueError  # *args, **kwargs
        args = [ast.literal_eval(a) for a in call.args]
        kwargs = {k.arg: ast.literal_eval(k.value) for k in call.keywords if k.arg is not None}
    except (SyntaxError, ValueError):
        raise ValueError(f"strategy {item!r}: arguments must be literals, as in Commit(steps=18)") from None
    cls = _strategy_class(name)
    try:
        return cls(*args, **kwargs)
    except TypeError as e:
        raise ValueError(f"strategy {item!r}: {e}; its parameters: {', '.join(cls.PARAMS) or 'none'}") from None


def parse_strategies(spec, stored: tuple[Strategy, ...] = ()) -> tuple[Strategy, ...]:
    """Strategies from ``spec``: a sequence of :class:`Strategy` objects or spec strings, or one
    string of comma-separated items such as ``"SafestCandidate, Commit(steps=18), Restart(0.3)"``
    (``""``: none, the core alone).  When every item starts with ``-`` or ``+``, they edit
    ``stored`` (the model's composition): ``-Commit`` removes the Commit, ``+Commit(5)`` replaces
    it in place (or appends one).  An unknown name or bad argument is a ``ValueError`` naming it."""
    if not isinstance(spec, (str, list, tuple)):
        raise ValueError(f"strategies must be a spec string or a sequence of strategies, got {spec!r}")
    items: list = _split(spec) if isinstance(spec, str) else list(spec)
    if any(not isinstance(s, (str, Strategy)) for s in items):
        raise ValueError(f"strategies must be Strategy objects or spec strings, got {spec!r}")
    edits = [s for s in items if isinstance(s, str) and s[:1] in "+-"]
    if edits and len(edits) != len(items):
        raise ValueError(f"strategies {spec!r}: either every item edits the stored ones (+/-) or none does")
    if not edits:
        out = tuple(s if isinstance(s, Strategy) else _parse_one(s) for s in items)
    else:
        out = tuple(stored)
        for item in edits:
            if item[0] == "-":  # removal names a class: nothing is built
                cls = _strategy_class(item[1:].partition("(")[0].strip())
                if not any(type(s) is cls for s in out):
                    have = ", ".join(s.name for s in out) or "none"
                    raise ValueError(f"strategy {item!r}: no {cls.__name__} to remove (the stored ones: {have})")
                out = tuple(s for s in out if type(s) is not cls)
                continue
            new = _parse_one(item[1:].strip())
            at = [i for i, s in enumerate(out) if type(s) is type(new)]
            out = out[: at[0]] + (new,) + out[at[0] + 1 :] if at else (*out, new)
    names = [type(s) for s in out]
    if len(set(names)) != len(names):
        raise ValueError(f"strategies {spec!r}: each strategy may appear once")
    return out


def strategy_specs(strategies) -> list[str]:
    """The spec strings of ``strategies`` (as stored in a model file's decision)."""
    return [s.spec() for s in strategies]
