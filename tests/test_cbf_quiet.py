"""OSQP's unasked-for line is kept out of the process's standard output, and nothing else is."""

import sys

import numpy as np
import osqp
import pytest
import scipy.sparse as sp

from rmm_guardians.cbf.quiet import quietly


def _unconstrained_solver():
    """min x^2 over -1 <= x <= 1 with polishing: the optimum 0 has no active row."""
    s = osqp.OSQP()
    s.setup(
        sp.csc_matrix([[2.0]]),
        np.zeros(1),
        sp.csc_matrix([[1.0]]),
        np.array([-1.0]),
        np.array([1.0]),
        verbose=False,
        polishing=True,
    )
    return s


def test_the_polishing_line_is_dropped_and_the_solution_kept(capsys):
    s = _unconstrained_solver()
    s.solve(raise_error=False)
    if "Polishing not needed" not in capsys.readouterr().out:
        pytest.skip("this OSQP does not print the line")
    res = quietly(lambda: s.solve(raise_error=False))
    assert capsys.readouterr().out == ""
    assert res.info.status_val == 1 and abs(res.x[0]) < 1e-9


def test_output_before_and_after_the_solve_reaches_standard_output(capsys):
    print("before")
    stream = sys.stdout
    assert quietly(lambda: print("inside") or 7) == 7
    assert sys.stdout is stream
    print("after")
    assert capsys.readouterr().out == "before\nafter\n"


def test_an_exception_in_the_solve_puts_standard_output_back(capsys):
    stream = sys.stdout
    with pytest.raises(ZeroDivisionError):
        quietly(lambda: 1 / 0)
    assert sys.stdout is stream
    print("still here")
    assert capsys.readouterr().out == "still here\n"


def test_the_cbf_solvers_print_nothing_when_no_row_is_active(capsys):
    """The quadrotor command QP (direct OSQP, polished) with its one barrier row far from active,
    and the Dubins4D CBF-CLF QP filtering a reference inside every row: solved, nothing printed."""
    from rmm_guardians.cbf.quadrotor_rows import CommandQP
    from tests.test_cbf_solvers import dubins4d

    lo, hi = np.array([-2.0, -2.0, -1.0]), np.array([2.0, 2.0, 1.0])
    qp = CommandQP(1, lo, hi, slack_weight=100.0, eps=1e-6)
    u = qp.solve(np.array([[1.0, 0.0, 0.0]]), np.array([10.0]), np.array([0.5, -0.25, 0.1]))
    np.testing.assert_allclose(u[:3], [0.5, -0.25, 0.1], atol=1e-6)
    g = dubins4d("osqp")
    u_ref = np.array([0.01, 0.02])  # gentle, at rest far from the obstacles: no row active
    z, _, _ = g.solve(np.zeros(4), u_ref)
    np.testing.assert_allclose(z[:2], u_ref, atol=1e-6)
    assert capsys.readouterr().out == ""
