"""What ``tolerance`` promises, enforced for every solver (issue 13, items 4, 6 and 8): an accepted
answer's penetration and, for complementarity, its complementarity residual ‖min(λ̃, B̃ỹ − b̃)‖∞
are at most min(100·tolerance, 0.1) in the scaled units; answers beyond it are refused."""

import numpy as np
import pytest

import qpcontact as qc
from qpcontact.resolve import acceptance_limit, metrics, reference
from qpcontact.solvers import get_solver, qpsolvers_bridge
from qpcontact.studies import scenes

QP_SOLVERS = [name for name in qc.available_solvers() if "complementarity" in get_solver(name).formulations]


def test_the_limit_is_a_hundred_times_the_tolerance_capped_at_a_tenth():
    assert acceptance_limit(1e-6) == pytest.approx(1e-4)
    assert acceptance_limit(1e-3) == pytest.approx(0.1)
    assert acceptance_limit(0.999) == 0.1


#: Cases measured not to converge on these scenes (solver, form, dimensions, tolerance): HiGHS in
#: the primal form (3D: "not solved"; 2D at 1e-6: its duals disagree with its ỹ, multiplier
#: inconsistency 3e-4). Each must then be reported through the documented path; every other case
#: must converge. A listed case that converges is held to the promise like any other.
KNOWN_UNCONVERGED = {("highs", "primal", 3, 1e-6), ("highs", "primal", 3, 1e-4), ("highs", "primal", 2, 1e-6)}


def assert_reported_unconverged(cells, result, **options):
    """The documented path of an unconverged answer: ``on_failure="return"`` flags it with a
    message and hands back the cells unchanged (a copy); the default raises
    ``SolverFailedError`` carrying that result. Nothing is applied."""
    assert not result.converged and result.message
    assert result.cells is not cells and np.array_equal(result.cells.momenta, cells.momenta)
    with pytest.raises(qc.SolverFailedError) as raised:
        qc.resolve(cells, **options)
    assert raised.value.result is not None and not raised.value.result.converged


@pytest.mark.parametrize("solver", QP_SOLVERS)
@pytest.mark.parametrize("dimensions", [2, 3])
@pytest.mark.parametrize("tolerance", [1e-6, 1e-4])
def test_every_accepted_complementarity_answer_keeps_the_promise(solver, dimensions, tolerance):
    """Graded by an independent certificate, not by another solver: the KKT conditions of the
    complementarity QP (``metrics.kkt_residuals``) hold to what the tolerance promises,
    ``min(100·tolerance, 0.1)``; and the answer is within that of the verified optimum (an exact
    KKT point: ``reference(...).verified``). An all-zero answer fails both (penetration 1)."""
    cells = (scenes.colony_2d if dimensions == 2 else scenes.colony_3d)(300, 1)
    limit = acceptance_limit(tolerance)
    for form in get_solver(solver).forms:
        options = dict(solver=solver, form=form, tolerance=tolerance)
        result = qc.resolve(cells, on_failure="return", **options)
        if not result.converged:
            assert (solver, form, dimensions, tolerance) in KNOWN_UNCONVERGED, (form, result.message)
            assert_reported_unconverged(cells, result, **options)
            continue
        system, y = result.system, result.scaled_solution
        kkt = metrics.kkt_residuals(system, y, system.from_contact_impulses(result.contact_impulses))
        assert max(kkt.values()) <= limit, (form, kkt)
        optimum = reference(system, "complementarity")
        assert optimum.verified, optimum.method
        assert metrics.distance(y, optimum.y) <= limit, form


def test_the_certificate_refuses_an_all_zero_answer_and_a_doubled_one():
    result = qc.resolve(scenes.colony_2d(300, 1), solver="clarabel", tolerance=1e-8)
    system, y = result.system, result.scaled_solution
    lam = system.from_contact_impulses(result.contact_impulses)
    assert max(metrics.kkt_residuals(system, y, lam).values()) <= 1e-6
    assert metrics.kkt_residuals(system, 0 * y, 0 * lam)["primal"] == pytest.approx(1.0)
    assert metrics.kkt_residuals(system, 2 * y, 2 * lam)["complementarity"] > 0.1


