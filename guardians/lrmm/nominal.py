"""Rating the driver's own control with an LRMM model, from the local observation alone.

The ``lrmm`` guardian's ``trigger="driver"`` (see :mod:`guardians.lrmm.guardian`) asks how risky
the driver's next control is, ``info["nominal_control"]``, and how much risk the head's safest
candidate would save.  The head rates only its fixed candidates, so both are rated here the same
way: the model's state risk (unit 0) of the observation *predicted* after holding the control
for the head's hold time (``candidate_hold``, 1 s for the shipped models), a cheap one-step
prediction that moves only what the observation measures of the control's effect:

* a velocity command (``vforward_ctrl``, ``vleft_ctrl``, ``vup_ctrl``: the quadrotor) replaces
  the measured heading-frame ``"velocity"`` (the stabilising controller tracks a command within
  a fraction of a second);
* an acceleration (``accel_ctrl``: Dubins4D) changes the ``"speed"`` by ``a * hold``, clipped
  to the observation space's bounds;
* a turn rate (``turnrate_ctrl``) turns the ``"heading"`` by ``w * hold`` (wrapped to
  ``[-pi, pi)``) and the rays with it, when they are evenly spaced over the full circle from the
  heading: the ray at angle ``a`` then reads what the ray at ``a + w * hold`` read, linearly
  interpolated between the two nearest rays.

A yaw rate is not predicted (the quadrotor's rays turn with the body, but its rater leaves
them).  The position does not move: the rays keep their lengths apart from the turn.  That is the
prediction's stated error; it rates a control by the state it leads to *here*, which is what
separates "keep flying at the wall" from "stop" or "back off" for a risk model of random futures.

**When** (:func:`driver_at_risk`): in control while the driver's control is rated above the
threshold and either the head's best candidate is rated more than ``margin`` lower, or (``still``)
the zero control, holding still, is rated more than ``still`` lower; once in control it stays
while the driver's control is rated above the threshold (``stay``, the default), then ``commit``
steps more.  **What** (``slide``, :class:`Slide`): the variant of the driver's control nearest
to it that is rated at or below the threshold, else the head's safest candidate.

**Why, on the quadrotor** (the shipped ``quadrotor_cmd_act.npz``: threshold 0.2, margin 0.15,
still 0.05, slide, commit 20).  The rule before (margin 0.1 against the best candidate only,
applying the head's safest candidate) timed out in 35% of the development episodes
(``rmm-bench --env QuadrotorRoomParallel-v0 --seed 5``, 128 episodes, fixed 1 ms clock:
51.6 / 13.3 / 35.2 success / collision / timeout %; the pilot alone 37.5 / 62.5 / 0), in two
ways seen in the episodes: backing off from a wall for the pilot to fly back at it, hand-back
after hand-back; and, in a narrow spot (a waypoint between walls 2 m apart), rating even holding
still at about 0.2, so that the pilot's slow descent to the waypoint was "risky", the guardian
climbed, handed back, and the pilot descended again.  Against holding still, that descent adds
no risk: ``still`` takes control when the driver's control itself is what is risky, and the
margin 0.15 against the best candidate still acts early when a candidate saves much more (a
wall ahead in a cluttered spot, where holding still is risky too).  Climbing is the one move
that does not undo the pilot's progress and that the rooms always allow (they have no
ceiling): the slide keeps the pilot's horizontal velocity (then half, then none) and yaw rate
and climbs at 1 m/s, so the body rises over the obstacle while the pilot flies on.

Alternatives tried (the same development episodes; success / collision / timeout %; 32
episodes of ``--seed 5`` unless stated, where the rule before gives 56.2 / 6.2 / 37.5):

* slides turning the pilot's horizontal velocity by 0, +-45 or +-90 degrees at full or half
  speed, with its vertical velocity or climbing: 41.4 / 26.6 / 32.0 (128 episodes); the same
  with no horizontal speed too: 46.9 / 25.0 / 28.1.  The prediction moves no position, so a
  variant close to the pilot's command is rated safe while it still flies at the wall;
  straight only, keeping the pilot's vertical velocity too: 37.5 / 28.1 / 34.4; with commit 5:
  34.4 / 25.0 / 40.6; a variant needing a rating at most 0.1: 53.1 / 12.5 / 34.4;
* climbing slides only (the chosen moves) with the rule before: 62.5 / 0.0 / 37.5, and adding
  the pilot's command with half its vertical velocity: 50.0 / 21.9 / 28.1, or with no
  horizontal velocity and half the vertical: 56.2 / 6.2 / 37.5;
* the head's candidate nearest to the pilot's command among those rated at most 0.2 (0.3,
  0.4): 25.0 / 12.5 / 62.5 (21.9 / 12.5 / 65.6, 15.6 / 6.2 / 78.1): hovering stalls; with
  the pilot's yaw rate: 25.0 / 25.0 / 50.0; preferring climbing candidates within 0.05 of the
  safest: 56.2 / 9.4 / 34.4; the pilot's yaw rate in the head's candidates: 53.1 / 6.2 / 40.6;
  commit 40: 43.8 / 0.0 / 56.2;
* handing back as soon as the margin test fails (no ``stay``), margin 0.1 (0.05): 53.1 /
  15.6 / 31.2 (50.0 / 6.2 / 43.8);
* with the climbing slide, ``still`` alone (no margin test) and no ``stay``, 0.03 / 0.05 /
  0.07: 56.2 / 9.4 / 34.4, 78.1 / 9.4 / 12.5, 75.0 / 18.8 / 6.2; 0.05 with commit 10: 65.6 /
  18.8 / 15.6; with ``stay``, 0.05 (0.1): 78.1 / 12.5 / 9.4 (65.6 / 28.1 / 6.2), and 0.05 over
  128 episodes of ``--seed 5`` and of ``--seed 6``: 70.3 / 21.1 / 8.6 and 75.8 / 14.8 / 9.4
  (too many collisions: a wall ahead in a cluttered spot adds little to the risk of holding
  still there);
* still 0.05 and margin 0.12 (0.15): 65.6 / 12.5 / 21.9 (67.2 / 15.6 / 17.2) on 64
  episodes; the chosen rule over 128 episodes of ``--seed 5`` and ``--seed 6``: 68.8 / 14.8 /
  16.4 and 73.4 / 11.7 / 14.8; without ``stay``: 67.2 / 14.8 / 18.0 and 73.4 / 12.5 / 14.1.

The rule was chosen as the one meeting issue 28's targets (at most 15% collisions, at most 20%
timeouts, at least the pilot's success) on both development seeds.  On seed 11, run once after
that (512 episodes, docs/reproduction.md): 69.3 / 13.3 / 17.4, the pilot alone 45.1 / 54.9 / 0.  What remains: collisions
after a climb, when the pilot descends onto a wall top its horizontal rays no longer see and
the downward ray sees only when it is already below (0.1 m), and timeouts where every command
is rated risky and the guardian holds the body.
"""

