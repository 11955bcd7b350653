"""The solver registry: what it lists, the named errors, how a solver's spec is read, and a solver
added at run time (the worked example of docs/architecture.md) used by resolve and the studies."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
import qpsolvers

import qpcontact as qc
from qpcontact.errors import InvalidArgumentError, SolverFailedError, SolverNotInstalledError, UnknownSolverError
from qpcontact.resolve import metrics
from qpcontact.solvers import (
    DEFAULT_FORM,
    Problem,
    SolverOutput,
    SolverSpec,
    available_solvers,
    get_solver,
    register,
    registered_solvers,
    solve,
    unregister,
)
from qpcontact.solvers.qpsolvers_bridge import KNOWN_BACKENDS
from qpcontact.studies import compare, stability
from tests.helpers import assert_kkt, random_scene, system_of

ROOT = Path(__file__).resolve().parents[2]


def test_listing_order_plain_solve_then_built_in_then_every_installed_backend():
    backends = sorted(qpsolvers.available_solvers)
    assert available_solvers() == ["linear", "mprgp", "ipm", *backends]
    assert available_solvers(include_baselines=True) == ["linear", "mprgp", "ipm", *backends, "cg", "cg_euclidean",
                                                         "bbpgd"]
    assert set(KNOWN_BACKENDS) <= set(registered_solvers())  # known even when not installed
    assert qc.available_solvers() == available_solvers()


def test_unknown_and_uninstalled_solvers_are_named_errors():
    with pytest.raises(UnknownSolverError, match=re.escape(f"unknown solver 'fast'; installed: {available_solvers()}")):
        get_solver("fast")
    missing = next(name for name in KNOWN_BACKENDS if name not in available_solvers())
    with pytest.raises(SolverNotInstalledError, match=re.escape(
            f"solver '{missing}' is a qpsolvers backend but its package is not installed (pip install "
            "'qpcontact[solvers]' or the backend's own package)")):
        get_solver(missing)


def test_plan_reads_formulation_and_form_from_the_spec():
    assert get_solver("osqp").plan("complementarity") == ("complementarity", DEFAULT_FORM["complementarity"])
    assert get_solver("osqp").plan("least_squares", "contact") == ("least_squares", "contact")
    assert get_solver("linear").plan("complementarity") == ("linear", "contact")  # plain: the plain problem
    assert get_solver("linear").plan("least_squares", "primal") == ("linear", "primal")
    assert get_solver("cg").plan("complementarity") == ("linear", "normal_equations")
    assert get_solver("mprgp").plan("complementarity", "auto") == ("complementarity", "contact")
    with pytest.raises(InvalidArgumentError, match=re.escape(
            "solver 'mprgp' solves the complementarity formulation in contact form only "
            "(got formulation 'least_squares', form 'primal')")):
        get_solver("mprgp").plan("least_squares", "primal")
    with pytest.raises(InvalidArgumentError, match="contact form only"):
        get_solver("mprgp").plan("complementarity", "primal")


def test_settings_the_spec_does_not_list_are_refused_by_name():
    problem = Problem.of(system_of(random_scene(0, n_cells=15)))
    with pytest.raises(InvalidArgumentError, match=re.escape(
            "solver_settings: mprgp takes max_iterations and proportioning; got ['eps_abs']")):
        solve(problem, "mprgp", settings={"eps_abs": 1e-3})
    with pytest.raises(InvalidArgumentError, match="solver_settings: linear takes estimate_condition"):
        solve(problem, "linear", settings={"max_iter": 3})
    out = solve(problem, "osqp", settings={"max_iter": 2})  # a backend's own options pass through
    assert not out.found
    with pytest.raises(InvalidArgumentError, match="initial: solver 'osqp' takes no initial guess"):
        solve(problem, "osqp", initial=np.zeros(problem.shape[0]))
    with pytest.raises(InvalidArgumentError, match="tolerance"):
        solve(problem, "osqp", tolerance=2.0)


def test_register_refuses_taken_names_and_unknown_formulations():
    spec = get_solver("linear")
    with pytest.raises(ValueError, match="already registered"):
        register(spec)
    with pytest.raises(ValueError, match="formulations"):
        register(dataclasses.replace(spec, name="elastic", formulations=("elastic",)))
    with pytest.raises(ValueError, match="matrix_free"):
        register(dataclasses.replace(spec, name="odd", matrix_free=("normal_equations",)))
    assert "elastic" not in registered_solvers() and "odd" not in registered_solvers()


# ------------------------------------------------------------------------------------------
# A solver added at run time: the worked example of docs/architecture.md
# ------------------------------------------------------------------------------------------
@pytest.fixture
def pgs():
    """Registers the projected Gauss-Seidel solver of docs/architecture.md, exactly as written
    there, for one test."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    block = re.search(r"## How to add a solver.*?```python\n(.*?)```", text, re.S).group(1)
    exec(compile(block, "docs/architecture.md", "exec"), {"__name__": "qpcontact.solvers.pgs"})
    try:
        yield get_solver("pgs")
    finally:
        unregister("pgs")


