"""The LRMM guardians: take control when the learned risk of the local observation is high.

Both read the local observation only (no privileged data) and run one numpy forward pass per
step.  ``lrmm`` (:class:`LRMMGuardian`, the default) takes control while the model's risk (or,
with ``trigger="driver"``, the driver's own control rated) is above the threshold, applies the
candidate manoeuvre its action-conditioned head rates safest, and stays in control ``commit``
steps past the risk; its defaults come from the model file or the env's shipped entry
(:mod:`rmm_guardians.lrmm.defaults`).  ``lrmm-paper`` (:class:`LRMMPaperGuardian`) is the paper's
rule: risk above 0.85, maximum braking and a maximum turn toward the more open side.

Offers :class:`LRMMGuardian`, :class:`LRMMPaperGuardian`, :data:`PAPER_THRESHOLD` and
:data:`TRIGGERS`.  What each rule does on each system, how the defaults were chosen and what
it needs from an env: ``docs/design-notes.md``.
"""

from __future__ import annotations

import math
import os
import sys
import warnings
from collections import deque
from pathlib import Path
from types import FrameType

import numpy as np

from rmm_envs.portable import wrap_angle
from rmm_guardians._checks import integer
from rmm_guardians.base import Guardian
from rmm_guardians.lrmm.defaults import PAPER_THRESHOLD, check_threshold, decision_threshold, stored_decision
from rmm_guardians.lrmm.model import SHIPPED, LRMMModel, default_model_path, load_model
from rmm_guardians.lrmm.nominal import TRIGGERS, Slide, driver_at_risk, driver_control, hand_back_options, make_rater

__all__ = ["PAPER_THRESHOLD", "TRIGGERS", "LRMMGuardian", "LRMMPaperGuardian"]

ACTIONS = ("head", "heuristic", "turn", "safe")
DEFAULT_ENV = "Dubins4DGuarded-v0"  # whose shipped model a guardian built without env_id or model reads
#: how to get the model of another env: the guardian picks its model when it is built, not at reset
REMEDY = (
    "; the shipped model is chosen when the guardian is built: make_guardian('lrmm', env_id=<this env's id>) "
    "(as rmm-bench does), or model=<a model trained on this env>"
)
#: this package's folder: a warning points past its frames, at the code that built the guardian
_PACKAGE_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep


def _caller_level() -> int:
    """The ``stacklevel`` of the first frame, outward from the one calling ``warnings.warn``,
    outside this package (the user's line that built the guardian, directly or by
    ``make_guardian``), for a warning raised by this package's code."""
    level = 1  # the frame calling warnings.warn
    frame: FrameType | None = sys._getframe(1)
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(_PACKAGE_DIR):
        frame, level = frame.f_back, level + 1
    return level


_SIDE_RAY = math.pi / 6  # the heuristic compares the rays 30 degrees left and right of the heading


