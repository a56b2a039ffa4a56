"""The LRMM guardians: take control when the learned risk of the local observation is high.

Both read the local observation only (no privileged data) and run one numpy forward pass per
step.  The core of :class:`LRMMGuardian` is the paper's method: in control while the model's
risk of the observation is above the threshold, applying the env's safe default; every rule
beyond that is a named strategy (:mod:`rmm_guardians.lrmm.strategies`) composed in its settings
(:class:`~rmm_guardians.lrmm.settings.LRMMSettings`: by default the model's decision, the text
file beside the model file, :mod:`rmm_guardians.lrmm.decision`).  ``lrmm`` (the default) uses the
decision's composition and refuses a model without a decision unless given a threshold;
``lrmm-paper`` (:class:`LRMMPaperGuardian`) is the paper's rule: risk above 0.85, then
:class:`~rmm_guardians.lrmm.strategies.BrakeTurn`, and reads no decision.

Offers :class:`LRMMGuardian`, :class:`LRMMPaperGuardian` and :data:`PAPER_THRESHOLD`.  Why:
docs/decisions/0017-lrmm-rule.md, 0018-lrmm-other-systems.md, 0024-lrmm-core-and-strategies.md.
"""

from __future__ import annotations

import math
from pathlib import Path

from rmm_guardians.base import Guardian
from rmm_guardians.lrmm.decision import decision_for, is_shipped, no_decision_message
from rmm_guardians.lrmm.model import SHIPPED, LRMMModel, default_model_path, load_model
from rmm_guardians.lrmm.nominal import driver_control
from rmm_guardians.lrmm.settings import LRMM_PRESETS, PAPER_THRESHOLD, LRMMSettings
from rmm_guardians.lrmm.shipped import DEFAULT_ENV
from rmm_guardians.lrmm.strategies import DecisionContext, Strategy

__all__ = ["PAPER_THRESHOLD", "LRMMGuardian", "LRMMPaperGuardian"]

#: how to get the model of another env: the guardian picks its model when it is built, not at reset
REMEDY = (
    "; the shipped model is chosen when the guardian is built: make_guardian('lrmm', env_id=<this env's id>) "
    "(as rmm-bench does), or model=<a model trained on this env>"
)


def _overrides(strategy: Strategy, method: str) -> bool:
    return getattr(type(strategy), method) is not getattr(Strategy, method)