from __future__ import annotations

import math
import warnings
from typing import Sequence

import numpy as np

from rmm_envs.portable import wrap_angle

__all__ = ["SLIDE_MOVES", "TRIGGERS", "VELOCITY_CONTROLS", "PredictRater", "Slide", "driver_at_risk", "driver_control", "hand_back_options",
           "make_rater"]

TRIGGERS = ("risk", "driver")  # when lrmm takes control: the state risk, or the driver's control rated

#: control field -> component of the observation's ``"velocity"`` field that measures it
VELOCITY_CONTROLS = {"vforward_ctrl": 0, "vleft_ctrl": 1, "vup_ctrl": 2}


class PredictRater:
    """The model's state risk (unit 0) of the observation predicted after holding a control.

    Args:
        layout: the observation's :class:`~rmm_envs.autonomy.ObservationLayout`.
        controls: the action space's control fields, in order.
        hold: seconds the control is held (the head's ``candidate_hold``).
        low, high: the observation space's bounds (the predicted speed is clipped to them).
    """

    def __init__(self, layout, controls: Sequence[str], hold: float, low, high) -> None:
        self.hold = float(hold)
        self.velocity = [(j, layout["velocity"].start + VELOCITY_CONTROLS[c]) for j, c in enumerate(controls)
                         if c in VELOCITY_CONTROLS and "velocity" in layout]
        self.accel = self.turn = None
        if "accel_ctrl" in controls and "speed" in layout:
            i = layout.index("speed")
            self.accel = (controls.index("accel_ctrl"), i, float(low[i]), float(high[i]))
        n = layout.size_of("rays") if "rays" in layout else 0
        even = n > 0 and all(abs(float(wrap_angle(a - 2.0 * math.pi * k / n))) < 1e-9 for k, a in enumerate(layout.ray_angles))
        if "turnrate_ctrl" in controls and "heading" in layout and even:
            self.turn = (controls.index("turnrate_ctrl"), layout.index("heading"), layout["rays"].start, n)

    @property
    def applies(self) -> bool:
        return bool(self.velocity) or self.accel is not None or self.turn is not None

    def predict(self, x, u) -> np.ndarray:
        """The observation ``x`` as predicted after holding control ``u`` for ``hold`` seconds."""
        y = np.array(x, dtype=float)
        for j, i in self.velocity:  # the velocity loop tracks the command within a fraction of a second
            y[i] = u[j]
        if self.accel is not None:
            j, i, lo, hi = self.accel
            y[i] = min(max(y[i] + u[j] * self.hold, lo), hi)
        if self.turn is not None:
            j, h, r0, n = self.turn
            delta = u[j] * self.hold
            y[h] = float(wrap_angle(y[h] + delta))
            # the ray at angle a after the turn reads what the ray at a + delta read before it
            shift = delta * n / (2.0 * math.pi)
            old = [float(v) for v in x[r0:r0 + n]]
            for k in range(n):
                f = k + shift
                lo_k = math.floor(f)
                w = f - lo_k
                y[r0 + k] = (1.0 - w) * old[lo_k % n] + w * old[(lo_k + 1) % n]
        return y

    def rate_many(self, controls, model, x) -> list[float]:
        """The model's state risk of ``x`` predicted after each of ``controls``; ``ValueError``
        naming the controls when a risk is not finite (NaN would compare as "safe")."""
        rows = np.stack([self.predict(x, u) for u in controls])
        rated = [float(v) for v in model.predict_all(rows)[:, 0]]
        if not all(map(math.isfinite, rated)):
            raise ValueError(f"the LRMM model rated the controls {[list(u) for u in controls]} with non-finite risks {rated}")
        return rated


