"""Make ``hj_circle_reference.npz``: the fine-grid answer of the HJ circle convergence case.

The case (issue 13): the backward reachable tube of one circle of radius 3 at the origin for
Dubins4D with ``|u1| <= 0.25``, ``|u2| <= 0.5``, speed dynamics on ``v in [0, 4]`` (no speed
clamp below the grid's top), horizon 4 s, on the grid ``x, y in [-15, 15]`` (41 points),
heading periodic on ``[-pi, pi)`` (21 points), ``v in [0, 4]`` (21 points).

The reference is the ENO2 / TVD-RK3 solution on the grid refined ``--refine`` times per axis
(default 2: 81 x 81 x 42 x 41 nodes, 11 M; about a minute on two cores), whose nodes include
every node of the 41-point grid.  Only what the test needs is stored: the sign of ``V`` at
the coarse nodes, packed into bits (93 kB), and the unsafe fraction.

Run from the repository root: ``python tests/data/make_hj_circle_reference.py [--refine 2]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
OUT = HERE / "hj_circle_reference.npz"


def circle_case(refine: int = 1):
    """``(grid, dynamics, target)`` of the case on the grid refined ``refine`` times."""
    from rmm_guardians.hj.dynamics import Dubins4DHJ
    from rmm_guardians.hj.grid import Grid
    from rmm_guardians.hj.guardian import obstacle_target

    k = int(refine)
    grid = Grid(
        [-15.0, -15.0, -np.pi, 0.0],
        [15.0, 15.0, np.pi, 4.0],
        [40 * k + 1, 40 * k + 1, 21 * k, 20 * k + 1],
        periodic=[2],
    )
    return grid, Dubins4DHJ(v_max=4.0), obstacle_target(grid, np.array([[0.0, 0.0, 3.0]]))


def save_reference(V_fine: np.ndarray, refine: int, path: Path = OUT) -> None:
    k = int(refine)
    unsafe = V_fine[::k, ::k, ::k, ::k] <= 0
    assert unsafe.shape == (41, 41, 21, 21), unsafe.shape
    np.savez_compressed(
        path,
        unsafe_bits=np.packbits(unsafe.reshape(-1)),
        shape=np.array(unsafe.shape),
        refine=k,
        unsafe_fraction=unsafe.mean(),
    )


def load_reference(path: Path = OUT) -> np.ndarray:
    with np.load(path) as z:
        shape = tuple(int(n) for n in z["shape"])
        return np.unpackbits(z["unsafe_bits"])[: int(np.prod(shape))].reshape(shape).astype(bool)


def main(argv=None) -> None:
    from rmm_guardians.hj.solver import solve_brt

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--refine", type=int, default=2)
    args = ap.parse_args(argv)
    grid, dyn, target = circle_case(args.refine)
    V, info = solve_brt(grid, dyn, target, 4.0, order=2, rk=3)
    save_reference(V, args.refine)
    print(
        f"refine {args.refine}: {info['steps']} steps, {info['seconds']:.1f} s; unsafe fraction {np.mean(load_reference()):.5f}"
    )


if __name__ == "__main__":
    main()
