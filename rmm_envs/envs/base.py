"""The skeleton every environment of this package shares: :class:`LabelledEnvBase`.

An env module is then its system, its world, its driver (if any) and its docstring; this module
provides, once: argument and option checks (:func:`check_arguments`, :func:`option_vector`,
:meth:`LabelledEnvBase.check_options`), running-state guards (``step`` before ``reset`` or after
the episode ended raises ``RuntimeError``), seeded rejection sampling (:func:`draw_until`,
:func:`rejection_sample`), rendering (``"rgb_array"``, ``"human"``) and the labelling hooks of
:class:`rmm_envs.risk.LabelledEnv` that do not depend on the env.

Subclasses set ``self.scene`` at every ``reset`` (to the :class:`rmm_envs.risk.RiskScene` of the
new episode) and call :meth:`~LabelledEnvBase.begin_episode` there, and
:meth:`~LabelledEnvBase.end_episode` on the step that ends it.  Each piece in detail: the
docstrings of :class:`LabelledEnvBase` and of the functions.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, TypeVar

import gymnasium as gym
import numpy as np

from rmm_envs.worlds.bounds import MAX_MAGNITUDE, within_bounds

if TYPE_CHECKING:
    from rmm_envs.risk.protocol import RiskScene

__all__ = [
    "MAX_ROUNDS",
    "LabelledEnvBase",
    "check_arguments",
    "draw_until",
    "finite",
    "option_vector",
    "rejection_sample",
    "state_rows",
    "whole",
]

T = TypeVar("T")

#: Rounds of :func:`rejection_sample` before it gives up.  Each round draws twice the missing
#: count, so with an acceptance rate ``p`` the missing count shrinks by about ``1 - 2p`` a round
#: and ``n`` samples take about ``ln(n) / (2p)`` rounds: 10,000 rounds serve acceptance rates
#: down to ~0.04% for a thousand samples.  Measured over 20 seeded episodes each, the envs'
#: ``sample_states`` accept 45% (worst) / 62% (mean) of draws for Dubins4D, 90% / 91% in mazes and
#: 2% / 51% in rooms (a small room in its expanded box), so reaching the limit means the scene
#: leaves (almost) no free space, and an error says so instead of looping for ever.
MAX_ROUNDS = 10_000


def finite(x) -> bool:
    """A real number (not a bool, string or array), finite and of magnitude at most
    :data:`rmm_envs.worlds.bounds.MAX_MAGNITUDE` (1e9): larger ones (``1e300``, ``10**400``)
    overflow the arithmetic they configure (``ray_length=1e300`` gave infinite observations)."""
    if not isinstance(x, (int, float, np.integer, np.floating)) or isinstance(x, bool):
        return False
    return within_bounds(x)


def whole(x) -> bool:
    """An integer value (``3`` or ``3.0``), finite."""
    return finite(x) and float(x) == int(x)


def check_arguments(checks: Iterable[tuple[bool, str, Any, str]]) -> None:
    """Raise ``ValueError("<name> must be <expected>, got <value>")`` for the first failed
    ``(ok, name, value, expected)`` check."""
    for ok, name, value, expected in checks:
        if not ok:
            numbers = list(value) if isinstance(value, (list, tuple)) else [value]
            huge = [
                v
                for v in numbers
                if isinstance(v, (int, float, np.integer, np.floating))
                and not isinstance(v, bool)
                and not within_bounds(v)
                and not (isinstance(v, (float, np.floating)) and not math.isfinite(v))
            ]
            why = f" (at most {MAX_MAGNITUDE:g} in magnitude: larger values overflow the arithmetic)" if huge else ""
            raise ValueError(f"{name} must be {expected}{why}, got {str(value)[:200] if huge else repr(value)}")


def option_vector(value, n: int, name: str, what: str = "") -> np.ndarray:
    """The reset option ``name`` as ``n`` finite floats (a fresh array); ``ValueError`` naming
    the option otherwise.  ``what`` describes the numbers (e.g. ``" [x, y, psi]"``)."""
    try:
        arr = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError, OverflowError):  # OverflowError: an integer beyond a float (10**400)
        arr = None
    if arr is None or arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"option {name!r} must be {n} finite numbers{what}, got {_short(value)}")
    if not within_bounds(arr):
        raise ValueError(
            f"option {name!r} must be {n} numbers of magnitude at most {MAX_MAGNITUDE:g}{what} (larger ones "
            f"overflow the geometry), got {_short(value)}"
        )
    return arr


def _short(value, limit: int = 200) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def state_rows(states, dim: int, what: str = "states") -> np.ndarray:
    """``states`` as a float array ``(N, dim)`` of finite numbers, else ``ValueError`` naming the
    shape or the first row that is not finite (the labelling hooks' input check)."""
    try:
        s = np.asarray(states, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(
            f"{what} must be an array of shape (N, {dim}) of numbers, got {type(states).__name__}"
        ) from None
    if s.ndim != 2 or s.shape[1] != dim:
        raise ValueError(f"{what} must have shape (N, {dim}), got shape {s.shape}")
    bad = np.flatnonzero(~np.isfinite(s).all(axis=1))
    if bad.size:
        raise ValueError(f"{what} must be finite: row {bad[0]} is {s[bad[0]].tolist()}")
    return s


def draw_until(draw: Callable[[], T], accept: Callable[[T], bool], max_draws: int) -> T | None:
    """The first of at most ``max_draws`` calls of ``draw()`` that ``accept`` accepts, else
    ``None`` (the caller raises, naming what it could not draw and why)."""
    for _ in range(max_draws):
        x = draw()
        if accept(x):
            return x
    return None


def rejection_sample(
    rng: np.random.Generator,
    n: int,
    dim: int,
    draw: Callable[[np.random.Generator, int], np.ndarray],
    rejected: Callable[[np.ndarray], np.ndarray],
    what: str,
    max_rounds: int = MAX_ROUNDS,
) -> np.ndarray:
    """``(n, dim)`` rows of ``draw(rng, k) -> (k, dim)`` that ``rejected(rows) -> (k,) bool``
    does not reject, in the order drawn; rounds of ``max(2 * missing, 16)`` candidates, at most
    ``max_rounds`` of them, then ``RuntimeError`` naming ``what`` and the acceptance seen."""
    if not (whole(n) and n >= 0):
        raise ValueError(f"the number of {what} to draw must be an integer >= 0, got {n!r}")
    out = np.empty((0, dim))
    drawn = 0
    for _ in range(max_rounds):
        if out.shape[0] >= n:
            return out[:n]
        k = max(2 * (n - out.shape[0]), 16)
        cand = draw(rng, k)
        drawn += k
        out = np.vstack([out, cand[~np.asarray(rejected(cand), dtype=bool)]])
    if out.shape[0] >= n:
        return out[:n]
    raise RuntimeError(
        f"could not draw {n} {what}: only {out.shape[0]} of {drawn} candidates were accepted in "
        f"{max_rounds} rounds of rejection sampling; the scene leaves (almost) no free space"
    )


class LabelledEnvBase(gym.Env):
    """A Gymnasium env with the shared skeleton of the module docstring.

    * **Running-state guards**: :meth:`check_can_step` (``step`` before ``reset`` or after the
      episode ended raises ``RuntimeError``) and :meth:`require_episode` (accessors that need a
      ``reset`` first); :meth:`check_options` refuses unknown reset options.
    * **Rendering**: :meth:`render` warns and returns ``None`` without a ``render_mode``, returns
      :meth:`render_frame` for ``"rgb_array"`` and shows it with pygame for ``"human"`` (offered
      by an env only where pygame is installed).
    * **The labelling hooks** of :class:`rmm_envs.risk.LabelledEnv`: :meth:`risk_scene` (the
      current episode's ``self.scene``) and :meth:`dataset_notes` (none by default); each env adds
      ``true_state``, ``sample_states``, ``observe_states`` and ``privileged``.

    Every draw of :func:`draw_until` and :func:`rejection_sample` takes the caller's
    ``numpy.random.Generator``, so the same seed gives the same samples."""

    #: the keys ``reset(options=...)`` accepts, in the order error messages list them
    reset_options: tuple[str, ...] = ()
    #: the :class:`rmm_envs.risk.RiskScene` of the current episode (``None`` before ``reset``)
    scene: RiskScene | None = None
    _done = False
    _window = None

    # ------------------------------------------------------------------ checks
    def check_render_mode(self, render_mode: str | None) -> tuple[bool, str, Any, str]:
        """The constructor check of ``render_mode`` (for :func:`check_arguments`)."""
        modes = self.metadata["render_modes"]
        return render_mode is None or render_mode in modes, "render_mode", render_mode, f"one of {modes}"

    def check_options(self, options: dict | None) -> dict:
        """A copy of the reset ``options``; ``ValueError`` listing any unknown key."""
        options = dict(options or {})
        unknown = set(options) - set(self.reset_options)
        if unknown:
            raise ValueError(
                f"unknown reset options {sorted(unknown)}; expected any of "
                f"{', '.join(repr(k) for k in self.reset_options)}"
            )
        return options

    # ------------------------------------------------------------------ running state
    def begin_episode(self) -> None:
        """Mark a new episode running (call in ``reset``, after setting ``self.scene``)."""
        self._done = False

    def end_episode(self) -> None:
        """Mark the episode ended: further steps raise until the next ``reset``."""
        self._done = True

    def require_episode(self) -> None:
        """``RuntimeError`` before the first ``reset``."""
        if self.scene is None:
            raise RuntimeError("call reset() first")

    def check_can_step(self) -> None:
        """``RuntimeError`` when stepping before ``reset`` or after the episode ended."""
        if self.scene is None:
            raise RuntimeError("call reset() before step()")
        if self._done:
            raise RuntimeError("the episode has ended; call reset() before stepping again")

    # ------------------------------------------------------------------ labelling hooks
    def risk_scene(self):
        """The :class:`rmm_envs.risk.RiskScene` of the current episode (for risk labelling)."""
        self.require_episode()
        return self.scene

    def dataset_notes(self) -> dict:
        """Facts about :meth:`observe_states` a dataset records in its metadata; here
        ``obs_time_feature``: how a simulated-time feature is drawn (``None``: the
        observation has none)."""
        return {"obs_time_feature": None}

    # ------------------------------------------------------------------ rendering
    def render_frame(self) -> np.ndarray:  # pragma: no cover - each env implements it
        raise NotImplementedError

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        frame = self.render_frame()
        if self.render_mode == "rgb_array":
            return frame
        try:
            import pygame
        except ImportError as e:  # pragma: no cover - optional extra
            raise gym.error.DependencyNotInstalled(
                "render_mode='human' needs pygame: the human extra, pip install -e '.[human]' in a clone"
            ) from e
        if self._window is None:  # pragma: no cover - needs a display
            pygame.init()
            self._window = pygame.display.set_mode(frame.shape[:2])
        surf = pygame.surfarray.make_surface(frame.swapaxes(0, 1))  # pragma: no cover
        self._window.blit(surf, (0, 0))  # pragma: no cover
        pygame.event.pump()  # pragma: no cover
        pygame.display.flip()  # pragma: no cover
        return None

    def close(self):
        if self._window is not None:  # pragma: no cover
            import pygame

            pygame.display.quit()
            pygame.quit()
            self._window = None