#: the slide's variants of the driver's velocity command: (cos, sin) of the turn of its horizontal
#: velocity, the fraction of that velocity kept, and the vertical velocity: ``"climb"`` (the box's
#: largest) or the fraction of the driver's kept
SLIDE_MOVES = (((1.0, 0.0), 1.0, "climb"), ((1.0, 0.0), 0.5, "climb"), ((1.0, 0.0), 0.0, "climb"))


class Slide:
    """The driver's own velocity command bent around what the model rates risky (``slide``).

    The variants of the driver's command ``u`` (forward, left, up velocity and the rest, in the
    action space's order) are :data:`SLIDE_MOVES`; every other control (the yaw rate) is the
    driver's.  ``u`` itself is not one of them: a slide is applied only while the guardian is in
    control.  They are ordered by how far they are from ``u`` (Euclidean over the velocities),
    the order of :data:`SLIDE_MOVES` on ties; :meth:`choose` rates them as ``u`` is rated and
    returns the first one rated at or below the threshold, ``None`` when none is.

    Args:
        controls: the action space's control fields (``vforward_ctrl``, ``vleft_ctrl`` and
            ``vup_ctrl`` needed).
        low, high: the action space's control bounds (variants are clipped to them).
        moves: ``(turn, kept, vertical)`` triples as in :data:`SLIDE_MOVES` (default: those).
    """

    def __init__(self, controls, low, high, moves=None) -> None:
        controls = tuple(controls)
        if any(c not in controls for c in VELOCITY_CONTROLS):
            raise ValueError(f"slide bends a velocity command: it needs the controls {tuple(VELOCITY_CONTROLS)}, "
                             f"got {controls}")
        self.f, self.l, self.up = (controls.index(c) for c in VELOCITY_CONTROLS)
        self.low, self.high = [float(v) for v in low], [float(v) for v in high]
        self.moves = SLIDE_MOVES if moves is None else moves

    def variants(self, u) -> list[list[float]]:
        """The variants of ``u``, nearest first (class docstring)."""
        u = [float(v) for v in u]
        out = []
        for (c, s), k, z in self.moves:
            v = list(u)
            v[self.f] = k * (c * u[self.f] - s * u[self.l])
            v[self.l] = k * (s * u[self.f] + c * u[self.l])
            v[self.up] = self.high[self.up] if z == "climb" else z * u[self.up]
            v = [min(max(a, lo), hi) for a, lo, hi in zip(v, self.low, self.high)]
            if v != u and v not in out:
                out.append(v)
        gap = [math.sqrt(sum((v[j] - u[j]) ** 2 for j in (self.f, self.l, self.up))) for v in out]
        return [out[i] for i in sorted(range(len(out)), key=lambda i: gap[i])]

    def choose(self, rater: "PredictRater", model, x, u, threshold: float) -> list | None:
        """The nearest variant of ``u`` rated at or below ``threshold``; ``None`` if none is."""
        options = self.variants(u)
        if not options:
            return None
        rated = rater.rate_many(options, model, x)
        return next((v for v, r in zip(options, rated) if r <= threshold), None)