class LRMMGuardian(Guardian):
    """Args:
    model: an :class:`LRMMModel`, a model file path, or ``None`` for the shipped model of
        ``env_id`` (the table's ``"act"`` variant for ``lrmm``, ``"paper"`` for ``lrmm-paper``).
    settings: an :class:`~rmm_guardians.lrmm.settings.LRMMSettings` or a preset name
        (``"lrmm"``, ``"lrmm-paper"``, ``"core"``; default: the guardian's own preset).
    env_id: the env served (default ``None``: the table's ``DEFAULT_ENV``): picks the shipped model and the
        observation field it reads (:data:`rmm_guardians.lrmm.shipped.SHIPPED`).
    threshold, strategies, inputs: change those fields of ``settings`` (``None``: unchanged), e.g.
        ``strategies="-Commit"`` (the stored composition without its Commit) or ``strategies=""``
        (the core alone); ``--agent-opt lrmm.strategies='"-Commit"'`` from the command line.

    What is not given comes from the model's decision (``NAME.decision.toml`` beside ``NAME.npz``);
    a model without one is refused (``ValueError``, one line naming ``rmm-bench tune``) unless
    ``threshold`` is given.
    """

    name = "lrmm"
    observation_type = "local"
    privileged = False
    default_model = "act"
    preset = "lrmm"  #: the LRMM_PRESETS entry used when no settings are given
    reads_decision = True  #: whether the model's decision fills what the settings leave open
    #: the threshold when neither the settings nor a decision give one (``None``: refuse the model)
    fallback_threshold: float | None = None

    def __init__(
        self,
        model: LRMMModel | str | Path | None = None,
        settings: LRMMSettings | str | None = None,
        env_id: str | None = None,
        *,
        threshold: float | None = None,
        strategies=None,
        inputs: str | None = None,
    ) -> None:
        super().__init__()
        if settings is None or isinstance(settings, str):
            settings = LRMMSettings.preset(self.preset if settings is None else settings)
        elif not isinstance(settings, LRMMSettings):
            raise ValueError(
                f"settings must be an LRMMSettings or a preset name {sorted(LRMM_PRESETS)}, got {settings!r}"
            )
        given = {"threshold": threshold, "strategies": strategies, "inputs": inputs}
        self.settings = settings = settings.replace(**{k: v for k, v in given.items() if v is not None})
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
        # the observation field the model reads: given, else the env's entry in the table, else all of it
        self.inputs = settings.inputs if settings.inputs is not None else (ship.inputs if ship is not None else None)
        decision, self._decision_file = None, None  # the decision file read and its digest, unless shipped
        if self.reads_decision and settings.needs_decision():
            decision, file, digest = decision_for(self.model, self.env_id)
            if file is not None and not is_shipped(file):  # a shipped one changes only with the package
                self._decision_file = (str(file), digest)
        if settings.threshold is not None:
            self.threshold, self.threshold_source = settings.threshold, "argument"
        elif decision is not None:
            self.threshold, self.threshold_source = decision.threshold, "stored decision"
        elif self.fallback_threshold is not None:
            self.threshold, self.threshold_source = self.fallback_threshold, "paper"
        else:
            raise ValueError(no_decision_message(self.model, self.env_id))
        self.strategies = settings.resolve(decision.parsed() if decision is not None else ())
        for s in self.strategies:
            s.check_model(self.model, self.inputs)
        cands = self.model.candidates
        #: the head's candidate controls as tuples (none without a head)
        self.candidates = () if cands is None else tuple(tuple(float(x) for x in c) for c in cands)
        self._when = [s for s in self.strategies if _overrides(s, "take")]
        self._what = [s for s in self.strategies if _overrides(s, "act")]
        self._reads_driver = any(s.reads_driver for s in self.strategies)
        self._chooses = any(s.chooses for s in self.strategies)
        self._warned = False
        self._step = DecisionContext(self.threshold)
        self.last_risk = float("nan")

    def input_files(self) -> dict[str, str]:
        """The model file this guardian was built from (given or shipped) and the SHA-256 of the
        bytes it was loaded from (none for a model given as an object), and the decision file it
        read unless it is one this package ships (which changes only with the package, as its code)."""
        path, digest = getattr(self.model, "path", None), getattr(self.model, "file_sha256", None)
        out = {str(path): digest} if path is not None and digest is not None else {}
        return out | (dict([self._decision_file]) if self._decision_file else {})

    def check_spaces(self, observation_space, action_space) -> None:
        """Refuse (``ValueError`` naming what is missing) an env this guardian cannot serve: the
        model's input (the whole observation, or the field ``inputs``) must have the model's
        size; without a strategy that chooses the control, the env's action space must state a
        safe default; then each strategy's own check."""
        actions = self.require_action_space(space=action_space)
        size: int | None
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
        if not self._chooses and actions.safe_default is None:
            raise ValueError(
                f"guardian {self.name!r}: in control, the core applies the env's safe default, and this env's "
                "action space states none (GuardianActionSpace(safe_default=...)); add a strategy that chooses "
                "the control (SafestCandidate, BrakeTurn, RayTurn)"
            )
        for s in self.strategies:
            s.check(self, observation_space, actions)

    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        self.check_spaces(self.observation_space, self.action_space)
        actions = self.action_space
        assert actions is not None  # check_spaces refused anything but a GuardianActionSpace
        self._in = slice(None)
        if self.inputs is not None:
            lay = getattr(self.observation_space, "layout", None)
            assert lay is not None  # check_spaces required a layout with the input field
            self._in = lay[self.inputs]
        if actions.safe_default is not None:  # what the core applies when no strategy chose a control
            self._safe = actions.safe_default.policy(actions, self.rng)
        for s in self.strategies:
            s.reset(self)
        self._step.active = False
        self.last_risk = float("nan")

    def signals(self) -> dict[str, float]:
        """``risk``: the model's risk of the last observation decided on; ``risk_threshold``: the
        threshold it is compared with; then the strategies' (``risk_driver``: the risk rated for
        the driver's control, with :class:`~rmm_guardians.lrmm.strategies.RatedDriver`); ``nan``
        until a decision computes them."""
        out = {"risk": float(self.last_risk), "risk_threshold": float(self.threshold)}
        for s in self.strategies:
            out.update(s.signals())
        return out

    def alarm(self) -> tuple[float, float]:
        """``(risk, threshold)``: the model's risk of the last observation and the threshold it
        takes control above (``nan`` before a decision); the strategies may veto or force a
        takeover, the alarm is the core rule's."""
        return float(self.last_risk), float(self.threshold)

    def risk(self, observation):
        return self.model.predict(observation)

    def act(self, observation, info=None):
        x = observation[self._in]
        out = self.model.predict_all(x)
        risk = float(out[0])
        if not math.isfinite(risk):
            raise ValueError(f"the LRMM model returned a non-finite risk ({risk}) for observation {list(observation)}")
        self.last_risk = risk
        step = self._step
        step.observation, step.x, step.out, step.risk, step.info = observation, x, out, risk, info
        if self._reads_driver:
            step.nominal = self._nominal(info)
        take = risk > self.threshold
        for s in self._when:
            take = s.take(step, take)
        step.active = take
        if not take:
            return self.action_space.inactive()
        control = None
        for s in self._what:
            control = s.act(step, control)
        return self.action_space.active(self._safe(observation) if control is None else control)

    def _nominal(self, info) -> list | None:  # None (one warning per guardian): this step uses the state risk
        u = driver_control(info, self.action_space, warn=not self._warned)
        self._warned = self._warned or u is None
        return u


class LRMMPaperGuardian(LRMMGuardian):
    """The paper's rule: ``risk > 0.85``, then brake fully and turn to the more open side
    (the ``lrmm-paper`` preset: :class:`~rmm_guardians.lrmm.strategies.BrakeTurn`), on the
    paper-reproducing model (the table's ``"paper"`` variant).  Same arguments as :class:`LRMMGuardian`;
    it reads no decision: what the settings leave open is the paper's (0.85, no strategies)."""

    name = "lrmm-paper"
    default_model = "paper"
    preset = "lrmm-paper"
    reads_decision = False
    fallback_threshold = PAPER_THRESHOLD
