"""``N`` Dubins4D parallel-autonomy worlds as arrays: the native vector env of ``Dubins4DGuarded-v0``.

``gym.make_vec("Dubins4DGuarded-v0", num_envs=N, vectorization_mode="vector_entry_point")``
returns a :class:`Dubins4DCirclesVectorEnv`.  It is ``N`` independent copies of
:class:`rmm_envs.systems.dubins4d.env.Dubins4DGuardedEnv` (whose module docstring is the world's spec:
dynamics, driver, rays, rewards, episode end, starting states, info) stepped together, with
Gymnasium's vector API (``gymnasium.vector.VectorEnv``, gymnasium >= 1.0).

## Equality with the single env

After ``reset(seed=s)``, sub-env ``i`` is exactly the single env after ``reset(seed=s + i)``,
step for step and bit for bit, across autoresets (tested against Gymnasium's
``SyncVectorEnv`` of single envs: observations, rewards, ``terminated``, ``truncated`` and every
info entry), with the same ``disturbances`` too (each sub-env draws its own realisation as the
single env with its seed does; a mismatch, whose plant differs per sub-env, steps row by row).
It holds by construction: each sub-env has its own random generator, seeded as the
single env's, and draws its starts with the single env's own generation code; a step runs the
single env's batched functions (:func:`rmm_envs.systems.dubins4d.step.advance`: the driver's
closed-form QP, the exact path, the contact test; and the ray caster), each a compiled loop whose
result for one world does not depend on the rest of the batch.

## Spaces

``single_observation_space``: the single env's ``Box(17,)`` float32; ``observation_space``:
``Box((N, 17))``.  ``single_action_space``: the single env's ``Dict(active_ctrl=Discrete(2),
turnrate_ctrl=Box(-0.25, 0.25, (1,)), accel_ctrl=Box(-0.5, 0.5, (1,)))``; ``action_space``: its
batch, ``Dict(active_ctrl=MultiDiscrete([2] * N), turnrate_ctrl=Box((N, 1)),
accel_ctrl=Box((N, 1)))``.  An action is a dict of arrays with those keys: ``active_ctrl`` of
``N`` zeros and ones (``(N,)`` or ``(N, 1)``), the continuous fields of ``N`` numbers (``(N,)``
or ``(N, 1)``), clipped to their bounds as in the single env.  A missing or unknown key, a wrong
shape, a non-numeric or non-finite value or an ``active_ctrl`` other than 0/1 raises
``ValueError`` naming the field and the first bad sub-env.

## Autoreset

``autoreset_mode`` (an argument; also ``metadata["autoreset_mode"]``):

* ``AutoresetMode.NEXT_STEP`` (the default, as Gymnasium's own vector envs): a sub-env whose
  episode ended is reset by the *next* ``step``, which ignores its action and returns its first
  observation with reward 0, ``terminated = truncated = False`` and the reset info.
* ``AutoresetMode.SAME_STEP``: it is reset within the step that ended it; the returned
  observation is the new episode's first, and the info carries ``final_obs`` and ``final_info``
  (the ended episode's last observation and step info).
* ``AutoresetMode.DISABLED``: never reset automatically; ``reset(options={"reset_mask": m})``
  resets the sub-envs where the boolean ``(N,)`` array ``m`` is true.  Stepping a sub-env whose
  episode ended raises ``RuntimeError`` naming it.

A reset after the first draws from each sub-env's generator, so sub-env ``i``'s episodes are the
single env's successive episodes after ``reset(seed=s + i)``.  ``reset(seed=None)`` seeds every
generator not yet seeded from fresh entropy and keeps the others; ``seed`` may also be a list of
``N`` ints (or ``None``).  ``options`` (``state``, ``goal``, ``obstacles``, as the single env's,
plus ``reset_mask``) apply to every sub-env reset by that call; given ``obstacles`` must number
``n_obstacles`` here (all worlds of a batch hold the same number of circles).

## Infos

Dicts of arrays, Gymnasium's convention: each key ``k`` has an ``(N, ...)`` array and a boolean
mask ``_k`` telling which sub-envs have it.  Every step (and ``reset``): ``sim_time`` ``(N,)``,
``state`` ``(N, 4)`` (privileged: the true state) and ``nominal_control`` ``(N, 2)`` (the
driver's control at the state the returned observation shows, the single env's); ``active``
``(N,)``, ``control`` ``(N, 2)`` and ``cost`` ``(N,)`` (1.0 on a collision, else 0.0) for the
sub-envs that stepped (not those being reset in ``NEXT_STEP`` mode); for the sub-envs whose
episode ended, ``outcome`` (object array of ``"goal"``/``"collision"``/``"timeout"``) and
``episode_stats`` (a dict of arrays of the single env's episode statistics, with its own
masks).  ``episode`` is left to Gymnasium's ``RecordEpisodeStatistics`` (tested, with
``NormalizeObservation`` on top).

## Compute time and clock

``clock`` is as the single env's (``"wall"`` by default, ``"cpu"``, ``"fixed:MS"`` or a
:class:`rmm_envs.clocks.Clock`): the time from the end of one call to the start of the next
``step`` is the agent's, and is charged to every sub-env that steps (one agent decided for all
of them).  With ``"fixed:MS"`` the statistics equal the single env's under the same clock.

## Arguments

``Dubins4DCirclesVectorEnv(num_envs, autoreset_mode=AutoresetMode.NEXT_STEP, clock=None,
**kwargs)`` where ``kwargs`` are the single env's arguments (``step_dt``, ``n_rays``,
``n_obstacles``, ``driver_params``, ...; same defaults, same validation).  Not supported here:
``render_mode`` other than ``None`` (render one single env instead) and ``driver_solver="osqp"``
(OSQP keeps state between solves and solves one world at a time; the exact closed form is the
one batched solver).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from rmm_envs.autonomy import GuardianActionSpace
from rmm_envs.clocks import make_clock
from rmm_envs.disturbances import Realisation
from rmm_envs.disturbances.rows import RowStreams, observation_rows
from rmm_envs.systems.dubins4d.circles import ray_cast_each
from rmm_envs.systems.dubins4d.env import Dubins4DGuardedEnv
from rmm_envs.systems.dubins4d.plant import plant_model
from rmm_envs.systems.dubins4d.scene import observation
from rmm_envs.systems.dubins4d.step import advance, nominal_controls
from rmm_envs.systems.dubins4d.vector_disturbances import advance_disturbed
from rmm_envs.systems.dubins4d.vector_info import _masked, reset_info
from rmm_envs.systems.dubins4d.vector_info import ended_info as vector_ended_info

__all__ = ["Dubins4DCirclesVectorEnv"]


class Dubins4DCirclesVectorEnv(VectorEnv):
    """``num_envs`` Dubins4D parallel-autonomy worlds as arrays; see the module docstring."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        clock=None,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        try:
            autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ValueError(
                f"autoreset_mode must be one of {[m.value for m in AutoresetMode]}, got {autoreset_mode!r}"
            ) from None
        if render_mode is not None:
            raise ValueError(
                f"render_mode must be None for the vector env (render a single env instead), got {render_mode!r}"
            )
        if kwargs.get("driver_solver", "closed_form") != "closed_form":
            raise ValueError(
                f"driver_solver must be 'closed_form' in the vector env (the batched exact solver), "
                f"got {kwargs['driver_solver']!r}"
            )
        self.num_envs = int(num_envs)
        self.autoreset_mode = autoreset_mode
        self.metadata = {**self.metadata, "autoreset_mode": autoreset_mode}
        self.render_mode = None
        # One single env holds the configuration (validated there), the spaces, the driver and
        # the generation code; it is never stepped.
        self._single = Dubins4DGuardedEnv(**kwargs)
        self.clock = make_clock(clock)
        self.single_observation_space = self._single.observation_space
        self.single_action_space = self._single.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

        n, k = self.num_envs, self._single.n_obstacles
        self._rngs: list[np.random.Generator | None] = [None] * n
        self._states = np.zeros((n, 4))
        self._circles = np.zeros((n, k + 1, 3))  # obstacles, then the goal
        self._sim_time = np.zeros(n)
        self._n_steps = np.zeros(n, dtype=np.int64)
        self._n_active = np.zeros(n, dtype=np.int64)
        self._active_time = np.zeros(n)
        self._cum_compute = np.zeros(n)
        self._cum_reward = np.zeros(n)
        self._cum_cost = np.zeros(n)
        self._nominal = np.zeros((n, 2))  # the driver's control at each state (info["nominal_control"])
        self._ended = np.zeros(n, dtype=bool)  # the episode ended at the last step
        obs_shape = self._single.observation_space.shape
        assert obs_shape is not None  # the single env's observation space is a Box
        self._obs = np.zeros((n, obs_shape[0]), dtype=np.float32)
        self._started = False
        # disturbances: each sub-env draws as the single env with its seed would (its seed, then
        # how many episodes since), its own plant and gains under a mismatch
        self._seeds: list[tuple[int, int]] = [(0, 0)] * n
        self._draws: list[Realisation | None] = [None] * n
        self._plants = [self._single.dynamics] * n
        self._gains = np.ones((n, 2))
        self._streams = RowStreams(n)  # each sub-env's current block of its white-noise streams
        self._moves_plant = getattr(self._single.disturbance_plan, "moves_plant", False)  # else sensors alone

    # ------------------------------------------------------------------ observations
    def _observe(self, idx=slice(None)) -> np.ndarray:
        """Observations of sub-envs ``idx``: the single env's, each world with its own circles."""
        st = self._states[idx]
        circles = self._circles[idx]
        e = self._single
        rays = ray_cast_each(st[:, :2], st[:, 2], circles[:, :-1], e.n_rays, e.ray_length)
        obs = observation(st, self._sim_time[idx], circles[:, -1, :2], rays)
        if e.disturbances:  # what each sub-env's sensors report
            rows = np.arange(self.num_envs)[idx]
            obs = observation_rows([self._draws[i] for i in rows], obs, self._sim_time[rows], self._streams, rows)
        return obs

    # ------------------------------------------------------------------ reset
    def _reset_one(self, i: int, options: dict | None) -> None:
        e = self._single
        rng = self._rngs[i]
        assert rng is not None  # reset seeds sub-env i before resetting it
        obstacles, state, goal = e.generate_start(rng, options)
        self._check_start(obstacles, state, goal)
        self._states[i] = state
        self._circles[i, :-1] = obstacles
        self._circles[i, -1] = goal
        self._sim_time[i] = 0.0
        self._n_steps[i] = 0
        self._n_active[i] = 0
        self._active_time[i] = 0.0
        self._cum_compute[i] = 0.0
        self._cum_reward[i] = 0.0
        self._cum_cost[i] = 0.0
        self._ended[i] = False
        if e.disturbances:
            base, count = self._seeds[i]
            plan = e.disturbance_plan
            assert plan is not None  # set with the disturbances
            key = (base,) if count == 0 else (base, count)
            self._draws[i] = draw = Realisation(plan.disturbances, plan.support, key, plan)
            self._streams.forget(i)
            self._seeds[i] = (base, count + 1)
            mismatch = any(d.kind == "mismatch" for d in e.disturbances)
            self._plants[i], self._gains[i] = plant_model(e.dynamics, dict(draw.parameters) if mismatch else None)

    def _check_start(self, obstacles, state, goal) -> None:
        k = self._single.n_obstacles
        if obstacles.shape[0] != k:
            raise ValueError(
                f"option 'obstacles' must hold n_obstacles = {k} circles in the vector env "
                f"(every world of a batch has as many), got {obstacles.shape[0]}"
            )

    def reset(self, *, seed: int | list | None = None, options: dict[str, Any] | None = None):
        """Reset every sub-env (or those of ``options["reset_mask"]``); see the module docstring."""
        n = self.num_envs
        seeds: list[int | None]
        if seed is None:
            seeds = [None] * n
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            super().reset(seed=int(seed))  # the vector env's own np_random (unused by the worlds)
            seeds = [int(seed) + i for i in range(n)]
        elif isinstance(seed, (list, tuple)) and len(seed) == n:
            seeds = list(seed)
        else:
            raise ValueError(f"seed must be None, an int or a list of {n} ints or None, got {seed!r}")
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if mask is None:
            idx = np.arange(n)
        else:
            if not (isinstance(mask, np.ndarray) and mask.dtype == np.bool_ and mask.shape == (n,)):
                raise ValueError(f"options['reset_mask'] must be a numpy bool array of shape ({n},), got {mask!r}")
            if not mask.any():
                raise ValueError("options['reset_mask'] must select at least one sub-env, got none")
            if not self._started and not mask.all():
                raise ValueError("the first reset must reset every sub-env; options['reset_mask'] selects only some")
            idx = np.nonzero(mask)[0]
        if options:  # bad options fail before any sub-env changes (a dry run on a throwaway generator)
            self._check_start(*self._single.generate_start(np.random.default_rng(0), options))
        for i in idx:
            if seeds[i] is not None or self._rngs[i] is None:
                self._rngs[i], used = seeding.np_random(seeds[i])
                self._seeds[i] = (int(used) & 0xFFFF_FFFF_FFFF_FFFF, 0)
            self._reset_one(int(i), options or None)
        self._started = True
        self._obs = self._obs.copy()  # the array returned earlier stays as it was
        self._obs[idx] = self._observe(idx)
        self._update_nominal(idx)
        self.clock.start()
        return self._obs, reset_info(self, idx)

    # ------------------------------------------------------------------ actions
    def _parse_actions(self, actions) -> tuple[np.ndarray, np.ndarray]:
        """Validate a batched guardian action; ``(active (N,) bool, controls (N, 2) clipped)``."""
        space = self.single_action_space
        assert isinstance(space, GuardianActionSpace)  # the single env's action space
        return space.parse_batch(actions, self.num_envs, self.action_space)

    # ------------------------------------------------------------------ step
    def step(self, actions):
        """Step every sub-env (resetting those due, per ``autoreset_mode``); the usual 5-tuple of arrays."""
        compute = self.clock.elapsed()
        if not self._started:
            raise RuntimeError("call reset() before step()")
        active, ctrl = self._parse_actions(actions)
        n, e = self.num_envs, self._single
        mode = self.autoreset_mode
        if mode == AutoresetMode.DISABLED and self._ended.any():
            i = int(np.argmax(self._ended))
            raise RuntimeError(
                f"sub-env {i}'s episode has ended and autoreset_mode is DISABLED: reset it first "
                "with reset(options={'reset_mask': mask})"
            )
        # Every world is advanced, those about to be reset too (NEXT_STEP: their episode ended at
        # the last step): one pass over whole arrays, no gathers; what the resetting ones
        # computed is discarded and their bookkeeping restarts in _reset_one.
        resetting = self._ended if mode == AutoresetMode.NEXT_STEP else np.zeros(n, dtype=bool)
        any_resetting = bool(resetting.any())
        if self._moves_plant:  # sensors alone disturbed: the plant steps as undisturbed
            nxt, u, hit_obst, hit_goal = advance_disturbed(self, active, ctrl)
        else:
            nxt, u, hit_obst, hit_goal = advance(
                e.dynamics, self._nominal, self._states, self._circles, active, ctrl, e._step_times
            )
        dt = e.step_dt
        self._n_steps += 1
        self._n_active += active
        self._active_time += np.where(active, dt, 0.0)
        self._cum_compute += compute
        self._sim_time += dt
        self._states = nxt
        collision = np.isfinite(hit_obst) & (hit_obst <= hit_goal)
        goal = ~collision & np.isfinite(hit_goal)
        rewards = np.where(collision, -1.0, np.where(goal, 1.0, 0.0))
        self._cum_reward += rewards
        cost = collision.astype(float)
        self._cum_cost += cost
        truncated = self._sim_time >= e.max_episode_sim_time - 1e-9
        if any_resetting:
            stepping = ~resetting
            collision &= stepping
            goal &= stepping
            rewards[resetting] = 0.0
            cost[resetting] = 0.0
            truncated &= stepping
            active = active & stepping
            u[resetting] = 0.0
        else:
            stepping = np.ones(n, dtype=bool)
        terminated = collision | goal
        truncated &= ~terminated
        ended = terminated | truncated
        control, act_all, coll_all, goal_all = u, active, collision, goal
        infos = {
            "sim_time": self._sim_time.copy(),
            "_sim_time": np.ones(n, dtype=bool),
            "state": self._states.copy(),
            "_state": np.ones(n, dtype=bool),
            "active": act_all,
            "_active": stepping.copy(),
            "control": control,
            "_control": stepping.copy(),
            "cost": cost,
            "_cost": stepping.copy(),
        }
        any_ended = bool(ended.any())
        if any_ended:
            ended_info = vector_ended_info(self, ended, coll_all, goal_all)

        if resetting.any():  # NEXT_STEP: sub-envs whose episode ended at the last step
            ridx = np.nonzero(resetting)[0]
            for i in ridx:
                self._reset_one(int(i), None)
            infos["sim_time"][ridx] = 0.0
            infos["state"][ridx] = self._states[ridx]
        obs = self._observe()
        self._update_nominal()
        infos["nominal_control"], infos["_nominal_control"] = self._nominal.copy(), np.ones(n, dtype=bool)
        if mode == AutoresetMode.SAME_STEP:
            if any_ended:
                ended_idx = np.nonzero(ended)[0]
                final_obs = np.full(n, None, dtype=object)
                for i in ended_idx:
                    final_obs[i] = obs[i].copy()
                final_info = {
                    k: (_masked(v, ended) if not k.startswith("_") else v & ended) for k, v in infos.items()
                } | ended_info
                for key in ("active", "control", "cost"):  # now in final_info: absent (zero, unmasked) at the top
                    infos[f"_{key}"] = infos[f"_{key}"] & ~ended
                    infos[key] = _masked(infos[key], ~ended)
                for i in ended_idx:
                    self._reset_one(int(i), None)
                infos["sim_time"][ended_idx] = 0.0
                infos["state"][ended_idx] = self._states[ended_idx]
                obs[ended_idx] = self._observe(ended_idx)
                self._update_nominal(ended_idx)
                infos["nominal_control"][ended_idx] = self._nominal[ended_idx]
                infos.update(
                    {
                        "final_obs": final_obs,
                        "_final_obs": ended.copy(),
                        "final_info": final_info,
                        "_final_info": ended.copy(),
                    }
                )
            self._ended[:] = False
        else:
            if any_ended:
                infos.update(ended_info)
            self._ended = ended
        for key in ("active", "control", "cost"):  # a key no sub-env has is absent, as in Gymnasium's own vector envs
            if not infos[f"_{key}"].any():
                del infos[key], infos[f"_{key}"]
        self._obs = obs  # a fresh array every step, never written to afterwards: no copy needed
        self.clock.start()
        return obs, rewards, terminated, truncated, infos

    def _update_nominal(self, idx=slice(None)) -> None:
        """The driver's control at the states of sub-envs ``idx`` (kept in ``_nominal``: what an
        interval the driver controls applies)."""
        self._nominal[idx] = nominal_controls(self._single.driver, self._states[idx], self._circles[idx])

    def close_extras(self, **kwargs: Any) -> None:
        self._single.close()
