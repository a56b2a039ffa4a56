"""The ``cbf`` guardian's settings, checked once, and its named presets (``cbf``, ``cbf-paper``).

:class:`CBFSettings` holds every argument of :class:`rmm_guardians.cbf.guardian.CBFGuardian` (the
meaning of each in :mod:`rmm_guardians.cbf`); a bad value is refused at construction with a message
naming it.  :data:`CBF_PRESETS` names the guardians' defaults: ``CBFSettings.preset("cbf-paper",
p1=0.5)`` is the paper's rule with another gain.  The guardian's keyword arguments and
``--agent-opt cbf.KEY=VALUE`` build one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from rmm_envs.systems.dubins4d.dynamics import Dubins4D
from rmm_guardians._checks import Settings, finite, integer, number_pair
from rmm_guardians.cbf.backend import parse_solver

__all__ = ["CBFSettings", "CBF_PRESETS", "REFERENCES", "box_problem"]

#: What the QP keeps the control close to: the driver's ``info["nominal_control"]`` (a safety
#: filter) or, as the paper, a goal-seeking control re-derived from CLF rows.
REFERENCES = ("nominal", "clf")


def box_problem(u1, u2) -> str | None:
    """Why the control box ``u1 x u2`` cannot serve the guardian, or ``None``."""
    if u1[0] <= 0 <= u1[1] and u2[0] < 0 < u2[1]:
        return None
    return "the control box must contain 0 in u1 and allow braking and accelerating in u2"


@dataclass(frozen=True)
class CBFSettings(Settings):
    """The Dubins4D ``cbf`` guardian's settings (normalised: floats, ``(min, max)`` tuples).
    ``maze`` / ``quadrotor``: the arguments of the maze car's / the quadrotor's guardian (a
    dict; ``False`` refuses those envs), checked by the guardian that builds them."""

    p1: float = 0.7535
    p2: float = 0.6664
    inflation: float = 1.05
    gamma_vmin: float = 1.0
    gamma_vmax: float = 1.0
    lambda_theta: float = 1.0
    lambda_v: float = 1.0
    p_theta: float = 1.0
    p_v: float = 1.0
    u1_bounds: Any = None
    u2_bounds: Any = None
    v_bounds: Any = None
    active_atol: float = 1e-3
    active_rtol: float = 0.0
    low_speed_stop: bool = False
    max_obstacles: int = 64
    eps: float = 1e-6
    predict_latency: bool = True
    recovery: bool = True
    v_stuck: float = 0.05
    lap_guess: float = 0.1
    goal_aware_margin: bool = True
    solver: str = "osqp"
    maze: Any = None
    reference: str = "nominal"
    quadrotor: Any = None

    def __post_init__(self) -> None:
        if self.reference not in REFERENCES:
            raise ValueError(
                f"reference must be one of {REFERENCES} (filter the driver's info['nominal_control'], "
                f"or the paper's CLF rows), got {self.reference!r}"
            )
        parse_solver(self.solver)  # a bad name fails here, listing the installed solvers
        for name in ("p1", "p2"):
            self._set(name, finite(f"{name} (class-K gain)", getattr(self, name), 0.0, lo_open=True))
        k = finite("inflation", self.inflation)
        if not k >= 1:
            raise ValueError(f"inflation must be >= 1 (1 = the obstacle itself), got {self.inflation!r}")
        self._set("inflation", k)
        for name in ("gamma_vmin", "gamma_vmax", "lambda_theta", "lambda_v", "p_theta", "p_v", "eps", "lap_guess"):
            self._set(name, finite(name, getattr(self, name), 0.0, lo_open=True))
        for name in ("active_atol", "active_rtol", "v_stuck"):
            self._set(name, finite(name, getattr(self, name), 0.0))
        for name in ("u1_bounds", "u2_bounds", "v_bounds"):
            if getattr(self, name) is not None:
                self._set(name, number_pair(name, getattr(self, name)))
        if self.u1_bounds is not None and box_problem(self.u1_bounds, (-1.0, 1.0)):
            raise ValueError(f"u1_bounds must contain 0, got {self.u1_bounds!r}")
        if self.u2_bounds is not None and box_problem((0.0, 0.0), self.u2_bounds):
            raise ValueError(f"u2_bounds must allow braking and accelerating (min < 0 < max), got {self.u2_bounds!r}")
        self._set("max_obstacles", integer("max_obstacles", self.max_obstacles, 0))
        for name in ("low_speed_stop", "predict_latency", "recovery", "goal_aware_margin"):
            self._set(name, bool(getattr(self, name)))

    @property
    def speed_bounds(self) -> tuple[float, float]:
        """``v_bounds``, or the Dubins4D system's speed range when not given."""
        return (Dubins4D.v_min, Dubins4D.v_max) if self.v_bounds is None else self.v_bounds


#: The named presets: ``cbf`` (latency prediction, recovery, goal-aware margin, filtering the
#: driver's control; the maze car and the quadrotor served) and ``cbf-paper`` (the paper's
#: rule: the CBF-CLF QP at the observed state, maximum braking when infeasible, Dubins4D only).
CBF_PRESETS = {
    "cbf": CBFSettings(),
    "cbf-paper": CBFSettings(
        predict_latency=False, recovery=False, goal_aware_margin=False, maze=False, reference="clf", quadrotor=False
    ),
}
CBFSettings.PRESETS = CBF_PRESETS
