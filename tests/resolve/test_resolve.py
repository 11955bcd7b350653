"""Solving: the textbook two-body impulse, the invariants after every solve, QP = linear when all
contacts are active, what happens in jammed packings, and the documented failures."""

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import qpcontact as qc
from qpcontact import build_system, colliding, find_contacts
from qpcontact.errors import InvalidArgumentError, SolverFailedError, SolverNotInstalledError, UnknownSolverError
from qpcontact.geometry.contacts import relative_normal_velocity
from qpcontact.resolve import metrics
from qpcontact.solvers import solve_min_norm
from qpcontact.solvers.qpsolvers_bridge import KNOWN_BACKENDS
from qpcontact.studies import scenes
from tests.helpers import pulling_scene, random_scene

QP_SOLVERS = [s for s in qc.available_solvers() if s != "linear"]
FORMULATIONS = ["complementarity", "least_squares"]


def post_velocity(result):
    """Relative normal velocity at each colliding contact after the impulses."""
    c = result.contacts
    return relative_normal_velocity(result.cells, c.cell_a, c.cell_b, c.normal, c.offset_a, c.offset_b,
                                    c.stretch_a, c.stretch_b)


def textbook_impulse(cells, contacts):
    """λ = −u / (1/m_a + 1/m_b + (r_a×n)ᵀI_a⁻¹(r_a×n) + (r_b×n)ᵀI_b⁻¹(r_b×n) + growth terms)."""
    n = contacts.normal[0]
    denominator = 0.0
    for side in ("a", "b"):
        i = getattr(contacts, f"cell_{side}")[0]
        r = getattr(contacts, f"offset_{side}")[0]
        s = getattr(contacts, f"stretch_{side}")[0]
        one = cells.subset([i])
        rn = np.cross(r, n)
        denominator += 1 / one.masses[0] + rn @ one.apply_inverse_inertia(rn[None])[0]
        denominator += (s * (one.axes[0] @ n)) ** 2 / one.growth_inertia[0]
    return -contacts.normal_velocity[0] / denominator


@pytest.mark.parametrize("solver", qc.available_solvers())
@pytest.mark.parametrize("tilt", [0.0, 0.3, 1.2])
def test_two_capsules_get_the_textbook_inelastic_impulse(solver, tilt):
    axes = [[1.0, 0.0, 0.0], [np.cos(tilt), 0.2, np.sin(tilt)]]
    cells = qc.Cells([[0.4, 0.9, 0.1], [0.0, 0.0, 0.0]], axes, [2.0, 3.0], [0.5, 0.45], masses=[1.0, 2.5],
                     growth_inertia=[0.7, 1.3], momenta=[[0.1, -1.0, 0.0], [0.0, 0.5, 0.2]],
                     angular_momenta=[[0.0, 0.1, 0.3], [0.2, 0.0, 0.0]], growth_momenta=[0.4, 0.9], normalize_axes=True)
    # Every installed solver must solve this (a failure fails the test; a backend that is not
    # installed is simply not in available_solvers()).
    result = qc.resolve(cells, solver=solver, tolerance=1e-8)
    assert len(result.contacts) == 1
    expected = textbook_impulse(cells, result.contacts)
    assert expected > 0
    assert result.contact_impulses[0] == pytest.approx(expected, rel=1e-5)
    n = result.contacts.normal[0]
    assert np.allclose(result.impulses[0, :3], expected * n, rtol=1e-5, atol=1e-7)
    assert np.allclose(result.impulses[1, :3], -expected * n, rtol=1e-5, atol=1e-7)
    assert post_velocity(result)[0] == pytest.approx(0.0, abs=1e-5 * abs(result.contacts.normal_velocity[0]))


