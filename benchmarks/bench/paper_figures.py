"""``rmm-bench riskmap`` and ``rmm-bench quadrisk``: the paper's figures of a learned risk model at work.

    rmm-bench riskmap --world-seed 3 --png riskmap.png     # Fig. 1: maze states coloured by inferred risk
    rmm-bench riskmap --labels                       # ... by the sampling tree's risk instead
    rmm-bench quadrisk --world-seed 1 --png quadrisk.png # Fig. 3: the quadrotor coloured by inferred risk

``riskmap`` samples ``--n`` states (default 1,000, the figure's density) in a freshly
generated maze (``--maze``, ``--world-seed``) and draws each as an arrow coloured green to red by
the risk the LRMM model infers from its local observation (default: the model shipped for
``Dubins3DMaze-v0``; ``--model`` another file), or with ``--labels`` by the sampling-tree
risk that labels the training data (the estimator's defaults, n=32, m=2, t=2 s).
``quadrisk`` renders the quadrotor in three hand-picked situations (level and still; tilted
and flying at a wall; upside down and falling) in a room 3 m high, its body coloured by the
risk the shipped ``QuadrotorRoom-v0`` model infers.  Both write a PNG (``--png``, ``--dpi``,
default 110: legible on screen at a small file size).

These commands live in ``benchmarks`` because they load a guardian's model: the packages stack
``benchmarks`` -> ``guardians`` -> ``rmm_envs``, and ``rmm-envs`` (the environments' own
command) imports no guardian.  They are subcommands of ``rmm-bench``, the command of this
package, rather than a console script of their own, so an existing install gains them
without reinstalling.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np

import rmm_envs  # noqa: F401  (registers the environments)
from rmm_bench.options import refuse
from rmm_envs.risk import RiskEstimator
from rmm_envs.systems.maze.env import Dubins3DMazeEnv
from rmm_envs.systems.maze.mazes import render_occupancy
from rmm_envs.systems.quadrotor.env import QuadrotorRoomEnv
from rmm_guardians.lrmm.model import LRMMModel, default_model_path

__all__ = ["quadrisk", "quadrisk_cmd", "quadrisk_parser", "riskmap", "riskmap_cmd", "riskmap_parser"]


def _png(out) -> Path:
    """Where a figure goes: ``out``, with ``.png`` added when it has no suffix (as matplotlib
    adds it), so the path printed is the file written."""
    path = Path(out)
    return path if path.suffix else path.with_name(path.name + ".png")


def riskmap(args: argparse.Namespace) -> int:
    """The paper's Fig. 1: sampled states in a maze as arrows coloured by inferred risk."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    env = gym.make("Dubins3DMaze-v0", maze_kind=args.maze).unwrapped
    if not isinstance(env, Dubins3DMazeEnv):
        raise TypeError(f"Dubins3DMaze-v0 made a {type(env).__name__}, not the Dubins3DMazeEnv this figure draws")
    env.reset(seed=args.world_seed)
    rng = np.random.default_rng(args.world_seed)
    states = env.sample_states(rng, args.n)
    obs = env.observe_states(states)
    if args.labels:
        risk = RiskEstimator(env.risk_scene()).estimate(states, rng).risk
        what = "sampling-tree risk (n=32, m=2, t=2 s)"
    else:
        model = LRMMModel.load(args.model or default_model_path("Dubins3DMaze-v0"), env_id="Dubins3DMaze-v0")
        risk = np.asarray(model.predict(obs))  # a batch: an array (a float only for one observation)
        what = "inferred risk (LRMM)"
    maze = env.risk_scene().maze
    occ = render_occupancy(maze, resolution=maze.thickness / 3)
    fig, ax = plt.subplots(figsize=(9, 8))
    ax.imshow(occ, cmap="gray_r", origin="lower", extent=(0, maze.width, 0, maze.height), alpha=0.9)
    L = 45.0
    q = ax.quiver(
        states[:, 0],
        states[:, 1],
        L * np.cos(states[:, 2]),
        L * np.sin(states[:, 2]),
        risk,
        cmap="RdYlGn_r",
        angles="xy",
        scale_units="xy",
        scale=1.0,
        width=0.0025,
        clim=(0, 1),
    )
    fig.colorbar(q, ax=ax, label=what)
    ax.set_title(f"{len(states)} sampled states in a {args.maze} maze (seed {args.world_seed}); arrow base = position")
    ax.set_xlim(0, maze.width)
    ax.set_ylim(0, maze.height)
    ax.set_aspect("equal")
    fig.tight_layout()
    out = _png(args.png)
    fig.savefig(out, dpi=args.dpi)
    print(f"wrote {out}: mean risk {risk.mean():.3f}, {np.mean(risk > 0.5) * 100:.0f}% of states above 0.5")
    return 0


