"""The built-in matrix-free solver (qpcontact.solvers.mprgp): it finds the complementarity optimum where
the plain solve would pull, is invariant to the row scaling it undoes, reports what it did not
finish, and takes only the formulation it solves."""

import numpy as np
import pytest
import scipy.sparse as sp

import qpcontact as qc
from qpcontact.errors import InvalidArgumentError, SolverFailedError
from qpcontact.resolve import metrics
from qpcontact.resolve.validation import reference_solution
from qpcontact.solvers.mprgp import mprgp
from qpcontact.studies import scenes
from tests.helpers import assert_kkt, pulling_scene, random_scene


def system_of(cells):
    active, b = qc.colliding(qc.find_contacts(cells))
    return qc.build_system(cells, active, b)


@pytest.mark.parametrize("scene", [
    lambda: random_scene(3, n_cells=60),
    lambda: scenes.colony_2d(400, 1),
    lambda: scenes.colony_3d(400, 2),
])
def test_mprgp_reaches_the_complementarity_optimum(scene):
    system = system_of(scene())
    reference = reference_solution(system, "complementarity")
    out = mprgp(system.matrix, system.rhs, tolerance=1e-9)
    assert out.converged and out.status == "converged" and out.residual <= 1e-9
    assert metrics.distance(out.y, reference) < 1e-6
    assert np.all(out.lam >= 0)
    assert np.allclose(out.y, system.matrix.T @ out.lam)
    assert metrics.penetration(system, out.y) <= 1e-8


def test_mprgp_finds_the_contacts_that_stop_pushing():
    """On a scene where the plain solve pulls, the answer has contacts at the bound, and it is
    the optimum: the KKT conditions of the complementarity QP hold (an independent certificate,
    whatever solver produced the answer), and Clarabel finds the same answer."""
    cells = pulling_scene()
    result = qc.resolve(cells, solver="mprgp", tolerance=1e-9)
    assert result.converged and np.any(result.contact_impulses == 0)
    assert_kkt(result.system, result.scaled_solution, result.system.from_contact_impulses(result.contact_impulses), 1e-8)
    clarabel = qc.resolve(cells, solver="clarabel", tolerance=1e-10)
    assert metrics.distance(result.scaled_solution, clarabel.scaled_solution) < 1e-6


def test_a_wrong_answer_fails_the_kkt_certificate():
    """The check above can fail: pulling impulses (the plain solve) or too large ones do not pass."""
    cells = pulling_scene()
    linear = qc.resolve(cells, solver="linear")
    with pytest.raises(AssertionError, match="pulling"):
        assert_kkt(linear.system, linear.scaled_solution, linear.system.from_contact_impulses(linear.contact_impulses),
                   1e-8)
    optimum = qc.resolve(cells, solver="mprgp", tolerance=1e-9)
    lam = optimum.system.from_contact_impulses(optimum.contact_impulses)
    with pytest.raises(AssertionError, match="slackness"):
        assert_kkt(optimum.system, 2 * optimum.scaled_solution, 2 * lam, 1e-8)


def test_row_scaling_does_not_change_the_answer():
    """D B̃ ỹ ≥ D b̃ is the same constraint set for any positive diagonal D; the Jacobi scaling
    inside makes the solver see the same problem."""
    system = system_of(scenes.colony_3d(300, 0))
    d = np.random.default_rng(0).uniform(1e-3, 1e3, system.matrix.shape[0])
    plain = mprgp(system.matrix, system.rhs, tolerance=1e-10)
    scaled = mprgp(sp.diags(d) @ system.matrix, d * system.rhs, tolerance=1e-10 * d.min())
    assert scaled.converged
    assert metrics.distance(scaled.y, plain.y) < 1e-7


def test_a_warm_start_at_the_answer_needs_no_iteration():
    system = system_of(scenes.colony_2d(200, 0))
    first = mprgp(system.matrix, system.rhs, tolerance=1e-8)
    again = mprgp(system.matrix, system.rhs, tolerance=1e-8, initial=first.lam)
    assert again.converged and again.iterations == 0


def test_an_unfinished_solve_is_reported_and_never_applied():
    cells = scenes.colony_3d(300, 0)
    out = mprgp(system_of(cells).matrix, system_of(cells).rhs, tolerance=1e-10, max_iterations=3)
    assert not out.converged and out.status == "max_iterations" and out.iterations == 3 and out.residual > 1e-10
    with pytest.raises(SolverFailedError, match="mprgp did not converge"):
        qc.resolve(cells, solver="mprgp", solver_settings={"max_iterations": 3})
    flagged = qc.resolve(cells, solver="mprgp", solver_settings={"max_iterations": 3}, on_failure="return")
    assert not flagged.converged and flagged.status == "max_iterations"


def test_zero_rows_are_empty_or_infeasible():
    matrix = sp.csr_matrix(np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 2.0]]))
    ok = mprgp(matrix, np.array([1.0, -0.5, 1.0]), tolerance=1e-12)
    assert ok.converged and ok.lam[1] == 0 and np.allclose(ok.y, [1.0, 0.5])
    bad = mprgp(matrix, np.array([1.0, 0.5, 1.0]))
    assert not bad.converged and bad.status == "infeasible"


def test_mprgp_takes_only_the_complementarity_formulation_and_its_own_settings():
    cells = random_scene(0, n_cells=20)
    with pytest.raises(InvalidArgumentError, match="'mprgp' solves the complementarity formulation"):
        qc.resolve(cells, solver="mprgp", formulation="least_squares")
    with pytest.raises(InvalidArgumentError, match="contact form only"):
        qc.resolve(cells, solver="mprgp", form="primal")
    with pytest.raises(InvalidArgumentError, match="mprgp takes max_iterations and proportioning"):
        qc.resolve(cells, solver="mprgp", solver_settings={"eps_abs": 1e-3})
    with pytest.raises(InvalidArgumentError, match="proportioning"):
        qc.resolve(cells, solver="mprgp", solver_settings={"proportioning": -1.0})
    with pytest.raises(InvalidArgumentError, match="tolerance"):
        mprgp(sp.eye(2, format="csr"), np.ones(2), tolerance=0.0)