@pytest.mark.parametrize("solver, formulation", [(s, f) for s in qc.available_solvers() for f in qc.get_solver(s).formulations])
@pytest.mark.parametrize("seed", range(3))
def test_invariants_after_every_solve(solver, formulation, seed):
    cells = random_scene(seed, n_cells=40)
    result = qc.resolve(cells, solver=solver, formulation=formulation, tolerance=1e-7)
    assert result.converged and len(result.contacts) > 10
    u0 = -result.system.b
    after = post_velocity(result)
    scale = np.max(np.abs(u0))
    assert np.all(after >= -1e-4 * scale)  # no colliding contact approaches any more
    if solver == "linear":
        assert np.allclose(after, 0.0, atol=1e-9 * scale)  # the plain solve stops every contact exactly
    assert result.errors["momentum_change"] < 1e-6
    assert result.errors["angular_momentum_change"] < 1e-6
    assert result.errors["energy_change"] <= 1e-6 * abs(result.errors["energy_change"]) + 1e-12
    # The kinetic energy from the cells themselves agrees (no fixed bodies here).
    assert result.cells.kinetic_energy() - cells.kinetic_energy() == pytest.approx(result.errors["energy_change"], rel=1e-6, abs=1e-9)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), n=st.integers(4, 14), planar=st.booleans(), mass_spread=st.sampled_from([1.0, 10.0, 1000.0]))
def test_qp_equals_the_linear_solve_when_all_contacts_are_active(seed, n, planar, mass_spread):
    cells = random_scene(seed, n_cells=n, box=1.0 + 0.25 * n, planar=planar, mass_spread=mass_spread)
    linear = qc.resolve(cells, solver="linear")
    assume(len(linear.contacts) > 0 and np.all(linear.contact_impulses > 1e-6 * np.max(linear.contact_impulses)))
    reference = linear.impulses
    scale = np.max(np.abs(reference))
    for solver in ("osqp", "clarabel", "mprgp"):
        for formulation in qc.get_solver(solver).formulations:
            result = qc.resolve(cells, solver=solver, formulation=formulation, tolerance=1e-9)
            agreement = qc.compare_with_linear(result, tolerance=1e-4)
            assert agreement.all_active, (solver, formulation)
            assert agreement.agrees, (solver, formulation, agreement)
            assert np.allclose(result.impulses, reference, atol=1e-4 * scale), (solver, formulation)


def test_complementarity_never_pulls_where_the_linear_solve_does():
    cells = pulling_scene()
    linear = qc.resolve(cells, solver="linear")
    result = qc.resolve(cells, solver="clarabel", tolerance=1e-9)
    assert np.all(result.contact_impulses >= -1e-7 * np.max(result.contact_impulses))
    assert result.errors["complementarity"] < 1e-5
    agreement = qc.compare_with_linear(result)
    assert not agreement.all_active and agreement.inactive > 0 and agreement.agrees is None
    assert agreement.distance > 1e-3
    # Gauss's principle: the complementarity answer has less impulse energy than the linear one.
    assert np.sum(result.scaled_solution**2) < np.sum(linear.scaled_solution**2)


def jammed_packing(overlap=0.05):
    """Hexagonally packed planar spheres (2 unknowns each, ~3 contacts each), squeezed inwards,
    with uneven overlaps."""
    rng = np.random.default_rng(5)
    i, j = np.meshgrid(np.arange(7), np.arange(7))
    centres = np.stack([i + 0.5 * (j % 2), j * np.sqrt(3) / 2, 0 * i], axis=-1).reshape(-1, 3) * (1.0 - overlap)
    n = len(centres)
    centres[:, :2] += rng.normal(0, 0.01, (n, 2))
    velocity = -(centres - centres.mean(axis=0)) + rng.normal(0, 0.05, (n, 3))
    velocity[:, 2] = 0
    return qc.Cells(centres, [1.0, 0.0, 0.0], 0.0, 0.5, momenta=velocity)


