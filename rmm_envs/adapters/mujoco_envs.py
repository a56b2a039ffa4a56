"""Risk adapters for Gymnasium's MuJoCo envs (optional extra ``rmm-envs[mujoco]``).

State: MuJoCo's full physics state (``mjSTATE_FULLPHYSICS``: time, ``qpos``, ``qvel``, actuator
activations and the rest of what the integrator reads), got and set with ``mj_getState`` /
``mj_setState``.  One env step is the env's ``frame_skip`` physics steps with the control held,
so ``dt`` is the env's ``dt``.  Branches are batched through ``mujoco.rollout`` (many initial
states and held controls per call, in blocks of at most 32 MiB of states); each branch starts
with a zero constraint warm start (the state does not hold one), so contact-rich models (Hopper)
can differ from the env stepping on from the same state by solver tolerance, while models
without contacts match it exactly (pinned by a test).

Controls: the env's action space (a Box), uniform, held for ``t``.

Failure (the env's unhealthy termination, evaluated on states, whether or not the env was made
to terminate on it), and the default horizon ``t``:

``InvertedPendulum-v5``
    ``|qpos[1]| > 0.2`` rad (the pole's hinge angle).  ``t`` = 0.04 s (1 step).
``InvertedDoublePendulum-v5``
    The tip's height ``site_xpos[0][2] <= 1`` m (MuJoCo's kinematics per state).  ``t`` = 0.1 s
    (2 steps of 0.05 s).
``Hopper-v5``
    Not ``is_healthy``: ``qpos[1]`` (height) outside the env's ``healthy_z_range``,
    ``qpos[2]`` (torso angle) outside ``healthy_angle_range``, or an element of
    ``(qpos, qvel)[2:]`` outside ``healthy_state_range`` (all open intervals, as the env's).
    ``t`` = 0.04 s (5 steps of 0.008 s).
any other MuJoCo env
    Only the user's failure test (required): ``failure=`` in Python, ``--failure
    module:callable`` for ``rmm-datagen``, called as ``failure(states) -> (N,) bool`` on
    ``(N, d)`` full states whose **column 0 is the simulated time**, columns ``1 .. nq`` are
    ``qpos`` and the next ``nv`` are ``qvel`` (then ``act`` and the rest, if the model has them;
    :func:`state_columns` names every column of a model).  ``t`` = 2 steps.
    ``Walker2d-v5``: :func:`walker2d_unhealthy` is Gymnasium's unhealthy termination of the
    walker with its default ranges (``--failure rmm_envs.adapters.mujoco_envs:walker2d_unhealthy``;
    its dataset and model: docs/reproduction.md, "Risk labels and a model for Walker2d-v5").

Every state that is not finite fails as well, and a user's ``failure`` adds to the env's.  Why
these horizons: docs/decisions/0009-simulator-adapters.md.

Sampler (``sample_states``, for datasets): *visited states*: the env is reset (seeded from the
generator; the env's state and generator are restored afterwards) and then stepped with uniform
random actions, a fresh one each env step, for a number of steps drawn uniformly from 0 to 1 s of
simulated time; a branch that fails stops at its last healthy state.  Observation: the env's own
``_get_obs`` in that state.
"""

from __future__ import annotations

import copy

import numpy as np

from rmm_envs.adapters.base import AdaptedEnv, SimulatorScene

try:
    import mujoco
    from mujoco import rollout as _rollout
except ImportError:  # pragma: no cover - the extra is missing
    mujoco = None

__all__ = ["MujocoAdapter", "MujocoScene", "MujocoSnapshot", "state_columns", "walker2d_unhealthy"]

_BLOCK_BYTES = 32 * 2**20


def _require_mujoco(name: str) -> None:
    if mujoco is None:
        raise TypeError(f"{name}: the MuJoCo risk adapter needs the mujoco package: pip install 'rmm-envs[mujoco]'")


