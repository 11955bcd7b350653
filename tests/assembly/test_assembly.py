"""The assembled system against independent constructions: the slot frame by hand and by its
defining properties, and ``B̃`` against the dense world-frame ``M = J W`` of model.md
(:func:`tests.helpers.world_operators`), which knows nothing of slots, reduction or scaling."""

from __future__ import annotations

import numpy as np
import pytest

import qpcontact as qc
from qpcontact.assembly import SLOTS, slot_directions
from tests.helpers import random_scene, world_operators

ROTATION = slice(3, 6)


def _frame(cells: qc.Cells, cell: int) -> np.ndarray:
    """(3, 3): the rotation slots (spin, roll1, roll2) of one cell as rows, in the world frame."""
    rows = slot_directions(cells, np.full(3, cell), np.array([3, 4, 5]))
    assert np.all(rows[:, :3] == 0) and np.all(rows[:, 6] == 0)  # rotation slots carry ΔL only
    return rows[:, ROTATION]


@pytest.mark.parametrize("axis, roll1, roll2", [
    ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0)),   # e₁ = â × ẑ, e₂ = â × e₁
    ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, -1.0)),
    ((0.6, 0.8, 0.0), (0.8, -0.6, 0.0), (0.0, 0.0, -1.0)),    # in the plane: e₂ = −ẑ, the planar roll
    ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (-1.0, 0.0, 0.0)),   # near ẑ the reference is x̂: e₁ = ẑ × x̂
    ((0.0, 0.6, -0.8), (0.6, 0.0, 0.0), (0.0, -0.8, -0.6)),  # |a_z| < 0.9: e₁ = â × ẑ (then normalized)
])
def test_slot_frames_computed_by_hand(axis, roll1, roll2):
    cells = qc.Cells([[0.0, 0.0, 0.0]], [axis], 2.0, 0.5)
    expected = np.array([axis, roll1, roll2])
    expected /= np.linalg.norm(expected, axis=1)[:, None]
    np.testing.assert_allclose(_frame(cells, 0), expected, atol=1e-15)


def test_slot_frames_are_right_handed_orthonormal_and_start_with_the_axis():
    rng = np.random.default_rng(0)
    axes = rng.normal(size=(200, 3))
    axes[:20] = [0.0, 0.0, 1.0] + 1e-3 * rng.normal(size=(20, 3))  # around the switch of reference axis
    axes[20:40, 2] = 0.0  # in the plane
    cells = qc.Cells(rng.normal(size=(200, 3)), axes, 1.0, 0.5, normalize_axes=True)
    for cell in range(cells.n):
        frame = _frame(cells, cell)
        np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(frame) == pytest.approx(1.0, abs=1e-14)
        np.testing.assert_allclose(frame[0], cells.axes[cell], atol=1e-15)
    planar = _frame(cells, 25)
    np.testing.assert_allclose(planar[2], [0.0, 0.0, -1.0], atol=1e-15)  # planar scenes keep only e₂ = −ẑ
    # Translation and growth slots are the world's unit vectors.
    others = slot_directions(cells, np.zeros(4, dtype=int), np.array([0, 1, 2, 6]))
    np.testing.assert_array_equal(others, np.eye(7)[[0, 1, 2, 6]])
    assert SLOTS == ("tx", "ty", "tz", "spin", "roll1", "roll2", "growth")


def _scenes():
    rng = np.random.default_rng(7)
    for seed in range(3):
        cells = random_scene(seed, n_cells=30)
        # some fixed cells and some that cannot grow
        cells = cells.replace(masses=np.where(rng.random(cells.n) < 0.15, np.inf, cells.masses),
                              growth_inertia=np.where(rng.random(cells.n) < 0.3, np.inf, cells.growth_inertia))
        yield f"3d-{seed}", cells
    yield "planar", random_scene(5, n_cells=30, planar=True)
    spheres = random_scene(6, n_cells=30)
    yield "spheres", spheres.replace(lengths=np.where(np.arange(30) % 2 == 0, 0.0, spheres.lengths))


@pytest.mark.parametrize("reduce", [True, False])
@pytest.mark.parametrize("name, cells", list(_scenes()), ids=[n for n, _ in _scenes()])
def test_scaled_matrix_reproduces_the_world_frame_operator(name, cells, reduce):
    """``B̃B̃ᵀσ_B² = J W Jᵀ`` (the Delassus operator does not depend on the basis, and the unknowns
    left out contribute nothing), and the impulses of any scaled answer change the normal
    velocities by ``σ_b B̃ỹ``."""
    active, b = qc.colliding(qc.find_contacts(cells))
    system = qc.build_system(cells, active, b, reduce=reduce)
    J, W = world_operators(cells, active)
    delassus = J @ W @ J.T
    scale = np.abs(delassus).max()
    B = system.matrix.toarray()
    np.testing.assert_allclose(B @ B.T * system.operator_scale**2, delassus, rtol=0, atol=1e-12 * scale)
    y = np.random.default_rng(1).normal(size=system.shape[1])
    change = J @ W @ system.to_impulses(y).ravel()
    np.testing.assert_allclose(change, system.velocity_scale * (B @ y), rtol=0,
                               atol=1e-12 * np.abs(change).max())
    np.testing.assert_allclose(system.rhs * system.velocity_scale, b, rtol=1e-15)


@pytest.mark.parametrize("name, cells", list(_scenes()), ids=[n for n, _ in _scenes()])
def test_each_column_is_a_principal_direction_of_the_inverse_mass(name, cells):
    """The body-frame slots diagonalize W: ``W d = w d`` for each column's direction ``d`` and
    its ``column_inverse_mass`` ``w`` (so ``ỹ = W^{1/2}x`` needs no matrix square root)."""
    active, b = qc.colliding(qc.find_contacts(cells))
    system = qc.build_system(cells, active, b)
    _, W = world_operators(cells, active)
    for cell, direction, w in zip(system.column_cell, system.column_basis, system.column_inverse_mass, strict=True):
        block = W[7 * cell:7 * cell + 7, 7 * cell:7 * cell + 7]
        np.testing.assert_allclose(block @ direction, w * direction, atol=1e-12 * max(w, 1.0))
        assert w > 0 and np.linalg.norm(direction) == pytest.approx(1.0)
