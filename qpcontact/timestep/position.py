"""The position-level step: non-penetration at the end of the step, by sequential linearization.

The velocity-level :func:`qpcontact.colony.step.step` makes contacts stop approaching at the
start of the step, which holds to first order in ``dt``; its time step must shrink as the colony
grows, and overlap accumulates where cells turn. This step instead asks for the *positions at the
end of the step* to be free of overlap (the "hard model" of growing rod colonies, backward Euler
for overdamped dynamics with contact constraints):

    minimize ½ xᵀWx   subject to   d_k(q ⊕ dt W (p₀ + x)) ≥ target_k   for every contact k,

with ``x`` the contact impulses (N, 7), ``p₀`` the driving momenta (growth, user forces), ``W``
the inverse generalized mass at the start of the step, ``q ⊕ Δ`` the motion of the cells
(:func:`move`: exact rotations) and ``d_k`` the true capsule separation of contact ``k`` at the
end of the step. The targets are ``0`` (touching) for every contact, except that overlap present
at the start of the step (a division, a state from another simulator) is removed at a bounded
speed: ``target_k = min(0, d_k(q) + relaxation·(ρ_a + ρ_b))``, so no cell is thrown or spun.

The constraints are nonlinear (rotations), so the step iterates (sequential quadratic
programming): move the cells with the current ``x``, find the contacts at those positions (a
broad phase with a reach of ``margin`` diameters, every contact kept once found within the
step), linearize each separation there, and solve the contact QP of :mod:`qpcontact.solvers` for
a new ``x``::

    d_k + dt·(J W (x_new − x))_k ≥ target_k      ⇔      (J W x_new)_k ≥ (target_k − d_k)/dt + (J W x)_k,

which is the system of :func:`qpcontact.assembly.build_system` with that right-hand side. The
step stops when every contact meets its target to within ``overlap_tolerance`` (measured with
the true distance at the re-detected positions, not the linearization). Two bounds keep the
linearization honest, both on the unknowns (so only solvers taking bounds can be used: the
built-in ``"ipm"``, or a qpsolvers backend in the primal form):

- *turning*: no cell turns its tips by more than ``turn_limit`` of its diameter in a step, and by
  no more than ``trust`` of that per iteration (a trust region: large turns of short cells are
  where the linearization is poor);
- *shrinking*: no cell gets shorter (growth can be compressed to zero, not reversed).

An iteration that makes the largest overlap grow on a contact it already knew halves the
following updates (an SQP iterate can alternate between two states when a contact carries a
large impulse and its curvature is ignored); a larger overlap on a contact found only then (a
cell pushed into a neighbour beyond the search margin) is left to the next full update.

A step that does not reach the tolerance within ``max_iterations`` raises
:class:`~qpcontact.errors.StepFailedError` (its result attached, with ``converged=False``) or,
with ``on_failure="return"``, returns that result; it is never applied as if it had converged.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..assembly.system import ContactSystem, Turned, build_system
from ..errors import InvalidArgumentError, StepFailedError
from ..geometry.cells import Cells
from ..geometry.contacts import (
    KIND_BITS,
    Contacts,
    concatenate,
    contact_keys,
    evaluate_contacts,
    relative_normal_velocity,
    select_contacts,
)
from ..geometry.motion import left_jacobian, move, rotate, turning_vectors
from ..geometry.regions import ONE, Split
from ..geometry.surfaces import Plane, evaluate_plane_contacts, plane_contacts
from ..resolve.resolve import acceptance_failure
from ..schema import check_fields, documented, setting
from ..solvers import Problem, SolverSpec, get_solver, solve

__all__ = ["CellMotion", "ContactImpulses", "PositionSettings", "PositionStepResult", "move", "position_step"]


@documented
@dataclass(frozen=True)
class PositionSettings:
    """The parameters of :func:`position_step`; the ``[position]`` table of a run's settings
    (:class:`qpcontact.simulation.Settings`), flags ``--position-*``. Each field is described once,
    with its unit, in its :func:`~qpcontact.schema.setting` (listed below)."""

    overlap_tolerance: float = setting(
        0.01, unit="fraction of the pair's diameter ρ_a + ρ_b", above=0,
        help="largest overlap a step may leave beyond its target")
    margin: float | None = setting(
        None, unit="diameters", above=0,
        help="reach of the contact search around the moved cells; pairs farther apart are not constraints in that "
             "iteration. none: 0.75 in a monolayer, 0.5 in 3D (in grown 2D colonies of 10⁴-2·10⁴ cells a few cells "
             "moved more than 0.5 relative to a neighbour in a step, and each such pair cost a whole linearization "
             "more; in a 3D biofilm 0.75 made a step 1.3× dearer for nothing, docs/model-notes.md)")
    max_iterations: int = setting(30, unit="linearizations", at_least=1, help="cap on linearizations per step")
    turn_limit: float | None = setting(
        None, unit="diameters of that cell", above=0,
        help="a cap on the displacement of a cell's tips by turning in one step; none (the default): no cap. A cap "
             "changes the physics, not only the numerics: at 0.2, the default until 2026-12, a 2D colony of 5,000 "
             "cells grew microdomains 1.6× and edge alignment 1.8× those of the converged colony "
             "(docs/model-notes.md)")
    trust: float | None = setting(
        1.0, unit="diameters of that cell", above=0,
        help="trust region of each linearization: a cell's tips move by turning at most this much from the last "
             "linearization's answer; an answer that sits on it is followed by another linearization, so the trust "
             "region sets the cost of a step, not its result; none: no trust region")
    relaxation: float = setting(
        0.05, unit="fraction of the pair's diameter", above=0,
        help="overlap present at the start of the step is removed by at most this much per step")
    aim: float = setting(
        0.0, unit="fraction of the pair's diameter", at_least=0,
        help="the smallest gap the linearizations aim at beyond each contact's target (contacts rest at it, as if "
             "the cells were this much thicker: 0.03 made a 2D colony 2.5 % less packed than 0.01, docs/model-notes.md); "
             "where a linearization over-predicted a contact's separation, the next aims at that error instead")
    trust_rounds: int = setting(
        2, unit="linearizations", at_least=0,
        help="linearizations a step takes beyond meeting the overlap tolerance while some cell's turn sits on its "
             "trust region (each widening that cell's region)")
    allow_shrinking: bool = setting(
        False, unit="", help="contacts may shorten a cell (off: they can stop its growth but not reverse it)")
    solver: str = setting(
        "ipm", unit="",
        help="the QP solver of each linearization; it must take bounds (ipm, mprgp, or a qpsolvers backend in the "
             "primal form) unless turn_limit and trust are none and allow_shrinking is on")
    tolerance: float = setting(
        1e-4, unit="dimensionless, scaled", above=0, below=1,
        help="its tolerance, in the scaled units of qpcontact.assembly.system (impulses relative to the largest, "
             "velocities relative to the fastest approach): at 10⁻⁴ a grown colony's end positions are within "
             "3·10⁻⁴ of a diameter of the exact step's, at 10⁻³ within 3·10⁻³, for 14 interior-point iterations "
             "instead of 11 (a grown 2D colony of 5,000 cells; docs/model-notes.md)")

    def __post_init__(self) -> None:
        check_fields(self)

    @property
    def bounded(self) -> bool:
        """The step bounds the unknowns (turning or shrinking)."""
        return self.turn_limit is not None or self.trust is not None or not self.allow_shrinking


@dataclass(frozen=True)
class ContactImpulses:
    """Contact impulses of a step keyed by cell ids and contact kind: the warm start of the next
    step (:func:`position_step`'s ``warm``), matched contact by contact whatever the cells'
    order.

    Attributes:
        a: (K,) id of cell a.
        b: (K,) id of cell b, or ``-1 - j`` for plane ``j``.
        kind: (K,) contact kind (:class:`qpcontact.geometry.Contacts`).
        impulse: (K,) normal impulse [momentum].
    """

    a: np.ndarray
    b: np.ndarray
    kind: np.ndarray
    impulse: np.ndarray

    @classmethod
    def empty(cls) -> ContactImpulses:
        none = np.zeros(0, dtype=np.int64)
        return cls(none, none.copy(), none.copy(), np.zeros(0))

    def lookup(self, a: np.ndarray, b: np.ndarray, kind: np.ndarray) -> np.ndarray:
        """The impulse of each contact ``(a[i], b[i], kind[i])``; 0 where there is none."""
        if self.impulse.size == 0 or a.size == 0:
            return np.zeros(a.size)
        span = 1 + max(int(np.max(self.a)), int(np.max(a)), int(np.max(np.abs(self.b))), int(np.max(np.abs(b))))
        reference = contact_keys(self.a, self.b, self.kind, span)
        order = np.argsort(reference)
        reference, values = reference[order], self.impulse[order]
        query = contact_keys(a, b, kind, span)
        where = np.minimum(np.searchsorted(reference, query), reference.size - 1)
        return np.where(reference[where] == query, values[where], 0.0)


@dataclass(frozen=True)
class CellMotion:
    """Each cell's velocity over a step, keyed by cell id: the predictor of where the next step
    will take the cells, so that its first linearization already holds the contacts that the
    motion will make (:func:`position_step`'s ``motion``).

    A colony's flow changes little from one step to the next, while a cell can move a diameter
    relative to a neighbour in a step (a cell pushed out of a jam): searching for contacts only
    around the free motion (growth in place) missed such pairs, and a second linearization was
    needed to catch them (on grown 2D colonies of 5,000–10⁴ cells, overlaps of 0.26–0.47 of a
    diameter after the first; docs/model-notes.md).

    Attributes:
        ids: (M,) cell ids.
        velocity: (M, 3) the velocity of each cell's centre over the step [length/time].
        turning: (M, 3) its rotation vector per unit time [rad/time].
    """

    ids: np.ndarray
    velocity: np.ndarray
    turning: np.ndarray

    @classmethod
    def empty(cls) -> CellMotion:
        return cls(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)))

    @classmethod
    def of(cls, start: Cells, end: Cells, ids: np.ndarray, dt: float, drive_and_impulses: np.ndarray) -> CellMotion:
        """The motion of a step from ``start`` to ``end`` with these momenta."""
        return cls(np.asarray(ids, dtype=np.int64).copy(), (end.centers - start.centers) / dt,
                   turning_vectors(start, dt, drive_and_impulses) / dt)

    def velocities(self, ids: np.ndarray, parents: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) velocities and (N, 3) turning rates of the cells with these ids (or their
        parents' ids); 0 for unknown ids."""
        if self.ids.size == 0:
            return np.zeros((len(ids), 3)), np.zeros((len(ids), 3))
        order = np.argsort(self.ids)
        known = self.ids[order]

        def index_of(query: np.ndarray) -> np.ndarray:
            where = np.minimum(np.searchsorted(known, query), known.size - 1)
            return np.where(known[where] == query, order[where], -1)

        row = index_of(np.asarray(ids, dtype=np.int64))
        if parents is not None:
            row = np.where(row >= 0, row, index_of(np.asarray(parents, dtype=np.int64)))
        moving = (row >= 0)[:, None]
        return (np.where(moving, self.velocity[np.maximum(row, 0)], 0.0),
                np.where(moving, self.turning[np.maximum(row, 0)], 0.0))

    def predict(self, cells: Cells, ids: np.ndarray, dt: float, parents: np.ndarray | None = None) -> Cells:
        """``cells`` moved by ``dt`` with the motion of their ids (or of their parents' ids, for
        cells born since: daughters move with their mother); cells of unknown ids stay."""
        if self.ids.size == 0 or cells.n == 0:
            return cells
        velocity, turning = self.velocities(ids, parents)
        return cells.replace(centers=cells.centers + velocity * dt, axes=rotate(cells.axes, turning * dt))


@dataclass
class PositionStepResult:
    """The outcome of one :func:`position_step`.

    Attributes:
        cells: the state at ``t + dt``; its momenta are ``drive + impulses`` (the momenta that
            moved the cells over the step, a predictor for the next one).
        impulses: (N, 7) contact impulses ``x`` ``(Δp, ΔL, Δg)`` [momentum units].
        converged: every contact met its target to within the overlap tolerance.
        iterations: linearizations made.
        contacts: the contacts at the end positions (every contact kept during the step).
        contact_impulses: (K,) normal impulse of each of those contacts in the last solve
            [momentum] (0 for contacts that entered after it).
        overlaps: largest overlap (fraction of the pair's diameter) at each iteration's
            positions, the last one being the end of the step.
        start_overlap: largest overlap at the start of the step.
        max_overlap: largest overlap at the end of the step.
        excess: largest shortfall of a contact below its target at the end, as a fraction of the
            pair's diameter (≤ ``overlap_tolerance`` when converged).
        times: seconds spent in ``detect``, ``assemble``, ``solve`` and in ``total``.
        solver_iterations: the solver's iterations, summed over the step.
        message: why the step did not converge, if it did not.
        warm: the contact impulses keyed by cell ids (``ids`` of :func:`position_step`), the warm
            start of the next step.
        turn_limited: cells whose turning sat on a bound (the step's limit or the iteration's
            trust region) in the last solve.
        motion: each cell's motion over the step, keyed by ``ids``: the predictor of the next
            step (its ``motion``).
    """

    cells: Cells
    impulses: np.ndarray
    converged: bool
    iterations: int
    contacts: Contacts
    contact_impulses: np.ndarray
    overlaps: list[float]
    start_overlap: float
    max_overlap: float
    excess: float
    times: dict[str, float] = field(default_factory=dict)
    solver_iterations: int = 0
    message: str = ""
    warm: ContactImpulses = field(default_factory=ContactImpulses.empty)
    turn_limited: int = 0
    motion: CellMotion = field(default_factory=CellMotion.empty)

    @property
    def contact_forces(self) -> np.ndarray:
        """(K,) normal force of each contact of :attr:`contacts` over the step, ``≥ 0`` (a push),
        in the units in which the drive is a force.

        The step is overdamped: a cell moves by ``dt·W·(drive + impulses)``, so its "mass" ``m``
        is a drag coefficient (velocity = ``p/m``) and the drive ``p`` is a force [mass·length/
        time in the library's labels; with ``qpcontact simulate``'s masses = volumes, a free cell
        of volume V [µm³] driven by f moves at f/V µm per doubling time]. The contact
        "impulses" enter the motion exactly as the drive does, so they are these forces: a cell
        held still against a wall by a drive f carries f at that contact, and the force on cell
        a of contact k is ``contact_forces[k]·normal[k]`` at ``offset_a[k]`` (minus that on b).

        They are :attr:`contact_impulses`, the last solve's multipliers: they balance
        ``impulses`` (the momenta the cells moved with) when that solve's answer was applied in
        full, which is every step except those whose last linearization was damped or
        backtracked. A step that needed no solve (the free motion was within the overlap
        tolerance, e.g. a drive too weak to move a cell by 0.02 diameters against its
        neighbour) reports no force; contacts first found after the last solve report 0.
        Where contacts are redundant (statically indeterminate: two rods side by side keep the
        closest points and both ends; loops of a jammed packing) the split of a load between
        them is the solver's pick; the net force and torque on each cell are determined (they
        are the step's ``impulses``).
        """
        return self.contact_impulses


# ---------------------------------------------------------------------------------------------
# The contacts of a step: found at the moved positions, kept for the rest of the step
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Tracked:
    """Contacts kept during a step: cells ``a``, ``b`` (``-1 - j`` for plane ``j``) and contact
    kind (:class:`qpcontact.geometry.Contacts`), with their keys (:func:`contact_keys`)."""

    a: np.ndarray
    b: np.ndarray
    kind: np.ndarray
    keys: np.ndarray

    @classmethod
    def of(cls, a: np.ndarray, b: np.ndarray, kind: np.ndarray, span: int) -> _Tracked:
        """The contacts ``(a, b, kind)``, each once (in the order of their keys)."""
        keys, first = np.unique(contact_keys(a, b, kind, span), return_index=True)
        return cls(a[first], b[first], kind[first], keys)

    def keyed(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(a, b)`` with cells as their ids (planes stay ``-1 - j``): the contacts as
        :class:`ContactImpulses` keys them."""
        return ids[self.a], np.where(self.b >= 0, ids[np.maximum(self.b, 0)], self.b)

    def union(self, other: _Tracked, span: int) -> _Tracked:
        return _Tracked.of(np.concatenate([self.a, other.a]), np.concatenate([self.b, other.b]),
                           np.concatenate([self.kind, other.kind]), span)


def _detect(cells: Cells, planes: Sequence[Plane], reach: float, span: int, pairs: np.ndarray | None = None,
            split: Split = ONE) -> _Tracked:
    """Every contact within ``reach`` [length] of the cells as they are (the closest points of
    every pair, whatever its ends: across the linearizations the closest point moves along the
    pair, and only kind 0 follows it; docs/model-notes.md), among the candidate ``pairs`` when
    given (a superset of the pairs within reach, :func:`_first_pairs`); the search and the narrow
    phase shared among the processes of ``split``."""
    if pairs is None:
        pairs = split.candidate_pairs(cells, reach)
    else:  # a superset for several configurations: the pairs whose enclosing spheres are within reach here
        i, j = pairs[:, 0], pairs[:, 1]
        apart = cells.centers[i] - cells.centers[j]
        within = 0.5 * (cells.lengths[i] + cells.lengths[j]) + cells.radii[i] + cells.radii[j] + reach
        pairs = pairs[np.einsum("ij,ij->i", apart, apart) <= within * within]
    parts = split.gather(select_contacts(cells, pairs[split.share(len(pairs))], reach, always_closest=True))
    for index, plane in enumerate(planes):
        found = plane_contacts(cells, [plane], reach)
        parts.append((found.cell_a, np.full(len(found), -1 - index), found.kind))
    a, b, kind = (np.concatenate(x) for x in zip(*parts, strict=True))
    return _Tracked.of(a, b, kind, span)


def _evaluate(cells: Cells, found: _Tracked, planes: Sequence[Plane], planar: bool, split: Split = ONE) -> Contacts:
    """The contacts of ``found`` at the cells' present positions, in the order of ``found``
    (their geometry: the normal velocities are left 0, :func:`_result` gives the last ones theirs),
    the pairs shared among the processes of ``split`` (each evaluates a contiguous part)."""
    pairwise = np.flatnonzero(found.b >= 0)
    mine = pairwise[split.share(pairwise.size)]
    parts = split.gather(evaluate_contacts(cells, found.a[mine], found.b[mine], found.kind[mine], planar=planar,
                                           velocities=False))
    order = [pairwise]
    for j, plane in enumerate(planes):
        on = np.flatnonzero(found.b == -1 - j)
        parts.append(evaluate_plane_contacts(cells, plane, found.a[on], found.kind[on]))
        order.append(on)
    return concatenate(parts).subset(np.argsort(np.concatenate(order), kind="stable"))


def _diameters(cells: Cells, contacts: Contacts) -> np.ndarray:
    """(K,) ``ρ_a + ρ_b`` (``2ρ_a`` against a plane)."""
    rho_a = cells.radii[contacts.cell_a]
    return rho_a + np.where(contacts.cell_b >= 0, cells.radii[np.maximum(contacts.cell_b, 0)], rho_a)


@dataclass(frozen=True)
class _Floors:
    """Overlap present at the start of the step sets the floor of its own pair's target:
    ``min(0, d_start + relaxation·(ρ_a + ρ_b))``, per pair key (:data:`KIND_BITS` dropped)."""

    pairs: np.ndarray
    values: np.ndarray

    def targets(self, found: _Tracked) -> np.ndarray:
        """(K,) the target separation of each contact of ``found`` [length]."""
        if self.pairs.size == 0:
            return np.zeros(found.keys.size)
        pair = found.keys >> KIND_BITS
        where = np.minimum(np.searchsorted(self.pairs, pair), self.pairs.size - 1)
        return np.where(self.pairs[where] == pair, np.minimum(0.0, self.values[where]), 0.0)


def _start(cells: Cells, planes: Sequence[Plane], planar: bool, span: int,
           settings: PositionSettings, pairs: np.ndarray, split: Split = ONE) -> tuple[_Floors, float]:
    """The floors of the targets and the largest overlap at the start of the step (among the
    candidate ``pairs``, a superset of the touching ones)."""
    found = _detect(cells, planes, 0.0, span, pairs, split)
    start = _evaluate(cells, found, planes, planar, split)
    diameter = _diameters(cells, start)
    overlapping = start.separation < 0
    pairs = found.keys[overlapping] >> KIND_BITS
    values = start.separation[overlapping] + settings.relaxation * diameter[overlapping]
    order = np.argsort(pairs)
    return _Floors(pairs[order], values[order]), float(np.max(-start.separation / diameter, initial=0.0))


# ---------------------------------------------------------------------------------------------
# One linearization: the QP of the step's contacts at the moved positions
# ---------------------------------------------------------------------------------------------
def _bounds(system: ContactSystem, cells: Cells, drive: np.ndarray, impulses: np.ndarray, dt: float,
            settings: PositionSettings, radius: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bounds on the scaled unknowns ỹ: turning (each cell's trust region of ``radius``
    diameters around the impulses so far, and a cap on the step's turn where one is set) and
    shrinking; ``(lower, upper, cap)``, with ``cap`` the cap of each column (inf: none)."""
    n = system.shape[1]
    lower, upper, cap = np.full(n, -np.inf), np.full(n, np.inf), np.full(n, np.inf)
    cell, slot = system.column_cell, system.column_slot
    turning = np.flatnonzero((slot == 4) | (slot == 5))
    if turning.size and (radius is not None or settings.turn_limit is not None):
        # ỹ of a column is sqrt(w)·x·σ_B/σ_b; its turning angle is dt·w·x = ỹ·unit⁻¹, and a turn
        # by one radian moves the tips by l/2 + ρ, i.e. by (l/2 + ρ)/(2ρ) diameters.
        unit = system.operator_scale / (dt * np.sqrt(system.column_inverse_mass[turning]) * system.velocity_scale)
        c = cell[turning]
        per_diameter = 2.0 * cells.radii[c] / (cells.lengths[c] / 2 + cells.radii[c]) * unit
        if radius is not None:
            now, reach = system.from_impulses(impulses)[turning], radius[c] * per_diameter
            lower[turning], upper[turning] = now - reach, now + reach
        if settings.turn_limit is not None:
            cap[turning] = settings.turn_limit * per_diameter
            lower[turning] = np.maximum(lower[turning], -cap[turning])
            upper[turning] = np.minimum(upper[turning], cap[turning])
    if not settings.allow_shrinking:
        growth = np.flatnonzero(slot == 6)
        # l̇ = (g₀ + x_g)/G ≥ 0  ⇔  x_g ≥ −g₀  ⇔  ỹ ≥ −g₀·sqrt(w)·σ_B/σ_b
        lower[growth] = np.minimum(-drive[cell[growth], 6] * np.sqrt(system.column_inverse_mass[growth])
                                   * system.operator_scale / system.velocity_scale, upper[growth])
    return lower, upper, cap


def _linearize(cells: Cells, now: Cells, contacts: Contacts, target: np.ndarray, aim: np.ndarray,
               dt: float, drive: np.ndarray, impulses: np.ndarray, planar: bool, settings: PositionSettings,
               radius: np.ndarray | None) -> tuple[ContactSystem, Problem, np.ndarray] | None:
    """The QP of one linearization (module docstring) and its turning caps (:func:`_bounds`), or
    None when no contact asks for a push.

    The unknowns are the impulses of the whole step in the cells' frame at the start of the step
    (its axes, its masses and inertia, as :func:`move` uses them), and each row is the exact
    derivative of the contact's separation at the moved positions: rotations enter through the
    left Jacobian of each cell's turn (:class:`qpcontact.assembly.system.Turned`), so in 3D the
    linearization is exact to first order (turning about the moved axes instead, as this step did
    until 2026-12, made the linearizations converge only linearly: 3–6 per step)."""
    turned = Turned(axes=now.axes, jacobian=left_jacobian(turning_vectors(cells, dt, drive + impulses)))
    # The rows first (the right-hand side needs their product with the impulses so far), then
    # d_k + dt·(J W (x_new − x))_k ≥ target_k + aim_k  ⇔  (J W x_new)_k ≥ (target_k + aim_k − d_k)/dt + (J W x)_k
    b = (target + aim - contacts.separation) / dt
    if not np.any(impulses):  # the first linearization: nothing to add
        if not np.any(b > 0):
            return None
        system = build_system(cells, contacts, b, planar=planar, turned=turned)
    else:
        system = build_system(cells, contacts, np.ones(len(contacts)), planar=planar, turned=turned)
        b = b + system.velocity_changes(impulses)
        if not np.any(b > 0):
            return None
        system = system.with_rhs(b)
    if not settings.bounded:
        return system, Problem(system.matrix, system.rhs, system.column_inverse_mass), np.full(system.shape[1], np.inf)
    lower, upper, cap = _bounds(system, cells, drive, impulses, dt, settings, radius)
    return system, Problem(system.matrix, system.rhs, system.column_inverse_mass, lower=lower, upper=upper), cap


def _aims(progress: _Progress, contacts: Contacts, diameter: np.ndarray, settings: PositionSettings) -> np.ndarray:
    """(K,) the gap each contact's linearization aims at beyond its target [length]: ``aim``
    diameters, or as much as the last linearization over-predicted that contact's separation
    (its error, up to :data:`MAX_AIM` diameters), whichever is larger. A contact rests at its
    aim: a gap kept everywhere (0.03 of a diameter until 2026-12) made the cells that much
    thicker, and a 2D colony 2.5 % less packed than at 0.01 (docs/model-notes.md); an aim where
    the linearization erred (a cell turning fast) lasts as long as the error."""
    aim = settings.aim * diameter
    if progress.predicted is None or len(contacts) == 0:
        return aim
    keys, separation = progress.predicted
    where = np.minimum(np.searchsorted(keys, progress.found.keys), max(keys.size - 1, 0))
    known = keys[where] == progress.found.keys if keys.size else np.zeros(len(contacts), dtype=bool)
    error = np.where(known, separation[where] - contacts.separation, 0.0)
    return np.maximum(aim, np.minimum(error, MAX_AIM * diameter))


def _turn_limited(system: ContactSystem, problem: Problem, cap: np.ndarray, y: np.ndarray) -> tuple[int, np.ndarray]:
    """Cells whose turning sits on a bound in the answer ``y``: how many on any bound, and which
    on their trust region (a bound that is not the step's ``cap``): those would have turned
    further."""
    if problem.lower is None or problem.upper is None:
        return 0, np.zeros(0, dtype=np.intp)
    turning = np.flatnonzero((system.column_slot == 4) | (system.column_slot == 5))
    lower, upper, cap = problem.lower[turning], problem.upper[turning], cap[turning]
    span = np.maximum(upper - lower, 1e-300)
    at_lower, at_upper = y[turning] - lower <= 1e-3 * span, upper - y[turning] <= 1e-3 * span
    finite = np.isfinite(span)
    trusting = ((at_lower & (lower > -cap)) | (at_upper & (upper < cap))) & finite
    cells_at = system.column_cell[turning]
    return int(np.unique(cells_at[(at_lower | at_upper) & finite]).size), np.unique(cells_at[trusting])


def _adapt_trust(progress: _Progress, before: np.ndarray, trusting: np.ndarray, settings: PositionSettings) -> None:
    """Each cell's trust region after a solve that moved the impulses from ``before``: halved
    for a cell whose turn went back against its last one (the linearization overshot: an SQP
    iterate can swing a cell between two turns across a cap's contacts), doubled for a cell that
    sat on it and kept its direction (its turn is longer than one linearization, and the last one
    held); ``progress.trusting`` counts the cells still on it that could turn by more than the
    overlap tolerance."""
    if progress.radius is None:
        return
    change = progress.impulses[:, 3:6] - before[:, 3:6]
    back = np.einsum("ij,ij->i", change, progress.turned) < 0
    progress.radius[back] *= 0.5
    ahead = trusting[~back[trusting]]
    progress.radius[ahead] = np.minimum(2.0 * progress.radius[ahead], MAX_TRUST_GROWTH * (settings.trust or 0.0))
    progress.turned = change
    progress.trusting = int(np.count_nonzero(progress.radius[trusting] > settings.overlap_tolerance))


# ---------------------------------------------------------------------------------------------
# The step
# ---------------------------------------------------------------------------------------------
#: A linearization whose update leaves a larger overlap than this (fraction of the diameter, and
#: more than before it) is backtracked half way, at most :data:`MAX_BACKTRACKS` times a step.
BACKTRACK_OVERLAP = 0.5
MAX_BACKTRACKS = 6
#: A cell's trust region widens, linearization after linearization, to at most this many times
#: ``PositionSettings.trust``.
MAX_TRUST_GROWTH = 8.0
#: The largest gap a contact's linearization aims at for the error of the last one [diameters].
MAX_AIM = 0.1


@dataclass
class _Progress:
    """What the linearizations of a step carry from one to the next."""

    impulses: np.ndarray
    found: _Tracked
    previous: np.ndarray | None = None  # the impulses of the last kept iterate
    relaxation: float = 1.0  # the fraction of each update taken
    backtracks: int = 0
    overlaps: list[float] = field(default_factory=list)
    last: ContactImpulses = field(default_factory=ContactImpulses.empty)  # the last solve's, keyed by ids
    solver_iterations: int = 0
    turn_limited: int = 0
    trusting: int = 0  # cells whose turn sat on the trust region in the last solve (and could go further)
    radius: np.ndarray | None = None  # (N,) each cell's trust region [diameters]
    # each contact's separation as the last linearization predicted it, by key: (keys, separation [length])
    predicted: tuple[np.ndarray, np.ndarray] | None = None
    trust_rounds: int = 0  # linearizations taken at feasible positions for cells on their trust region
    turned: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (N, 3) the change of each cell's angular impulse in the last solve


def search_margin(settings: PositionSettings, planar: bool) -> float:
    """The reach of the contact search [diameters]: the setting, or its default for the scene
    (``margin = None``: 0.75 in a monolayer, 0.5 in 3D)."""
    if settings.margin is not None:
        return settings.margin
    return 0.75 if planar else 0.5


def _checked(cells: Cells, dt: float, drive: np.ndarray | None, planes: Sequence[Plane], planar: bool | None,
             settings: PositionSettings | None, ids: np.ndarray | None, warm: ContactImpulses | None,
             motion: CellMotion | None, parents: np.ndarray | None, on_failure: str) -> tuple[PositionSettings, SolverSpec, np.ndarray, list[Plane], bool, np.ndarray]:
    """The arguments of :func:`position_step`, checked: ``(settings, solver, drive, planes,
    planar, ids)``."""
    settings = PositionSettings() if settings is None else settings
    if not isinstance(settings, PositionSettings):
        raise InvalidArgumentError(f"settings: expected PositionSettings, got {type(settings).__name__}")
    if isinstance(dt, bool) or not isinstance(dt, (int, float, np.floating)) or not (np.isfinite(dt) and dt > 0):
        raise InvalidArgumentError(f"dt: must be a finite number > 0, got {dt!r}")
    if on_failure not in ("raise", "return"):
        raise InvalidArgumentError(f"on_failure: expected 'raise' or 'return', got {on_failure!r}")
    spec = get_solver(settings.solver)
    if settings.bounded and not spec.bounds:
        raise InvalidArgumentError(f"solver {settings.solver!r} takes no bounds on the unknowns; the position step "
                                   "bounds turning and shrinking (use solver='ipm', or turn_limit=None and "
                                   "allow_shrinking=True)")
    planes = list(planes)
    for plane in planes:
        if not isinstance(plane, Plane):
            raise InvalidArgumentError(f"planes: expected Plane objects, got {type(plane).__name__}")
    n = cells.n
    ids = np.arange(n) if ids is None else np.asarray(ids)
    if ids.shape != (n,) or not np.issubdtype(ids.dtype, np.integer):
        raise InvalidArgumentError(f"ids: expected {n} integers, got {ids.dtype} of shape {ids.shape}")
    if warm is not None and not isinstance(warm, ContactImpulses):
        raise InvalidArgumentError(f"warm: expected ContactImpulses, got {type(warm).__name__}")
    if motion is not None and not isinstance(motion, CellMotion):
        raise InvalidArgumentError(f"motion: expected CellMotion, got {type(motion).__name__}")
    if parents is not None and (np.shape(parents) != (n,) or not np.issubdtype(np.asarray(parents).dtype, np.integer)):
        raise InvalidArgumentError(f"parents: expected {n} integers, got shape {np.shape(parents)}")
    drive = np.zeros((n, 7)) if drive is None else np.asarray(drive, dtype=float)
    if drive.shape != (n, 7) or not np.all(np.isfinite(drive)):
        raise InvalidArgumentError(f"drive: expected finite values of shape ({n}, 7), got shape {drive.shape}")
    if planar is None:  # a monolayer whose driving momenta and planes keep it in its plane
        moving = cells.replace(momenta=drive[:, 0:3], angular_momenta=drive[:, 3:6], growth_momenta=drive[:, 6])
        planar = moving.is_monolayer() and all(abs(plane.normal[2]) == 0 for plane in planes)
    return settings, spec, drive, planes, bool(planar), ids


def _judge(progress: _Progress, contacts: Contacts, diameter: np.ndarray, known: np.ndarray,
           iteration: int, settings: PositionSettings) -> bool:
    """Record the overlap of this iterate and decide on damping; True when the iterate is to be
    backtracked (not kept) instead."""
    progress.overlaps.append(float(np.max(-contacts.separation / diameter, initial=0.0)))
    overlaps = progress.overlaps
    # A linearization that left a larger overlap on a contact it knew has met the curvature of
    # turning (an SQP iterate can then alternate between two states): later updates go half
    # way. A larger overlap on a contact found only now (a cell pushed far, into a neighbour
    # beyond the search margin) says nothing about the linearization: full updates go on.
    worst = int(np.argmax(-contacts.separation / diameter)) if len(contacts) else -1
    if len(overlaps) >= 2 and overlaps[-1] > overlaps[-2] and np.isin(progress.found.keys[worst], known):
        progress.relaxation = 0.5
    # An update that put cells deep into each other (rods crossing: the linearization of a
    # nearly infeasible jam, far outside where it holds) is not kept: back half way to the
    # last iterate and look again (measured: a newborn squeezed in a 27,601-cell colony went
    # from 0.15 to 1.0, rods through each other, and no later linearization separated them).
    if (progress.previous is not None and overlaps[-1] > max(BACKTRACK_OVERLAP, overlaps[-2])
            and progress.backtracks < MAX_BACKTRACKS and iteration < settings.max_iterations):
        progress.impulses = progress.previous + 0.5 * (progress.impulses - progress.previous)
        progress.backtracks += 1
        progress.predicted = None  # it predicted the full update
        progress.relaxation = 0.5
        overlaps.pop()
        return True
    return False


def _track(found: _Tracked, now: Cells, predicted: Cells | None, planes: Sequence[Plane], reach: float,
           span: int, pairs: np.ndarray | None = None, split: Split = ONE) -> _Tracked:
    """The contacts kept so far and those within ``reach`` of the cells where they are now (and,
    at the first linearization, where the last step's motion would take them, ``predicted``),
    among the candidate ``pairs`` when given (the first linearization's, :func:`_first_pairs`).

    Every linearization searches the whole margin: a cell pushed out of a jam can move a diameter
    against a neighbour within one linearization (measured on a grown colony of 10⁴ cells, with
    half the margin after the first: 0.14 of a diameter of overlap at the seventh linearization,
    with a pair found only then)."""
    found = found.union(_detect(now, planes, reach, span, pairs, split), span)
    return found if predicted is None else found.union(_detect(predicted, planes, reach, span, pairs, split), span)


def _tip_displacement(start: Cells, end: Cells) -> np.ndarray:
    """(N,) the largest displacement of a point of each cell's axis between two configurations
    [length]: that of one of its tips (a point of the axis moves by an affine mix of the two)."""
    half_start, half_end = 0.5 * start.lengths[:, None], 0.5 * end.lengths[:, None]
    moved = end.centers - start.centers
    plus = moved + half_end * end.axes - half_start * start.axes
    minus = moved - half_end * end.axes + half_start * start.axes
    return np.sqrt(np.maximum(np.einsum("ij,ij->i", plus, plus), np.einsum("ij,ij->i", minus, minus)))


def _first_pairs(cells: Cells, now: Cells, predicted: Cells | None, reach: float, split: Split = ONE) -> np.ndarray:
    """One broad phase for the start of the step and its first linearization: the candidate
    pairs of the cells at the start, each cell's reach widened by how far its axis moves to the
    first linearization's positions ``now`` (the free motion) and to ``predicted``. The start's
    overlaps and the first linearization's contacts are then found among them (a broad phase is
    2/3 of a detection; three were made at 10⁴ cells, 2026-12-04).

    Where the step moves many cells further than the search's reach (a large step of a fast
    colony: the edge of a 2D colony of 5,000 cells moves microns in a step of 0.2 growth), the
    widened reach would take in every neighbour of a moving region (2.4·10⁶ candidate pairs,
    ``TooManyContactsError``, 2026-12-04): each configuration is then searched on its own and the
    pairs put together, which bounds them by those of a packing."""
    slack = _tip_displacement(cells, now)
    if predicted is not None:
        slack = np.maximum(slack, _tip_displacement(cells, predicted))
    if slack.size == 0 or float(np.quantile(slack, 0.99)) <= reach:
        return split.candidate_pairs(cells, reach, slack)
    pairs = [split.candidate_pairs(c, reach) for c in (cells, now, predicted) if c is not None]
    n = np.int64(max(cells.n, 1))
    key = np.unique(np.concatenate([p[:, 0].astype(np.int64) * n + p[:, 1] for p in pairs]))
    return np.column_stack([key // n, key % n]).astype(np.intp)


def _solve(progress: _Progress, system: ContactSystem, problem: Problem, cap: np.ndarray, separation: np.ndarray,
           dt: float, spec: SolverSpec, form: str, settings: PositionSettings, ids: np.ndarray, times: dict[str, float], comm: Any = None) -> str:
    """Solve one linearization's QP and take its answer into ``progress``; why not, if it was
    not taken. An answer is taken only when its solver stands by it and it passes the acceptance
    checks of every answer (resolve's, with the bounds): a stalled answer within the acceptance
    limits has still moved cells of a settled layer (docs/performance.md)."""
    key_a, key_b = progress.found.keyed(ids)
    initial = system.from_contact_impulses(progress.last.lookup(key_a, key_b, progress.found.kind)) \
        if spec.warm_start else None
    t0 = time.perf_counter()
    out = solve(problem, settings.solver, "complementarity", form, tolerance=settings.tolerance, initial=initial,
                settings=None if comm is None else {"comm": comm})
    times["solve"] += time.perf_counter() - t0
    progress.solver_iterations += out.iterations or 0
    refused = "" if out.y is None or not out.found else acceptance_failure(
        system, "complementarity", out.y, out.lam, settings.tolerance, problem.lower, problem.upper)
    if not out.found or out.y is None or not np.all(np.isfinite(out.y)) or refused:
        return f"{out.status} {out.error or ''} {refused}".strip()
    lam = system.to_contact_impulses(out.lam) if out.lam is not None else np.zeros(problem.matrix.shape[0])
    progress.last = ContactImpulses(key_a, key_b, progress.found.kind.copy(), lam)
    progress.turn_limited, trusting = _turn_limited(system, problem, cap, out.y)
    progress.previous = progress.impulses
    progress.impulses = progress.impulses + progress.relaxation * (system.to_impulses(out.y) - progress.impulses)
    _adapt_trust(progress, progress.previous, trusting, settings)
    moved = system.velocity_changes(progress.impulses) - system.velocity_changes(progress.previous)
    progress.predicted = (progress.found.keys, separation + dt * moved)
    return ""


def _result(progress: _Progress, cells: Cells, end: Cells, contacts: Contacts, diameter: np.ndarray,
            converged: bool, iteration: int, excess: float, start_overlap: float, ids: np.ndarray, dt: float,
            drive: np.ndarray, message: str, times: dict[str, float]) -> PositionStepResult:
    """The step's result at the positions of the last kept impulses."""
    if iteration == 0:
        progress.last = ContactImpulses.empty()  # nothing was solved: no contact pushed in this step
    key_a, key_b = progress.found.keyed(ids)
    impulse_of_contact = progress.last.lookup(key_a, key_b, progress.found.kind)
    contacts = dataclasses.replace(contacts, normal_velocity=relative_normal_velocity(
        end, contacts.cell_a, contacts.cell_b, contacts.normal, contacts.offset_a, contacts.offset_b,
        contacts.stretch_a, contacts.stretch_b))
    return PositionStepResult(
        cells=end, impulses=progress.impulses, converged=converged, iterations=iteration, contacts=contacts,
        contact_impulses=impulse_of_contact, overlaps=progress.overlaps, start_overlap=start_overlap,
        max_overlap=float(np.max(-contacts.separation / diameter, initial=0.0)), excess=excess, times=times,
        solver_iterations=progress.solver_iterations, message=message,
        warm=ContactImpulses(key_a, key_b, progress.found.kind.copy(), impulse_of_contact),
        turn_limited=progress.turn_limited, motion=CellMotion.of(cells, end, ids, dt, drive + progress.impulses))


def position_step(
    cells: Cells,
    dt: float,
    *,
    drive: np.ndarray | None = None,
    planes: Sequence[Plane] = (),
    planar: bool | None = None,
    settings: PositionSettings | None = None,
    ids: np.ndarray | None = None,
    warm: ContactImpulses | None = None,
    motion: CellMotion | None = None,
    parents: np.ndarray | None = None,
    on_failure: str = "raise",
    comm: Any = None,
) -> PositionStepResult:
    """Advance overdamped cells by ``dt`` with non-penetration at the end of the step (module
    docstring). The phases of each linearization: move the cells (:func:`move`), find and
    evaluate the contacts (:func:`_track`, :func:`_evaluate`), judge the iterate (:func:`_judge`:
    backtracked, damped; converged), build its QP (:func:`_linearize`), solve it and take the
    answer (:func:`_solve`); then the result (:func:`_result`).

    Args:
        cells: the state at time ``t`` (its momenta are ignored: overdamped dynamics).
        dt: the time step [time], > 0.
        drive: (N, 7) driving momenta ``(p, L, g)`` (growth, user forces) [momentum units];
            None = 0.
        planes: static planes (:class:`qpcontact.geometry.Plane`).
        planar: the scene is a monolayer in the xy-plane (planar unknowns only); None: detected
            (:meth:`~qpcontact.geometry.Cells.is_monolayer` of the cells with the driving momenta,
            and every plane's normal in the xy-plane).
        settings: :class:`PositionSettings` (defaults if None).
        ids: (N,) cell ids that stay with the cells from step to step (default: their indices),
            the keys of the warm start.
        warm: contact impulses of the previous step (its result's ``warm``): the first solve of
            a solver that takes a warm start starts from them, contact by contact; later solves
            of the step start from the previous solve's.
        motion: the motion of the previous step (its result's ``motion``): the first
            linearization also holds the contacts the cells would make if they moved as they did
            then (:class:`CellMotion`); None: only those around the free motion.
        parents: (N,) each cell's parent id, so that a cell born since the previous step moves
            with its mother in that prediction (``motion``); None: such cells stay.
        on_failure: ``"raise"`` a :class:`~qpcontact.errors.StepFailedError` when the step does
            not converge (default), or ``"return"`` the unconverged result.
        comm: the MPI processes the solves are split over (an mpi4py communicator; solver
            ``"ipm-petsc"``, and every process of ``comm`` calls with the same arguments and gets
            the same result: docs/distributed.md); None: the solver's own (``ipm-petsc``: all of
            MPI's world).

    Returns:
        A :class:`PositionStepResult`.

    Raises:
        StepFailedError: the step did not reach the overlap tolerance (``on_failure="raise"``),
            or a solve failed; nothing is applied.
        InvalidArgumentError: bad arguments.
    """
    settings, spec, drive, planes, planar, ids = _checked(cells, dt, drive, planes, planar, settings, ids, warm,
                                                          motion, parents, on_failure)
    if comm is not None and spec.name != "ipm-petsc":
        raise InvalidArgumentError(f"comm: only the solver ipm-petsc splits a step among processes; got {spec.name!r}")
    n, span = cells.n, cells.n + len(planes) + 1
    form = next(f for f in ("contact", "primal") if f in spec.forms and (not settings.bounded or f in spec.bounds))
    times = {"detect": 0.0, "assemble": 0.0, "solve": 0.0}
    t_start = t0 = time.perf_counter()
    reach = search_margin(settings, planar) * 2.0 * float(np.median(cells.radii)) if n else 0.0
    free = move(cells, dt, drive)
    predicted = None if motion is None else motion.predict(cells.replace(lengths=free.lengths), ids, dt, parents)
    split = Split(comm)
    first_pairs = _first_pairs(cells, free, predicted, reach, split)
    floors, start_overlap = _start(cells, planes, planar, span, settings, first_pairs, split)
    times["detect"] += time.perf_counter() - t0
    empty = np.zeros(0, dtype=np.intp)
    progress = _Progress(impulses=np.zeros((n, 7)), found=_Tracked(empty, empty, empty, empty.astype(np.int64)),
                         last=ContactImpulses.empty() if warm is None else warm, turned=np.zeros((n, 3)),
                         radius=None if settings.trust is None else np.full(n, settings.trust))
    converged, message, iteration, excess = False, "", 0, 0.0
    for iteration in range(settings.max_iterations + 1):
        now = move(cells, dt, drive + progress.impulses)
        t0 = time.perf_counter()
        known = progress.found.keys
        progress.found = (_track(progress.found, now, predicted, planes, reach, span, first_pairs, split)
                          if iteration == 0 else _track(progress.found, now, None, planes, reach, span, None, split))
        contacts = _evaluate(now, progress.found, planes, planar, split)
        diameter = _diameters(now, contacts)
        times["detect"] += time.perf_counter() - t0
        if _judge(progress, contacts, diameter, known, iteration, settings):
            continue
        target = floors.targets(progress.found)
        excess = float(np.max((target - contacts.separation) / diameter, initial=0.0))
        # The free motion itself may be within the tolerance (nothing pushes): nothing to solve
        # (and a solve would be ill-posed: its right-hand side, the scale of the problem, is ~0).
        # A cell whose turn the trust region stopped would have turned further: not done yet.
        if excess <= settings.overlap_tolerance:
            if progress.trusting == 0 or progress.trust_rounds >= settings.trust_rounds:
                converged = True
                break
            progress.trust_rounds += 1
        if iteration == settings.max_iterations:
            message = (f"largest overlap beyond its target {excess:.3g} of a diameter after {iteration} "
                       f"linearizations (tolerance {settings.overlap_tolerance:g})" if excess > settings.overlap_tolerance
                       else f"{progress.trusting} cells still turning at the trust region's edge after {iteration} "
                       f"linearizations (trust {settings.trust:g} diameters)")
            break
        t0 = time.perf_counter()
        linear = _linearize(cells, now, contacts, target, _aims(progress, contacts, diameter, settings), dt, drive,
                            progress.impulses, planar, settings, progress.radius)
        times["assemble"] += time.perf_counter() - t0
        if linear is None:  # nothing asks for a push: the free motion is the answer
            progress.impulses, progress.last, progress.trusting = np.zeros((n, 7)), ContactImpulses.empty(), 0
            continue
        message = _solve(progress, *linear, contacts.separation, dt, spec, form, settings, ids, times, comm)
        if message:
            message = f"{settings.solver} failed at linearization {iteration}: {message}"
            break
    # The loop always ends on a detection at the positions of the impulses it kept.
    times["total"] = time.perf_counter() - t_start
    result = _result(progress, cells, now, contacts, diameter, converged, iteration, excess, start_overlap, ids, dt,
                     drive, message, times)
    if not converged and on_failure == "raise":
        raise StepFailedError(f"position step did not converge: {message}; {what_to_try(settings)}", result)
    return result


def what_to_try(settings: PositionSettings) -> str:
    """What to change when a position step fails, with the settings' current values (a failed
    step's message ends with it)."""
    other = "mprgp or clarabel" if settings.solver == "ipm" else "ipm"
    return (f"try: a smaller dt (half: each linearization is then nearer to linear), more linearizations "
            f"(max_iterations, now {settings.max_iterations}), a looser solver tolerance (tolerance, now "
            f"{settings.tolerance:g}) or overlap_tolerance (now {settings.overlap_tolerance:g}), or another solver "
            f"(solver, now {settings.solver}: {other})")
