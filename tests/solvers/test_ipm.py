"""The built-in interior-point solver (qpcontact.solvers.ipm): it reaches the complementarity
optimum (decided by an independent solver and by the KKT conditions), honours bounds on the
unknowns, reports what it could not do, and is reachable through the registry and resolve."""

import numpy as np
import pytest
import scipy.sparse as sp

import qpcontact as qc
from qpcontact import solvers
from qpcontact.errors import InvalidArgumentError
from qpcontact.resolve import metrics
from qpcontact.resolve.validation import reference_solution
from qpcontact.solvers.ipm import interior_point
from qpcontact.studies import scenes
from tests.helpers import random_scene


def system_of(cells):
    active, b = qc.colliding(qc.find_contacts(cells))
    return qc.build_system(cells, active, b)


def random_problem(seed, k=50, n=70):
    rng = np.random.default_rng(seed)
    B = (sp.random(k, n, density=0.08, random_state=seed, format="csr") + sp.eye(k, n, format="csr")).tocsr()
    return B, rng.standard_normal(k), rng


def assert_bounded_kkt(B, b, lower, upper, y, lam, tol):
    """KKT of min ½‖y‖² s.t. By ≥ b, l ≤ y ≤ u, with the bound multipliers recovered from the
    stationarity residual: r = y − Bᵀλ must be ≥ 0 only where y sits on its lower bound and
    ≤ 0 only where it sits on its upper bound."""
    slack = B @ y - b
    assert slack.min() >= -tol
    assert lam.min() >= 0
    assert np.max(np.abs(np.minimum(lam / max(1.0, lam.max()), slack))) <= tol
    assert np.all(y >= lower - tol) and np.all(y <= upper + tol)
    r = y - B.T @ lam
    at_lower, at_upper = np.abs(y - lower) <= 1e-6, np.abs(y - upper) <= 1e-6
    assert np.all(np.abs(r[~at_lower & ~at_upper]) <= 1e-5)
    assert np.all(r[at_lower & ~at_upper] >= -1e-5)
    assert np.all(r[at_upper & ~at_lower] <= 1e-5)


@pytest.mark.parametrize("scene", [
    lambda: random_scene(3, n_cells=60),
    lambda: scenes.colony_2d(400, 1),
    lambda: scenes.colony_3d(300, 2),
])
def test_ipm_reaches_the_complementarity_optimum(scene):
    system = system_of(scene())
    reference = reference_solution(system, "complementarity")
    out = interior_point(system.matrix, system.rhs, tolerance=1e-9)
    assert out.converged and out.status == "converged"
    assert metrics.distance(out.y, reference) < 1e-5
    assert np.all(out.lam >= 0)
    assert metrics.penetration(system, out.y) <= 1e-8


def feasible_bounds(B, b, rng):
    """Bounds on about a third of the columns each side that keep a known point feasible (the
    unbounded optimum pushed further in the direction of B̃ᵀ1) but cut the unbounded optimum
    itself, so that some bounds bind."""
    n = B.shape[1]
    free = interior_point(B, b, tolerance=1e-10).y
    inside = free + 0.5 * np.abs(free).max() * (B.T @ np.ones(B.shape[0])) / np.abs(B.T @ np.ones(B.shape[0])).max()
    assert np.all(B @ inside - b >= -1e-9)
    width = np.abs(inside - free) + 0.05
    lower = np.where(rng.random(n) < 0.3, np.minimum(inside, free + 0.5 * width) - 1e-3, -np.inf)
    upper = np.where(rng.random(n) < 0.3, np.maximum(inside, free - 0.5 * width) + 1e-3, np.inf)
    return lower, upper


@pytest.mark.parametrize("seed", range(6))
def test_ipm_honours_bounds_and_agrees_with_clarabel(seed):
    B, b, rng = random_problem(seed)
    lower, upper = feasible_bounds(B, b, rng)
    out = interior_point(B, b, lower, upper, tolerance=1e-10)
    assert out.converged
    assert_bounded_kkt(B, b, lower, upper, out.y, out.lam, 1e-8)
    ref = solvers.solve(solvers.Problem(B, b, lower=lower, upper=upper), "clarabel", "complementarity", "primal",
                        tolerance=1e-10)
    assert ref.found
    assert np.max(np.abs(out.y - ref.y)) < 1e-6
    free = interior_point(B, b, tolerance=1e-10).y
    assert np.max(np.abs(out.y - free)) > 1e-3  # the bounds bind: the test is not the unbounded one