def test_jammed_packing_without_position_correction_is_still_consistent():
    """The original design notes say the plain solve leaves jammed contacts penetrating. Without position
    correction that cannot happen: b = −u = −J v lies in the range of M (x = −p solves it), so
    M x = b is consistent however many contacts there are."""
    cells = jammed_packing()
    result = qc.resolve(cells, solver="linear")
    k, unknowns = result.system.shape
    assert k > unknowns  # over-determined: more contacts than degrees of freedom
    assert result.errors["penetration"] < 1e-10
    ls = qc.resolve(cells, solver="clarabel", formulation="least_squares", tolerance=1e-9)
    assert qc.compare_with_linear(ls, tolerance=1e-5).agrees


def test_jammed_packing_with_position_correction_separates_least_squares_from_linear():
    cells = jammed_packing()
    kw = dict(position_correction=0.5, dt=0.01)
    linear = qc.resolve(cells, solver="linear", on_failure="return", **kw)
    # inconsistent: the least-squares answer penetrates, and is refused (issue 13, item 6)
    assert linear.errors["penetration"] > 1e-4 and not linear.converged and "no solution" in linear.message
    for solver in ("clarabel", "osqp"):
        ls = qc.resolve(cells, solver=solver, formulation="least_squares", tolerance=1e-8, **kw)
        assert ls.errors["penetration"] < 1e-5
        agreement = qc.compare_with_linear(ls)
        assert not agreement.all_active and agreement.distance > 1e-4


def same_cells_not_aliased(returned, given):
    """The returned cells hold the given values but are not the caller's object (nor its
    arrays): changing one never changes the other (issue 19)."""
    fields = ("centers", "axes", "lengths", "momenta", "angular_momenta", "growth_momenta")
    return returned is not given and all(
        np.array_equal(getattr(returned, f), getattr(given, f)) and not np.shares_memory(getattr(returned, f), getattr(given, f))
        for f in fields)


def test_no_colliding_contact_never_reaches_a_solver():
    cells = qc.Cells([[0, 0, 0], [5, 0, 0]], [1, 0, 0], 2.0, 0.5, momenta=[[1, 0, 0], [-1, 0, 0]])
    for solver in qc.available_solvers():
        result = qc.resolve(cells, solver=solver)
        assert result.status == "no_contact" and result.converged
        assert np.all(result.impulses == 0) and same_cells_not_aliased(result.cells, cells)


def test_unknown_and_missing_solvers_and_bad_options_raise():
    cells = random_scene(0, n_cells=10)
    with pytest.raises(UnknownSolverError, match="unknown solver 'fast'"):
        qc.resolve(cells, solver="fast")
    missing = [s for s in KNOWN_BACKENDS if s not in qc.available_solvers()]
    with pytest.raises(SolverNotInstalledError, match=f"solver '{missing[0]}'.*not installed"):
        qc.resolve(cells, solver=missing[0])
    with pytest.raises(InvalidArgumentError, match="formulation"):
        qc.resolve(cells, formulation="elastic")
    with pytest.raises(InvalidArgumentError, match="tolerance"):
        qc.resolve(cells, tolerance=0.0)
    with pytest.raises(InvalidArgumentError, match="form"):
        qc.resolve(cells, form="dual")
    with pytest.raises(InvalidArgumentError, match="on_failure"):
        qc.resolve(cells, on_failure="ignore")
    with pytest.raises(InvalidArgumentError, match="time_limit"):
        qc.resolve(cells, time_limit=-1.0)


def test_a_solver_that_does_not_converge_is_reported_and_never_applied():
    cells = random_scene(2, n_cells=40)
    with pytest.raises(SolverFailedError, match="did not converge") as info:
        qc.resolve(cells, solver="osqp", tolerance=1e-9, solver_settings={"max_iter": 2})
    assert info.value.result is not None and not info.value.result.converged
    result = qc.resolve(cells, solver="osqp", tolerance=1e-9, solver_settings={"max_iter": 2}, on_failure="return")
    assert not result.converged and same_cells_not_aliased(result.cells, cells) and "did not converge" in result.message