class LRMMGuardian(Guardian):
    """Args:
    model: an :class:`LRMMModel`, a model file path, or ``None`` for the shipped model
        (``dubins4d_act.npz`` for ``lrmm``, ``dubins4d.npz`` for ``lrmm-paper``).
    threshold: take control while the risk is strictly above it; ``None`` (default) uses
        the model's stored threshold (the paper's 0.85 if it has none, with a warning).
    action: ``"head"`` (the safest candidate of the model's head), ``"heuristic"`` (brake
        and turn to the more open +-30 degree ray), ``"turn"`` (turn toward the lower-risk
        side; one-control systems whose model reads the rays), ``"safe"`` (the env's safe default,
        ``action_space.safe_default``: hover and level for the quadrotor) or ``None`` (default: ``"head"`` when
        the model has one, else ``"heuristic"`` with a warning).
    hysteresis: use the original's moving-average release rule (default False).
    window: moving-average length with ``hysteresis`` (default 20).
    commit: steps to stay in control after the risk is back at or below the threshold;
        ``None`` (default) uses the model's stored value (0 if it has none).
    u1_max, u2_min: turn rate and braking of the heuristic (``u1_max`` also of ``"turn"``);
        ``None`` (default): the action space's largest turn rate and strongest braking
        (0.25, -0.5 for Dubins4D).
    env_id: the env served (default ``None``: Dubins4D): picks the shipped model, its
        input field and decision defaults from :data:`rmm_guardians.lrmm.shipped.SHIPPED`.
    inputs: the observation field the model reads (default ``None``: the table's for
        ``env_id``, else the whole observation).
    trigger, margin, restart, slide, still, stay: the hand-back rule (module docstring);
        ``None`` (default): the model's stored values, else ``"risk"``, 0, 0, False, None, True.
    """

    name = "lrmm"
    observation_type = "local"
    privileged = False
    default_model = "act"

    def __init__(
        self,
        model: LRMMModel | str | Path | None = None,
        threshold: float | None = None,
        action: str | None = None,
        hysteresis: bool = False,
        window: int = 20,
        commit: int | None = None,
        u1_max: float | None = None,
        u2_min: float | None = None,
        env_id: str | None = None,
        inputs: str | None = None,
        trigger: str | None = None,
        margin: float | None = None,
        restart: float | None = None,
        slide: bool | None = None,
        still: float | None = None,
        stay: bool | None = None,
    ) -> None:
        super().__init__()
        check_threshold(threshold)  # refused before any file is read
        integer("window", window, 1)
        if commit is not None:
            integer("commit", commit, 0, "steps to stay in control after the risk falls back")
        if action not in (None, *ACTIONS):
            raise ValueError(f"action must be one of {ACTIONS} or None, got {action!r}")
        if env_id is not None and not isinstance(env_id, str):
            raise ValueError(f"env_id must be a registered env id (str) or None, got {env_id!r}")
        self.env_id = env_id or DEFAULT_ENV
        ship = SHIPPED.get(self.env_id)
        if isinstance(model, LRMMModel):
            self.model = model
        else:
            self.model = load_model(
                model if model is not None else default_model_path(self.env_id, variant=self.default_model)
            )
        where = str(getattr(self.model, "path", "the model"))
        # the observation field the model reads: given, else the env's entry in the table, else all of it
        self.inputs = inputs if inputs is not None else (ship.inputs if ship is not None else None)
        decision = stored_decision(self.model.meta, ship, model is not None)
        if action is None and decision and decision.get("action") is not None:
            action = decision["action"]
            if action not in ACTIONS:
                raise ValueError(f"{where}: stored decision action must be one of {ACTIONS}, got {action!r}")
        if action is None:
            if self.model.candidates is None:
                action = "heuristic"
                self._fallback_warning(f"{where} has no 'candidates' head: using the paper's brake-and-turn heuristic")
            else:
                action = "head"
        elif action == "head" and self.model.candidates is None:
            raise ValueError(f"action='head' needs a model with a 'candidates' head; {where} has none")
        if commit is None:
            commit = int(decision.get("commit", 0)) if decision else 0
        # argument > the model's stored decision > the shipped entry's > the paper's (rmm_guardians.lrmm.defaults)
        self.threshold, self.threshold_source = decision_threshold(threshold, decision, where)
        if self.threshold_source == "paper":
            self._fallback_warning(f"{where} has no 'decision' threshold: using the paper's {PAPER_THRESHOLD}")
        self.trigger, self.margin, self.restart, self.slide, self.still, self.stay = hand_back_options(
            trigger, margin, restart, decision, action, hysteresis, slide, still, stay
        )
        self._warned = False
        self.action = action
        self.hysteresis = bool(hysteresis)
        self.window = int(window)
        self.commit = int(commit)
        self._committed, self._active = 0, False
        self._u1_max_arg = None if u1_max is None else float(u1_max)
        self._u2_min_arg = None if u2_min is None else float(u2_min)
        self.u1_max, self.u2_min = self._u1_max_arg, self._u2_min_arg
        self._history: deque = deque(maxlen=self.window)
        self.last_risk = float("nan")
        if action == "head":
            assert self.model.candidates is not None  # action 'head' without a 'candidates' head was refused above
            self._cands = [tuple(float(x) for x in c) for c in self.model.candidates]  # any control count

    def input_files(self) -> dict[str, str]:
        """The model file this guardian was built from (given or shipped) and the SHA-256 of the
        bytes it was loaded from; none for a model given as an object."""
        path, digest = getattr(self.model, "path", None), getattr(self.model, "file_sha256", None)
        return {str(path): digest} if path is not None and digest is not None else {}

    def _fallback_warning(self, text: str) -> None:
        if type(self) is LRMMGuardian:  # the paper preset expects the paper's rule: nothing to warn about
            warnings.warn(f"lrmm: {text}", UserWarning, stacklevel=_caller_level())

    def check_spaces(self, observation_space, action_space) -> None:
        """Refuse (``ValueError`` naming what is missing) an env this guardian cannot serve: the
        model's input (the whole observation, or the field ``inputs``) must have the model's
        size; ``head`` needs the head's control count, ``heuristic`` two controls (turn rate,
        acceleration) and rays, ``turn`` one control (the turn rate) and the model reading rays
        evenly spaced over the full circle."""
        actions = self.require_action_space(space=action_space)
        size = None
        if self.inputs is not None:
            lay = self.require_layout(self.inputs, observation_space=observation_space)
            size = lay.size_of(self.inputs)
        else:
            size = (getattr(observation_space, "shape", None) or (None,))[0]
        if size != self.model.obs_dim:
            what = (
                f"observation field {self.inputs!r} has {size} numbers"
                if self.inputs
                else f"observation space is {getattr(observation_space, 'shape', observation_space)}"
            )
            raise ValueError(
                f"guardian {self.name!r}: the LRMM model (trained on {self.model.env_id}) expects observations "
                f"of shape ({self.model.obs_dim},), the env's {what}{REMEDY}"
            )
        if self.action == "head":
            candidates = self.model.candidates
            assert candidates is not None  # the constructor refused action 'head' without a 'candidates' head
            if candidates.shape[1] != actions.control_dim:
                k = candidates.shape[1]
                raise ValueError(
                    f"guardian {self.name!r} needs an action space with {k} controls (the model's candidate "
                    f"controls have {k} components), got {actions.control_dim} ({actions.controls})"
                )
            low, high = np.asarray(actions.control_low, float), np.asarray(actions.control_high, float)
            outside = [c.tolist() for c in candidates if np.any(c < low) or np.any(c > high)]
            if outside:
                raise ValueError(
                    f"guardian {self.name!r}: candidate controls {outside} of "
                    f"{getattr(self.model, 'path', 'the model')} lie outside the env's control bounds "
                    f"[{low.tolist()}, {high.tolist()}] ({actions.controls})"
                )
        if self.trigger == "driver" and self._rater_for(observation_space, actions) is None:
            raise ValueError(
                f"guardian {self.name!r}: trigger 'driver' needs the model reading the whole observation and a "
                "field the controls move ('velocity', 'speed', or 'heading' with evenly spaced rays; "
                f"rmm_guardians.lrmm.nominal); got controls {actions.controls}, inputs={self.inputs!r}"
            )
        if self.restart > 0 and (
            "accel_ctrl" not in actions.controls or "speed" not in getattr(observation_space, "layout", ())
        ):
            raise ValueError(
                f"guardian {self.name!r}: restart needs an 'accel_ctrl' control and a 'speed' observation "
                f"field, got controls {actions.controls}"
            )
        if self.action == "heuristic":
            if actions.control_dim != 2 and actions.safe_default is not None:
                raise ValueError(
                    f"guardian {self.name!r}: the brake-and-turn heuristic (the action of a model without "
                    f"a head) needs the Dubins car's two controls, got {actions.control_dim} "
                    f"({actions.controls}); this env states a safe default ({actions.safe_default.description}): "
                    f"action='safe' applies it (rmm-bench --agent-opt {self.name}.action='\"safe\"')"
                )
            self.require_action_space(controls=2, space=action_space)  # (turn rate, acceleration)
            self._require_named(
                "rays",
                observation_space,
                actions,
                "the brake-and-turn heuristic (the action of a model without a 'candidates' head)",
            )
            self.require_layout("rays", observation_space=observation_space)
        if self.action == "safe" and actions.safe_default is None:
            raise ValueError(
                f"guardian {self.name!r}: action 'safe' applies the env's safe default, and this env's "
                "action space states none (GuardianActionSpace(safe_default=...))"
            )
        if self.action == "turn":
            self.require_action_space(controls=1, space=action_space)  # the turn rate
            self._require_named("rays", observation_space, actions, "action 'turn'")
            lay = self.require_layout("rays", observation_space=observation_space)
            n = lay.size_of("rays")
            even = np.allclose(wrap_angle(np.asarray(lay.ray_angles) - 2 * np.pi * np.arange(n) / n), 0, atol=1e-9)
            if self.inputs != "rays" or not even:
                raise ValueError(
                    f"guardian {self.name!r}: action 'turn' judges a turn by the model's risk of the rays "
                    "rotated by one ray, so the model must read the 'rays' field, rays evenly spaced over the "
                    f"full circle from the heading; got inputs={self.inputs!r}, ray angles {lay.ray_angles}"
                )

    def _require_named(self, field: str, observation_space, actions, what: str) -> None:
        """A ``ValueError`` saying what to do instead (from the command line too) when ``what``
        needs the observation field ``field`` by name and the env's observation names no field
        (an env of one's own, e.g. made by rmm_envs.envs.driven.guarded/parallel); the layout's
        other refusals are :meth:`require_layout`'s."""
        if getattr(observation_space, "layout", None) is not None or actions.safe_default is None:
            return
        raise ValueError(
            f"guardian {self.name!r}: {what} reads the observation field {field!r} by name, and this env's "
            f"observation names no fields (an env of your own, e.g. made by rmm_envs.envs.driven.guarded or "
            f"parallel); to take the env's safe default ({actions.safe_default.description}) while the risk is "
            f"above the threshold, give rmm-bench --agent-opt {self.name}.action='\"safe\"' "
            f"(in Python: action='safe')"
        )

    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        self.check_spaces(self.observation_space, self.action_space)
        actions = self.action_space
        assert actions is not None  # check_spaces refused anything but a GuardianActionSpace
        # the observation's layout; check_spaces required one wherever it is read below
        lay = getattr(self.observation_space, "layout", None)
        if self.inputs is not None:
            assert lay is not None
            self._in = lay[self.inputs]
        else:
            self._in = slice(None)
        if self.action == "heuristic":
            assert lay is not None
            self._left, self._right = lay.ray_index(_SIDE_RAY), lay.ray_index(-_SIDE_RAY)
        self.u1_max = float(actions.control_high[0]) if self._u1_max_arg is None else self._u1_max_arg
        if self.action == "heuristic":
            self.u2_min = float(actions.control_low[1]) if self._u2_min_arg is None else self._u2_min_arg
        if self.action == "safe":
            assert actions.safe_default is not None  # check_spaces refused an env without one
            self._safe = actions.safe_default.policy(actions, self.rng)
        if self.action == "turn":
            assert lay is not None
            rays = lay["rays"]
            self._lside = [
                rays.start + i for i, a in enumerate(lay.ray_angles) if 0 < math.remainder(a, 2 * math.pi) < math.pi
            ]
            self._rside = [
                rays.start + i for i, a in enumerate(lay.ray_angles) if -math.pi < math.remainder(a, 2 * math.pi) < 0
            ]
        if self.trigger == "driver":
            self._rater = self._rater_for(self.observation_space, actions)
        self._slide = Slide(actions.controls, actions.control_low, actions.control_high) if self.slide else None
        if self.restart > 0:
            assert lay is not None
            self._speed, self._accel = lay.index("speed"), actions.controls.index("accel_ctrl")
        self._history = deque([self.threshold] * self.window, maxlen=self.window)
        self.last_risk = self.last_driver_risk = float("nan")
        self._committed, self._active = 0, False

    def signals(self) -> dict[str, float]:
        """``risk``: the model's risk of the last observation decided on; ``risk_threshold``: the
        threshold it is compared with; with ``trigger="driver"`` also ``risk_driver``, the risk
        rated for the driver's control (``nan`` until a decision computes them)."""
        out = {"risk": float(self.last_risk), "risk_threshold": float(self.threshold)}
        if self.trigger == "driver":
            out["risk_driver"] = float(getattr(self, "last_driver_risk", float("nan")))
        return out

    def risk(self, observation) -> np.ndarray | float:
        return self.model.predict(observation)

    def act(self, observation, info=None):
        x = observation[self._in]
        out = self.model.predict_all(x)
        risk = float(out[0])
        if not math.isfinite(risk):
            raise ValueError(f"the LRMM model returned a non-finite risk ({risk}) for observation {list(observation)}")
        self.last_risk = risk
        nominal = self._nominal(info) if self.trigger == "driver" else None
        intervene = risk > self.threshold if nominal is None else self._driver_at_risk(x, nominal)
        if self.hysteresis:
            self._history.append(risk)
            intervene = intervene or (sum(self._history) / len(self._history) > self.threshold)
        if intervene:
            self._committed = self.commit
        elif self._committed > 0:
            self._committed -= 1
            intervene = True
        self._active = intervene
        if not intervene:
            return self.action_space.inactive()
        if self.action == "head":
            cand = out[1:].tolist()
            if not all(map(math.isfinite, cand)):
                raise ValueError(f"the LRMM model returned non-finite candidate risks {cand}")
            bent = (
                self._slide.choose(self._rater, self.model, x, nominal, self.threshold)
                if self._slide and nominal
                else None
            )
            if bent is not None:
                return self.action_space.active(bent)
            k = cand.index(min(cand))  # the first of the lowest
            if self.restart > 0 and observation[self._speed] < self.restart:  # a stopped car: move on safely
                go = [(r, i) for i, r in enumerate(cand) if self._cands[i][self._accel] > 0 and r <= self.threshold]
                k = min(go)[1] if go else k
            return self.action_space.active(self._cands[k])
        if self.action == "turn":
            return self.action_space.active((self._turn(observation, x),))
        if self.action == "safe":
            return self.action_space.active(self._safe(observation))
        left, right = observation[self._left], observation[self._right]
        turn = 0.0 if np.isclose(left, right) else (self.u1_max if left > right else -self.u1_max)
        return self.action_space.active((turn, self.u2_min))

    def _rater_for(self, observation_space, actions):
        if self.inputs is not None:  # the model reads one field; the prediction moves others
            return None
        return make_rater(
            actions.controls,
            getattr(observation_space, "layout", None),
            self.model.candidate_hold,
            observation_space.low,
            observation_space.high,
        )

    def _nominal(self, info) -> list | None:  # None (one warning per guardian): this step uses "risk"
        u = driver_control(info, self.action_space, warn=not self._warned)
        self._warned = self._warned or u is None
        return u

    def _driver_at_risk(self, x, nominal) -> bool:
        rated = self._rater.rate_many([nominal, [0.0] * len(nominal), *self._cands], self.model, x)
        self.last_driver_risk = rated[0]
        return driver_at_risk(rated, self.threshold, self.margin, self.still, self._active and self.stay)

    def _turn(self, observation, rays) -> float:
        """The maximum turn rate toward the lower-risk side: the model's risk of the rays as
        they would read with the heading one ray further left (``roll(rays, -1)``) or right
        (``roll(rays, 1)``); on a tie (``numpy.isclose``), toward the side whose nearest wall is
        farther, left on a second tie."""
        r_left, r_right = self.model.predict_all(np.stack([np.roll(rays, -1), np.roll(rays, 1)]))[:, 0]
        if not (math.isfinite(r_left) and math.isfinite(r_right)):
            raise ValueError(f"the LRMM model returned non-finite risks {[r_left, r_right]} for the turned rays")
        if np.isclose(r_left, r_right):
            left = min(observation[i] for i in self._lside) >= min(observation[i] for i in self._rside)
        else:
            left = r_left < r_right
        assert self.u1_max is not None  # set at reset
        return self.u1_max if left else -self.u1_max


class LRMMPaperGuardian(LRMMGuardian):
    """The paper's rule: ``risk > 0.85``, then brake fully and turn to the more open side.

    Same arguments as :class:`LRMMGuardian`; the defaults differ: ``threshold=0.85``,
    ``action="heuristic"`` and the paper-reproducing model ``dubins4d.npz``.
    """

    name = "lrmm-paper"
    default_model = "paper"

    def __init__(
        self,
        model: LRMMModel | str | Path | None = None,
        threshold: float | None = PAPER_THRESHOLD,
        action: str | None = "heuristic",
        **kwargs,
    ) -> None:
        super().__init__(model=model, threshold=threshold, action=action, **kwargs)
