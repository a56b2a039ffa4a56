"""Guardian decision time: observation in, action out, one state (issue figures).

Run: ``python -m benchmarks.perf_guardians``.  Prints, for every available guardian, the
median and 90th percentile of its decisions over an episode stream on ``Dubins4DGuarded-v0``,
twice: **wall** time (``time.perf_counter``) and the calling thread's **CPU** time
(``time.thread_time_ns``).  On a quiet machine the two agree; on a shared one the wall time
also counts the moments the process waited for a core, which the CPU time leaves out (it still
feels cache and memory contention), so the CPU column is the figure to compare across
machines of unknown load.  Then, for the LRMM, its inference next to the same network in torch
(measured in the same run).  Then the guardians that serve other systems, on those systems'
blocking envs (:data:`OTHER_SYSTEMS`).
"""

from __future__ import annotations

import statistics
import time

import gymnasium as gym
import numpy as np

import rmm_envs  # noqa: F401
from rmm_guardians import available_guardians, make_guardian

#: ``(env id, guardian, decisions)`` timed after the Dubins4D ones (the blocking env of each system).
OTHER_SYSTEMS = [
    ("QuadrotorRoomGuarded-v0", "cbf", 1000),
    ("QuadrotorRoomGuarded-v0", "lrmm", 1000),
    ("Dubins3DMazeGuarded-v0", "lrmm", 1000),
    ("Dubins3DMazeGuarded-v0", "cbf", 1000),
]
#: ``lrmm`` rating the driver's own command on Dubins4D (the decision of the reproduction report's
#: ``lrmm-rated-dubins4d`` table, not the shipped one), timed with the Dubins4D guardians
RATED = {
    "threshold": 0.4,
    "strategies": "SafestCandidate(), RatedDriver(), Commit(steps=18), Restart(speed=0.7, turn=True)",
}


def decision_times(guardian, env_id="Dubins4DGuarded-v0", steps=3000, seed=0, cpu: list | None = None) -> list[float]:
    """Wall seconds of each of ``steps`` decisions; when ``cpu`` is a list, the thread CPU
    seconds of each decision are appended to it."""
    env = gym.make(env_id)
    obs, info = env.reset(seed=seed)
    guardian.reset(
        seed=seed,
        observation_space=env.observation_space,
        action_space=env.action_space,
        privileged=env.unwrapped.privileged,
    )
    times = []
    ep = 0
    for _ in range(steps):
        c0 = time.thread_time_ns()
        t0 = time.perf_counter()
        a = guardian.act(obs, info)
        times.append(time.perf_counter() - t0)
        if cpu is not None:
            cpu.append((time.thread_time_ns() - c0) * 1e-9)
        obs, r, te, tr, info = env.step(a)
        if te or tr:
            ep += 1
            obs, info = env.reset(seed=seed + ep)
            guardian.reset(
                seed=seed + ep,
                observation_space=env.observation_space,
                action_space=env.action_space,
                privileged=env.unwrapped.privileged,
            )
    return times


def torch_lrmm_time(model, obs, repeats=3000) -> float:
    import torch

    torch.set_num_threads(1)
    layers = []
    for W, b in model.weights:
        lin = torch.nn.Linear(W.shape[1], W.shape[0], bias=b is not None, dtype=torch.float64)
        with torch.no_grad():
            lin.weight.copy_(torch.as_tensor(W))
            if b is not None:
                lin.bias.copy_(torch.as_tensor(b))
        layers += [lin, torch.nn.Sigmoid()]
    net = torch.nn.Sequential(*layers).eval()
    lo = torch.as_tensor(model.scaler_min)
    sc = torch.as_tensor(model.scaler_scale)
    times = []
    with torch.inference_mode():
        for _ in range(repeats):
            t0 = time.perf_counter()
            x = (torch.as_tensor(obs, dtype=torch.float64) - lo) * sc
            float(net(x)[0])
            times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _row(name: str, wall: list[float], cpu: list[float]) -> str:
    """One line of the table: wall and CPU medians and 90th percentiles, in microseconds."""
    return (
        f"  {name:10s} {statistics.median(wall) * 1e6:9.1f} us {np.quantile(wall, 0.9) * 1e6:7.1f} us "
        f"{statistics.median(cpu) * 1e6:9.1f} us {np.quantile(cpu, 0.9) * 1e6:7.1f} us"
    )


def main() -> None:
    print(
        "Guardian decision time (observation in, action out), Dubins4DGuarded-v0, one process; "
        "targets: lrmm <= 20 us, cbf <= 100 us, hj <= 50 us"
    )
    print(f"  {'':10s} {'wall median':>12s} {'wall p90':>10s} {'CPU median':>12s} {'CPU p90':>10s}")
    for name in available_guardians():
        g = make_guardian(name)
        cpu: list[float] = []
        t = decision_times(g, cpu=cpu)
        print(_row(name, t, cpu))
    cpu = []
    t = decision_times(make_guardian("lrmm", **RATED), cpu=cpu)
    print(_row("lrmm rated", t, cpu) + "  (threshold 0.4, " + RATED["strategies"] + ")")
    print("Guardians on other systems (the same measure)")
    for env_id, name, steps in OTHER_SYSTEMS:
        cpu = []
        t = decision_times(make_guardian(name, env_id=env_id), env_id=env_id, steps=steps, cpu=cpu)
        print(_row(name, t, cpu) + f"  on {env_id}")
    lrmm = make_guardian("lrmm")
    obs = gym.make("Dubins4DGuarded-v0").reset(seed=0)[0]
    t_np = statistics.median(timeit_np(lrmm.model, obs))
    t_torch = torch_lrmm_time(lrmm.model, obs)
    print(
        f"LRMM network only: numpy {t_np * 1e6:.1f} us, torch {t_torch * 1e6:.1f} us ({t_torch / t_np:.1f}x); "
        "the paper reports 2.4 ms per decision; target <= 20 us"
    )


def timeit_np(model, obs, repeats=3000):
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        model.predict(obs)
        out.append(time.perf_counter() - t0)
    return out


if __name__ == "__main__":
    main()