def test_bounds_that_bind_change_the_answer():
    """Bounds at half the unbounded answer's largest entries must be active in the bounded one."""
    B, b, _ = random_problem(11)
    free = interior_point(B, b, tolerance=1e-10)
    cap = 0.5 * np.abs(free.y).max()
    bounded = interior_point(B, b, np.full(B.shape[1], -cap), np.full(B.shape[1], cap), tolerance=1e-10)
    if bounded.converged:  # the bounded problem may have no solution; then it must not claim one
        assert np.abs(bounded.y).max() <= cap * (1 + 1e-8)
        assert np.isclose(np.abs(bounded.y).max(), cap)
    else:
        assert bounded.status in ("stalled", "max_iterations")


def test_an_empty_bound_interval_is_reported_infeasible():
    B, b, _ = random_problem(1)
    n = B.shape[1]
    lower, upper = np.zeros(n), np.zeros(n)
    lower[3], upper[3] = 1.0, 0.5
    out = interior_point(B, b, lower, upper)
    assert not out.converged and out.status == "infeasible"


def test_conflicting_bounds_and_contacts_are_not_claimed_solved():
    """A contact asking for ỹ₀ ≥ 1 with ỹ₀ ≤ 0.5 has no solution."""
    B = sp.csr_matrix(np.array([[1.0, 0.0], [0.0, 1.0]]))
    out = interior_point(B, np.array([1.0, 0.2]), np.full(2, -np.inf), np.array([0.5, np.inf]), tolerance=1e-8,
                         max_iterations=60)
    assert not out.converged


def test_time_limit_and_iteration_cap_are_reported():
    system = system_of(scenes.colony_2d(300, 0))
    out = interior_point(system.matrix, system.rhs, tolerance=1e-12, max_iterations=2)
    assert not out.converged and out.status == "max_iterations" and out.iterations == 2
    out = interior_point(system.matrix, system.rhs, tolerance=1e-12, time_limit=1e-9)
    assert not out.converged and out.status == "time_limit"


def test_registry_lists_ipm_and_rejects_bounds_for_solvers_without_them():
    assert "ipm" in solvers.available_solvers()
    spec = solvers.get_solver("ipm")
    assert spec.bounds == ("contact",) and spec.bundled
    B, b, _ = random_problem(2)
    bounded = solvers.Problem(B, b, lower=np.full(B.shape[1], -1.0))
    with pytest.raises(InvalidArgumentError, match="bounds"):
        solvers.solve(bounded, "bbpgd", "complementarity", "contact")
    with pytest.raises(InvalidArgumentError, match="bounds"):
        solvers.solve(bounded, "clarabel", "complementarity", "contact")
    ipm = solvers.solve(bounded, "ipm", "complementarity", tolerance=1e-9)
    # MPRGP takes the bounds as more contact rows; the same optimum
    rows = solvers.solve(bounded, "mprgp", "complementarity", tolerance=1e-9)
    assert ipm.found and rows.found and np.allclose(ipm.y, rows.y, atol=1e-6)
    assert np.all(rows.y >= -1.0 - 1e-9)


def test_resolve_with_ipm_passes_the_acceptance_checks():
    cells = scenes.colony_2d(500, 3)
    result = qc.resolve(cells, solver="ipm", tolerance=1e-8)
    reference = qc.resolve(cells, solver="clarabel", tolerance=1e-10)
    assert result.converged
    assert np.max(np.abs(result.impulses - reference.impulses)) <= 1e-5 * np.max(np.abs(reference.impulses))


