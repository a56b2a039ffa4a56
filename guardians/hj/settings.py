"""The ``hj`` guardian's settings, checked once, and its named presets (``hj``, ``hj-paper``).

:class:`HJSettings` holds every argument of :class:`rmm_guardians.hj.guardian.HJGuardian` (the
meaning of each in :mod:`rmm_guardians.hj.guardian`); a bad value is refused at construction with a
message naming it.  :data:`HJ_PRESETS` names the guardians' defaults: ``HJSettings.preset(
"hj-paper", horizon=2.0)`` is the paper's rule over a shorter horizon.  The guardian's keyword
arguments and ``--agent-opt hj.KEY=VALUE`` build one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from rmm_envs.disturbances import parse_disturbances
from rmm_guardians._checks import Settings, finite, integer
from rmm_guardians.hj.solver import BACKENDS, check_scheme

__all__ = ["HJSettings", "HJ_PRESETS", "MODES", "RULES", "disturbance_setting", "env_disturbance_bound"]

RULES = ("distance", "gradient", "value")
MODES = ("avoid", "reach_avoid")


def disturbance_setting(value) -> float | str:
    """An HJ guardian's ``disturbance``: ``"env"`` (the run's own ``dyn-rate`` bound, read at
    reset) or a bound ``>= 0`` on the position rates; anything else refused, naming it."""
    if isinstance(value, str):
        if value == "env":
            return value
        raise ValueError(f'disturbance must be a finite number >= 0.0 or "env", got {value!r}')
    return finite("disturbance", value, 0.0)


@dataclass(frozen=True)
class HJSettings(Settings):
    """The Dubins4D ``hj`` guardian's settings (normalised).  ``grid`` / ``grid_n``: the grid, or
    its node counts on the default box (at most one; neither: the default grid); ``margin``
    ``None``: half a position cell; ``threads`` ``None``: :func:`rmm_guardians.hj.solver.default_threads`;
    ``maze`` / ``quadrotor``: the arguments of the maze car's / the quadrotor's guardian (a dict;
    ``False`` refuses those envs), checked by the guardian that builds them."""

    grid: Any = None
    grid_n: Any = None
    horizon: float = 4.0
    order: int = 2
    rk: int = 3
    cfl: float = 0.8
    rule: str = "distance"
    margin: float | None = None
    delay: int = 1
    lap: float | None = None
    disturbance: float | str = 0.0  # or "env": the run's dyn-rate bound, read at reset
    cache_dir: Any = None
    cache: bool = True
    cache_max_files: int = 64
    mode: str = "avoid"
    ra_horizon: float = 10.0
    ra_margin: float = 0.5
    backend: str = "auto"
    standstill_lookup: bool = True
    threads: int | None = None
    maze: Any = None
    quadrotor: Any = None

    def __post_init__(self) -> None:
        self._set("standstill_lookup", bool(self.standstill_lookup))
        self._set("horizon", finite("horizon", self.horizon, 0.0, lo_open=True))
        if self.mode not in MODES:
            raise ValueError(f"mode must be 'avoid' or 'reach_avoid', got {self.mode!r}")
        if self.rule not in RULES:
            raise ValueError(f"rule must be one of {RULES}, got {self.rule!r}")
        for name, value in zip(("order", "rk", "cfl"), check_scheme(self.order, self.rk, self.cfl), strict=True):
            self._set(name, value)
        if self.threads is not None:
            self._set("threads", integer("threads", self.threads, 1, "or None"))
        self._set("cache_max_files", integer("cache_max_files", self.cache_max_files, 1))
        self._set("ra_horizon", finite("ra_horizon", self.ra_horizon, 0.0, lo_open=True))
        self._set("ra_margin", finite("ra_margin", self.ra_margin, 0.0))
        self._set("delay", integer("delay", self.delay, 0, "laps between a decision and its effect"))
        if self.lap is not None:
            self._set("lap", finite("lap", self.lap, 0.0, lo_open=True))
        if self.grid is not None and self.grid_n is not None:
            raise ValueError("give grid or grid_n, not both")
        if self.grid_n is not None:
            self._set("grid_n", tuple(int(k) for k in self.grid_n))
        if self.margin is not None:
            self._set("margin", finite("margin", self.margin))
        self._set("disturbance", disturbance_setting(self.disturbance))
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {self.backend!r}")
        self._set("cache", bool(self.cache))


#: The named presets: ``hj`` (ENO2/RK3, take control within the distance two laps cover, the
#: maze car and the quadrotor served) and ``hj-paper`` (the paper's: first order with RK2, take
#: control at ``V <= 0`` with the bang-bang control, no latency allowance, Dubins4D only).
HJ_PRESETS = {
    "hj": HJSettings(),
    "hj-paper": HJSettings(
        order=1, rk=2, rule="value", margin=0.0, standstill_lookup=False, maze=False, quadrotor=False
    ),
}
HJSettings.PRESETS = HJ_PRESETS


def env_disturbance_bound(disturbances) -> float:
    """The bound ``d_max`` of the position-rate disturbance among ``disturbances`` (an env's
    ``privileged()["disturbances"]``, strings): the largest ``dyn-rate`` level acting on ``x`` or
    ``y``, 0 when there is none (impulses and the other kinds are not a bounded rate)."""
    bound = 0.0
    for d in parse_disturbances(list(disturbances)):
        if d.kind == "dyn-rate" and (not d.on or {"x", "y"} & set(d.on)):
            bound = max(bound, d.level)
    return bound
