"""Solving per independent block (registry.solve_by_blocks): the blocks partition the system into
uncoupled parts, the split solve equals the whole one, and a failed block gives no answer."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

import qpcontact as qc
from qpcontact.resolve import metrics
from qpcontact.solvers import Problem, blocks, get_solver, registry, solve
from qpcontact.studies import scenes


def _many_components():
    """A colony whose colliding contacts form several independent components."""
    cells = scenes.colony_2d(400, seed=2)
    active, b = qc.colliding(qc.find_contacts(cells, planar=True))
    return cells, qc.build_system(cells, active, b)


def test_independent_blocks_partition_the_system_into_uncoupled_parts():
    _, system = _many_components()
    k, n = system.shape
    parts = blocks.independent_blocks(system.matrix)
    assert len(parts) > 3
    rows = np.concatenate([r for r, _ in parts])
    cols = np.concatenate([c for _, c in parts])
    assert np.array_equal(np.sort(rows), np.arange(k)) and np.array_equal(np.sort(cols), np.arange(n))
    coo = sp.coo_matrix(system.matrix)
    merged = blocks.independent_blocks(system.matrix, min_rows=k // 3)
    assert 1 < len(merged) < len(parts)
    for partition in (parts, merged):
        row_block, col_block = np.empty(k, int), np.empty(n, int)
        for i, (r, c) in enumerate(partition):
            row_block[r], col_block[c] = i, i
        assert np.array_equal(row_block[coo.row], col_block[coo.col])  # no non-zero links two blocks


@pytest.mark.parametrize("solver, form, formulation", [
    (solver, form, formulation) for solver, form in (("osqp", "contact"), ("osqp", "primal"), ("clarabel", "primal"),
                                                     ("mprgp", "contact"))
    for formulation in ("complementarity", "least_squares") if formulation in get_solver(solver).formulations
    # OSQP's lifted least-squares contact form (not a default) does not reach 1e-8, split or not,
    # where loops of side-by-side rods make Ã singular (docs/solvers.md).
    and (solver, form, formulation) != ("osqp", "contact", "least_squares")])
def test_split_solve_equals_the_unsplit_solve(solver, form, formulation, monkeypatch):
    _, system = _many_components()
    reference = qc.reference_solution(system, formulation)
    monkeypatch.setattr(blocks, "BLOCK_ROWS", 50)
    split = solve(Problem.of(system), solver, formulation, form, tolerance=1e-8, split=True)
    whole = solve(Problem.of(system), solver, formulation, form, tolerance=1e-8, split=False)
    assert split.found and whole.found and split.extras["blocks"] > 1 and whole.extras["blocks"] == 1
    assert metrics.distance(split.y, whole.y) < 1e-4
    # as accurate as the unsplit solve, or as the solver is (Clarabel's ỹ is only ~1e-5 accurate at
    # tolerance 1e-8, by block)
    floor = 1e-5 if solver == "clarabel" else 1e-6
    assert metrics.distance(split.y, reference) < max(floor, 3 * metrics.distance(whole.y, reference))
    if split.lam is not None and whole.lam is not None:
        assert np.allclose(split.lam, whole.lam, atol=1e-4 * np.abs(whole.lam).max())


def test_a_warm_start_is_split_with_the_blocks(monkeypatch):
    """Each block gets its own rows of the initial λ̃: started at the answer, MPRGP does nothing."""
    _, system = _many_components()
    monkeypatch.setattr(blocks, "BLOCK_ROWS", 50)
    first = solve(Problem.of(system), "mprgp", tolerance=1e-9)
    again = solve(Problem.of(system), "mprgp", tolerance=1e-9, initial=first.lam)
    assert first.extras["blocks"] > 1 and again.found and again.iterations == 0


@pytest.mark.parametrize("how", ["no answer", "not converged, right answer", "not converged, wrong answer"])
def test_a_failed_block_gives_no_partial_answer(monkeypatch, how):
    """When one block returns no answer, the output must carry no ỹ (a block's ỹ has only its
    own columns: resolve crashed on it), and resolve must not apply anything. A block that
    returns an answer without its solver's success word (Clarabel's "AlmostSolved") keeps it:
    the whole answer is then judged by its residuals (issue 19), accepted if right, refused if
    wrong."""
    cells = scenes.colony_2d(400, seed=1)
    real = get_solver("osqp")
    calls = []

    def second_block_fails(problem, *args, **kwargs):
        out = real.solve(problem, *args, **kwargs)
        calls.append(problem.shape)
        if len(calls) == 2:
            out.found, out.status = False, "made to fail"
            if how == "no answer":
                out.y = out.lam = None
            elif how == "not converged, wrong answer":
                out.y, out.lam = 0.5 * out.y, 0.5 * out.lam
        return out

    monkeypatch.setattr(blocks, "BLOCK_ROWS", 50)
    monkeypatch.setitem(registry._SOLVERS, "osqp", dataclasses.replace(real, solve=second_block_fails))
    result = qc.resolve(cells, solver="osqp", on_failure="return")
    assert "made to fail" in result.status
    if how == "not converged, right answer":
        assert len(calls) > 2 and result.converged and result.status.endswith("(accepted by its residuals)")
        return
    assert not result.converged
    assert (result.scaled_solution is None) == (how == "no answer")
    if how == "no answer":
        assert len(calls) == 2
    np.testing.assert_array_equal(result.cells.momenta, cells.momenta)
