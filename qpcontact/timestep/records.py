"""What a position step carries to the next and what it returns: the contact impulses keyed by
cell ids (a warm start), each cell's motion (the next step's predictor), and the step's result
(:func:`qpcontact.timestep.position_step`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry.cells import Cells
from ..geometry.contacts import Contacts, contact_keys
from ..geometry.motion import rotate, turning_vectors


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
        times: seconds spent in ``detect``, ``assemble``, ``solve`` and in ``total`` (wall clock), and the
            CPU seconds of this process in each (``detect_cpu``, ``assemble_cpu``, ``solve_cpu``, ``total_cpu``).
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
