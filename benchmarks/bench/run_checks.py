"""What ``rmm-bench`` checks before any episode runs: agent names and options, the env, each guardian.

The env must offer the **parallel-autonomy contract** that the runner drives guardians
through (the Dubins4D envs' module docstring describes it in full):

* a constructor argument ``clock`` (a stopwatch measuring the guardian's compute time per
  step, read back as the env's ``clock`` attribute);
* an action space that is a :class:`rmm_envs.autonomy.GuardianActionSpace` (a ``Dict`` holding
  ``active_ctrl``, ``Discrete(2)``: 0 lets the built-in driver control the step, 1 applies the
  guardian's control, and the control fields);
* on the step that ends an episode, ``info["outcome"]`` (``goal``, ``collision``,
  ``timeout``) and ``info["episode_stats"]``, the statistics the store keeps (see
  :data:`rmm_bench.runner.EPISODE_STATISTICS`).

Of this command's env options, the env is given those its constructor takes: ``clock``
always, ``time_accel`` and ``base_step`` only if it takes them (a non-blocking env such as
``Dubins4DParallel-v0``).  The last part of the contract can only be seen when an episode
ends: an env that breaks it gets an error naming the missing key in every episode.
"""

from __future__ import annotations

import json
from typing import Any

import rmm_envs  # noqa: F401
from rmm_bench.config import AgentRun, accepts_argument, input_digests
from rmm_envs.autonomy import ACTIVE, GuardianActionSpace
from rmm_envs.catalog import guardian_envs_of
from rmm_envs.env_plugins import describe_env_error, resolve_env_id
from rmm_guardians import available_guardians, make_guardian
from rmm_guardians.registry import guardian_set, load_guardian_class

__all__ = ["check_env_contract", "check_runs", "env_arguments", "env_parameters", "parse_agent_opts", "resolve_agents"]

#: Options of this command that an env may take, in the order the run's env_kwargs list them.
ENV_OPTIONS = ("time_accel", "base_step", "clock")


def resolve_agents(spec: str) -> dict[str, Any]:
    """``--agent``: a name, a comma list, ``all``, ``paper`` or ``module:Class``; each one's class
    (or factory), resolved here once for the whole run (name -> class, in order)."""

    available = available_guardians()
    names = guardian_set(spec)
    if names is None:
        names = [s.strip() for s in spec.split(",") if s.strip()]
    if not names:
        raise ValueError(f"--agent is empty; choose from {available}, 'all', 'paper' or 'module:Class'")
    return {n: load_guardian_class(n) for n in names}  # ValueError listing the valid names


def parse_agent_opts(items: list[str], agents: list[str]) -> dict[str, dict]:
    """Parse ``AGENT.KEY=VALUE`` options (VALUE as JSON, else a string)."""
    out: dict[str, dict] = {}
    for item in items:
        head, eq, value = item.partition("=")
        agent, dot, key = head.rpartition(".")
        if not eq or not dot or not agent or not key:
            raise ValueError(f"--agent-opt {item!r}: expected AGENT.KEY=VALUE, e.g. hj.margin=0.3")
        if agent not in agents:
            raise ValueError(f"--agent-opt {item!r}: agent {agent!r} is not in this run ({agents})")
        if key == "env_id":
            raise ValueError(
                f"--agent-opt {item!r}: every guardian is built for the run's env (--env); "
                "run another --env instead of setting env_id"
            )
        try:
            parsed = json.loads(value)
        except json.JSONDecodeError:
            parsed = value
        out.setdefault(agent, {})[key] = parsed
    return out


def _env_creator(env_id: str):
    import gymnasium as gym
    from gymnasium.envs.registration import load_env_creator

    env_id = resolve_env_id(env_id)  # module:Id imported, entry points loaded; ValueError naming the id otherwise
    entry = gym.spec(env_id).entry_point
    try:
        return load_env_creator(entry) if isinstance(entry, str) else entry
    except Exception as e:
        raise ValueError(
            f"--env {env_id}: its entry point {entry!r} cannot be loaded: {type(e).__name__}: {e}"
        ) from None


def env_arguments(env_id: str) -> set[str]:
    """Which of :data:`ENV_OPTIONS` the registered env ``env_id`` takes (ValueError if it is not registered)."""
    creator = _env_creator(env_id)
    return {name for name in ENV_OPTIONS if accepts_argument(creator, name)}


def _env_flag(key: str, value) -> str:
    """How this command's user gave the env argument ``key``: its own flag, or ``--env-opt``."""
    if key in ENV_OPTIONS:
        return f"--{key.replace('_', '-')} {value}"
    return f"--env-opt {key}={json.dumps(value)}"


def env_parameters(env_id: str) -> set[str] | None:
    """The names of the registered env ``env_id``'s constructor arguments (``--env-opt`` keys), or
    None when they cannot be known (a creator taking ``**kwargs`` or without a signature)."""
    import inspect

    try:
        params = inspect.signature(_env_creator(env_id)).parameters.values()
    except (TypeError, ValueError):
        return None
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        return None
    return {p.name for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}


def env_default(env_id: str, name: str, fallback):
    """The default of the registered env ``env_id``'s constructor argument ``name`` (``fallback``
    when it takes none or states no default)."""
    import inspect

    try:
        param = inspect.signature(_env_creator(env_id)).parameters.get(name)
    except (TypeError, ValueError):  # a creator without a signature
        return fallback
    return fallback if param is None or param.default is inspect.Parameter.empty else param.default


