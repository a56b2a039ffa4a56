"""What an env does to take disturbances: :class:`Disturbable`, mixed into the guarded envs.

An env declares what it offers (:meth:`Disturbable.disturbance_support`: its observation's
fields, its control's bounds, the state components a rate disturbance adds to, the plant's
parameters a mismatch scales), checks the ``disturbances`` argument once when it is made, draws
one :class:`~rmm_envs.disturbances.Realisation` per episode at ``reset`` from the episode's seed
(never from the env's generator, so the start, the world and the driver draw exactly as they do
undisturbed), and routes three things through it: the observation it returns (:meth:`sensed`),
the control the plant applies (:meth:`actuated`) and the state's rates (:meth:`drift`).  With no
disturbance every one of these returns its input untouched, so an undisturbed episode is the
same bits as an env without this mixin.
"""

from __future__ import annotations

from collections.abc import Mapping

import gymnasium as gym
import numpy as np

from rmm_envs.autonomy import ObservationLayout
from rmm_envs.disturbances.realisation import Plan, Realisation
from rmm_envs.disturbances.spec import Disturbance, SystemSupport, parse_disturbances

__all__ = ["Disturbable"]


class Disturbable:
    """The disturbance hooks of an env (see the module docstring)."""

    #: the state components a rate disturbance (``dyn-rate``, ``impulse``) adds to: name -> index
    disturbance_rates: Mapping[str, int] = {}
    #: the disturbances this env applies (none by default)
    disturbances: tuple[Disturbance, ...] = ()
    _realisation: Realisation | None = None
    _disturbance_seed: tuple[int, int] | None = None
    _dist_plan: Plan | None = None

    def disturbance_parameters(self) -> dict[str, float]:
        """The plant's nominal parameters a ``mismatch`` may scale (none by default)."""
        return {}

    def disturbance_dt(self) -> float:
        """The sim-time step the disturbances are indexed by (the env's fixed step)."""
        return float(getattr(self, "step_dt", 0.1))

    def disturbance_support(self) -> SystemSupport:
        """What this env offers disturbances, from its spaces and declarations."""
        obs_space = getattr(self, "observation_space", None)
        layout = getattr(obs_space, "layout", None)
        if layout is None and isinstance(obs_space, gym.spaces.Box) and len(obs_space.shape) == 1:
            layout = ObservationLayout.of(("obs", obs_space.shape[0]))  # a plain vector: one field
        act = getattr(self, "action_space", None)
        low, high = getattr(act, "control_low", None), getattr(act, "control_high", None)
        return SystemSupport(
            dt=self.disturbance_dt(),
            horizon=float(getattr(self, "max_episode_sim_time", 100.0)),
            layout=layout,
            obs_high=None if layout is None else np.asarray(obs_space.high, float),  # type: ignore[union-attr]
            action_low=None if low is None else np.asarray(low, float),
            action_high=None if high is None else np.asarray(high, float),
            rates=dict(self.disturbance_rates),
            parameters=self.disturbance_parameters(),
            system=type(self).__name__,
        )

    def set_disturbances(self, spec) -> None:
        """Read and check ``spec`` (the env's ``disturbances`` argument) against this env: one
        line naming what is wrong (:class:`~rmm_envs.disturbances.DisturbanceError`) when it
        cannot be applied.  Call it once the spaces are set."""
        found = parse_disturbances(spec)
        self._dist_plan = Plan(found, self.disturbance_support()) if found else None
        self.disturbances = found

    def start_disturbances(self, seed: int | None) -> None:
        """Draw this episode's realisation (call at ``reset``, with ``reset``'s seed): from the seed
        when one is given, else from the last seed and the number of episodes since."""
        if not self.disturbances:
            self._realisation = None
            return
        if seed is not None:
            self._disturbance_seed = (int(seed), 0)
        elif self._disturbance_seed is None:
            self._disturbance_seed = (int(getattr(self, "np_random_seed", 0)) & 0xFFFF_FFFF_FFFF_FFFF, 0)
        else:
            base, count = self._disturbance_seed
            self._disturbance_seed = (base, count + 1)
        base, count = self._disturbance_seed
        plan = self._dist_plan
        assert plan is not None  # set with the disturbances
        self._realisation = Realisation(plan.disturbances, plan.support, (base,) if count == 0 else (base, count), plan)

    @property
    def disturbance_plan(self) -> Plan | None:
        """What this env's disturbances do, worked out when it was made (``None``: none)."""
        return self._dist_plan

    @property
    def realisation(self) -> Realisation | None:
        """This episode's draw of the disturbances (``None`` when there are none)."""
        return self._realisation

    def sensed(self, obs: np.ndarray, t: float) -> np.ndarray:
        """The observation the sensors report at sim time ``t`` (``obs`` itself when undisturbed)."""
        r = self._realisation
        return obs if r is None or not r.senses else r.observation(obs, t)

    @property
    def moves_plant(self) -> bool:
        """Whether this episode's plant is disturbed (its control, its rates or its parameters):
        ``False`` when only the sensors are, or nothing is."""
        r = self._realisation
        return r is not None and (r.actuates or r.pushes or bool(r.plan.mismatch))

    def actuated(self, u: np.ndarray, t: float) -> np.ndarray:
        """The control the actuators apply at sim time ``t`` when ``u`` is commanded (``u`` itself
        when undisturbed)."""
        r = self._realisation
        if r is None or not r.actuates:
            return u
        return r.control(u, t)

    def drift(self, t: float, dim: int) -> np.ndarray | None:
        """The additive state-rate disturbance at sim time ``t`` (``None`` when there is none)."""
        r = self._realisation
        if r is None or not r.pushes:
            return None
        return r.rate(t, dim)

    def plant_parameters(self) -> dict[str, float] | None:
        """This episode's plant parameters under a mismatch (``None`` when the plant is nominal)."""
        r = self._realisation
        if r is None or not any(d.kind == "mismatch" for d in r.disturbances):
            return None
        return dict(r.parameters)