@pytest.mark.parametrize("solver", ["clarabel", "piqp"])
def test_interior_point_answers_at_tolerance_1e_6_are_accurate_not_just_accepted(solver):
    """Clarabel at 1e-6 returned a residual of 2e-4–1e-3 (up to 1000× the tolerance) and answers
    2e-4 off, and resolve accepted them (the checks tested penetration and the duality gap). Its
    gap tolerance is now squared: the answers are within a few times the tolerance of the verified
    optimum (an exact KKT point, not Clarabel's own answer)."""
    if solver not in qc.available_solvers():
        pytest.skip(f"{solver} is not installed")
    for cells in (scenes.colony_2d(3000, 1), scenes.colony_3d(500, 1)):
        result = qc.resolve(cells, solver=solver, tolerance=1e-6)
        assert result.errors["complementarity"] <= 1e-5
        optimum = reference(result.system, "complementarity")
        assert optimum.verified, optimum.method
        assert metrics.distance(result.scaled_solution, optimum.y) <= 1e-5


def test_an_answer_beyond_the_promised_residual_is_refused(monkeypatch):
    """With the old tolerance mapping (gap = tolerance) Clarabel's answer has a residual of
    several 100·tolerance: resolve must refuse it, whatever the solver says."""
    old = qpsolvers_bridge.tolerance_settings

    def gap_equals_tolerance(backend, tolerance, time_limit, formulation="complementarity"):
        settings = old(backend, tolerance, time_limit, formulation)
        settings.update(tol_gap_abs=tolerance, tol_gap_rel=tolerance)
        return settings

    monkeypatch.setattr(qpsolvers_bridge, "tolerance_settings", gap_equals_tolerance)
    result = qc.resolve(scenes.colony_2d(3000, 1), solver="clarabel", tolerance=1e-6, on_failure="return")
    assert result.errors["complementarity"] > 1e-4
    assert not result.converged and "complementarity residual" in result.message
    with pytest.raises(qc.SolverFailedError, match="complementarity residual"):
        qc.resolve(scenes.colony_2d(3000, 1), solver="clarabel", tolerance=1e-6)


@pytest.mark.parametrize("tolerance", [0.999, 0.5])
def test_a_loose_tolerance_still_refuses_garbage(tolerance):
    """100·tolerance >= 1 accepted anything: MPRGP at 0.999 was accepted with penetration 0.38.
    Its answer at that tolerance is refused now; the one at a tenth of it keeps the cap."""
    from qpcontact.resolve import acceptance_failure
    from qpcontact.solvers import Problem, solve

    cells = scenes.colony_2d(500, 1)
    system = qc.resolve(cells, solver="mprgp").system
    first = solve(Problem.of(system), "mprgp", tolerance=tolerance)
    assert first.found and metrics.penetration(system, first.y) > 0.1
    assert "min(100·tolerance, 0.1)" in acceptance_failure(system, "complementarity", first.y, first.lam, tolerance)
    result = qc.resolve(cells, solver="mprgp", tolerance=tolerance, on_failure="return")
    assert result.converged and result.status.endswith(f"(again at {tolerance / 10:g})")
    assert result.errors["penetration"] <= 0.1 and result.errors["complementarity"] <= 0.1


def squeezed():
    """A cell squeezed between two fixed cells, overlapping both."""
    return qc.Cells([[0, 0, 0], [0, 0.9, 0], [0, -0.9, 0]], [1, 0, 0], 2.0, 0.5, masses=[1.0, np.inf, np.inf])


def test_the_plain_solve_of_an_inconsistent_system_is_refused():
    """Issue 13, item 6: with position correction the two overlaps ask the middle cell to move
    both ways; Mx = b has no solution, and the plain solve's least-squares answer (penetration
    1.0) was reported converged and applied by step."""
    cells = squeezed()
    result = qc.resolve(cells, solver="linear", position_correction=1.0, dt=0.1, on_failure="return")
    assert result.status == "solved (lsmr, least squares)" and result.errors["penetration"] == pytest.approx(1.0)
    assert not result.converged and "Mx = b has no solution" in result.message
    np.testing.assert_array_equal(result.cells.momenta, cells.momenta)
    with pytest.raises(qc.SolverFailedError, match="no solution"):
        qc.step(cells, 0.1, solver="linear", position_correction=1.0)
    rod = qc.Cells([[0, 0, 0]], [1, 0, 0], 2.0, 0.7)  # wider than the channel
    with pytest.raises(qc.SolverFailedError, match="no solution"):
        qc.step(rod, 0.01, planes=qc.channel(1.2), solver="linear", position_correction=1.0, planar=True)
    # without position correction the same scene is consistent and accepted
    moving = cells.replace(momenta=[[0, 1.0, 0], [0, 0, 0], [0, 0, 0]])
    assert qc.resolve(moving, solver="linear").converged


