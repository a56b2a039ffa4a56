"""Dubins4D on a map of your own: shapes from JSON, rays and collisions answered by pymunk.

``Dubins4DMapGuarded-v0`` (blocking, fixed step) and ``Dubins4DMapParallel-v0`` (non-blocking: the
guardian's thinking time passes in the world): the parallel-autonomy world of
``Dubins4DGuarded-v0`` (same car, reckless driver, guardian action, observation, rewards and
statistics) among obstacles you draw, with the optional extra ``rmm-envs[map]`` (pymunk).

## Description

``gym.make("Dubins4DMapGuarded-v0", map="my_map.json")`` (or ``map=`` the list already loaded):
the car drives from a start in the map's start box toward a goal disc; a built-in reckless
driver (:class:`rmm_envs.systems.dubins4d.driver.CLFDriver`) steers it to the goal's centre and ignores the
obstacles; the agent is a *guardian* that decides at each step whether to take control.
Everything but the world is :class:`rmm_envs.systems.dubins4d.env.Dubins4DGuardedEnv`'s (this env is
its subclass): read that spec for the parts only summarised here.  Without ``map`` the example
shipped in ``rmm_envs/assets/maps/example.json`` is used (two circles, an L-shaped and a
triangular polygon, two walls, in ``[-10, 10]^2``).

## Map format

A JSON list of entries, each an object with one key:

| entry | meaning |
|-------|---------|
| ``{"circle": [x, y, r]}`` | a disc, ``r > 0`` |
| ``{"polygon": [[x, y], ...]}`` | a simple polygon (below) |
| ``{"segment": [[x0, y0], [x1, y1], thickness]}`` | a wall (below) |
| ``{"goal": [x, y, r]}`` | optional, at most one: a fixed goal disc (else drawn each episode) |
| ``{"start": [[x_min, y_min], [x_max, y_max]]}`` | optional, at most one: where starts (and drawn goals) are drawn |

A polygon has >= 3 vertices, either orientation, convex or not; its edges may not cross or touch
(except neighbours at their shared vertex); a closing vertex equal to the first is dropped.  A
wall is every point within ``thickness / 2`` (``> 0``) of its segment (rounded ends).  The start
box defaults to the bounding box of every other entry.

Or an object ``{"shapes": [...obstacle entries...], "goal": [...], "start": [...]}`` meaning the
same.  At least one obstacle is required, every number must be finite and at most 1e9 in
magnitude (larger ones overflow the geometry), a file holds at most 16 MiB and a polygon at most
5,000 vertices, and obstacles may overlap.  A bad map (an unknown shape, a self-intersecting polygon, NaN or infinity, a wrong
number of values, no obstacle, an unreadable or non-JSON file) raises one
``rmm_envs.systems.dubins4d_map.shape_map.MapError`` (a ``ValueError``) naming the entry by its index and its
content, e.g. ``map 'my_map.json', entry 3 {"polygon": ...}: edges 0 (...) and 2 (...) cross or
touch; a polygon must be simple``.  A walk-through: ``docs/tutorials/own-map.md``.

## Dynamics

Those of ``Dubins4DGuarded-v0``: state ``(x, y, theta, v)``, ``x' = v cos theta, y' = v sin
theta, theta' = u1, v' = u2``, ``v`` held in ``[0, 2]`` m/s, exact zero-order-hold steps.
Nothing bounds the plane: leaving the start box is allowed.

## Action space

``Dict(active_ctrl=Discrete(2), turnrate_ctrl=Box(-0.25, 0.25, (1,)), accel_ctrl=Box(-0.5, 0.5,
(1,)))``, as for ``Dubins4DGuarded-v0`` (out-of-bound controls clipped, malformed actions
refused).  Its ``obstacle_shapes`` lists the map's obstacle shapes: the privileged guardians
``cbf`` and ``hj`` model circles only, so their ``check_spaces`` refuse a map with polygons or
segments (naming them) and run on a map of circles only.

## Observation space

``Box(5 + n_rays,)`` float32, the table of ``Dubins4DGuarded-v0``: simulated time, goal offset
``(x, y)``, heading in ``[-pi, pi)``, speed, then ``n_rays`` ray lengths in ``[0, ray_length]``
(ray ``i`` at ``theta + 2 pi i / n_rays``).  Rays see every obstacle of the map (pymunk
``segment_query_first``), are capped at ``ray_length`` and read 0 from inside an obstacle.

## Rewards

``+1`` on reaching the goal, ``-1`` on collision, ``0`` otherwise.  Contacts are checked along
the step's whole path (``n_path_points`` points and the segments between them): obstacles by
pymunk queries (the first point's ``point_query_nearest``, then ``segment_query_first`` along
each segment, giving the exact first contact), the goal disc analytically; the first contact
wins and a tie is a collision.  On a map of circles only, rays and contacts agree with
``Dubins4DGuarded-v0`` given the same obstacles to rounding (tested to 1e-4).

## Episode end

``terminated`` on goal or collision; ``truncated`` at ``max_episode_sim_time`` (100 s).

## Starting state

In order, from the seed: the vehicle, position uniform on the start box, heading
``U(-pi, pi)``, speed ``U(0, 2)``, redrawn while inside an obstacle (boundary included) or the
goal (when the goal is fixed); then, without a fixed goal, the goal, centre uniform on the
start box and radius ``U(goal_min_rad, goal_max_rad)``, redrawn while it holds the vehicle or
its centre is inside an obstacle (the driver steers to the centre, so it must be free).

``reset(seed=..., options={"state": [x, y, theta, v], "goal": [x, y, r]})`` sets either
explicitly (a given goal replaces the map's), the rest is drawn around it by the same rules.  A
given state inside an obstacle or the goal, a goal centre inside an obstacle, a speed outside
``[0, 2]``, a radius <= 0, non-finite numbers, wrong lengths and unknown keys raise
``ValueError`` naming the option.  After 100,000 rejected draws (a start box with no free room)
a ``ValueError`` says so.  The map's own goal is checked when the env is built.

## Risk labelling

:class:`rmm_envs.risk.LabelledEnv`: ``risk_scene()`` is the episode's
:class:`rmm_envs.systems.dubins4d_map.scene.Dubins4DMapScene` (whose pymunk world the env's own checks
use); ``sample_states`` draws uniformly over the start box x ``[-pi, pi)`` x ``[0, 2]``,
rejecting states inside an obstacle; ``observe_states`` draws the time feature uniformly on
``[0, max_episode_sim_time]``.  ``RiskLabel`` and ``rmm-datagen --env Dubins4DMapGuarded-v0`` work
unchanged (every configuration of a dataset is the same map; episodes differ in goal).

## Info

As ``Dubins4DGuarded-v0``: every step ``sim_time``, ``state`` (privileged), ``active``,
``control``, ``cost`` and ``nominal_control`` (the driver's control, also on ``reset``); on
the last step ``outcome`` and ``episode_stats``.  :meth:`Dubins4DMapEnv.privileged`
returns ``state``, ``goal``, ``sim_time``, ``obstacles`` (the map's circles ``(K, 3)``: all of
its obstacles only on a map of circles only) and ``map`` (the map's entries, as JSON data).

## Arguments

``gym.make("Dubins4DMapGuarded-v0", map=None, step_dt=0.1, n_rays=12, ray_length=10.0,
max_episode_sim_time=100.0, goal_min_rad=0.1, goal_max_rad=1.0, n_path_points=16,
driver_params=None, clock=None, render_mode=None, driver_solver="closed_form", disturbances=None)``
(``disturbances`` as in Dubins4DGuarded-v0); ``map`` is a
path to a JSON file, the list (or object) already loaded, or ``None`` for the example; the
other arguments and their defaults are ``Dubins4DGuarded-v0``'s (the paper's).  The map is
parsed and its pymunk space built once, at construction.

``gym.make("Dubins4DMapParallel-v0", time_accel=10.0, base_step=0.1, clock=None, **same but step_dt)``:
the same world under :class:`rmm_envs.wrappers.NonBlockingStepping` (each ``step(a)``
advances ``elapsed * time_accel + base_step`` simulated seconds under the previous action), so
``rmm-bench --env Dubins4DMapParallel-v0`` runs guardians on the example map.  For your own
map with ``rmm-bench``, register an id in a module that ``--agent module:Class`` imports:
``gym.register("MyMap-v0", entry_point="rmm_envs.systems.dubins4d_map.env:parallel_env",
kwargs={"map": "my_map.json"})``.

## Speed

A step costs a few pymunk queries (one bounding-box query skips a path far from every
obstacle; rays need up to ``n_rays`` segment queries), so it is slower than the compiled
circle kernels of ``Dubins4DGuarded-v0``: about 2.8-2.9x its step time on the example map and 2.4-2.6x
on a map of its five circles, and about 2x its time per risk label (``benchmarks/perf_map.py``,
CPU time, both envs in one run: ratios, not timings).

## Rendering

``render_mode="rgb_array"``: a 512x512 top-down frame of the square around the map and its
start box (outlined): obstacles red, goal green (with a ring), rays grey, the vehicle blue
(driver) or orange (guardian).  ``"human"`` shows it with pygame (extra ``rmm-envs[human]``).
"""