def test_a_backend_error_is_reported_as_solver_failure():
    cells = random_scene(2, n_cells=20)
    with pytest.raises(SolverFailedError, match="clarabel"):
        qc.resolve(cells, solver="clarabel", solver_settings={"no_such_setting": 1})


def test_backend_prints_do_not_reach_stdout(capfd):
    """OSQP prints "Polishing not needed" from C when no constraint is active (here: a block of
    separating contacts kept with keep_separating), even with verbose=False."""
    cells = qc.Cells([[0, 0.9, 0], [0, 0, 0], [50, 0.9, 0], [50, 0, 0]], [[1, 0, 0], [0, 0, 1]] * 2, 2.0, 0.5,
                     momenta=[[0, -1, 0], [0, 0, 0], [0, 1, 0], [0, 0, 0]])
    result = qc.resolve(cells, solver="osqp", keep_separating=True)
    assert result.converged and len(result.contacts) == 2
    assert capfd.readouterr().out == ""


@pytest.mark.parametrize("name, n", [("jammed_packing", 61), ("colony_3d", 300)])
def test_plain_right_hand_side_is_always_consistent(name, n):
    """With b = −u (no position correction) stopping every cell, x = −p, solves Mx = b, so the
    plain solve never leaves a contact penetrating, even in a jammed packing with more contacts
    than unknowns (the original design notes expect penetration there; it needs position correction with
    non-uniform overlaps)."""
    cells = scenes.make_scene(name, n)
    active, b = colliding(find_contacts(cells))
    system = build_system(cells, active, b)
    assert system.shape[0] > system.shape[1] or name != "jammed_packing"
    stop_all = system.from_impulses(-cells.generalized_momenta())
    assert metrics.penetration(system, stop_all) < 1e-12
    lin = solve_min_norm(system.matrix, system.rhs, tolerance=1e-10)
    assert lin.consistent and metrics.penetration(system, lin.y) < 1e-10


def test_the_plain_solve_answers_the_plain_problem_whatever_formulation_is_asked_for():
    cells = random_scene(1, n_cells=20)
    default = qc.resolve(cells, solver="linear")
    for formulation in qc.FORMULATIONS:
        result = qc.resolve(cells, solver="linear", formulation=formulation)
        assert (result.formulation, result.form) == ("linear", "contact")
        np.testing.assert_array_equal(result.impulses, default.impulses)
    lsmr = qc.resolve(cells, solver="linear", form="primal")  # LSMR on B̃, no factorization
    assert lsmr.form == "primal" and lsmr.status.startswith("solved (lsmr")
    assert metrics.distance(lsmr.scaled_solution, default.scaled_solution) < 1e-6
    with pytest.raises(InvalidArgumentError, match="solver 'osqp' solves the least_squares and complementarity "
                                                   "formulations in primal and contact form only"):
        qc.resolve(cells, solver="osqp", formulation="linear")


@pytest.mark.parametrize("n_cells", [40, 61])
@pytest.mark.parametrize("form", ["primal", "contact"])
def test_cvxopt_solves_least_squares_on_a_jammed_pile(n_cells, form):
    """issue 28: cvxopt/least_squares failed ("Terminated (singular KKT matrix)", status
    unknown) on a valid jammed pile whose B̃ has dependent rows (more contacts than unknowns) and
    columns (61 cells: rigid motions no contact resists), where the other backends solve it. It
    is solved again with a tiny ridge (qpsolvers_bridge.RIDGE), and says so."""
    cells = scenes.jammed_packing(n_cells)
    system = qc.resolve(cells, solver="clarabel", formulation="least_squares", tolerance=1e-9).system
    assert np.linalg.matrix_rank(system.matrix.toarray()) < max(system.shape)
    reference = qc.resolve(cells, solver="clarabel", formulation="least_squares", form=form, tolerance=1e-9)
    result = qc.resolve(cells, solver="cvxopt", formulation="least_squares", form=form)
    assert result.converged and "with a ridge of 1e-10" in result.status
    assert metrics.distance(result.scaled_solution, reference.scaled_solution) < 1e-5
