"""The contact system: sparse ``M``, right-hand side ``b``, metric ``W``, reduced and scaled.

Row k of ``M`` is ``nᵀM_{r_a}`` in a's columns and ``−nᵀM_{r_b}`` in b's, so ``(M x)_k`` is the
change of relative normal velocity at contact k for stacked impulses ``x``. ``M = J W``, with
``W`` the inverse generalized mass and ``J`` the contact Jacobian (``nᵀ``, ``(r × n)ᵀ``,
``(s/l)(â·n)`` per side).

Unknowns (model.md, "Leaving out what a scene does not need"): each cell has seven *slots* in
its body frame, translation along x, y, z; rotation about â, e₁, e₂ (e₁, e₂ ⊥ â); growth. In
this basis ``W`` is diagonal (``1/m``, ``1/I∥``, ``1/I⊥``, ``1/I⊥``, ``1/G``). A slot becomes a
column only when the scene needs it: the cell is in a colliding contact and not fixed; never the
spin about â (its column of M is zero); rotation only for rods (l > 0); growth only for finite
G; in a planar scene (axes and normals in the xy-plane) only x, y, rotation about z and growth.

Scaling (unit invariance): the solvers see ``B̃ ỹ ≥ b̃`` with the mass-weighted unknowns
``y = W^{1/2} x`` (so the kinetic-energy metric becomes Euclidean and ``‖x‖_W = ‖y‖``),
``B̃ = J W^{1/2} / σ_B`` and ``b̃ = b / σ_b``, where ``σ_b = max b`` [length/time] (the fastest
approach; ``max|b|`` if no contact approaches) and
``σ_B² = mean diag(J W Jᵀ)`` [1/mass] (mean effective inverse mass of a contact). Both are
dimensionless: a scene in µm/pg and in m/kg gives the same ``B̃``, ``b̃``, and ``ỹ``.
Physical impulses are ``x = W^{-1/2} ỹ σ_b/σ_B``; contact impulses ``λ = λ̃ σ_b/σ_B²``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidArgumentError
from ..geometry.cells import PLANAR_TOLERANCE, Cells, perpendicular_basis
from ..geometry.contacts import Contacts
from ..geometry.regions import ONE, Split

#: Slots of a cell, in order. Their world-frame directions come from :func:`slot_directions`.
SLOTS = ("tx", "ty", "tz", "spin", "roll1", "roll2", "growth")


def slot_directions(cells: Cells, cell: np.ndarray, slot: np.ndarray) -> np.ndarray:
    """(m, 7): the direction of slot ``slot[i]`` of cell ``cell[i]`` in the world (Δp, ΔL, Δg)
    space. Only the rows asked for are built (not 7 × 7 per cell: at 10⁵ cells that was the
    largest cost of assembly)."""
    out = np.zeros((cell.size, 7))
    translation = slot < 3
    out[translation, slot[translation]] = 1.0
    out[slot == 6, 6] = 1.0
    rotation = np.flatnonzero((slot >= 3) & (slot <= 5))
    if rotation.size:
        axes = cells.axes[cell[rotation]]
        e1, e2 = perpendicular_basis(axes)
        out[rotation, 3:6] = np.stack([axes, e1, e2])[slot[rotation] - 3, np.arange(rotation.size)]
    return out


def slot_inverse_mass(cells: Cells, index: np.ndarray) -> np.ndarray:
    """(len(index), 7) the diagonal of W in the slot basis (0 for a fixed or non-growing cell)."""
    inv_m = cells.inverse_masses[index]
    inv_perp = cells.inverse_inertia_perpendicular[index]
    return np.stack([
        inv_m, inv_m, inv_m, cells.inverse_inertia_parallel[index], inv_perp, inv_perp,
        cells.inverse_growth_inertia[index],
    ], axis=1)


def is_planar(cells: Cells, contacts: Contacts) -> bool:
    """True when every contact normal and every contacting cell's axis lie in the xy-plane: the
    system's planar reduction applies (a mechanics scene is planar by another test,
    :func:`qpcontact.timestep.mechanics.is_monolayer_scene`)."""
    cells_in = np.concatenate([contacts.cell_a, contacts.cell_b[contacts.cell_b >= 0]])
    return bool(
        np.all(np.abs(contacts.normal[:, 2]) <= PLANAR_TOLERANCE)
        and np.all(np.abs(cells.axes[cells_in, 2]) <= PLANAR_TOLERANCE)
    )


@dataclass(frozen=True, eq=False)
class ContactSystem:
    """The scaled, reduced system handed to the solvers (see the module docstring).

    Attributes:
        matrix: (K, n) sparse CSR ``B̃ = J W^{1/2}/σ_B`` (dimensionless).
        rhs: (K,) ``b̃ = b/σ_b`` (dimensionless, max 1).
        b: (K,) ``b`` [length/time], the required change of normal velocity.
        velocity_scale: ``σ_b`` [length/time].
        operator_scale: ``σ_B`` [1/sqrt(mass)].
        column_cell: (n,) the cell each column belongs to.
        column_slot: (n,) the slot (index into ``SLOTS``) of each column.
        column_basis: (n, 7) the column's direction in its cell's world (Δp, ΔL, Δg) space.
        column_inverse_mass: (n,) the diagonal of W for each column.
        n_cells: number of cells in the scene.
        planar: whether the planar reduction was used.
        contacts: the K colliding contacts, in row order.
        owned_rows: the rows this process assembled, when the system is shared among the
            processes of ``split`` (:func:`build_system`'s ``split``): the other rows of
            ``matrix`` are empty and those of ``rhs`` and ``b`` are not meaningful; None: every
            row is here.
        split: the processes the system is shared among (:class:`~qpcontact.geometry.regions.Split`).
    """

    matrix: sp.csr_matrix
    rhs: np.ndarray
    b: np.ndarray
    velocity_scale: float
    operator_scale: float
    column_cell: np.ndarray
    column_slot: np.ndarray
    column_basis: np.ndarray
    column_inverse_mass: np.ndarray
    n_cells: int
    planar: bool
    contacts: Contacts
    owned_rows: np.ndarray | None = None
    split: Split = ONE

    @property
    def shape(self) -> tuple[int, int]:
        """``(K, n)``: contact rows, unknowns."""
        return self.matrix.shape

    def to_impulses(self, y: np.ndarray) -> np.ndarray:
        """(N, 7) physical impulses ``(Δp, ΔL, Δg)`` from scaled unknowns ``ỹ``."""
        w = self.column_inverse_mass
        x = np.zeros_like(y)
        pos = w > 0
        x[pos] = y[pos] / np.sqrt(w[pos]) * (self.velocity_scale / self.operator_scale)
        out = np.zeros((self.n_cells, 7))
        contributions = x[:, None] * self.column_basis
        for j in range(7):  # seven bincounts over the columns (not a loop over cells)
            out[:, j] = np.bincount(self.column_cell, weights=contributions[:, j], minlength=self.n_cells)
        return out

    def to_contact_impulses(self, lam: np.ndarray) -> np.ndarray:
        """Physical contact impulses ``λ`` [mass·length/time] from scaled ``λ̃``."""
        return lam * self.velocity_scale / self.operator_scale**2

    def from_contact_impulses(self, contact_impulses: np.ndarray) -> np.ndarray:
        """Scaled ``λ̃`` from physical contact impulses ``λ`` (the inverse of
        :meth:`to_contact_impulses`)."""
        return contact_impulses * self.operator_scale**2 / self.velocity_scale

    def velocity_changes(self, impulses: np.ndarray) -> np.ndarray:
        """(K,) ``(M x)_k = (J W x)_k`` [length/time]: the change of each contact's relative normal
        velocity that the (N, 7) impulses ``x`` make (their part in the columns: a slot left out
        moves no contact of the system), one product with ``B̃``."""
        x = np.einsum("ij,ij->i", impulses[self.column_cell], self.column_basis)
        return self.matrix @ (x * np.sqrt(self.column_inverse_mass) * self.operator_scale)

    def with_rhs(self, b: np.ndarray) -> ContactSystem:
        """The same (scaled) system with the right-hand side ``b`` [length/time] and its scale ``σ_b``."""
        b = np.asarray(b, dtype=float)
        if b.shape != self.b.shape:
            raise InvalidArgumentError(f"b: expected shape {self.b.shape}, got {b.shape}")
        scale = _velocity_scale(b, self.owned_rows, self.split)
        return dataclasses.replace(self, rhs=b / scale, b=b, velocity_scale=scale)

    def from_impulses(self, impulses: np.ndarray) -> np.ndarray:
        """Scaled unknowns ``ỹ`` for (N, 7) impulses (the part that lies in the columns)."""
        x = np.einsum("ij,ij->i", impulses[self.column_cell], self.column_basis)
        return x * np.sqrt(self.column_inverse_mass) * (self.operator_scale / self.velocity_scale)


@dataclass(frozen=True, eq=False)
class Turned:
    """Contacts evaluated at the end of a step that turned the cells: the unknowns stay in the
    slots of the cells at the start of the step (their axes, their W), and the rows of ``M`` are
    the exact derivatives of the end-of-step normal gaps (the position-level step,
    :mod:`qpcontact.timestep.position`).

    Attributes:
        axes: (N, 3) the axes at the end of the step (a contact point rides along these as the
            cell grows).
        jacobian: (N, 3, 3) the left Jacobian of each cell's turn over the step
            (:func:`qpcontact.geometry.motion.left_jacobian`): a change ``δθ`` of the turn in the
            start frame turns the end state by ``J·δθ``.
    """

    axes: np.ndarray
    jacobian: np.ndarray


def contact_jacobian(contacts: Contacts, cells: Cells, side: str, turned: Turned | None = None) -> np.ndarray:
    """(K, 7) one side of J in the slot basis of its cell (without the ± sign):
    ``[nᵀ, (r × n)·â, (r × n)·e₁, (r × n)·e₂, (s/l)(â·n)]``; for contacts at the end of a turned
    step (:class:`Turned`), the moment is ``Jᵀ(r × n)`` and the growth term uses the end axis."""
    cell = contacts.cell_a if side == "a" else contacts.cell_b
    offset = contacts.offset_a if side == "a" else contacts.offset_b
    stretch = contacts.stretch_a if side == "a" else contacts.stretch_b
    n = contacts.normal
    moment = np.cross(offset, n)
    axes = cells.axes[cell]
    riding = axes
    if turned is not None:
        moment = np.einsum("kji,kj->ki", turned.jacobian[cell], moment)
        riding = turned.axes[cell]
    e1, e2 = perpendicular_basis(axes)
    dot = lambda u, v: np.einsum("ij,ij->i", u, v)  # noqa: E731
    return np.column_stack([n, dot(moment, axes), dot(moment, e1), dot(moment, e2), stretch * dot(riding, n)])


def velocity_changes(cells: Cells, contacts: Contacts, impulses: np.ndarray, turned: Turned | None = None) -> np.ndarray:
    """(K,) ``(M x)_k`` [length/time]: the change of each contact's relative normal velocity that
    the (N, 7) impulses ``x`` make, with the rows of :func:`build_system` (the same ``turned``),
    for every slot of every cell but the spin about the own axis (which moves no contact point,
    and which the position-level motion drops): :meth:`ContactSystem.velocity_changes` of the
    system of these contacts (all slots but the spin)."""
    return build_system(cells, contacts, np.ones(len(contacts)), planar=False, turned=turned).velocity_changes(impulses)


def _velocity_scale(b: np.ndarray, rows: np.ndarray | None = None, split: Split = ONE) -> float:
    """``σ_b`` [length/time]: the fastest approach, ``max b`` (``max|b|`` if none approaches);
    over the ``rows`` each process of ``split`` holds when the system is shared."""
    if rows is None:
        return float(np.max(b)) if np.max(b) > 0 else float(np.max(np.abs(b)))
    own = b[rows]
    fastest = split.most(float(np.max(own, initial=-np.inf)))
    return fastest if fastest > 0 else split.most(float(np.max(np.abs(own), initial=0.0)))


def build_system(
    cells: Cells, contacts: Contacts, b: np.ndarray, *, reduce: bool = True, planar: bool | None = None,
    scale: bool = True, turned: Turned | None = None, split: Split = ONE, owner: np.ndarray | None = None,
) -> ContactSystem:
    """Assemble the scaled system for the colliding ``contacts`` with right-hand side ``b``.

    Args:
        cells: the scene.
        contacts: the colliding contacts (see :func:`qpcontact.geometry.colliding`).
        b: (K,) required change of normal velocity, > 0 [length/time].
        reduce: leave out the unknowns the scene does not need (default). ``False`` keeps all
            seven slots of every cell (for tests: the answer must not change).
        planar: use the planar reduction; ``None`` detects it (:func:`is_planar`). ``True`` on a
            scene that is not planar raises.
        scale: divide by ``σ_b`` and ``σ_B`` (default). ``False`` sets both to 1 (the matrix is
            then ``J W^{1/2}`` in the caller's units), only to measure the effect of scaling.
        turned: the contacts are those at the end of a step that turned the cells
            (:class:`Turned`; the position-level step); None: at the cells as they are.
        split, owner: the processes sharing the assembly and the (N,) process that owns each
            cell: each process builds the rows of the contacts whose first cell is its own (the
            scales are reductions over the processes); the columns are numbered alike in every
            process. None (or one process): every row.

    Raises:
        InvalidArgumentError: a bad ``b`` or ``planar``, no contact, or a contact whose cells
            cannot move.
    """
    k = len(contacts)
    if b.shape != (k,):
        raise InvalidArgumentError(f"b: expected shape ({k},), got {b.shape}")
    if k == 0:
        raise InvalidArgumentError("build_system: no colliding contact (nothing to solve)")
    detected = is_planar(cells, contacts)
    if planar is None:
        planar = detected
    elif planar and not detected:
        raise InvalidArgumentError("planar=True, but some contact normal or axis leaves the xy-plane")
    planar = bool(planar and reduce)

    rows = None if owner is None or split.size == 1 else np.flatnonzero(owner[contacts.cell_a] == split.rank)
    column_of = _columns(cells, contacts, reduce, planar)
    inverse_mass = slot_inverse_mass(cells, np.arange(cells.n))
    raw = _raw_matrix(cells, contacts, column_of, np.sqrt(inverse_mass), turned, rows)
    diag = np.asarray(raw.multiply(raw).sum(axis=1)).ravel()
    held = slice(None) if rows is None else rows
    stuck = np.flatnonzero(~(diag[held] > 0))
    if split.most(float(stuck.size)) > 0:  # every process raises, not only the one that holds the row
        if stuck.size:
            bad = int(np.arange(k)[held][stuck[0]])
            raise InvalidArgumentError(
                f"contact {bad} (cells {contacts.cell_a[bad]}, {contacts.cell_b[bad]}) has no movable degree of freedom")
        raise InvalidArgumentError("a contact held by another process has no movable degree of freedom")
    # scale=False (σ_b = σ_B = 1) exists to measure what the scaling buys (docs/stability.md).
    mean = float(diag.mean()) if rows is None else split.total(float(diag.sum())) / k
    operator_scale = float(np.sqrt(mean)) if scale else 1.0
    # The approach speeds set the scale: separating contacts kept in the system (b <= 0) must
    # not shrink the colliding ones' right-hand sides towards the solvers' tolerances.
    velocity_scale = _velocity_scale(b, rows, split) if scale else 1.0
    # Columns were numbered in row-major order of column_of (involved is sorted), so np.nonzero
    # lists them in column order.
    col_cell, col_slot = np.nonzero(column_of >= 0)
    raw.data *= 1.0 / operator_scale  # as scipy divides a matrix by a scalar (same bits as before)
    return ContactSystem(
        matrix=raw,
        rhs=b / velocity_scale,
        b=np.asarray(b, dtype=float),
        velocity_scale=velocity_scale,
        operator_scale=operator_scale,
        column_cell=col_cell,
        column_slot=col_slot,
        column_inverse_mass=inverse_mass[col_cell, col_slot],
        column_basis=slot_directions(cells, col_cell, col_slot),
        n_cells=cells.n,
        planar=planar,
        contacts=contacts,
        owned_rows=rows,
        split=split,
    )


def _columns(cells: Cells, contacts: Contacts, reduce: bool, planar: bool) -> np.ndarray:
    """(N, 7) the column of each cell's slot in the system, -1 where it has none: which cells get
    columns (with ``reduce``, those in some contact that can move), and which of their seven
    slots (not the spin about the own axis, nor what the scene cannot use)."""
    if reduce:
        # Sorted cells in some contact (a bincount is O(N); np.unique sorts 2K indices).
        moving_b = contacts.cell_b[contacts.cell_b >= 0]
        involved = np.flatnonzero(np.bincount(np.concatenate([contacts.cell_a, moving_b]), minlength=cells.n))
        involved = involved[np.isfinite(cells.masses[involved])]
    else:
        involved = np.arange(cells.n)
    used = np.ones((involved.size, 7), dtype=bool)
    if reduce:
        used[:, 3] = False  # spin about the own axis never changes a normal velocity
        rod = cells.lengths[involved] > 0
        used[:, 4] &= rod
        used[:, 5] &= rod
        used[:, 6] = cells.inverse_growth_inertia[involved] > 0
        if planar:
            used[:, 2] = False  # tz
            used[:, 4] = False  # roll1 lies in the plane; roll2 = -z is kept
    column_of = np.full((cells.n, 7), -1, dtype=np.intp)
    column_of[involved] = np.where(used, np.cumsum(used).reshape(used.shape) - 1, -1)
    return column_of


def _raw_matrix(cells: Cells, contacts: Contacts, column_of: np.ndarray, sqrt_w: np.ndarray,
                turned: Turned | None, held: np.ndarray | None = None) -> sp.csr_matrix:
    """(K, columns) ``J W^{1/2}``, unscaled: each contact's Jacobian rows of its two sides; only
    the rows ``held`` when given (the others empty)."""
    rows, cols, vals = [], [], []
    everything = len(contacts)
    index = np.arange(everything) if held is None else held
    if held is not None:
        contacts = contacts.subset(held)
    for cell, sign, side in [(contacts.cell_a, 1.0, "a"), (contacts.cell_b, -1.0, "b")]:
        valid = cell >= 0
        jac = contact_jacobian(contacts if valid.all() else contacts.subset(valid), cells, side, turned) * sign
        c = cell[valid]
        col = column_of[c]
        entry = jac * sqrt_w[c]
        keep = col >= 0
        rows.append(np.broadcast_to(index[valid][:, None], col.shape)[keep])
        cols.append(col[keep])
        vals.append(entry[keep])
    rows_a, cols_a, vals_a = (np.concatenate(x) for x in (rows, cols, vals))
    return sp.csr_matrix((vals_a, (rows_a, cols_a)), shape=(everything, int((column_of >= 0).sum())))