from __future__ import annotations

from importlib import resources

import numpy as np

from rmm_envs.autonomy import GuardianActionSpace
from rmm_envs.catalog import system
from rmm_envs.envs import _render
from rmm_envs.envs.base import draw_until, option_vector, rejection_sample
from rmm_envs.envs.guarded import parallel_twin
from rmm_envs.systems.dubins4d.dynamics import wrap_angle
from rmm_envs.systems.dubins4d.env import CONTROLS, DYNAMICS_NAME, Dubins4DGuardedEnv
from rmm_envs.systems.dubins4d.starts import in_goal
from rmm_envs.systems.dubins4d_map.pymunk_world import PymunkWorld
from rmm_envs.systems.dubins4d_map.scene import Dubins4DMapScene
from rmm_envs.systems.dubins4d_map.shape_map import MapError, ShapeMap, load_map

__all__ = ["Dubins4DMapEnv", "example_map_path", "parallel_env"]


def example_map_path() -> str:
    """The path of the example map shipped with the package (``assets/maps/example.json``)."""
    return str(resources.files("rmm_envs") / "assets" / "maps" / "example.json")


class Dubins4DMapEnv(Dubins4DGuardedEnv):
    """Blocking Dubins4D parallel-autonomy env on a map; see the module docstring for the spec."""

    reset_options = ("state", "goal")
    #: a start box with this many rejected draws in a row leaves no room (a vehicle draw lands
    #: outside the obstacles about half the time on the example map)
    _MAX_DRAWS = 100_000

    def __init__(
        self,
        map: str | list | dict | ShapeMap | None = None,
        step_dt: float = 0.1,
        n_rays: int = 12,
        ray_length: float = 10.0,
        max_episode_sim_time: float = 100.0,
        goal_min_rad: float = 0.1,
        goal_max_rad: float = 1.0,
        n_path_points: int = 16,
        driver_params=None,
        clock=None,
        render_mode: str | None = None,
        driver_solver: str = "closed_form",
        disturbances=None,
    ) -> None:
        super().__init__(
            step_dt=step_dt,
            n_rays=n_rays,
            ray_length=ray_length,
            max_episode_sim_time=max_episode_sim_time,
            n_obstacles=0,
            goal_min_rad=goal_min_rad,
            goal_max_rad=goal_max_rad,
            n_path_points=n_path_points,
            driver_params=driver_params,
            clock=clock,
            render_mode=render_mode,
            driver_solver=driver_solver,
            disturbances=disturbances,
        )
        self.map = load_map(example_map_path() if map is None else map)
        self.world = PymunkWorld(self.map)
        self.n_obstacles = len(self.map.entries)
        if self.map.goal is not None:
            self._check_goal(self.map.goal, f"map {self.map.source}: its goal")
        self._obstacle_contact = self.world.first_contacts
        self.action_space = GuardianActionSpace.for_dynamics(
            self.dynamics,
            CONTROLS,
            safe_default=system("Dubins4DMap").make_safe_default(),
            obstacle_shapes=self.map.obstacle_shapes,
            dynamics_name=DYNAMICS_NAME,
        )

    # ------------------------------------------------------------------ starts
    def _check_goal(self, goal: np.ndarray, what: str) -> None:
        if self.world.points_inside(goal[None, :2])[0]:
            raise (MapError if what.startswith("map") else ValueError)(
                f"{what} {goal.tolist()} has its centre inside an obstacle of the map; the driver steers to the "
                "centre, so it must be free"
            )

    def _draw_state(self, rng: np.random.Generator, goal: np.ndarray | None) -> np.ndarray:
        assert self.map.start_box is not None  # load_map sets it (the bounding box when the map gives none)
        (x0, y0), (x1, y1) = self.map.start_box
        s = self.dynamics
        st = draw_until(
            lambda: np.array(
                [rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(-np.pi, np.pi), rng.uniform(s.v_min, s.v_max)]
            ),
            lambda st: not (self.world.points_inside(st[None, :2])[0] or (goal is not None and in_goal(st, goal))),
            self._MAX_DRAWS,
        )
        if st is None:
            raise ValueError(
                f"could not draw a start in the start box {self.map.start_box.tolist()} outside the obstacles"
                f"{' and the goal' if goal is not None else ''} in {self._MAX_DRAWS} draws: the box leaves "
                "too little free room; give a larger 'start' box or reset option 'state'"
            )
        return st

    def _draw_goal(self, rng: np.random.Generator, state: np.ndarray) -> np.ndarray:
        assert self.map.start_box is not None  # load_map sets it (the bounding box when the map gives none)
        (x0, y0), (x1, y1) = self.map.start_box
        g = draw_until(
            lambda: np.array([rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(*self.goal_rad)]),
            lambda g: not in_goal(state, g) and not self.world.points_inside(g[None, :2])[0],
            self._MAX_DRAWS,
        )
        if g is None:
            raise ValueError(
                f"could not place a goal in the start box {self.map.start_box.tolist()} in {self._MAX_DRAWS} draws; "
                "give one in the map or as reset option 'goal'"
            )
        return g

    def generate_start(self, rng: np.random.Generator, options: dict | None = None):
        """``(map, state, goal)`` of a new episode: the options checked, the rest drawn (see the spec)."""
        options = self.check_options(options)
        state = goal = None
        if "goal" in options:
            goal = option_vector(options["goal"], 3, "goal", " [x, y, r]")
            if goal[2] <= 0:
                raise ValueError(f"option 'goal': radius must be > 0, got {goal[2]}")
            self._check_goal(goal, "option 'goal'")
        elif self.map.goal is not None:
            goal = self.map.goal.copy()
        if "state" in options:
            state = option_vector(options["state"], 4, "state", " [x, y, theta, v]")
            if not (self.dynamics.v_min <= state[3] <= self.dynamics.v_max):
                raise ValueError(
                    f"option 'state': speed must be in [{self.dynamics.v_min}, {self.dynamics.v_max}], got {state[3]}"
                )
            state[2] = wrap_angle(state[2])
            if self.world.points_inside(state[None, :2])[0]:
                raise ValueError(f"option 'state': position {state[:2].tolist()} is inside an obstacle of the map")
            if goal is not None and in_goal(state, goal):
                raise ValueError(
                    f"option 'state': position {state[:2].tolist()} is already inside the goal {goal.tolist()}"
                )
        if state is None:
            state = self._draw_state(rng, goal)
        if goal is None:
            goal = self._draw_goal(rng, state)
        return self.map, state, goal

    def _start_episode(self, _map, state: np.ndarray, goal: np.ndarray) -> None:
        super()._start_episode(np.zeros((0, 3)), state, goal)  # the episode's bookkeeping and driver reset
        self.scene = Dubins4DMapScene(self.world, goal, self.dynamics, self.n_rays, self.ray_length)
        self._circles = self.scene.goal[None, :]  # the goal only: obstacles are the world's (_obstacle_contact)

    # ------------------------------------------------------------------ accessors and hooks
    def privileged(self) -> dict:
        """The true state, the goal, the map's circles (``obstacles``) and its entries (``map``):
        **privileged**, see the spec's "Info"."""
        out = super().privileged()
        out["map"] = self.map.to_json()
        return out

    def sample_states(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` states uniform over the start box x [-pi, pi) x [0, 2], outside every obstacle."""
        self.require_episode()
        assert self.scene is not None  # require_episode raised otherwise
        assert self.map.start_box is not None  # load_map sets it (the bounding box when the map gives none)
        (x0, y0), (x1, y1) = self.map.start_box
        s = self.dynamics
        return rejection_sample(
            rng,
            n,
            4,
            lambda r, m: np.column_stack(
                [
                    r.uniform(x0, x1, m),
                    r.uniform(y0, y1, m),
                    r.uniform(-np.pi, np.pi, m),
                    r.uniform(s.v_min, s.v_max, m),
                ]
            ),
            self.scene.state_failed,
            "states outside the map's obstacles",
        )

    def render_frame(self, size: int = 512) -> np.ndarray:
        """The ``rgb_array`` frame described under "Rendering" above."""
        if self.scene is None:
            return _render.Canvas(size, -15, 15, -15, 15).img
        return _render.map_frame(self.scene, self._state, self._last_active, self.map.start_box, size)


parallel_env = parallel_twin(Dubins4DMapEnv, "Dubins4DMapParallel-v0")
