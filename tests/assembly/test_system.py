"""The system: reduced unknowns give the full 7-per-cell answer, an independent dense build of
model.md's M agrees, planar equals 3D, and the scaled problem is unit-invariant."""

import numpy as np
import pytest

import qpcontact as qc
from qpcontact.assembly.system import build_system
from qpcontact.errors import InvalidArgumentError
from qpcontact.geometry.contacts import colliding
from tests.helpers import random_scene, world_operators


def with_fixed_and_rigid(cells, seed):
    rng = np.random.default_rng(seed)
    masses = np.where(rng.random(cells.n) < 0.15, np.inf, cells.masses)
    growth = np.where(rng.random(cells.n) < 0.3, np.inf, cells.growth_inertia)
    return cells.replace(masses=masses, growth_inertia=growth)


def dense_reference(cells, contacts, b):
    """Minimum-W-norm solution built straight from model.md's formulas (world frame, dense,
    :func:`tests.helpers.world_operators`): ``A = J W Jᵀ``, ``λ = A⁺b``, ``x = Jᵀλ`` on the
    movable degrees of freedom."""
    J, W = world_operators(cells, contacts)
    lam = np.linalg.pinv(J @ W @ J.T, rcond=1e-12) @ b
    x = J.T @ lam
    x[np.diag(W) == 0] = 0.0  # fixed cells and non-growing lengths take no impulse
    return x.reshape(cells.n, 7), lam


@pytest.mark.parametrize("seed", range(6))
def test_reduced_full_and_dense_agree(seed):
    cells = with_fixed_and_rigid(random_scene(seed, n_cells=25), seed)
    reduced = qc.resolve(cells, solver="linear")
    full = qc.resolve(cells, solver="linear", reduce=False)
    assert len(reduced.contacts) > 5
    assert reduced.n_unknowns < full.n_unknowns
    scale = np.max(np.abs(full.impulses))
    assert np.allclose(reduced.impulses, full.impulses, atol=1e-8 * scale)
    active, b = colliding(qc.find_contacts(cells))
    dense, lam = dense_reference(cells, active, b)
    assert np.allclose(reduced.impulses, dense, atol=1e-7 * scale)
    if np.linalg.matrix_rank(np.vstack([reduced.system.matrix.toarray()])) == len(active):
        assert np.allclose(reduced.contact_impulses, lam, atol=1e-7 * np.max(np.abs(lam)))


@pytest.mark.parametrize("solver", ["clarabel", "osqp"])
def test_reduction_does_not_change_the_qp_answer(solver):
    cells = with_fixed_and_rigid(random_scene(1, n_cells=25), 1)
    a = qc.resolve(cells, solver=solver, tolerance=1e-8)
    b = qc.resolve(cells, solver=solver, tolerance=1e-8, reduce=False)
    assert np.allclose(a.impulses, b.impulses, atol=1e-4 * np.max(np.abs(b.impulses)))


def test_unknown_counts_follow_the_scene():
    # Rods in 3D: 5 rigid + growth; spheres: 3; fixed: none; planar rods: 3 + growth.
    rods3d = qc.Cells([[0, 0.9, 0], [0, 0, 0]], [[1, 0, 0], [0, 0, 1]], 2.0, 0.5, growth_inertia=[1.0, np.inf],
                      momenta=[[0, -1, 0], [0, 0, 0]])
    assert qc.resolve(rods3d, solver="linear").n_unknowns == 6 + 5
    spheres = rods3d.replace(lengths=0.0, centers=[[0, 0.9, 0], [0, 0, 0]])
    assert qc.resolve(spheres, solver="linear").n_unknowns == 4 + 3
    fixed = rods3d.replace(masses=[1.0, np.inf])
    assert qc.resolve(fixed, solver="linear").n_unknowns == 6
    planar = rods3d.replace(axes=[[1, 0, 0], [0, 1, 0]], centers=[[0, 1.9, 0], [0, 0, 0]])
    r = qc.resolve(planar, solver="linear")
    assert r.planar and r.n_unknowns == 4 + 3


@pytest.mark.parametrize("solver", ["linear", "clarabel", "osqp"])
@pytest.mark.parametrize("seed", range(3))
def test_planar_scene_solved_as_planar_and_as_3d_gives_the_same_impulses(solver, seed):
    cells = random_scene(seed, n_cells=40, planar=True)
    contacts = qc.find_contacts(cells, planar=True)  # the same contacts (in-plane normals) for both
    planar = qc.resolve(cells, solver=solver, tolerance=1e-8, contacts=contacts)
    spatial = qc.resolve(cells, solver=solver, tolerance=1e-8, planar=False, contacts=contacts)
    assert planar.planar and not spatial.planar
    assert planar.n_unknowns < spatial.n_unknowns
    scale = np.max(np.abs(spatial.impulses))
    assert np.allclose(planar.impulses, spatial.impulses, atol=1e-4 * scale)
    # In-plane impulses only: no z momentum, no angular momentum about in-plane axes.
    assert np.all(planar.impulses[:, [2, 3, 4]] == 0)


def test_forcing_planar_on_a_3d_scene_raises():
    cells = random_scene(0, n_cells=20)
    active, b = colliding(qc.find_contacts(cells))
    with pytest.raises(InvalidArgumentError, match="planar=True"):
        build_system(cells, active, b, planar=True)


@pytest.mark.parametrize("solver", ["linear", "clarabel", "osqp"])
@pytest.mark.parametrize("formulation", ["complementarity", "least_squares"])
def test_results_are_unit_invariant(solver, formulation):
    """The same scene in µm/pg/s and in m/kg/s: the same dimensionless problem and answer."""
    micro = random_scene(4, n_cells=30, unit_length=1.0, unit_mass=1.0)  # µm, pg
    si = random_scene(4, n_cells=30, unit_length=1e-6, unit_mass=1e-15)  # m, kg
    a = qc.resolve(micro, solver=solver, formulation=formulation, tolerance=1e-7)
    b = qc.resolve(si, solver=solver, formulation=formulation, tolerance=1e-7)
    assert np.allclose(a.system.matrix.toarray(), b.system.matrix.toarray(), rtol=1e-9, atol=1e-12)
    assert np.allclose(a.system.rhs, b.system.rhs, rtol=1e-9)
    assert np.allclose(a.scaled_solution, b.scaled_solution, atol=1e-6 * np.max(np.abs(a.scaled_solution)))
    momentum_unit = np.array([1e-21] * 3 + [1e-27] * 3 + [1e-21])  # pg·µm/s in kg·m/s; ×µm for L
    assert np.allclose(b.impulses, a.impulses * momentum_unit, atol=1e-6 * np.max(np.abs(b.impulses)))
    assert a.errors["penetration"] == pytest.approx(b.errors["penetration"], abs=1e-9)
