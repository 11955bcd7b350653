"""The comparison command and the baseline solvers it measures."""

import csv
import os
import time

import numpy as np
import pytest

from qpcontact import build_system, colliding, find_contacts, reference_solution
from qpcontact.errors import InvalidArgumentError, UnknownSolverError
from qpcontact.resolve import metrics
from qpcontact.solvers import Problem, solve
from qpcontact.solvers.baselines import bbpgd, conjugate_gradient
from qpcontact.solvers.linear import solve_min_norm
from qpcontact.studies import compare, scenes


@pytest.fixture(scope="module")
def colony():
    cells = scenes.colony_2d(150, seed=5)
    active, b = colliding(find_contacts(cells))
    return cells, build_system(cells, active, b)


def read(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_quick_run_writes_csv_png_and_table(tmp_path):
    out = tmp_path / "cmp"
    code = compare.main(["--quick", "--scenes", "two_rods,colony_3d_100", "--solvers", "linear,cg,bbpgd,osqp",
                         "--tolerances", "1e-3,1e-6", "--out", str(out)])
    assert code == 0
    rows = read(out / "solvers.csv")
    assert tuple(rows[0].keys()) == compare.COLUMNS
    methods = {r["method"] for r in rows}
    assert methods == {"linear/linear/contact", "cg/linear/normal_equations", "bbpgd/complementarity/contact",
                       *(f"osqp/{f}/{form}" for f in ("complementarity", "least_squares") for form in ("primal", "contact"))}
    assert len(rows) == 2 * 7 * 2  # scenes × methods × tolerances: every run is a row
    assert {r["scene"] for r in rows} == {"two_rods", "colony_3d_100"}
    for r in rows:
        assert r["outcome"] in ("success", "converged_inaccurate", "not_converged", "time_limit", "timeout", "error", "crashed")
        assert float(r["tolerance"]) in (1e-3, 1e-6)
    # The plain solve is its own reference; OSQP at 1e-6 on complementarity is accurate.
    assert all(float(r["distance"]) < 1e-10 for r in rows if r["solver"] == "linear")
    assert all(r["success"] == "True" for r in rows if r["method"] == "osqp/complementarity/primal")
    assert (out / "solvers_scenes.png").stat().st_size > 1000
    png = (out / "solvers.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    text = (out / "solvers.md").read_text()
    assert "| method (solver/formulation/form) |" in text and "SGM" in text
    for m in methods:
        assert f"| {m} |" in text


def test_failures_and_time_outs_are_rows(tmp_path):
    out = tmp_path / "cmp"
    compare.main(["--scenes", "colony_2d_100", "--solvers", "cg,bbpgd", "--tolerances", "1e-9", "--repeats", "1",
                  "--time-limit", "1e-9", "--out", str(out)])
    rows = read(out / "solvers.csv")
    assert len(rows) == 2
    for r in rows:
        assert r["outcome"] == "time_limit" and r["success"] == "False" and r["converged"] == "False"
        assert "time_limit" in r["message"]
    text = (out / "solvers.md").read_text()
    assert "| cg/linear/normal_equations | 1 | 0 % | 0 | 1 |" in text


def test_guarded_reports_timeout_crash_and_error():
    import operator

    from qpcontact.studies.harness import guarded

    assert guarded(dict, ([("x", 1)],), 10) == ("ok", {"x": 1})
    start = time.perf_counter()
    assert guarded(time.sleep, (30,), 0.5) == ("timeout", None)
    assert time.perf_counter() - start < 10
    assert guarded(os._exit, (3,), 10) == ("crashed", 3)
    status, text = guarded(operator.truediv, (1, 0), 10)
    assert status == "error" and "ZeroDivisionError" in text


def test_shifted_geometric_mean():
    assert compare.shifted_geometric_mean(np.array([0.01, 0.01])) == pytest.approx(0.01)
    # exp(mean(log 0.01, log 0.04)) − 0.01 = 0.02 − 0.01
    assert compare.shifted_geometric_mean(np.array([0.0, 0.03])) == pytest.approx(0.01)


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


def test_a_failed_block_gives_no_partial_answer(monkeypatch):
    """solve_by_blocks splits independent components into blocks; when one block fails, the
    outcome must carry no ỹ (a block's ỹ has only its own columns: resolve crashed on it)."""
    import dataclasses

    from qpcontact import resolve
    from qpcontact.solvers import blocks, get_solver, registry

    cells = scenes.colony_2d(400, seed=1)
    real = get_solver("osqp")
    calls = []

    def second_block_fails(problem, *args, **kwargs):
        out = real.solve(problem, *args, **kwargs)
        calls.append(problem.shape)
        if len(calls) == 2:
            out.found, out.status = False, "made to fail"
        return out

    monkeypatch.setattr(blocks, "BLOCK_ROWS", 50)
    monkeypatch.setitem(registry._SOLVERS, "osqp", dataclasses.replace(real, solve=second_block_fails))
    result = resolve(cells, solver="osqp", on_failure="return")
    assert len(calls) == 2 and not result.converged
    assert "made to fail" in result.status and result.scaled_solution is None
    np.testing.assert_array_equal(result.cells.momenta, cells.momenta)


@pytest.mark.parametrize("name, n", [("jammed_packing", 61), ("colony_3d", 300)])
def test_plain_right_hand_side_is_always_consistent(name, n):
    """With b = −u (no position correction) stopping every cell, x = −p, solves Mx = b, so the
    plain solve never leaves a contact penetrating, even in a jammed packing with more contacts
    than unknowns (model.md expects penetration there; it needs position correction with
    non-uniform overlaps)."""
    cells = scenes.make_scene(name, n)
    active, b = colliding(find_contacts(cells))
    system = build_system(cells, active, b)
    assert system.shape[0] > system.shape[1] or name != "jammed_packing"
    stop_all = system.from_impulses(-cells.generalized_momenta())
    assert metrics.penetration(system, stop_all) < 1e-12
    lin = solve_min_norm(system.matrix, system.rhs, tolerance=1e-10)
    assert lin.consistent and metrics.penetration(system, lin.y) < 1e-10
