"""Risk adapters for Gymnasium's classic-control ``CartPole-v1`` and ``Pendulum-v1``.

Both step every ``dt`` seconds with the envs' documented equations, written here in numpy over
a whole batch of states (:class:`CartPoleScene`, :class:`PendulumScene`); the parameters
(masses, lengths, gravity, force, ``dt``, thresholds, integrator) are read from the env
instance, so an env made with other arguments is served as configured.  A test pins one batched
step to the env's own ``step`` for random states and actions.  :class:`ClassicControlSnapshot`
gives either env the :class:`rmm_envs.adapters.SnapshotSimulator` protocol (its ``state``
attribute read and written, its own ``step`` called), for the step-by-step reference.

CartPole-v1 (:class:`CartPoleAdapter`)
    State ``(x, x_dot, theta, theta_dot)``.  Fails where the env terminates: ``|x| > 2.4`` m
    or ``|theta| > 12 deg`` (the env's ``x_threshold`` and ``theta_threshold_radians``).
    Controls: ``Discrete(2)`` as the box ``[0, 2)``, each branch pushing left or right (10 N)
    with probability 1/2 for its whole ``t``.  Default ``t`` = 0.08 s (4 steps of 0.02 s; why:
    docs/decisions/0009-simulator-adapters.md).  Sampler: uniform on the non-failed box
    ``|x| < 2.4``, ``|x_dot| < 2`` m/s, ``|theta| < 12 deg``, ``|theta_dot| < 2`` rad/s.
    Observation: the state (float32), as the env returns it.

Pendulum-v1 (:class:`PendulumAdapter`)
    State ``(theta, theta_dot)``, ``theta = 0`` upright.  The env never terminates, so failure
    must be given: ``failure(states) -> (N,) bool``, for example
    ``lambda s: np.abs(s[:, 1]) > 6.0`` (angular speed beyond 6 rad/s); without one the adapter
    is refused.  Controls: the torque box ``[-2, 2]`` N m, uniform, held for ``t``.  Default
    ``t`` = 0.25 s (5 steps of 0.05 s).  Sampler: ``theta`` uniform on ``[-pi, pi)``,
    ``theta_dot`` uniform on ``[-8, 8]`` (the env's ``max_speed``), failed states rejected.
    Observation: ``(cos theta, sin theta, theta_dot)`` (float32), the env's own.
"""

from __future__ import annotations

import numpy as np

from rmm_envs.adapters.base import AdaptedEnv, SimulatorScene

__all__ = ["CartPoleAdapter", "CartPoleScene", "ClassicControlSnapshot", "PendulumAdapter", "PendulumScene"]


def _name(env) -> str:
    env_id = getattr(getattr(env, "spec", None), "id", None)
    return str(env_id) if env_id else type(env.unwrapped).__name__


