"""Tutorial: evaluate your own guardian, as a plain callable and as a plugin.

    python docs/examples/third_party_guardian.py

Three ways in:

1. a callable ``obs -> action`` wrapped by ``CallableGuardian`` (or an SB3 model by
   ``SB3Guardian``), run with the same loop the benchmark uses;
2. a ``Guardian`` subclass named to the benchmark as ``module:Class``
   (``rmm-bench --agent mypackage.guards:Cautious``);
3. an installed plugin: declare it in your package's ``pyproject.toml``::

       [project.entry-points."rmm_envs.guardians"]
       cautious = "mypackage.guards:Cautious"

   after ``pip install``, ``rmm-bench --agent cautious`` and ``make_guardian("cautious")`` find it.
"""

import tempfile

from rmm_bench.cli import main as rmm_bench
from rmm_guardians import CallableGuardian, Guardian


def keep_distance(obs):
    """A one-line policy: brake (and turn to the open side) when anything ahead is within 3 m."""
    rays = obs[5:]
    front = min(rays[0], rays[1], rays[-1])
    if front < 3.0:
        return [1.0, 0.25 if rays[1] > rays[-1] else -0.25, -0.5]  # [active, turn rate, accel]
    return [0.0, 0.0, 0.0]


class Cautious(Guardian):
    """A Guardian subclass: brake whenever the speed exceeds what the forward ray allows.

    It reads the observation by name (the layout of the env's observation space) and builds
    its actions through the env's action space, whose bounds give the strongest braking.
    """

    name = "cautious"
    observation_type = "local"

    def reset(self, **kwargs):
        super().reset(**kwargs)
        layout = self.require_layout("speed", "rays")  # refuses an env without these fields
        space = self.require_action_space(controls=2)  # (turn rate, acceleration)
        self.speed, self.forward = layout.index("speed"), layout.ray_index(0.0)
        self.brake = space.control_low[1]

    def act(self, obs, info):
        v, forward = obs[self.speed], obs[self.forward]
        if v * v / (2 * -self.brake) > 0.8 * forward:  # braking distance vs. free space ahead
            return self.action_space.active([0.0, self.brake])
        return self.action_space.inactive()


def main():
    import gymnasium as gym

    import rmm_envs  # noqa: F401

    # 1. a callable, in a hand-written loop
    env = gym.make("Dubins4DParallel-v0", clock="fixed:1")
    guardian = CallableGuardian(keep_distance, name="keep-distance")
    outcomes = {}
    for seed in range(5):
        obs, info = env.reset(seed=seed)
        guardian.reset(seed=seed, observation_space=env.observation_space, action_space=env.action_space)
        done = False
        while not done:
            obs, r, te, tr, info = env.step(guardian.act(obs, info))
            done = te or tr
        outcomes[info["outcome"]] = outcomes.get(info["outcome"], 0) + 1
    print("keep-distance over 5 episodes:", outcomes)
    assert sum(outcomes.values()) == 5 and set(outcomes) <= {"goal", "collision", "timeout"}

    # 2. the benchmark with a module:Class guardian next to a built-in one
    out = tempfile.mkdtemp(prefix="rmm-bench-tutorial-")
    # (this file's folder is on sys.path when it runs as a script, so it imports as a module)
    rc = rmm_bench(
        [
            "--agent",
            "third_party_guardian:Cautious,inactive",
            "--episodes",
            "6",
            "--workers",
            "1",
            "--clock",
            "fixed:1",
            "--out",
            out,
            "--no-progress",
        ]
    )
    assert rc == 0, f"rmm-bench exited with {rc}"
    table = open(f"{out}/table_I.csv").read()
    assert "third_party_guardian:Cautious," in table and "\ninactive," in table  # one row per agent
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