def _offset(model, bit) -> int:
    """Where component ``bit`` starts in a FULLPHYSICS state vector (components are in bit order)."""
    full = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
    below = full & (int(bit) - 1)
    return int(mujoco.mj_stateSize(model, below)) if below else 0


def state_columns(model) -> list[tuple[str, int, int]]:
    """The components of ``model``'s full state vector (what a ``failure(states)`` receives) as
    ``(name, first column, end column)``, in order, empty ones left out: ``("time", 0, 1)``,
    ``("qpos", 1, 1 + nq)``, ``("qvel", 1 + nq, 1 + nq + nv)``, then ``act`` and the rest."""
    full = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
    out = []
    for name, bit in mujoco.mjtState.__members__.items():
        b = int(bit)
        if b & full and b & (b - 1) == 0:  # one component of the full state
            size = int(mujoco.mj_stateSize(model, b))
            if size:
                lo = _offset(model, b)
                out.append((name.removeprefix("mjSTATE_").lower(), lo, lo + size))
    return sorted(out, key=lambda c: c[1])


def _describe_columns(model) -> str:
    """``column 0 the time, columns 1-9 qpos, columns 10-18 qvel`` (for messages)."""
    parts = []
    for name, lo, hi in state_columns(model):
        what = "the time" if name == "time" else name
        parts.append(f"column {lo} {what}" if hi == lo + 1 else f"columns {lo}-{hi - 1} {what}")
    return ", ".join(parts)


#: Gymnasium's ``Walker2d-v5`` defaults: ``healthy_z_range`` and ``healthy_angle_range``
WALKER2D_HEALTHY_Z = (0.8, 2.0)
WALKER2D_HEALTHY_ANGLE = (-1.0, 1.0)
WALKER2D_STATE_DIM = 19  # time, qpos (9), qvel (9)


def walker2d_unhealthy(states) -> np.ndarray:
    """The failure test of ``Walker2d-v5`` for ``--failure rmm_envs.adapters.mujoco_envs:walker2d_unhealthy``:
    Gymnasium's unhealthy termination of the walker with the env's default ranges, i.e. the
    torso's height ``qpos[1]`` (column 2) outside the open interval ``(0.8, 2.0)`` m or its angle
    ``qpos[2]`` (column 3) outside ``(-1, 1)`` rad.

    ``states``: ``(N, 19)`` full states of ``Walker2d-v5`` (column 0 the time, columns 1-9
    ``qpos``, columns 10-18 ``qvel``); ``ValueError`` naming the shape for any other.  An env
    made with other ``healthy_z_range`` / ``healthy_angle_range`` needs a test of its own.
    """
    s = np.asarray(states, dtype=float)
    if s.ndim != 2 or s.shape[1] != WALKER2D_STATE_DIM:
        raise ValueError(
            f"walker2d_unhealthy: states must be (N, {WALKER2D_STATE_DIM}) full states of Walker2d-v5 "
            f"(column 0 the time, columns 1-9 qpos, columns 10-18 qvel), got shape {s.shape}"
        )
    z, angle = s[:, 2], s[:, 3]
    (lo_z, hi_z), (lo_a, hi_a) = WALKER2D_HEALTHY_Z, WALKER2D_HEALTHY_ANGLE
    return ~((lo_z < z) & (z < hi_z) & (lo_a < angle) & (angle < hi_a))


#: failure tests the package ships for MuJoCo envs without a known one (unwrapped class name -> --failure value)
SHIPPED_FAILURES = {"Walker2dEnv": "rmm_envs.adapters.mujoco_envs:walker2d_unhealthy"}