def _action_space_lacks(space) -> str | None:

    if not isinstance(space, GuardianActionSpace):
        return (
            f"its action space is {space}, not a GuardianActionSpace (rmm_envs.autonomy: {ACTIVE!r} to take "
            "control or not, and the control)"
        )
    return None


def check_env_contract(env_id: str, env=None) -> None:
    """Raise ValueError naming ``env_id`` and what it lacks of the parallel-autonomy contract.

    ``env``: the env already built with this run's options (its action space is checked);
    without it, one is built with its defaults, and only if it takes no ``clock``."""
    lacks = []
    if "clock" not in env_arguments(env_id):
        lacks.append("its constructor takes no `clock` (the stopwatch of the guardian's compute time)")
    if env is None and lacks:
        import gymnasium as gym

        try:
            probe = gym.make(env_id)
        except Exception:  # noqa: BLE001 - what it lacks is said already
            probe = None
        if probe is not None:
            problem = _action_space_lacks(probe.action_space)
            probe.close()
            if problem:
                lacks.append(problem)
    elif env is not None:
        problem = _action_space_lacks(env.action_space)
        if problem:
            lacks.append(problem)
    if lacks:
        twins = [f"{i} ({'non-blocking' if 'Parallel' in i else 'blocking'})" for i in guardian_envs_of(env_id)]
        lacks.append(
            f"its system's guardian envs are {' and '.join(twins)}"
            if twins
            else "rmm_envs.envs.any_env.parallel(env, driver, safe_default, success) makes a guardian env of it "
            '(docs/tutorials/own-simulator.md, "The env\'s arguments")'
        )
        raise ValueError(
            f"--env {env_id}: rmm-bench runs guardians only on envs offering the parallel-autonomy contract, "
            f"and {env_id} does not: {'; '.join(lacks)}"
        )


def _keywords(agent: str, classes: dict | None) -> list[str]:
    """The keyword arguments the guardian ``agent`` takes (its constructor's named parameters)."""
    import inspect

    cls = (classes or {}).get(agent) or load_guardian_class(agent)
    try:
        params = inspect.signature(cls).parameters
    except (TypeError, ValueError):  # no signature to read
        return []
    return [n for n, q in params.items() if q.kind not in (q.VAR_POSITIONAL, q.VAR_KEYWORD) and n != "self"]


def check_runs(
    runs: dict[str, AgentRun], skip_inapplicable: bool = False, classes: dict | None = None
) -> dict[str, dict]:
    """Build the env and every guardian as the workers will, before any episode runs.

    Raises ValueError naming the flag and value at fault; returns, per agent, what ``report``
    prints later without importing anything (observation type, obstacle count) and the files
    its run reads (``inputs``: path -> SHA-256, part of the run's key).  With
    ``skip_inapplicable`` (the agents came from a named set, ``--agent all`` or ``paper``), a
    guardian that does not apply to the env (its ``check_spaces`` refuses it, or, given no
    ``--agent-opt``, it cannot be built for the env, e.g. no shipped model) is not an error: its
    entry is ``{"skipped": reason}`` instead.  ``classes``: each agent's class as the command
    resolved it (:func:`resolve_agents`); an agent not in it is resolved by name."""
    import gymnasium as gym

    meta: dict[str, dict] = {}
    envs: dict[str, int] = {}
    env_spaces: dict[str, tuple] = {}
    for agent, run in runs.items():
        ekey = json.dumps([run.env_id, run.env_kwargs], sort_keys=True)
        if ekey not in envs:
            if "clock" not in env_arguments(run.env_id):
                check_env_contract(run.env_id)
            try:
                env = gym.make(run.env_id, **run.env_kwargs)
            except Exception as e:
                raise ValueError(describe_env_error(e, run.env_id, run.env_kwargs, _env_flag)) from None
            try:
                check_env_contract(run.env_id, env)
                envs[ekey] = int(getattr(env.unwrapped, "n_obstacles", -1))  # optional: the table's Obstacles column
                env_spaces[ekey] = (env.observation_space, env.action_space)
            finally:
                env.close()
        try:
            guardian = make_guardian((classes or {}).get(agent, agent), env_id=run.env_id, **run.agent_kwargs)
        except Exception as e:
            if skip_inapplicable and not run.agent_kwargs:  # a set's member that cannot serve this env (no model)
                meta[agent] = {"skipped": f"cannot be built for it: {type(e).__name__}: {e}"}
                continue
            opts = " ".join(
                f"{agent}.{k}={v if isinstance(v, str) else json.dumps(v)}" for k, v in run.agent_kwargs.items()
            )
            where = f"--agent-opt {opts}" if opts else f"--agent {agent}"
            if isinstance(e, TypeError) and "unexpected keyword argument" in str(e):
                e = TypeError(f"{e}; {agent} takes {', '.join(_keywords(agent, classes) or ['no options'])}")
            raise ValueError(
                f"{where}: the guardian cannot be built for --env {run.env_id}: {type(e).__name__}: {e}"
            ) from None
        check = getattr(guardian, "check_spaces", None)
        if check is not None:  # what the guardian needs of the env's spaces, before any episode
            try:
                check(*env_spaces[ekey])
            except ValueError as e:
                if skip_inapplicable:
                    meta[agent] = {"skipped": str(e)}
                    continue
                raise ValueError(f"--agent {agent} does not apply to --env {run.env_id}: {e}") from None
        meta[agent] = {
            "observation": str(getattr(guardian, "observation_type", "?")),
            "n_obstacles": envs[ekey],
            "inputs": input_digests(guardian, run.agent_kwargs, run.env_kwargs),
        }
    return meta
