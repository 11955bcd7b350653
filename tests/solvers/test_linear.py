"""The plain linear solve: the Cholesky route (regularized, refined) gives the minimum-norm
least-squares answer where LU does and where LU cannot (singular Delassus operator), it warns when
its answer pulls, and compare_with_linear solves once per result."""

import warnings

import numpy as np
import pytest

import qpcontact as qc
from qpcontact.errors import PullingImpulseWarning, SolverFailedError
from qpcontact.resolve import validation
from qpcontact.solvers import solve_min_norm
from tests.helpers import pulling_scene, random_scene, system_of
from tests.resolve.test_resolve import jammed_packing


def test_cholesky_equals_lu_and_lsmr_on_a_regular_system():
    system = system_of(random_scene(3, n_cells=30))
    chol = solve_min_norm(system.matrix, system.rhs, tolerance=1e-12, method="cholesky")
    lu = solve_min_norm(system.matrix, system.rhs, tolerance=1e-12, method="lu")
    lsmr = solve_min_norm(system.matrix, system.rhs, tolerance=1e-12, method="lsmr")
    assert chol.method == "cholesky" and chol.consistent
    scale = np.linalg.norm(lu.y)
    assert np.linalg.norm(chol.y - lu.y) <= 1e-9 * scale
    assert np.linalg.norm(chol.y - lsmr.y) <= 1e-7 * scale
    assert np.allclose(system.matrix.T @ chol.lam, chol.y, atol=1e-12 * scale)
    assert solve_min_norm(system.matrix, system.rhs).method == "cholesky"  # the default route


def test_cholesky_solves_where_the_delassus_operator_is_singular():
    """A jammed packing has more contacts than unknowns: B̃B̃ᵀ is singular. Without position
    correction ``b = −u`` is in the range of B̃, and the regularized, refined Cholesky gives LSMR's
    minimum-norm answer."""
    system = system_of(jammed_packing())
    assert system.shape[0] > system.shape[1]  # rank(B̃B̃ᵀ) ≤ n < K
    chol = solve_min_norm(system.matrix, system.rhs, tolerance=1e-10, method="cholesky")
    lsmr = solve_min_norm(system.matrix, system.rhs, tolerance=1e-12, method="lsmr")
    assert chol.consistent and lsmr.consistent
    assert np.linalg.norm(chol.y - lsmr.y) <= 1e-6 * np.linalg.norm(lsmr.y)


def test_an_inconsistent_system_falls_back_to_lsmr():
    """With position correction the jammed packing's ``Mx = b`` has no solution: the Cholesky
    route stalls (the residual's part outside the range of B̃ is amplified by 1/δ into λ̃) and
    says so, and the default route gives LSMR's least-squares answer."""
    system = system_of(jammed_packing(), position_correction=0.5, dt=0.01)
    with pytest.raises(SolverFailedError, match="Cholesky answer failed the optimality check"):
        solve_min_norm(system.matrix, system.rhs, tolerance=1e-10, method="cholesky")
    auto = solve_min_norm(system.matrix, system.rhs, tolerance=1e-10)
    lsmr = solve_min_norm(system.matrix, system.rhs, tolerance=1e-10, method="lsmr")
    assert auto.method == "lsmr" and not auto.consistent
    assert np.allclose(auto.y, lsmr.y)


def test_the_plain_solve_warns_and_says_so_when_it_pulls():
    cells = pulling_scene()
    with pytest.warns(PullingImpulseWarning, match="answer pulls at some contacts"):
        result = qc.resolve(cells, solver="linear")
    assert result.pulling > 0 and result.pulling == int(np.sum(result.contact_impulses < 0))
    assert f"pulls at {result.pulling} contacts" in result.status


def test_the_plain_solve_is_quiet_when_every_contact_pushes():
    two = qc.Cells([[0.0, 0.0, 0.0], [0.9, 0.0, 0.0]], [0.0, 1.0, 0.0], 1.0, 0.5, momenta=[[1.0, 0, 0], [-1.0, 0, 0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error", PullingImpulseWarning)
        result = qc.resolve(two, solver="linear")
    assert result.pulling == 0 and result.contact_impulses[0] > 0


def test_compare_with_linear_solves_once_per_result(monkeypatch):
    result = qc.resolve(random_scene(4, n_cells=20), solver="clarabel", tolerance=1e-8)
    calls = []

    def counting(*args, **kwargs):
        calls.append(1)
        return solve_min_norm(*args, **kwargs)

    monkeypatch.setattr(validation, "solve_min_norm", counting)
    first = qc.compare_with_linear(result)
    second = qc.compare_with_linear(result, tolerance=1e-3)
    assert len(calls) == 1
    assert result.linear_solution is not None
    assert first.distance == second.distance
