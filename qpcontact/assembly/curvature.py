"""The second-order term of a linearization: the contacts' curvature in the scaled unknowns.

A position step (:mod:`qpcontact.timestep.position`) solves, at each linearization, the QP
``min ½‖ỹ‖² s.t. B̃ỹ ≥ b̃`` of :mod:`qpcontact.assembly.system`, whose rows are the gradients of
the constraints ``g_k(ỹ) = (d_k(ỹ) − target_k) / (dt σ_b) ≥ 0``. A sequential QP converges in
few linearizations only when its objective also holds the curvature of the constraints weighted
by their multipliers (the Hessian of the Lagrangian), ``−Σ λ̃_k ∇²g_k``. This module builds it,
from each contact's separation Hessian (:func:`qpcontact.geometry.curvature.separation_hessians`)
and the contact impulses of the last solve, as rows ``R`` of the objective's
``½‖R(ỹ − ỹ₀)‖²`` (``ỹ₀``: the unknowns of the linearization point).

Only the concave part of each separation is kept (where the linearization overstates the
separation: a point sliding along a turning rod, a turn's arc): the convex part (the normal
turning) would make the objective indefinite, and it errs on the safe side (the separation is
larger than predicted). Per contact, the negative eigenvalues of ``∇²g_k`` restricted to its two
cells' columns, each a row ``sqrt(λ̃_k μ) vᵀ``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..geometry.cells import Cells
from ..geometry.curvature import separation_hessians
from .system import ContactSystem, Turned

__all__ = ["curvature_rows"]

#: Eigenvalues below this fraction of a contact's largest are dropped (rounding).
SMALLEST_EIGENVALUE = 1e-10


def _column_directions(system: ContactSystem, turned: Turned | None, dt: float) -> np.ndarray:
    """(n, 7) each column's move of its cell's coordinates (centre, turn, length) per unit of
    ``ỹ``: ``dt·sqrt(w)·σ_b/σ_B`` along its slot, the turns through the step's left Jacobian."""
    n = system.shape[1]
    basis = system.column_basis
    direction = np.zeros((n, 7))
    direction[:, 0:3] = basis[:, 0:3]
    rotation = basis[:, 3:6]
    if turned is not None:
        rotation = np.einsum("kij,kj->ki", turned.jacobian[system.column_cell], rotation)
    direction[:, 3:6] = rotation
    direction[:, 6] = basis[:, 6]
    scale = dt * np.sqrt(system.column_inverse_mass) * system.velocity_scale / system.operator_scale
    return direction * scale[:, None]


def curvature_rows(system: ContactSystem, cells: Cells, contact_impulses: np.ndarray, dt: float,
                   turned: Turned | None = None) -> sp.csr_matrix | None:
    """The rows ``R`` (r, n) of the objective's curvature ``½‖R(ỹ − ỹ₀)‖²`` (module docstring)
    for the contacts of ``system`` with the physical ``contact_impulses`` (K,) of the last
    solve, at ``cells`` (those the contacts were evaluated at); None when no contact pushes.

    Args:
        system: the linearization's system (its scales and columns).
        cells: the cells where the contacts were evaluated (the moved cells of the step).
        contact_impulses: (K,) ``λ`` [mass·length/time] per row (0: a contact that did not push).
        dt: the step [time].
        turned: the step's turns (:class:`~qpcontact.assembly.system.Turned`), as in the rows.
    """
    pushing = np.flatnonzero(contact_impulses > 0)
    if pushing.size == 0:
        return None
    contacts = system.contacts.subset(pushing)
    # The columns of each contact's two cells (the slots any column uses), and their directions.
    n = system.shape[1]
    slots = np.unique(system.column_slot)
    column_of = np.full((system.n_cells + 1, 7), -1, dtype=np.intp)  # row n_cells: a plane's side
    column_of[system.column_cell, system.column_slot] = np.arange(n)
    cell_b = np.where(contacts.cell_b >= 0, contacts.cell_b, system.n_cells)
    columns = np.concatenate([column_of[contacts.cell_a][:, slots], column_of[cell_b][:, slots]], axis=1)
    directions = np.vstack([_column_directions(system, turned, dt), np.zeros((1, 7))])
    moves = directions[columns]  # (P, 2S, 7); an absent column (-1) takes the zero row
    m = slots.size
    to_coordinates = np.zeros((pushing.size, 14, 2 * m))
    to_coordinates[:, 0:7, :m] = moves[:, :m].transpose(0, 2, 1)
    to_coordinates[:, 7:14, m:] = moves[:, m:].transpose(0, 2, 1)
    # −∇²g_k = −∇²d_k / (dt σ_b) in the columns, weighted by λ̃_k; its positive part.
    weight = system.from_contact_impulses(contact_impulses[pushing]) / (dt * system.velocity_scale)
    concave = -weight[:, None, None] * separation_hessians(cells, contacts, to_coordinates)
    values, vectors = np.linalg.eigh(concave)  # (P, 2S), (P, 2S, 2S): eigenvectors in columns
    keep = (values > 0) & (values > SMALLEST_EIGENVALUE * values[:, -1:])
    entries = vectors * np.sqrt(np.where(keep, values, 0.0))[:, None, :]  # (P, column i, eigen e)
    contact, column, eigen = np.nonzero(keep[:, None, :] & (columns >= 0)[:, :, None]
                                        & (entries != 0.0))
    row_ids = contact * (2 * m) + eigen
    used, row = np.unique(row_ids, return_inverse=True)
    return sp.csr_matrix((entries[contact, column, eigen], (row, columns[contact, column])), shape=(used.size, n))