def quadrisk(args: argparse.Namespace) -> int:
    """The paper's Fig. 3: the quadrotor in a room coloured green to red by its inferred risk."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pybullet as p

    env = gym.make("QuadrotorRoom-v0", render_mode="rgb_array").unwrapped
    if not isinstance(env, QuadrotorRoomEnv):
        raise TypeError(f"QuadrotorRoom-v0 made a {type(env).__name__}, not the QuadrotorRoomEnv this figure draws")
    env.reset(seed=args.world_seed, options={"room": {"wall_height": 3.0}})
    model = LRMMModel.load(args.model or default_model_path("QuadrotorRoom-v0"), env_id="QuadrotorRoom-v0")
    room = env.room
    if room is None:  # reset builds the room
        raise RuntimeError("QuadrotorRoom-v0 has no room after reset")
    cells = np.argwhere(room.footprint)
    centre = room.origin + (cells[np.argmin(np.linalg.norm(cells - cells.mean(axis=0), axis=1))] + 0.5) * room.cell
    edge = room.origin + (cells[np.argmin(cells[:, 0])] + 0.5) * room.cell  # a cell at the footprint's -x edge
    tilt = p.getQuaternionFromEuler([0.0, -0.5, np.pi])
    flip = p.getQuaternionFromEuler([np.pi, 0.0, 0.0])
    cases = [
        ("level and still, mid-room, 2 m up", [centre[0], centre[1], 2.0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0]),
        ("tilted, flying at a wall at 3 m/s", [edge[0] + 1.0, edge[1], 1.5, *tilt, -3.0, 0, 0, 0, 0, 0]),
        ("upside down, falling near the floor", [centre[0], centre[1], 0.6, *flip, 0, 0, -2.0, 1.0, 0, 0]),
    ]
    states = np.array([c[1] for c in cases], dtype=float)
    risk = np.asarray(model.predict(env.observe_states(states)))  # a batch: an array
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    for ax, (name, _), st, r in zip(axes, cases, states, risk, strict=True):  # three cases, three panels
        env.set_state(st)
        p.changeVisualShape(env.body, -1, rgbaColor=[float(r), 1.0 - float(r), 0.0, 1.0], physicsClientId=env.client)
        view = p.computeViewMatrixFromYawPitchRoll(
            st[:3].tolist(), 3.0, 45.0, -60.0, 0.0, 2, physicsClientId=env.client
        )
        proj = p.computeProjectionMatrixFOV(60.0, 4 / 3, 0.05, 100.0, physicsClientId=env.client)
        _, _, rgba, _, _ = p.getCameraImage(
            320, 240, view, proj, renderer=p.ER_TINY_RENDERER, physicsClientId=env.client
        )
        ax.imshow(np.asarray(rgba, dtype=np.uint8).reshape(240, 320, 4)[..., :3])
        ax.set_title(f"{name}\ninferred risk {float(r):.3f}", fontsize=9)
        ax.axis("off")
    fig.suptitle(f"QuadrotorRoom-v0 (room seed {args.world_seed}): the body coloured green to red by inferred risk")
    fig.tight_layout()
    out = _png(args.png)
    fig.savefig(out, dpi=args.dpi)
    print(f"wrote {out}: inferred risks {[round(float(r), 3) for r in risk]}")
    return 0


def riskmap_parser() -> argparse.ArgumentParser:
    rm = argparse.ArgumentParser(
        prog="rmm-bench riskmap",
        description="The paper's Fig. 1: states in a maze coloured by inferred risk, as a PNG.",
    )
    rm.add_argument("--model", default=None, help="LRMM model file (default: the shipped maze model)")
    rm.add_argument(
        "--maze", default="rectangular", choices=["rectangular", "honeycomb"], help="maze layout (default: %(default)s)"
    )
    rm.add_argument(
        "--world-seed", type=int, default=0, help="seed of the maze and of the sampled states (default: %(default)s)"
    )
    rm.add_argument("--n", type=int, default=1000, help="number of sampled states (default: %(default)s)")
    rm.add_argument("--labels", action="store_true", help="colour by the sampling tree's risk instead of the model")
    _png_options(rm, "riskmap.png")
    refuse(rm, "--kind", "use --maze rectangular or --maze honeycomb")
    return rm


def quadrisk_parser() -> argparse.ArgumentParser:
    qr = argparse.ArgumentParser(
        prog="rmm-bench quadrisk", description="The paper's Fig. 3: the quadrotor coloured by inferred risk, as a PNG."
    )
    qr.add_argument("--model", default=None, help="LRMM model file (default: the shipped quadrotor model)")
    qr.add_argument(
        "--world-seed", type=int, default=0, help="seed of the room and of the sampled states (default: %(default)s)"
    )
    _png_options(qr, "quadrisk.png")
    return qr


def _png_options(p: argparse.ArgumentParser, default: str) -> None:
    p.add_argument("--png", default=default, metavar="FILE", help="the PNG to write (default: %(default)s)")
    p.add_argument("--dpi", type=int, default=110, help="resolution of the PNG (default: %(default)s)")
    refuse(p, "--out", "write the figure with --png FILE (--out is a directory in every command)")
    refuse(p, "--seed", "use --world-seed (--seed is the master seed of a run)")


def riskmap_cmd(argv: list[str]) -> int:
    """``rmm-bench riskmap``."""
    return _figure(riskmap_parser().parse_args(argv), riskmap)


def quadrisk_cmd(argv: list[str]) -> int:
    """``rmm-bench quadrisk``."""
    return _figure(quadrisk_parser().parse_args(argv), quadrisk)


def _figure(args: argparse.Namespace, draw) -> int:
    if getattr(args, "n", 1) < 1:
        raise ValueError(f"--n must be >= 1, got {args.n}")
    if args.dpi < 1:
        raise ValueError(f"--dpi must be >= 1, got {args.dpi}")
    return draw(args)