def make_rater(controls: Sequence[str], layout, hold, low, high) -> "PredictRater | None":
    """The rater for this env, or ``None`` when the observation measures none of the controls'
    effects (no ``layout``, or none of the fields :class:`PredictRater` predicts)."""
    if layout is None or hold is None:
        return None
    rater = PredictRater(layout, tuple(controls), hold, low, high)
    return rater if rater.applies else None


def driver_control(info, action_space, warn: bool = True) -> list | None:
    """The driver's control this step, ``info["nominal_control"]``, as a list in the action
    space's control order.  ``None`` when ``info`` has none (with a ``UserWarning`` naming the key
    if ``warn``); ``ValueError`` naming the value when it is not ``control_dim`` finite numbers."""
    u = info.get("nominal_control") if isinstance(info, dict) else None
    if u is None:
        if warn:
            keys = sorted(info) if isinstance(info, dict) else info
            warnings.warn(f"lrmm: trigger 'driver' rates the driver's control, info['nominal_control'], and this env "
                          f"gives none (info: {keys!r}); using the state risk (trigger 'risk') instead", UserWarning,
                          stacklevel=4)
        return None
    try:
        n = np.asarray(u, dtype=float).reshape(-1) if np.ndim(u) <= 1 else np.empty(0)
    except (TypeError, ValueError):  # not numbers
        n = np.empty(0)
    if n.shape[0] != action_space.control_dim or not np.all(np.isfinite(n)):
        raise ValueError(f"info['nominal_control'] must be {action_space.control_dim} finite numbers "
                         f"{action_space.controls}, got {u!r}")
    return n.tolist()


def hand_back_options(trigger, margin, restart, stored: dict | None, action: str, hysteresis: bool,
                      slide=None, still=None, stay=None) -> tuple:
    """``lrmm``'s ``(trigger, margin, restart, slide, still, stay)``: each given one, else the model
    file's stored decision (used only with ``action="head"`` and, for the trigger, without
    hysteresis: a file's defaults are for its own rule), else ``"risk"``, 0, 0, False, None, True;
    ``ValueError`` naming a bad value or a given combination that cannot work (both rate or
    accelerate with the head's candidates; ``slide``, ``still`` and ``stay=False`` change how the
    driver's control is judged, so they need ``trigger="driver"``)."""
    stored = dict(stored or {}) if action == "head" else {}
    if hysteresis:
        stored.pop("trigger", None)
    trigger = trigger if trigger is not None else stored.get("trigger", "risk")
    if trigger not in TRIGGERS:
        raise ValueError(f"trigger must be one of {TRIGGERS}, got {trigger!r}")
    if trigger == "driver" and (action != "head" or hysteresis):
        raise ValueError(f"trigger='driver' compares the driver's control with the head's candidates: it needs "
                         f"action='head' without hysteresis, got action={action!r}, hysteresis={hysteresis!r}")
    values = []
    for name, given, default in (("margin", margin, 0.0), ("restart", restart, 0.0), ("still", still, None)):
        value = given if given is not None else stored.get(name, default)
        if value is None:
            values.append(None)
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value < math.inf:
            raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        values.append(float(value))
    if values[1] > 0 and action != "head":
        raise ValueError(f"restart accelerates with the head's candidates: it needs action='head', got {action!r}")
    flags = []
    for name, given, default in (("slide", slide, False), ("stay", stay, True)):
        value = given if given is not None else stored.get(name, default)
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{name} must be True or False, got {value!r}")
        flags.append(bool(value))
    if trigger != "driver" and (flags[0] or values[2] is not None or not flags[1]):
        raise ValueError(f"slide, still and stay=False judge the driver's control, info['nominal_control']: they need "
                         f"trigger='driver', got {trigger!r}")
    margin, restart, still = values
    return trigger, margin, restart, flags[0], still, flags[1]


def driver_at_risk(rated, threshold: float, margin: float, still: float | None = None, holding: bool = False) -> bool:
    """Whether ``lrmm`` (``trigger="driver"``) is to be in control this step, from ``rated``: the
    driver's control, the zero control (holding still) and the head's candidates, each rated by
    :meth:`PredictRater.rate_many`.  Never at or below ``threshold``; above it, while ``holding``
    (in control, with ``stay``), when the best candidate is rated more than ``margin`` lower, or
    (with ``still``) when the zero control is rated more than ``still`` lower."""
    u, zero, best = rated[0], rated[1], min(rated[2:])
    if u <= threshold:
        return False
    return holding or u - best > margin or (still is not None and u - zero > still)
