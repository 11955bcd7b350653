"""Cells: construction, broadcasting, derived quantities, and the documented input errors."""

import numpy as np
import pytest

import qpcontact as qc
from qpcontact.errors import InvalidCellsError
from qpcontact.geometry.cells import Cells


def make(**kw):
    base = dict(centers=np.zeros((2, 3)), axes=[[1, 0, 0], [0, 1, 0]], lengths=[2.0, 1.0], radii=0.5)
    base.update(kw)
    return Cells(**base)  # (qc.Cells is the same class: test_the_public_api_is_the_wings_own below)


def test_scalars_broadcast_and_inputs_are_copied():
    centres = np.zeros((2, 3))
    cells = make(centers=centres, masses=2.0, momenta=[1.0, 0.0, 0.0])
    assert cells.masses.shape == (2,) and np.all(cells.masses == 2.0)
    assert cells.momenta.shape == (2, 3) and np.all(cells.momenta[:, 0] == 1.0)
    centres[0, 0] = 5.0
    assert cells.centers[0, 0] == 0.0


def test_inverse_inertia_is_the_axisymmetric_solid_cylinder():
    cells = make(masses=3.0)
    m, rho, length = 3.0, 0.5, 2.0
    i_par, i_perp = m * rho**2 / 2, m * (3 * rho**2 + length**2) / 12
    w = np.array([[1.0, 2.0, 3.0], [1.0, 2.0, 3.0]])
    got = cells.apply_inverse_inertia(w)[0]
    assert np.allclose(got, [1 / i_par, 2 / i_perp, 3 / i_perp])  # axis of cell 0 is x


def test_fixed_and_non_growing_cells_have_zero_inverse_mass():
    cells = make(masses=[np.inf, 1.0], growth_inertia=np.inf, momenta=[[1.0, 0, 0], [1.0, 0, 0]])
    assert cells.inverse_masses[0] == 0 and cells.velocities[0, 0] == 0
    assert np.all(cells.growth_rates == 0)


def test_kinetic_energy_matches_the_sum_of_parts():
    cells = make(masses=2.0, growth_inertia=4.0, momenta=[[2.0, 0, 0], [0, 0, 0]], growth_momenta=[0.0, 4.0])
    assert cells.kinetic_energy() == pytest.approx(0.5 * 4.0 / 2.0 + 0.5 * 16.0 / 4.0)


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(centers=np.zeros((2, 2))), "centers: expected shape"),
        (dict(lengths=[1.0, 2.0, 3.0]), "lengths: expected shape"),
        (dict(radii=[0.5, np.nan]), "radii: NaN"),
        (dict(centers=[[0, 0, np.inf], [0, 0, 0]]), "centers: NaN or inf"),
        (dict(radii=[0.5, -1.0]), "radii: must be > 0"),
        (dict(radii=0.0), "radii: must be > 0"),
        (dict(masses=[1.0, 0.0]), "masses: must be > 0"),
        (dict(masses=[1.0, np.nan]), "masses: NaN"),
        (dict(growth_inertia=-1.0), "growth_inertia: must be > 0"),
        (dict(lengths=[-1.0, 1.0]), "lengths: must be >= 0"),
        (dict(axes=[[0, 0, 0], [1, 0, 0]]), "axes: zero axis at cell 0"),
        (dict(axes=[[2, 0, 0], [1, 0, 0]]), "axes: not unit length at cell 0"),
        (dict(momenta=[[np.nan, 0, 0], [0, 0, 0]]), "momenta: NaN or inf"),
        (dict(masses="heavy"), "masses: expected numbers"),
        # issue 13, item 9
        (dict(centers=[[0, 0, 0], [1, 2]]), "centers: cannot be read as an array of numbers"),
        (dict(centers="origin"), "centers: expected numbers"),
        (dict(centers=[["0", "0", "0"], ["1", "0", "0"]]), "centers: expected numbers"),
        (dict(momenta=[[1 + 1j, 0, 0], [0, 0, 0]]), "momenta: complex values are not accepted"),
        (dict(radii=1e-170, angular_momenta=[0, 0, 1.0]), r"1/I∥ = 2/\(mρ²\) is not a finite positive number at cell 0"),
        (dict(masses=1e-320), "1/m is not a finite positive number"),
        (dict(normalize_axes="no"), "normalize_axes: expected True or False"),
    ],
)
def test_bad_inputs_raise_clear_errors(kw, match):
    with pytest.raises(InvalidCellsError, match=match):
        make(**kw)


def test_axes_are_normalized_only_on_request():
    cells = make(axes=[[2, 0, 0], [0, 3, 4]], normalize_axes=True)
    assert np.allclose(np.linalg.norm(cells.axes, axis=1), 1.0)
    nearly = make(axes=[[1 + 1e-9, 0, 0], [0, 1, 0]])  # within tolerance: renormalized exactly
    assert np.linalg.norm(nearly.axes[0]) == pytest.approx(1.0, abs=1e-15)


def test_with_impulses_checks_shape_and_adds():
    cells = make()
    with pytest.raises(InvalidCellsError, match=r"impulses: expected shape \(2, 7\)"):
        cells.with_impulses(np.zeros((2, 6)))
    out = cells.with_impulses(np.arange(14.0).reshape(2, 7))
    assert np.allclose(out.momenta[1], [7, 8, 9]) and np.allclose(out.growth_momenta, [6, 13])


def test_normalizing_huge_and_tiny_axes_keeps_their_direction():
    """Issue 13, item 9: |a| of an axis of 1e200 overflowed, and the axis became zero."""
    cells = make(axes=[[1e200, 1e200, 0], [0, 3e-200, 4e-200]], normalize_axes=True)
    np.testing.assert_allclose(cells.axes, [[2**-0.5, 2**-0.5, 0], [0, 0.6, 0.8]], rtol=1e-15)


def test_world_inverse_inertia_is_the_body_one_turned_from_x_to_the_axis():
    """docs/model.md, "Corrections to the original derivation": the original writes
    ``I⁻¹ = T I_cyl⁻¹ T⁻¹`` with ``T`` "from world to local coordinates, i.e. taking x to the
    axis" — two opposite maps. The right one is ``R I_cyl⁻¹ Rᵀ`` with ``R`` taking the body x
    axis to â (body to world), which is the axisymmetric form the package uses; the world-to-
    body map in its place gives a different tensor."""
    from scipy.spatial.transform import Rotation

    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    cells = make(axes=[axis, [0, 1, 0]], lengths=[2.0, 1.0], masses=3.0)
    m, rho, length = 3.0, 0.5, 2.0
    body = np.diag([2 / (m * rho**2), 12 / (m * (3 * rho**2 + length**2)), 12 / (m * (3 * rho**2 + length**2))])
    to_world = Rotation.align_vectors([axis], [[1.0, 0.0, 0.0]])[0].as_matrix()  # x ↦ â
    assert np.allclose(to_world @ [1.0, 0.0, 0.0], axis)
    world = to_world @ body @ to_world.T
    w = np.random.default_rng(0).normal(size=(2, 3))
    assert np.allclose(cells.apply_inverse_inertia(w)[0], world @ w[0])
    wrong = to_world.T @ body @ to_world  # T taken as world → body
    assert not np.allclose(wrong, world, atol=1e-3 * np.abs(world).max())


def test_the_public_api_is_the_wings_own():
    assert qc.Cells is Cells