class MujocoScene(SimulatorScene):
    """A MuJoCo env's dynamics over a batch of full states (see the module docstring)."""

    KNOWN = {  # unwrapped class name -> (its failure test, default steps per level)
        "InvertedPendulumEnv": ("inverted_pendulum", 1),
        "InvertedDoublePendulumEnv": ("inverted_double_pendulum", 2),
        "HopperEnv": ("hopper", 5),
    }

    def __init__(self, env, failure=None, default_horizon: float | None = None) -> None:
        u = env.unwrapped
        name = env.spec.id if getattr(env.spec, "id", None) else type(u).__name__
        _require_mujoco(name)
        known: tuple[str | None, int] = self.KNOWN.get(type(u).__name__, (None, 2))
        self.failure_test, steps = known
        if self.failure_test is None and failure is None:
            d = int(mujoco.mj_stateSize(u.model, int(mujoco.mjtState.mjSTATE_FULLPHYSICS)))
            shipped = SHIPPED_FAILURES.get(type(u).__name__)
            example = f"; for {name} the package ships one: --failure {shipped}" if shipped else ""
            raise TypeError(
                f"{name}: no failure test is known for this MuJoCo env (the adapters know "
                f"{', '.join(MujocoAdapter.env_ids)}); give one: failure=callable in Python, "
                f"--failure module:callable for rmm-datagen, called as failure(states) -> (N,) bool on (N, {d}) "
                f"full states ({_describe_columns(u.model)}){example}"
            )
        self.env = u
        self.model = u.model
        self.frame_skip = int(u.frame_skip)
        self.spec_bits = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
        self.qpos0 = _offset(self.model, mujoco.mjtState.mjSTATE_QPOS)
        self.qvel0 = _offset(self.model, mujoco.mjtState.mjSTATE_QVEL)
        self.nq, self.nv = self.model.nq, self.model.nv
        self._data = mujoco.MjData(self.model)  # scratch data: kinematics, rollouts
        super().__init__(
            name,
            mujoco.mj_stateSize(self.model, self.spec_bits),
            float(u.dt),
            u.action_space,
            failure,
            default_horizon if default_horizon is not None else steps * float(u.dt),
        )

    def qpos(self, states):
        return states[:, self.qpos0 : self.qpos0 + self.nq]

    def qvel(self, states):
        return states[:, self.qvel0 : self.qvel0 + self.nv]

    def env_failed(self, states):
        if self.failure_test == "inverted_pendulum":
            return np.abs(self.qpos(states)[:, 1]) > 0.2
        if self.failure_test == "hopper":
            u = self.env
            qpos = self.qpos(states)
            rest = np.concatenate([qpos, self.qvel(states)], axis=1)[:, 2:]
            lo_s, hi_s = u._healthy_state_range
            lo_z, hi_z = u._healthy_z_range
            lo_a, hi_a = u._healthy_angle_range
            healthy = (
                np.all((lo_s < rest) & (rest < hi_s), axis=1)
                & (lo_z < qpos[:, 1])
                & (qpos[:, 1] < hi_z)
                & (lo_a < qpos[:, 2])
                & (qpos[:, 2] < hi_a)
            )
            return ~healthy
        if self.failure_test == "inverted_double_pendulum":
            out = np.empty(states.shape[0], dtype=bool)
            d = self._data
            for i, s in enumerate(states):
                mujoco.mj_setState(self.model, d, s, self.spec_bits)
                mujoco.mj_kinematics(self.model, d)
                out[i] = d.site_xpos[0][2] <= 1
            return out
        return np.zeros(states.shape[0], dtype=bool)

    def physics(self, states: np.ndarray, controls: np.ndarray) -> np.ndarray:
        """Roll ``(N, nstate)`` states on under ``(N, S, nu)`` per-physics-step controls: ``(N, S, nstate)``."""
        n, steps = states.shape[0], controls.shape[1]
        out = np.empty((n, steps, self.state_dim))
        block = max(1, _BLOCK_BYTES // (8 * steps * self.state_dim))
        for lo in range(0, n, block):
            hi = min(n, lo + block)
            _rollout.rollout(
                self.model,
                self._data,
                np.ascontiguousarray(states[lo:hi]),
                np.ascontiguousarray(controls[lo:hi]),
                nstep=steps,
                state=out[lo:hi],
            )
        return out

    def advance(self, states, actions, k):
        held = np.broadcast_to(actions[:, None, :], (actions.shape[0], k * self.frame_skip, actions.shape[1]))
        out = self.physics(states, held)
        return out[:, self.frame_skip - 1 :: self.frame_skip], None


class MujocoSnapshot:
    """:class:`rmm_envs.adapters.SnapshotSimulator` of a MuJoCo env: full state through
    ``mj_getState``/``mj_setState``, the env's own ``step`` (its ``terminated`` is the step's
    failure) and the scene's failure test of states."""

    def __init__(self, env, scene: MujocoScene) -> None:
        self.env = env.unwrapped
        self.dt = scene.dt
        self.action_space = self.env.action_space
        self._scene = scene

    def get_state(self) -> np.ndarray:
        s = np.empty(self._scene.state_dim)
        mujoco.mj_getState(self.env.model, self.env.data, s, self._scene.spec_bits)
        return s

    def set_state(self, state) -> None:
        mujoco.mj_setState(self.env.model, self.env.data, np.asarray(state, dtype=float), self._scene.spec_bits)
        mujoco.mj_forward(self.env.model, self.env.data)

    def step(self, action) -> bool:
        return bool(self.env.step(action)[2])

    def state_failed(self, states):
        return self._scene.env_failed(np.asarray(states, dtype=float))


class MujocoAdapter(AdaptedEnv):
    env_ids = ("InvertedPendulum-v5", "InvertedDoublePendulum-v5", "Hopper-v5")

    scene: MujocoScene

    def __init__(self, env, failure=None) -> None:
        scene = MujocoScene(env, failure)
        super().__init__(env, scene)
        self._snap = MujocoSnapshot(env, scene)
        if failure is not None:  # a failure test of the wrong shape is refused here, before any labelling
            scene.state_failed(self._snap.get_state()[None])

    @property
    def true_state(self):
        return self._snap.get_state()

    def draw_states(self, rng, n):
        sc = self.scene
        starts = np.empty((n, sc.state_dim))
        u = self.unwrapped
        saved_state, saved_rng = self._snap.get_state(), copy.deepcopy(u.np_random)
        try:  # the env's own reset draws the starts; its episode and generator are put back after
            for i in range(n):
                self.env.reset(seed=int(rng.integers(2**31)))
                starts[i] = self._snap.get_state()
        finally:
            self._snap.set_state(saved_state)
            u.np_random = saved_rng
        kmax = max(1, int(round(1.0 / sc.dt)))
        k = rng.integers(0, kmax + 1, size=n)
        acts = rng.uniform(sc.control_low, sc.control_high, size=(n, kmax, len(sc.control_low)))
        acts = acts.astype(sc.action_space.dtype).astype(float)
        phys = sc.physics(starts, np.repeat(acts, sc.frame_skip, axis=1))
        traj = np.concatenate([starts[:, None], phys[:, sc.frame_skip - 1 :: sc.frame_skip]], axis=1)
        failed = sc.state_failed(traj.reshape(-1, sc.state_dim)).reshape(n, kmax + 1)
        first = np.where(failed.any(axis=1), failed.argmax(axis=1), kmax + 1)
        pick = np.clip(np.minimum(k, first - 1), 0, kmax)
        return traj[np.arange(n), pick]

    def observe_states(self, states, rng=None):
        states = np.asarray(states, dtype=float)
        saved = self._snap.get_state()
        try:
            rows = []
            for s in states:
                self._snap.set_state(s)
                rows.append(np.asarray(self.env.unwrapped._get_obs(), dtype=np.float32))
        finally:
            self._snap.set_state(saved)
        return np.array(rows, dtype=np.float32).reshape(states.shape[0], -1)
