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

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..assembly.system import build_system
from ..checks import number
from ..described import documented, setting
from ..errors import InvalidArgumentError, StepFailedError
from ..geometry.cells import Cells
from ..geometry.contacts import (
    Contacts,
    candidate_pairs,
    concatenate,
    evaluate_contacts,
    relative_normal_velocity,
    select_contacts,
)
from ..geometry.surfaces import Plane, evaluate_plane_contacts, plane_contacts
from ..solvers import Problem, get_solver, solve
from .step import rotate


@documented
@dataclass(frozen=True)
class PositionSettings:
    """The parameters of :func:`position_step`; the ``[position]`` table of a run's settings
    (:class:`qpcontact.colony.Settings`), flags ``--position-*``. Each field is described once,
    with its unit, in its :func:`~qpcontact.described.setting` (listed below)."""

    overlap_tolerance: float = setting(
        0.01, unit="fraction of the pair's diameter ρ_a + ρ_b", above=0,
        help="largest overlap a step may leave beyond its target")
    margin: float = setting(
        0.5, unit="diameters", above=0,
        help="reach of the contact search around the moved cells; pairs farther apart are not constraints in that "
             "iteration")
    max_iterations: int = setting(30, unit="linearizations", at_least=1, help="cap on linearizations per step")
    turn_limit: float | None = setting(
        0.2, unit="diameters of that cell", above=0,
        help="largest displacement of a cell's tips by turning in one step; none: no bound (then any complementarity "
             "solver can be used)")
    trust: float = setting(0.3, unit="dimensionless", above=0, at_most=1,
                           help="fraction of turn_limit the tips may move per iteration")
    relaxation: float = setting(
        0.05, unit="fraction of the pair's diameter", above=0,
        help="overlap present at the start of the step is removed by at most this much per step")
    aim: float = setting(
        0.01, unit="fraction of the pair's diameter", at_least=0,
        help="the linearizations aim at this gap beyond each target, so that the error of one linearization "
             "(turning is not linear) falls within the tolerance: on a grown colony of 10⁴ cells, one linearization "
             "per step instead of six (docs/performance.md); contacts then rest at up to this gap, as if the cells "
             "were this much thicker")
    allow_shrinking: bool = setting(
        False, unit="", help="contacts may shorten a cell (off: they can stop its growth but not reverse it)")
    solver: str = setting(
        "ipm", unit="",
        help="the QP solver of each linearization; it must take bounds (ipm, mprgp, or a qpsolvers backend in the "
             "primal form) unless turn_limit is none and allow_shrinking is on")
    tolerance: float = setting(
        1e-3, unit="dimensionless, scaled", above=0, below=1,
        help="its tolerance, in the scaled units of qpcontact.assembly.system (impulses relative to the largest, "
             "velocities relative to the fastest approach): 10⁻³ moves a contact by at most 10⁻³ of the step's "
             "largest approach, far below the overlap tolerance, in 14 interior-point iterations instead of 22 at "
             "10⁻⁵ (docs/performance.md)")

    def __post_init__(self) -> None:
        for name in ("overlap_tolerance", "margin", "trust", "relaxation", "tolerance", "turn_limit", "aim"):
            number(name, getattr(self, name), minimum=0.0, open_minimum=name != "aim", allow_none=name == "turn_limit")
        if self.trust > 1:
            raise InvalidArgumentError(f"trust: must be in (0, 1], got {self.trust!r}")
        if not (isinstance(self.max_iterations, int) and not isinstance(self.max_iterations, bool)
                and self.max_iterations >= 1):
            raise InvalidArgumentError(f"max_iterations: must be an integer >= 1, got {self.max_iterations!r}")
        if not isinstance(self.allow_shrinking, bool):
            raise InvalidArgumentError(f"allow_shrinking: must be True or False, got {self.allow_shrinking!r}")
        if not isinstance(self.solver, str):
            raise InvalidArgumentError(f"solver: expected a solver name, got {self.solver!r}")

    @property
    def bounded(self) -> bool:
        """The step bounds the unknowns (turning or shrinking)."""
        return self.turn_limit is not None or not self.allow_shrinking


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
        low = min(int(self.b.min()), int(b.min()), 0)
        base = max(int(self.a.max()), int(a.max()), int(self.b.max()), int(b.max())) - low + 1
        if base >= 2**28:
            raise InvalidArgumentError(f"ids: contact keys need ids below 2**28, got {base}")

        def key(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
            return (x.astype(np.int64) * base + (y.astype(np.int64) - low)) * 8 + z

        reference = key(self.a, self.b, self.kind)
        order = np.argsort(reference)
        reference, values = reference[order], self.impulse[order]
        query = key(a, b, kind)
        where = np.minimum(np.searchsorted(reference, query), reference.size - 1)
        return np.where(reference[where] == query, values[where], 0.0)


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


def move(cells: Cells, dt: float, momenta: np.ndarray) -> Cells:
    """The cells at the end of a step with generalized momenta ``momenta`` (N, 7): centres by
    ``dt·p/m``, axes turned exactly by ``dt·ω⊥`` (the angular velocity across the axis; a spin
    about the cell's own axis turns nothing), lengths by ``dt·g/G``. Masses and inertia are those
    of ``cells`` (the start of the step); the returned cells carry ``momenta``.

    Raises:
        InvalidArgumentError: a length would become negative.
    """
    moving = cells.replace(momenta=momenta[:, 0:3], angular_momenta=momenta[:, 3:6], growth_momenta=momenta[:, 6])
    omega = moving.angular_velocities
    omega -= np.einsum("ij,ij->i", omega, cells.axes)[:, None] * cells.axes
    lengths = cells.lengths + moving.growth_rates * dt
    if np.any(lengths < 0):
        i = int(np.flatnonzero(lengths < 0)[0])
        raise InvalidArgumentError(f"dt = {dt!r}: cell {i} would reach length {lengths[i]:.3g} < 0")
    return moving.replace(centers=cells.centers + moving.velocities * dt, axes=rotate(cells.axes, omega * dt),
                          lengths=lengths)


@dataclass
class _ContactSet:
    """Contacts kept during a step, as keys: cells ``a``, ``b`` (``-1 - j`` for plane ``j``) and
    contact kind (:class:`qpcontact.geometry.Contacts`)."""

    a: np.ndarray
    b: np.ndarray
    kind: np.ndarray

    def key(self, n_planes: int, n_cells: int) -> np.ndarray:
        base = np.int64(n_cells + n_planes)
        return ((self.a.astype(np.int64) * base) + (self.b + n_planes)) * 8 + self.kind

    def union(self, other: _ContactSet, n_planes: int, n_cells: int) -> _ContactSet:
        a, b, kind = (np.concatenate([u, v]) for u, v in
                      ((self.a, other.a), (self.b, other.b), (self.kind, other.kind)))
        joined = _ContactSet(a, b, kind)
        _, first = np.unique(joined.key(n_planes, n_cells), return_index=True)
        return _ContactSet(a[first], b[first], kind[first])


def _detect(cells: Cells, planes: Sequence[Plane], reach: float, planar: bool) -> _ContactSet:
    """Every contact within ``reach`` [length] of the cells as they are."""
    a, b, kind = select_contacts(cells, candidate_pairs(cells, reach), reach, always_closest=True)
    parts = [(a, b, kind)]
    for j, plane in enumerate(planes):
        found = plane_contacts(cells, [plane], reach)
        parts.append((found.cell_a, np.full(len(found), -1 - j), found.kind))
    a, b, kind = (np.concatenate(x) for x in zip(*parts, strict=True))
    return _ContactSet(a, b, kind)


def _evaluate(cells: Cells, found: _ContactSet, planes: Sequence[Plane], planar: bool) -> Contacts:
    """The contacts of ``found`` at the cells' present positions, in the order of ``found``."""
    pairwise = found.b >= 0
    parts = [evaluate_contacts(cells, found.a[pairwise], found.b[pairwise], found.kind[pairwise], planar=planar)]
    order = [np.flatnonzero(pairwise)]
    for j, plane in enumerate(planes):
        on = np.flatnonzero(found.b == -1 - j)
        parts.append(evaluate_plane_contacts(cells, plane, found.a[on], found.kind[on]))
        order.append(on)
    return concatenate(parts).subset(np.argsort(np.concatenate(order), kind="stable"))


#: A linearization whose update leaves a larger overlap than this (fraction of the diameter, and
#: more than before it) is backtracked half way, at most :data:`MAX_BACKTRACKS` times a step.
BACKTRACK_OVERLAP = 0.5
MAX_BACKTRACKS = 6


def _diameters(cells: Cells, contacts: Contacts) -> np.ndarray:
    """(K,) ``ρ_a + ρ_b`` (``2ρ_a`` against a plane)."""
    rho_a = cells.radii[contacts.cell_a]
    return rho_a + np.where(contacts.cell_b >= 0, cells.radii[np.maximum(contacts.cell_b, 0)], rho_a)


def _bounds(system: Any, cells: Cells, drive: np.ndarray, impulses: np.ndarray, dt: float,
            settings: PositionSettings) -> tuple[np.ndarray, np.ndarray]:
    """Bounds on the scaled unknowns ỹ: turning (total and per iteration) and shrinking."""
    n = system.shape[1]
    lower, upper = np.full(n, -np.inf), np.full(n, np.inf)
    # ỹ of a column is sqrt(w)·x·σ_B/σ_b; its turning angle is dt·w·x = ỹ·unit⁻¹.
    unit = system.operator_scale / (dt * np.sqrt(system.column_inverse_mass) * system.velocity_scale)
    cell, slot = system.column_cell, system.column_slot
    if settings.turn_limit is not None:
        turning = np.flatnonzero((slot == 4) | (slot == 5))
        c = cell[turning]
        angle = settings.turn_limit * 2.0 * cells.radii[c] / (cells.lengths[c] / 2 + cells.radii[c])
        cap = angle * unit[turning]
        now = system.from_impulses(impulses)[turning]
        lower[turning] = np.maximum(-cap, now - settings.trust * cap)
        upper[turning] = np.minimum(cap, now + settings.trust * cap)
    if not settings.allow_shrinking:
        growth = np.flatnonzero(slot == 6)
        # l̇ = (g₀ + x_g)/G ≥ 0  ⇔  x_g ≥ −g₀  ⇔  ỹ ≥ −g₀·sqrt(w)·σ_B/σ_b
        lower[growth] = np.minimum(-drive[cell[growth], 6] * np.sqrt(system.column_inverse_mass[growth])
                                   * system.operator_scale / system.velocity_scale, upper[growth])
    return lower, upper


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
    on_failure: str = "raise",
) -> PositionStepResult:
    """Advance overdamped cells by ``dt`` with non-penetration at the end of the step (module
    docstring).

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
        on_failure: ``"raise"`` a :class:`~qpcontact.errors.StepFailedError` when the step does
            not converge (default), or ``"return"`` the unconverged result.

    Returns:
        A :class:`PositionStepResult`.

    Raises:
        StepFailedError: the step did not reach the overlap tolerance (``on_failure="raise"``),
            or a solve failed; nothing is applied.
        InvalidArgumentError: bad arguments.
    """
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
    drive = np.zeros((n, 7)) if drive is None else np.asarray(drive, dtype=float)
    if drive.shape != (n, 7) or not np.all(np.isfinite(drive)):
        raise InvalidArgumentError(f"drive: expected finite values of shape ({n}, 7), got shape {drive.shape}")
    if planar is None:  # a monolayer whose driving momenta and planes keep it in its plane
        moving = cells.replace(momenta=drive[:, 0:3], angular_momenta=drive[:, 3:6], growth_momenta=drive[:, 6])
        planar = moving.is_monolayer() and all(abs(plane.normal[2]) == 0 for plane in planes)
    form = next(f for f in ("contact", "primal") if f in spec.forms and (not settings.bounded or f in spec.bounds))
    times = {"detect": 0.0, "assemble": 0.0, "solve": 0.0}
    t_start = time.perf_counter()
    reach = settings.margin * 2.0 * float(np.median(cells.radii)) if n else 0.0
    # Overlap at the start of the step sets the floor of its own pair's target.
    t0 = time.perf_counter()
    start_found = _detect(cells, planes, 0.0, planar)
    start = _evaluate(cells, start_found, planes, planar)
    start_diameter = _diameters(cells, start)
    start_overlap = float(np.max(-start.separation / start_diameter, initial=0.0))
    n_planes = len(planes)
    overlapping = start.separation < 0
    floor_keys = start_found.key(n_planes, n)[overlapping] // 8  # a pair (or a cell and a plane)
    floor_value = start.separation[overlapping] + settings.relaxation * start_diameter[overlapping]
    order = np.argsort(floor_keys)
    floor_keys, floor_value = floor_keys[order], floor_value[order]
    times["detect"] += time.perf_counter() - t0

    impulses = np.zeros((n, 7))
    found = _ContactSet(*(np.zeros(0, dtype=np.intp),) * 3)
    overlaps: list[float] = []
    relaxation = 1.0
    solver_iterations = 0
    last = ContactImpulses.empty() if warm is None else warm  # keyed by ids
    turn_limited = 0
    converged, message, iteration = False, "", 0
    previous: np.ndarray | None = None  # the impulses of the last kept iterate
    keys = found.key(n_planes, n)
    backtracks = 0
    for iteration in range(settings.max_iterations + 1):
        now = move(cells, dt, drive + impulses)
        t0 = time.perf_counter()
        # Every linearization searches the whole margin: a cell pushed out of a jam can move a
        # diameter against a neighbour within one linearization (measured on a grown colony of
        # 10⁴ cells, with half the margin after the first: 0.14 of a diameter of overlap at the
        # seventh linearization, with a pair found only then).
        known = keys  # the contacts of the last linearization
        found = found.union(_detect(now, planes, reach, planar), n_planes, n)
        keys = found.key(n_planes, n)
        contacts = _evaluate(now, found, planes, planar)
        times["detect"] += time.perf_counter() - t0
        diameter = _diameters(now, contacts)
        overlaps.append(float(np.max(-contacts.separation / diameter, initial=0.0)))
        # A linearization that left a larger overlap on a contact it knew has met the curvature of
        # turning (an SQP iterate can then alternate between two states): later updates go half
        # way. A larger overlap on a contact found only now (a cell pushed far, into a neighbour
        # beyond the search margin) says nothing about the linearization: full updates go on.
        worst = int(np.argmax(-contacts.separation / diameter)) if len(contacts) else -1
        if len(overlaps) >= 2 and overlaps[-1] > overlaps[-2] and np.isin(keys[worst], known):
            relaxation = 0.5
        # An update that put cells deep into each other (rods crossing: the linearization of a
        # nearly infeasible jam, far outside where it holds) is not kept: back half way to the
        # last iterate and look again (measured: a newborn squeezed in a 27,601-cell colony went
        # from 0.15 to 1.0, rods through each other, and no later linearization separated them).
        if (previous is not None and overlaps[-1] > max(BACKTRACK_OVERLAP, overlaps[-2])
                and backtracks < MAX_BACKTRACKS and iteration < settings.max_iterations):
            impulses = previous + 0.5 * (impulses - previous)
            backtracks += 1
            relaxation = 0.5
            overlaps.pop()
            continue
        target = np.zeros(len(contacts))
        if floor_keys.size:
            pair = keys // 8
            where = np.minimum(np.searchsorted(floor_keys, pair), floor_keys.size - 1)
            target = np.where(floor_keys[where] == pair, np.minimum(0.0, floor_value[where]), 0.0)
        shortfall = (target - contacts.separation) / diameter
        excess = float(np.max(shortfall, initial=0.0))
        # The free motion itself may be within the tolerance (nothing pushes): nothing to solve
        # (and a solve would be ill-posed: its right-hand side, the scale of the problem, is ~0).
        if excess <= settings.overlap_tolerance:
            converged = True
            break
        if iteration == settings.max_iterations:
            message = (f"largest overlap beyond its target {excess:.3g} of a diameter after {iteration} "
                       f"linearizations (tolerance {settings.overlap_tolerance:g})")
            break
        if len(contacts) == 0:
            impulses = np.zeros((n, 7))
            continue
        t0 = time.perf_counter()
        # Masses and inertia of the start of the step (as move() uses them), geometry of now.
        frame = now.replace(lengths=cells.lengths)
        current = frame.replace(momenta=impulses[:, 0:3], angular_momenta=impulses[:, 3:6],
                                growth_momenta=impulses[:, 6])
        u = relative_normal_velocity(current, contacts.cell_a, contacts.cell_b, contacts.normal, contacts.offset_a,
                                     contacts.offset_b, contacts.stretch_a, contacts.stretch_b)
        b = (target + settings.aim * diameter - contacts.separation) / dt + u
        if not np.any(b > 0):  # nothing asks for a push: the free motion is the answer
            impulses = np.zeros((n, 7))
            last = ContactImpulses.empty()
            times["assemble"] += time.perf_counter() - t0
            continue
        system = build_system(frame, contacts, b, planar=bool(planar))
        lower, upper = _bounds(system, cells, drive, impulses, dt, settings) if settings.bounded else (None, None)
        problem = Problem(system.matrix, system.rhs, system.column_inverse_mass, lower=lower, upper=upper)
        times["assemble"] += time.perf_counter() - t0
        key_a, key_b = ids[found.a], np.where(found.b >= 0, ids[np.maximum(found.b, 0)], found.b)
        initial = None
        if spec.warm_start:
            initial = system.from_contact_impulses(last.lookup(key_a, key_b, found.kind))
        t0 = time.perf_counter()
        out = solve(problem, settings.solver, "complementarity", form, tolerance=settings.tolerance, initial=initial)
        times["solve"] += time.perf_counter() - t0
        solver_iterations += out.iterations or 0
        if not out.found or out.y is None or not np.all(np.isfinite(out.y)):
            message = f"{settings.solver} failed at linearization {iteration}: {out.status} {out.error or ''}".strip()
            break
        lam = system.to_contact_impulses(out.lam) if out.lam is not None else np.zeros(len(contacts))
        last = ContactImpulses(key_a, key_b, found.kind.copy(), lam)
        if lower is not None and upper is not None:
            turning = np.flatnonzero((system.column_slot == 4) | (system.column_slot == 5))
            span = np.maximum(upper[turning] - lower[turning], 1e-300)
            at_bound = (np.minimum(out.y[turning] - lower[turning], upper[turning] - out.y[turning]) <= 1e-3 * span)
            turn_limited = int(np.unique(system.column_cell[turning[at_bound]]).size)
        previous = impulses
        impulses = impulses + relaxation * (system.to_impulses(out.y) - impulses)
    end = now  # the loop always ends on a detection at the positions of the impulses it kept
    if iteration == 0:
        last = ContactImpulses.empty()  # nothing was solved: no contact pushed in this step
    key_a, key_b = ids[found.a], np.where(found.b >= 0, ids[np.maximum(found.b, 0)], found.b)
    impulse_of_contact = last.lookup(key_a, key_b, found.kind)
    times["total"] = time.perf_counter() - t_start
    result = PositionStepResult(
        cells=end, impulses=impulses, converged=converged, iterations=iteration, contacts=contacts,
        contact_impulses=impulse_of_contact, overlaps=overlaps, start_overlap=start_overlap,
        max_overlap=float(np.max(-contacts.separation / diameter, initial=0.0)), excess=excess, times=times,
        solver_iterations=solver_iterations, message=message,
        warm=ContactImpulses(key_a, key_b, found.kind.copy(), impulse_of_contact), turn_limited=turn_limited)
    if not converged and on_failure == "raise":
        raise StepFailedError(f"position step did not converge: {message}", result)
    return result