def test_the_objective_s_curvature_gives_the_qp_s_own_answer():
    """``curvature=(R, ỹ₀)``: min ½‖ỹ‖² + ½‖R(ỹ − ỹ₀)‖² with bounds, as Clarabel solves it; R
    coupling unknowns no contact row couples (its own pattern) and, through solve(), blockwise."""
    import qpsolvers
    import scipy.sparse as sp

    from qpcontact.solvers import Problem, solve
    from qpcontact.solvers.ipm import interior_point

    rng = np.random.default_rng(0)
    k, n = 60, 40
    B = sp.random(k, n, density=0.1, random_state=1, format="csr")
    b = rng.standard_normal(k)
    R = sp.random(30, n, density=0.1, random_state=2, format="csr") * 3
    anchor = rng.standard_normal(n)
    lower, upper = np.full(n, -2.0), np.full(n, 2.0)
    out = interior_point(B, b, lower, upper, tolerance=1e-8, curvature=(R, anchor))
    expected = qpsolvers.solve_qp(sp.csc_matrix(sp.identity(n) + R.T @ R), -(R.T @ (R @ anchor)),
                                  G=sp.csc_matrix(-B), h=-b, lb=lower, ub=upper, solver="clarabel")
    assert out.converged and np.abs(out.y - expected).max() < 1e-6
    # Through the registry: the same answer; a solver that takes no curvature is refused by name.
    problem = Problem(B, b, lower=lower, upper=upper, curvature=R, anchor=anchor)
    assert np.abs(solve(problem, "ipm", tolerance=1e-8).y - expected).max() < 1e-6
    with pytest.raises(InvalidArgumentError, match="curvature"):
        solve(problem, "mprgp", tolerance=1e-8)


def test_a_curvature_is_split_with_its_blocks(monkeypatch):
    """Problem.block keeps each block's curvature rows and anchor: two independent problems
    solved blockwise give the answer of the whole one."""
    from qpcontact.solvers import Problem, blocks, solve

    monkeypatch.setattr(blocks, "BLOCK_ROWS", 1)  # each component its own block

    rng = np.random.default_rng(4)
    parts = [sp.random(20, 12, density=0.3, random_state=s, format="csr") + sp.eye(20, 12, format="csr")
             for s in (5, 6)]
    B = sp.block_diag(parts, format="csr")
    R = sp.block_diag([sp.random(6, 12, density=0.3, random_state=s) for s in (7, 8)], format="csr")
    problem = Problem(B, rng.standard_normal(40), curvature=R, anchor=rng.standard_normal(24))
    whole = solve(problem, "ipm", tolerance=1e-9, split=False)
    blockwise = solve(problem, "ipm", tolerance=1e-9)
    assert blockwise.extras["blocks"] == 2 and blockwise.found and whole.found
    assert np.abs(blockwise.y - whole.y).max() < 1e-6
    with pytest.raises(InvalidArgumentError, match="both"):
        solve(Problem(B, problem.rhs, curvature=R), "ipm")


def test_a_family_shares_its_set_up_and_a_new_family_never_depends_on_the_last(monkeypatch):
    """Problems of one family (a step's linearizations) grow their normal matrix from the last
    one's (:func:`qpcontact.solvers.ipm._gram_matrix`) and get the answers they get alone; a
    problem of another family gets, bit for bit, the answer it gets with nothing solved before
    it (a resumed run takes the same steps)."""
    import qpcontact.solvers.ipm as ipm
    from qpcontact.solvers import cholesky
    from tests.solvers.test_cholesky import _grown_pair

    monkeypatch.setattr(cholesky, "METIS_SIZE", 0)  # an ordering of its own to inherit
    first, second = _grown_pair(11)
    rhs = np.random.default_rng(12).standard_normal(second.shape[0])
    step = object()
    monkeypatch.setattr(ipm, "_LAST", [])
    interior_point(first, rhs[:first.shape[0]], tolerance=1e-8, family=step)
    grown = interior_point(second, rhs, tolerance=1e-8, family=step)
    assert ipm._LAST[0].inherited
    alone = interior_point(second, rhs, tolerance=1e-8)
    assert grown.converged and alone.converged
    assert np.abs(grown.y - alone.y).max() <= 1e-6 * max(1.0, np.abs(alone.y).max())
    # the same pattern in a new family: not the inherited ordering (refreshed only within its family)
    after = interior_point(second, rhs, tolerance=1e-8, family=object())
    assert not ipm._LAST[0].inherited
    monkeypatch.setattr(ipm, "_LAST", [])
    fresh = interior_point(second, rhs, tolerance=1e-8, family=object())
    assert np.array_equal(after.y, fresh.y) and np.array_equal(after.lam, fresh.lam)