class CartPoleScene(SimulatorScene):
    """CartPole's dynamics over a batch (see the module docstring)."""

    def __init__(self, env, failure=None, default_horizon: float = 0.08) -> None:
        u = env.unwrapped
        self.p = {
            k: float(getattr(u, k))
            for k in (
                "gravity",
                "masspole",
                "total_mass",
                "length",
                "polemass_length",
                "force_mag",
                "tau",
                "x_threshold",
                "theta_threshold_radians",
            )
        }
        self.euler = u.kinematics_integrator == "euler"
        super().__init__(_name(env), 4, self.p["tau"], u.action_space, failure, default_horizon)

    def env_failed(self, states):
        return (np.abs(states[:, 0]) > self.p["x_threshold"]) | (
            np.abs(states[:, 2]) > self.p["theta_threshold_radians"]
        )

    def step(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """One env step of ``(N, 4)`` states under ``(N, 1)`` actions in {0, 1}."""
        p = self.p
        x, x_dot, th, th_dot = states.T
        force = np.where(actions[:, 0] == 1, p["force_mag"], -p["force_mag"])
        cos, sin = np.cos(th), np.sin(th)
        temp = (force + p["polemass_length"] * np.square(th_dot) * sin) / p["total_mass"]
        th_acc = (p["gravity"] * sin - cos * temp) / (
            p["length"] * (4.0 / 3.0 - p["masspole"] * np.square(cos) / p["total_mass"])
        )
        x_acc = temp - p["polemass_length"] * th_acc * cos / p["total_mass"]
        tau = p["tau"]
        if self.euler:
            return np.stack([x + tau * x_dot, x_dot + tau * x_acc, th + tau * th_dot, th_dot + tau * th_acc], axis=1)
        x_dot = x_dot + tau * x_acc
        th_dot = th_dot + tau * th_acc
        return np.stack([x + tau * x_dot, x_dot, th + tau * th_dot, th_dot], axis=1)

    def advance(self, states, actions, k):
        out = np.empty((states.shape[0], k, 4))
        s = states
        with np.errstate(over="ignore", invalid="ignore"):
            for j in range(k):
                s = out[:, j] = self.step(s, actions)
        return out, None


class PendulumScene(SimulatorScene):
    """Pendulum's dynamics over a batch (see the module docstring)."""

    def __init__(self, env, failure=None, default_horizon: float = 0.25) -> None:
        u = env.unwrapped
        self.p = {k: float(getattr(u, k)) for k in ("g", "m", "l", "dt", "max_speed", "max_torque")}
        super().__init__(_name(env), 2, self.p["dt"], u.action_space, failure, default_horizon)

    def step(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """One env step of ``(N, 2)`` states under ``(N, 1)`` torques."""
        p = self.p
        th, th_dot = states.T
        # the env's torque is float32 (its action space's dtype) and so is its product with
        # 3 / (m l^2) there (numpy 2 keeps a float32 times a Python float in float32): done alike
        u = np.clip(actions[:, 0].astype(np.float32), np.float32(-p["max_torque"]), np.float32(p["max_torque"]))
        torque_term = np.float32(3.0 / (p["m"] * p["l"] ** 2)) * u
        new_dot = th_dot + (3 * p["g"] / (2 * p["l"]) * np.sin(th) + torque_term.astype(float)) * p["dt"]
        new_dot = np.clip(new_dot, -p["max_speed"], p["max_speed"])
        return np.stack([th + new_dot * p["dt"], new_dot], axis=1)

    def advance(self, states, actions, k):
        out = np.empty((states.shape[0], k, 2))
        s = states
        for j in range(k):
            s = out[:, j] = self.step(s, actions)
        return out, None


class ClassicControlSnapshot:
    """:class:`rmm_envs.adapters.SnapshotSimulator` of a classic-control env: its ``state``
    attribute is the full state, its own ``step`` advances it (``terminated`` is the step's
    failure) and ``scene.env_failed`` judges states."""

    def __init__(self, env, scene: SimulatorScene) -> None:
        self.env = env.unwrapped
        self.dt = scene.dt
        self.action_space = self.env.action_space
        self._scene = scene

    def get_state(self) -> np.ndarray:
        return np.array(self.env.state, dtype=float)

    def set_state(self, state) -> None:
        self.env.state = np.array(state, dtype=float)
        if hasattr(self.env, "steps_beyond_terminated"):
            self.env.steps_beyond_terminated = None  # a restored state starts afresh (no warning)

    def step(self, action) -> bool:
        return bool(self.env.step(action)[2])

    def state_failed(self, states):
        return self._scene.env_failed(np.asarray(states, dtype=float))


class _ClassicAdapter(AdaptedEnv):
    @property
    def true_state(self):
        if self.unwrapped.state is None:
            raise RuntimeError(f"{self.scene.name} has no state before its first reset")
        return np.array(self.unwrapped.state, dtype=float)


class CartPoleAdapter(_ClassicAdapter):
    env_ids = ("CartPole-v1",)

    def __init__(self, env, failure=None) -> None:
        super().__init__(env, CartPoleScene(env, failure))

    def draw_states(self, rng, n):
        p = self.scene.p
        hi = np.array([p["x_threshold"], 2.0, p["theta_threshold_radians"], 2.0])
        return rng.uniform(-hi, hi, size=(n, 4))

    def observe_states(self, states, rng=None):
        return np.asarray(states, dtype=np.float32)


class PendulumAdapter(_ClassicAdapter):
    env_ids = ("Pendulum-v1",)

    def __init__(self, env, failure=None) -> None:
        if failure is None:
            raise TypeError(
                f"{_name(env)} never terminates, so the risk adapter needs failure=callable(states "
                f"(N, 2) of (theta, theta_dot)) -> (N,) bool, for example "
                f"lambda s: np.abs(s[:, 1]) > 6.0 (angular speed beyond 6 rad/s); "
                f"rmm-datagen takes it as --failure module:callable"
            )
        super().__init__(env, PendulumScene(env, failure))

    def draw_states(self, rng, n):
        v = self.scene.p["max_speed"]
        return np.column_stack([rng.uniform(-np.pi, np.pi, n), rng.uniform(-v, v, n)])

    def observe_states(self, states, rng=None):
        s = np.asarray(states, dtype=float)
        return np.column_stack([np.cos(s[:, 0]), np.sin(s[:, 0]), s[:, 1]]).astype(np.float32)
