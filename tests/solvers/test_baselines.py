"""The baselines colony codes use today (qpcontact.solvers.baselines): CG reaches the plain
solve, BBPGD the complementarity optimum, and both report what they did not finish."""

import numpy as np
import pytest

from qpcontact import build_system, colliding, find_contacts, reference_solution
from qpcontact.errors import InvalidArgumentError, UnknownSolverError
from qpcontact.resolve import metrics
from qpcontact.solvers import Problem, available_solvers, get_solver, solve, solve_min_norm
from qpcontact.solvers.baselines import bbpgd, conjugate_gradient
from qpcontact.studies import scenes
from tests.helpers import assert_kkt


@pytest.fixture(scope="module")
def colony():
    cells = scenes.colony_2d(150, seed=5)
    active, b = colliding(find_contacts(cells))
    return cells, build_system(cells, active, b)


def test_cg_converges_to_the_plain_linear_solve(colony):
    _, system = colony
    lin = solve_min_norm(system.matrix, system.rhs, tolerance=1e-13)
    out = conjugate_gradient(system.matrix, system.rhs, tolerance=1e-10)
    assert out.converged and out.status == "converged" and out.iterations > 1
    assert metrics.distance(out.y, lin.y) < 1e-8
    assert metrics.distance(out.y, reference_solution(system, "least_squares")) < 1e-8


def test_bbpgd_converges_to_the_complementarity_answer(colony):
    _, system = colony
    reference = reference_solution(system, "complementarity")
    out = bbpgd(system.matrix, system.rhs, tolerance=1e-10)
    assert out.converged and np.all(out.lam >= 0)
    assert metrics.complementarity_residual(system, out.y, out.lam) <= 1e-10
    assert metrics.distance(out.y, reference) < 1e-7
    assert_kkt(system, out.y, out.lam, 1e-9)
    # The complementarity answer differs from the plain solve here (the plain solve pulls).
    lin = solve_min_norm(system.matrix, system.rhs, tolerance=1e-13)
    assert np.any(lin.lam < 0) and metrics.distance(out.y, lin.y) > 1e-4


@pytest.mark.parametrize("name", ["cg", "cg_euclidean", "bbpgd"])
def test_baselines_report_non_convergence(colony, name):
    _, system = colony
    out = solve(Problem.of(system), name, tolerance=1e-12, settings={"max_iterations": 2})
    assert not out.found and out.status == "max_iterations" and out.iterations == 2
    assert out.extras["residual"] > 1e-12


def test_baseline_arguments_are_checked(colony):
    _, system = colony
    with pytest.raises(InvalidArgumentError, match="tolerance"):
        bbpgd(system.matrix, system.rhs, tolerance=0.0)
    with pytest.raises(InvalidArgumentError, match="metric"):
        conjugate_gradient(system.matrix, system.rhs, metric="L1")
    with pytest.raises(UnknownSolverError, match="unknown solver 'pgs'"):
        solve(Problem.of(system), "pgs", tolerance=1e-6)


def test_baselines_are_registered_but_not_offered_by_default():
    assert {"cg", "cg_euclidean", "bbpgd"} <= set(available_solvers(include_baselines=True))
    assert not {"cg", "cg_euclidean", "bbpgd"} & set(available_solvers())
    assert get_solver("cg").plain and get_solver("cg").forms == ("normal_equations",)
    assert get_solver("bbpgd").formulations == ("complementarity",) and get_solver("bbpgd").warm_start