def test_a_solver_registered_at_run_time_is_used_by_resolve(pgs):
    assert "pgs" in available_solvers() and pgs.blockwise
    cells = random_scene(3, n_cells=40)
    result = qc.resolve(cells, solver="pgs", tolerance=1e-10)
    assert result.converged and result.solver == "pgs" and (result.formulation, result.form) == ("complementarity", "contact")
    assert_kkt(result.system, result.scaled_solution, result.system.from_contact_impulses(result.contact_impulses), 1e-8)
    reference = qc.reference_solution(result.system, "complementarity")
    assert metrics.distance(result.scaled_solution, reference) < 1e-6
    with pytest.raises(InvalidArgumentError, match="'pgs' solves the complementarity formulation in contact form"):
        qc.resolve(cells, solver="pgs", formulation="least_squares")
    with pytest.raises(SolverFailedError, match="pgs did not converge"):
        qc.resolve(cells, solver="pgs", tolerance=1e-10, solver_settings={"max_sweeps": 1})


def test_a_solver_registered_at_run_time_is_used_by_the_studies(pgs, tmp_path):
    assert compare.Method("pgs", "complementarity", "contact") in compare.all_methods(["pgs"])
    assert stability.runs(["pgs", "linear"], ["complementarity"], ["contact"]) == [
        ("pgs", "complementarity", "contact"), ("linear", "linear", "contact")]
    solution = qc.solve_system(system_of(random_scene(4, n_cells=20)), solver="pgs", tolerance=1e-9)
    assert isinstance(solution, qc.SystemSolution)
    assert solution.converged and solution.extras["blocks"] >= 1 and solution.y is not None


def test_an_answer_is_checked_before_it_is_applied_whatever_solver_gave_it():
    """A solver that reports success with a wrong answer (here: no impulse at all) is caught by
    resolve's acceptance checks; nothing is applied."""
    def liar(problem, formulation, form, *, tolerance, time_limit, settings, initial):
        k, n = problem.shape
        return SolverOutput(np.zeros(n), np.zeros(k), True, "solved", 1, 0.0, 0.0)

    register(SolverSpec("liar", formulations=("complementarity",), forms=("contact",), warm_start=False,
                        time_limit=False, solve=liar))
    try:
        cells = random_scene(2, n_cells=20)
        with pytest.raises(SolverFailedError, match="liar reported success but the answer penetrates by 1"):
            qc.resolve(cells, solver="liar")
        result = qc.resolve(cells, solver="liar", on_failure="return")
        assert not result.converged and result.cells is not cells
        np.testing.assert_array_equal(result.cells.momenta, cells.momenta)
    finally:
        unregister("liar")
    assert "liar" not in registered_solvers()


@pytest.mark.parametrize("backend", ["highs", "osqp"])
def test_backends_print_nothing(backend):
    """HiGHS printed its banner once per process: hundreds of times in the stability report,
    whose every run is a child process."""
    if backend not in qc.available_solvers():
        pytest.skip(f"{backend} is not installed")
    import subprocess
    import sys

    code = (f"import qpcontact as qc; from tests.helpers import random_scene; "
            f"qc.resolve(random_scene(0, 20), solver={backend!r})")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                          cwd=Path(__file__).resolve().parents[2])
    assert (done.stdout, done.stderr) == ("", "")