@pytest.mark.parametrize("sloppiness, converged", [(500.0, True), (5000.0, False)])
def test_a_rejected_answer_is_solved_for_once_more_at_a_tenth_of_the_tolerance(sloppiness, converged):
    """A solver whose stopping test is looser than the promise (its contact impulses are
    ``sloppiness·tolerance`` too large): the answer is rejected, asked for again at a tenth of
    the tolerance, and kept if that keeps the promise at the tolerance asked for."""
    from qpcontact.solvers import SolverOutput, SolverSpec, registry, solve_min_norm

    calls = []

    def sloppy(problem, formulation, form, *, tolerance, time_limit, settings, initial):
        calls.append(tolerance)
        lam = solve_min_norm(problem.matrix, problem.rhs).lam + sloppiness * tolerance
        return SolverOutput(problem.matrix.T @ lam, lam, True, "done", 1, 0.0, 0.0)

    registry.register(SolverSpec("sloppy", formulations=("complementarity",), forms=("contact",), warm_start=False,
                                 time_limit=True, solve=sloppy))
    try:
        cells = qc.Cells([[0, 0.9, 0], [0, 0, 0]], [[1, 0, 0], [0, 0, 1]], 2.0, 0.5, momenta=[[0, -1.0, 0], [0, 0, 0]])
        result = qc.resolve(cells, solver="sloppy", tolerance=1e-6, on_failure="return")
    finally:
        registry.unregister("sloppy")
    assert calls == [1e-6, pytest.approx(1e-7)]
    assert result.converged == converged
    if converged:
        assert result.status == "done (again at 1e-07)" and result.errors["complementarity"] <= 1e-4
    else:
        assert "complementarity residual" in result.message or "duality gap" in result.message


@pytest.mark.parametrize("formulation, truthful, converged", [
    ("complementarity", True, True), ("complementarity", False, False), ("least_squares", True, False)])
def test_an_answer_without_the_success_word_is_judged_by_its_residuals(formulation, truthful, converged):
    """Issue 19, item 4: Clarabel ended "AlmostSolved" with residuals inside what the tolerance
    promises (examples/channel.py) and the answer was refused for the word. A complementarity
    answer is now accepted by its residuals (they are its KKT conditions) whatever the word; a
    wrong one is still refused; least_squares' checks certify no optimum, so its word stands."""
    from qpcontact.solvers import SolverOutput, SolverSpec, registry, solve_min_norm

    def almost(problem, formulation, form, *, tolerance, time_limit, settings, initial):
        lam = solve_min_norm(problem.matrix, problem.rhs).lam * (1.0 if truthful else 2.0)
        return SolverOutput(problem.matrix.T @ lam, lam, False, "AlmostSolved", 9, 0.0, 0.0)

    registry.register(SolverSpec("almost", formulations=("complementarity", "least_squares"), forms=("contact",),
                                 warm_start=False, time_limit=True, solve=almost))
    try:
        cells = qc.Cells([[0, 0.9, 0], [0, 0, 0]], [[1, 0, 0], [0, 0, 1]], 2.0, 0.5, momenta=[[0, -1.0, 0], [0, 0, 0]])
        result = qc.resolve(cells, solver="almost", formulation=formulation, tolerance=1e-6, on_failure="return")
    finally:
        registry.unregister("almost")
    assert result.converged == converged
    if converged:
        assert result.status == "AlmostSolved (accepted by its residuals)"
        assert result.errors["penetration"] <= 1e-10 and result.errors["complementarity"] <= 1e-10
    else:
        assert "did not converge (status AlmostSolved)" in result.message
        assert ("do not certify" in result.message) == (formulation == "least_squares")


def test_the_reference_says_when_its_polish_failed(monkeypatch):
    """reference_solution fell back to Clarabel's raw answer without a word when no polish
    verified, so Clarabel was graded against itself; now it says so."""
    from qpcontact.resolve import UnverifiedReferenceWarning, reference_solution, validation

    system = qc.resolve(scenes.colony_2d(300, 1), solver="clarabel").system
    assert reference(system, "complementarity").verified
    monkeypatch.setattr(validation, "active_set_polish", lambda system, lam: None)
    found = reference(system, "complementarity")
    assert not found.verified and found.method == "clarabel, unpolished"
    with pytest.warns(UnverifiedReferenceWarning, match="not an independent reference"):
        reference_solution(system, "complementarity")
