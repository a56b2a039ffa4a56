"""High-order control barrier function (HOCBF) guardians, solved with OSQP: ``cbf`` and ``cbf-paper``.

Both use **privileged** information: the true state, the obstacles, the goal and the simulated
time (from the env's documented ``privileged()`` accessor).  After Xiao & Belta's HOCBFs, as in
the paper.

The QP
------
For each circular obstacle ``i`` a relative-degree-2 barrier with inflation ``k``::

    b_i = (x - x_i)^2 + (y - y_i)^2 - (k r_i)^2
    Lf b = 2 v ((x - x_i) cos th + (y - y_i) sin th),   Lf^2 b = 2 v^2
    LgLf b = [2 v ((y - y_i) cos th - (x - x_i) sin th),  2 ((x - x_i) cos th + (y - y_i) sin th)]
    Lf^2 b + LgLf b . u + p1 Lf b + p2 (Lf b + p1 b) >= 0        (linear class-K, p1, p2)

``cbf`` is a safety filter (``reference="nominal"``): it keeps the driver's intended
control, the env's ``info["nominal_control"]`` ``u_nom``, as close as the barriers allow::

    minimise |u - u_nom|^2
    s.t. the barrier rows above (hard), the speed barriers and control box (merged into one
    row on u2, as in the driver).

A nominal control that satisfies every row is the solution itself, and is passed on without
a solve.  ``cbf-paper`` (``reference="clf"``) re-derives a goal-seeking control instead, as the
paper did, over ``z = (u1, u2, d_th, d_v)``::

    minimise u1^2 + u2^2 + p_th d_th^2 + p_v d_v^2
    s.t. the same rows, the heading CLF (as the driver's) and a speed CLF toward
    v_d = min((d/2)^2, d/2) with V_v = (v - v_d)^2.

Both are one OSQP problem with a fixed sparsity (:mod:`guardians.cbf.qp`; the filter sets the
CLF rows' coefficients to 0 and their bounds to infinity).

Defaults shared by both guardians, and why:

* ``p1 = 0.7535, p2 = 0.6664``: the paper's class-K gains.
* ``inflation = 1.05``: the paper's 5% obstacle inflation (a margin of 0.1-0.25 m for radii of
  2-5 m, about one step of travel at full speed).
* ``gamma_vmin = gamma_vmax = lambda_theta = lambda_v = p_theta = p_v = 1``: the paper's (the
  same values the env's driver uses; the CLF gains and weights act under ``reference="clf"`` only).
* control box: read at ``reset`` from the env's action space (:class:`rmm_envs.autonomy.GuardianActionSpace`,
  ``|u1| <= 0.25``, ``|u2| <= 0.5`` for Dubins4D; ``u1_bounds``/``u2_bounds`` override it);
  speeds ``[0, 2]``: the Dubins4D system's (``rmm_envs.systems.dubins4d.Dubins4D``;
  ``v_bounds`` overrides them).
* The original wrote the speed CLF as ``(v - v_d) * 82`` (a typo for the square); we use the
  square.  The original also braked fully whenever ``v < 0.05`` (so a stopped car never moved
  again); that is off (``low_speed_stop=True`` restores it).
* Intervention: the guardian takes control, applying the QP's ``(u1, u2)``, when a barrier
  row is active at the solution (for the filter: when the barriers change the driver's control): ``|G_i z* - h_i| <= active_atol + active_rtol |h_i|``
  (``1e-3`` and ``0``: equality up to the solver's polished accuracy; the original used a loose
  0.1/0.1).  Otherwise the driver keeps control.  The rule is kept: a row that is not active
  at the CBF-CLF optimum is slack by more than ``1e-3``, and the one-step prediction below
  makes it hold for the state the decision is applied from.
* ``eps = 1e-6`` (OSQP's absolute/relative tolerance, solutions polished), ``max_obstacles = 64``
  (more is refused at reset: the QP is sized once per episode).

The problem is set up once per episode (fixed sparsity for the episode's obstacles) and each
step only updates values and bounds, then re-solves warm-started.  A state with NaN brakes at
maximum and is counted (``stats()["nan_states"]``).

``cbf-paper``: the paper's rule (:class:`CBFPaperGuardian`)
-----------------------------------------------------------
The QP is solved at the observed state; an infeasible or failed QP brakes at maximum with no
turn (``stats()["qp_fallbacks"]``).  This is the previous ``cbf`` exactly.  Its weakness: most
of its timeouts are a car that stopped for good.  Either it entered the inflation margin
facing the obstacle (the QP is infeasible there, it brakes, and a stopped car facing inward
can never satisfy the rows: at ``v = 0`` the turn rate drops out of them), or it stopped on
the margin with the goal behind the obstacle (the well-known CBF-QP deadlock: a stable
equilibrium with the barrier active and ``u = 0`` feasible but no motion).

``cbf``: the default (:class:`CBFGuardian`)
-------------------------------------------
Four changes, each for a stated reason:

0. **It filters the driver's control** (``reference="nominal"``) instead of re-deriving one.
   A safety filter's job is to change the controller's intended control minimally; the
   paper's QP replaced it with its own CLF controller whenever a barrier was active, so what
   the car did under "guardian control" was a different goal-seeker's choice.  The filter
   reads ``info["nominal_control"]`` (a ``ValueError`` naming the key when an env gives none;
   ``reference="clf"`` serves such envs).  Measured (``rmm-bench --agent cbf --clock fixed:1
   --episodes 256``, seed 0): 87.5 / 7.0 / 5.5 % success / collision / timeout, intervening
   27.7% of the simulated time, against 90.2 / 6.6 / 3.1 and 24.4% with the CLF reference
   (the sweep below): the same collisions within the noise (± 4), a few more timeouts where
   the driver heads for a goal behind an obstacle and the filter holds it at the margin.

1. **One-step latency** (``predict_latency=True``).  Under parallel autonomy the action
   returned for the state ``s_k`` is applied only from ``s_{k+1}``: during the lap from
   ``s_k`` to ``s_{k+1}`` the previous action (or the driver) still drives.  A lap lasts
   ``base_step + time_accel * thinking time`` (0.11 s under ``--clock fixed:1``), so at 2 m/s
   the car covers 0.22 m before the decision takes effect: as much as the whole 0.1-0.25 m
   inflation margin.  So the guardian solves its QP at the *predicted* state ``s_{k+1}``:
   the exact Dubins4D flow (``rmm_envs.systems``) from ``s_k`` under the control that will
   act during the lap.  If the guardian was in control that is its own last action, known
   exactly; if the driver was, it is the driver's control at ``s_k``, the step's
   ``info["nominal_control"]``, also exact (``reference="clf"`` does not read it and takes
   zero, which bounds the prediction error by ``|u2|max lap^2 / 2`` = 3.0 mm in position and
   ``|u1|max lap`` = 0.0275 rad in heading at 0.11 s).  The lap is measured from the simulated
   times the env reports (the previous lap's length; ``lap_guess = 0.1`` s, the base step,
   before the first measurement).  Nothing here is tuned: it is the env's documented timing.
   Measured (256 episodes, fixed 1 ms clock, seed 0), its effect on outcomes is within the
   run-to-run noise: 6.6% collisions with and without it at ``k = 1.05`` (timeouts 3.1% against
   4.3%); nearly all remaining collisions start at speed too close to an obstacle to avoid, so
   latency is not what limits safety here.  It is kept because the decision then refers to
   the state it acts from, which is what the HOCBF condition assumes.
2. **Recovery instead of braking forever** (``recovery=True``).  The guardian enters
   recovery when the QP is infeasible or fails, or when it is deadlocked: a barrier row is
   active and the QP's control leaves the speed below ``v_stuck = 0.05`` m/s after the lap
   (5.5 mm of travel per 0.11-s lap: stopped for practical purposes; the same threshold the
   original used to call the car stopped).  Recovery is a backup manoeuvre about the obstacle
   ``i*`` whose row is hardest to satisfy (the smallest ``h_i + max_u LgLf b_i . u`` over the
   admissible controls).  With ``n`` the outward normal at the car and ``t`` one of the two
   tangents:

   * the tangent ``t``: while the car moves (``v > v_stuck``) the one with ``t . heading >= 0``
     (turning toward it turns the heading away from the centre, the sign that maximises
     ``d^2 b / dt^2`` through ``u1``); when stopped, the one on the goal's side.  The choice
     is kept for the whole recovery (it goes round one way, no dithering);
   * target heading: along ``t``, tilted 45 degrees outward (``t + n``) while inside the
     margin (``b < 0``), so that the car leaves it;
   * ``u1`` turns to the target heading at full rate, proportionally within one lap
     (``err / lap``) so that it does not overshoot while the command is held; while the
     heading points inward it always turns the way that rotates it away from the centre
     (never through it), so ``heading . n`` rises monotonically;
   * ``u2``: full braking while the heading points inward (``heading . n < 0``), which with
     the turn makes ``d^2 b/dt^2 = 2 v^2 + LgLf b . u > 0`` strictly; full acceleration (up to
     the speed barrier) once it does not, so that ``db/dt = 2 v |d| heading . n >= 0`` and the
     car moves off along the tangent; the acceleration is capped by every obstacle's barrier
     row (another obstacle may lie ahead).  A stopped car facing inward turns in place (at
     ``v = 0`` nothing else can help) until it faces out.
   * Blocked (stopped, on target, the cap forbids moving: the notch where two obstacles
     overlap), it goes round the other way; blocked again, it recovers from the obstacle that
     now blocks.

   Recovery ends when the car is outside every margin (all ``b_i >= 0``), its heading does
   not point into ``i*``, and the straight line to the goal clears the inflated ``i*`` (so
   the same deadlock cannot form again).  Each step spent recovering is counted in
   ``stats()["recoveries"]`` and each entry in ``stats()["recovery_entries"]``;
   ``qp_fallbacks`` still counts every QP that failed or was infeasible (recovery took over).
   A state with NaN still brakes and is counted as ``nan_states``.
3. **A margin that never swallows the goal** (``goal_aware_margin=True``).  The env only
   guarantees that the goal is not entirely inside an obstacle; with the 5% inflation it is
   entirely inside some obstacle's *margin* in about 4% of episodes (measured over 1,000
   generated scenes), and a margin-respecting CBF can then never reach it (most of the
   remaining timeouts).  So each obstacle's inflated radius is
   ``max(r, min(k r, (r + F) / 2))`` with ``F`` the goal point farthest from its centre: the
   margin covers at most half of the goal's protrusion beyond the obstacle, and is the full
   ``k r`` for every obstacle not near the goal.

Inflation ``k = 1.05`` is kept at the paper's value.  A sweep over ``k`` (256 episodes, fixed
1 ms clock, seed 0; success / collision / timeout %; measured with the CLF reference, before
the filter) puts it at the knee: 1.0: 87.5 / 9.8 /
2.7; 1.02: 89.5 / 7.0 / 3.5; 1.05: 90.2 / 6.6 / 3.1; 1.1: 89.1 / 6.2 / 4.7; 1.2: 86.7 / 6.2 /
7.0.  Without a margin the sampled (0.11-s, zero-order-hold) loop lets the car graze
obstacles; beyond 5% collisions no longer fall while the margin blocks more gaps and goals.

Bad arguments (non-finite or non-positive gains, ``inflation < 1``, empty control or speed
ranges, negative tolerances) are refused at construction with a message naming the value; an
action space without two controls, or whose box does not contain ``u1 = 0`` and both signs of
``u2``, is refused at ``reset``, naming the guardian.

The maze car, the quadrotor and the solver
------------------------------------------
``cbf`` also serves the maze car (``Dubins3DMazeParallel-v0``): given an action space with the
maze car's one control (``turnrate_ctrl``) it hands the episode to
:class:`guardians.cbf.maze.MazeCBFGuardian` (walls as barriers that include the turn the car
needs; its module docstring has the rows and defaults).  ``maze`` (a dict) sets that
guardian's own arguments; ``solver``, ``eps``, ``predict_latency`` and ``lap_guess`` are
shared; ``maze=False`` refuses maze envs (``cbf-paper`` does: the paper's rule is Dubins4D's).
Given an action space with the quadrotor's four commands (``QuadrotorRoomGuarded-v0``,
``QuadrotorRoomParallel-v0``) it hands the episode to
:class:`guardians.cbf.quadrotor.QuadrotorCBFGuardian` in the same way (the room's floor, walls
and objects as barriers on the velocity command, a first-order tracking model; its module
docstring has the rows and defaults); ``quadrotor`` (a dict) sets that guardian's own
arguments, ``quadrotor=False`` refuses quadrotor envs (``cbf-paper`` does).
``solver``: ``"osqp"`` (default, the direct path below) or ``"qpsolvers:<name>"`` for any
solver qpsolvers has installed (:mod:`guardians.cbf.backend`).

The package, by responsibility: :mod:`guardians.cbf.barrier` (the barrier rows and the
obstacle choices, pure functions of the state), :mod:`guardians.cbf.qp` (the OSQP problem, set
up once per episode), :mod:`guardians.cbf.recovery` (the backup manoeuvre) and
:mod:`guardians.cbf.guardian` (the two guardians: configuration, latency and the decision),
:mod:`guardians.cbf.backend` (the solver choice), :mod:`guardians.cbf.maze` (the maze car),
:mod:`guardians.cbf.quadrotor` and :mod:`guardians.cbf.quadrotor_rows` (the quadrotor).
"""

from guardians.cbf.guardian import CBFGuardian, CBFPaperGuardian

__all__ = ["CBFGuardian", "CBFPaperGuardian"]
