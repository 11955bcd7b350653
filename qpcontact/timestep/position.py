"""The position-level step: non-penetration at the end of the step, by sequential linearization.

The velocity-level :func:`qpcontact.timestep.step` makes contacts stop approaching at the
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
the true distance at the re-detected positions, not the linearization). What keeps the
linearizations honest is meant to change their number, not the physics (docs/model-notes.md,
"The colony the physics makes"; a turn on its trust region when the step meets the tolerance
is kept as it is, after ``trust_rounds`` more linearizations, and counted in the result's
``turn_limited``):

- *trust regions*: in one linearization a cell's tips move by turning at most ``trust``
  diameters from where the last one left them (turns are where a linearization is poor); a cell
  whose answer sits on its region widens it (the step goes on while any overlap is beyond the
  tolerance, and up to ``trust_rounds`` linearizations beyond it: none by default, since any
  linearization past the tolerance moves hundreds of cells as far as those few), a cell whose
  turn goes back against its last one halves it. There is no cap on a step's turn unless ``turn_limit`` sets one (a cap of 0.2
  diameters, the default until 2026-12, bent the colony);
- *aim*: a linearization aims at a gap of ``aim`` beyond each target, room for its own error;
  contacts then rest at that gap, as if the cells were thicker, so the default is 0.001 of a
  diameter (not 0: contacts resting exactly on their constraint stalled the solver): contacts
  rest touching, and a linearization that left an overlap is followed by another;
- *shrinking*: no cell gets shorter (growth can be compressed to zero, not reversed): the model.

A linearization taken while some overlap is more than :data:`EARLY_EXCESS` overlap tolerances
beyond its target is solved only to ``early_tolerance`` (its own error, the overlap it leaves, is
larger than that solve's); the step never ends on such an answer.

The bounds are on the unknowns, so only solvers taking bounds can be used (the built-in
``"ipm"``, or a qpsolvers backend in the primal form).

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

from ..assembly.curvature import curvature_rows
from ..assembly.system import ContactSystem, Turned, build_system
from ..errors import InvalidArgumentError, StepFailedError
from ..geometry.cells import Cells
from ..geometry.contacts import Contacts, relative_normal_velocity
from ..geometry.motion import left_jacobian, move, turning_vectors
from ..geometry.regions import Split
from ..geometry.surfaces import Plane
from ..resolve.resolve import acceptance_failure
from ..schema import check_fields, documented, setting
from ..solvers import Problem, SolverSpec, get_solver, solve
from ..solvers.ipm import UNKNOWNS_ACCURACY
from .records import CellMotion, ContactImpulses, PositionStepResult
from .tracking import Floors, Tracked, diameters, evaluate, first_pairs, start_floors, track

__all__ = ["CellMotion", "ContactImpulses", "PositionSettings", "PositionStepResult", "move", "position_step",
           "uses_second_order"]

#: The tightest tolerance a second-order step's solves reach (:data:`UNKNOWNS_ACCURACY`/10: the
#: interior point's Newton systems in the unknowns, the only ones that take the curvature, lose
#: tighter answers to rounding).
SECOND_ORDER_TIGHTEST = 0.1 * UNKNOWNS_ACCURACY


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
             "linearization's answer (widened for a cell whose answer sat on it, halved when its turn goes back); it "
             "sets how many linearizations a turn takes, not the colony; none: no trust region")
    relaxation: float = setting(
        0.05, unit="fraction of the pair's diameter", above=0,
        help="overlap present at the start of the step is removed by at most this much per step")
    aim: float = setting(
        0.001, unit="fraction of the pair's diameter", at_least=0,
        help="the gap the linearizations aim at beyond each contact's target: contacts rest at it, as if the cells "
             "were this much thicker (at 0.03, the default until 2026-12, a 2D colony of 5,000 cells packed at 0.86, "
             "at 0.01 at 0.88, at 0 at 0.89); exactly 0 left contacts resting on their constraint, and the solver "
             "stalled in a narrow channel (docs/model-notes.md)")
    trust_rounds: int = setting(
        0, unit="linearizations", at_least=0,
        help="linearizations a step takes beyond meeting the overlap tolerance while some cell's turn sits on its "
             "trust region (each widening that cell's region). 0, the default since 2026-12-06 (2 before): any "
             "linearization past the tolerance moves hundreds of cells as far as it moves those few, and without "
             "these rounds the colony was the same for a seventh fewer linearizations (docs/model-notes.md)")
    second_order: bool | None = setting(
        False, unit="",
        help="each linearization also holds the contacts' curvature, weighted by the impulses of the last one (the "
             "Hessian of the Lagrangian: a contact point sliding along a turning rod, a turn's arc), its update taken "
             "whole, and the step ends with one first-order linearization; none: on where the solver takes it (ipm) "
             "at a tolerance of 10⁻⁴ or looser. Off by default: growing a 2D colony to 10⁴ cells it takes a fifth "
             "fewer linearizations but 1.07 times the time (its curvature costs), and at 5,000 cells its colony's "
             "nematic length is 1.12 times and its edge alignment 0.07 from the converged colony's, against the "
             "first-order step's 1.016 times and 0.02 (docs/model-notes.md, \"A second-order step\")")
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
             "3·10⁻⁴ of a diameter of the exact step's, at 10⁻³ within 3·10⁻³, for 13 interior-point iterations "
             "instead of 10 (a grown 2D colony of 5,000 cells; docs/model-notes.md); 10⁻³ bends the colony (local "
             "order +0.04, larger microdomains), 10⁻⁵ gives the colony of 10⁻⁴ (docs/statistics.md)")
    early_tolerance: float | None = setting(
        1e-2, unit="dimensionless, scaled", above=0, below=1,
        help="the solver tolerance of a linearization taken while some overlap is more than six times "
             "overlap_tolerance beyond its target: such a linearization is far from the step's answer, its own "
             "error larger than a loose solve's; a step never ends on such an answer; none: every one to tolerance "
             "(docs/model-notes.md, Early linearizations)")

    def __post_init__(self) -> None:
        check_fields(self)
        if self.early_tolerance is not None and self.early_tolerance < self.tolerance:
            raise InvalidArgumentError(f"early_tolerance: the tolerance of a step's early solves must be at least "
                                       f"tolerance ({self.tolerance:g}); got {self.early_tolerance:g}")
        if self.second_order:  # what a second-order step needs, refused before any run starts
            if not get_solver(self.solver).curvature:
                raise InvalidArgumentError(f"second_order: solver {self.solver!r} takes no curvature of the objective "
                                           "(use solver='ipm', or second_order=None or False)")
            if self.tolerance < SECOND_ORDER_TIGHTEST:
                raise InvalidArgumentError(f"second_order: its solves reach a tolerance of {SECOND_ORDER_TIGHTEST:g} "
                                           f"at best; got tolerance {self.tolerance:g}")

    @property
    def bounded(self) -> bool:
        """The step bounds the unknowns (turning or shrinking)."""
        return self.turn_limit is not None or self.trust is not None or not self.allow_shrinking


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
               radius: np.ndarray | None, split: Split, pushed: np.ndarray | None,
               family: object | None = None) -> tuple[ContactSystem, Problem, np.ndarray] | None:
    """The QP of one linearization (module docstring) and its turning caps (:func:`_bounds`), or
    None when no contact asks for a push.

    The unknowns are the impulses of the whole step in the cells' frame at the start of the step
    (its axes, its masses and inertia, as :func:`move` uses them), and each row is the exact
    derivative of the contact's separation at the moved positions: rotations enter through the
    left Jacobian of each cell's turn (:class:`qpcontact.assembly.system.Turned`), so in 3D the
    linearization is exact to first order (turning about the moved axes instead, as this step did
    until 2026-12, made the linearizations converge only linearly: 3–6 per step).

    Over several processes (``split``), each assembles the rows of the contacts whose first cell
    it owns (:func:`~qpcontact.assembly.system.build_system`); the rest is the same in every one.

    ``pushed``: (K,) each contact's impulse in the last solve, for a second-order linearization
    (the objective's curvature, :func:`~qpcontact.assembly.curvature.curvature_rows`); None: first
    order. ``family``: the step's (:attr:`~qpcontact.solvers.registry.Problem.family`: its
    linearizations share the solver's set-up)."""
    turned = Turned(axes=now.axes, jacobian=left_jacobian(turning_vectors(cells, dt, drive + impulses)))
    # The rows first (the right-hand side needs their product with the impulses so far), then
    # d_k + dt·(J W (x_new − x))_k ≥ target_k + aim_k  ⇔  (J W x_new)_k ≥ (target_k + aim_k − d_k)/dt + (J W x)_k
    b = (target + aim - contacts.separation) / dt
    if not np.any(impulses):  # the first linearization: nothing to add
        if not np.any(b > 0):
            return None
        system = build_system(cells, contacts, b, planar=planar, turned=turned, split=split, owner=split.owner)
    else:
        system = build_system(cells, contacts, np.ones(len(contacts)), planar=planar, turned=turned, split=split,
                              owner=split.owner)
        b = b + system.velocity_changes(impulses)  # right only in the rows this process holds
        held = b if system.owned_rows is None else b[system.owned_rows]
        if not split.most(float(np.any(held > 0))):
            return None
        system = system.with_rhs(b)
    curvature = None if pushed is None else curvature_rows(system, now, pushed, dt, turned)
    anchor = None if curvature is None else system.from_impulses(impulses)
    if not settings.bounded:
        return system, Problem(system.matrix, system.rhs, system.column_inverse_mass, curvature=curvature,
                               anchor=anchor, family=family), np.full(system.shape[1], np.inf)
    lower, upper, cap = _bounds(system, cells, drive, impulses, dt, settings, radius)
    return system, Problem(system.matrix, system.rhs, system.column_inverse_mass, lower=lower, upper=upper,
                           curvature=curvature, anchor=anchor, family=family), cap


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
#: A linearization taken while some overlap is more than this many overlap tolerances beyond its
#: target is solved to ``PositionSettings.early_tolerance`` (docs/model-notes.md, "Early
#: linearizations").
EARLY_EXCESS = 6.0


@dataclass
class _Progress:
    """What the linearizations of a step carry from one to the next."""

    impulses: np.ndarray
    found: Tracked
    previous: np.ndarray | None = None  # the impulses of the last kept iterate
    relaxation: float = 1.0  # the fraction of each update taken
    backtracks: int = 0
    overlaps: list[float] = field(default_factory=list)
    last: ContactImpulses = field(default_factory=ContactImpulses.empty)  # the last solve's, keyed by ids
    solver_iterations: int = 0
    turn_limited: int = 0
    trusting: int = 0  # cells whose turn sat on the trust region in the last solve (and could go further)
    radius: np.ndarray | None = None  # (N,) each cell's trust region [diameters]
    trust_rounds: int = 0  # linearizations taken at feasible positions for cells on their trust region
    turned: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (N, 3) the change of each cell's angular impulse in the last solve
    # A second-order answer holds the curvature about its linearization point, which pulls it
    # towards that point: where the step would stop, it takes one more linearization without it
    # (first order, whole), and stops there if that is within the tolerance (without it, one seed
    # of a 2D colony of 5,000 cells grew a local order of 0.81 against the reference's 0.76).
    polished: bool = False
    loose: bool = False  # the last answer was solved to early_tolerance: the step does not end on it


def uses_second_order(settings: PositionSettings, comm: Any = None) -> bool:
    """Whether the step's linearizations hold the contacts' curvature: the setting, or where it is
    none, whether its solver takes it at its tolerance (ipm at 10⁻⁴ or looser) in one process."""
    if settings.second_order is not None:
        return settings.second_order
    return get_solver(settings.solver).curvature and comm is None and settings.tolerance >= UNKNOWNS_ACCURACY


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
                                   "bounds turning and shrinking (use solver='ipm', or turn_limit=None, trust=None "
                                   "and allow_shrinking=True)")
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
           iteration: int, settings: PositionSettings, second_order: bool) -> bool:
    """Record the overlap of this iterate and decide on damping (first-order linearizations
    only: a second-order one models the curvature that damping stands in for); True when the
    iterate is to be backtracked (not kept) instead."""
    progress.overlaps.append(float(np.max(-contacts.separation / diameter, initial=0.0)))
    overlaps = progress.overlaps
    # A linearization that left a larger overlap on a contact it knew has met the curvature of
    # turning (an SQP iterate can then alternate between two states): later updates go half
    # way. A larger overlap on a contact found only now (a cell pushed far, into a neighbour
    # beyond the search margin) says nothing about the linearization: full updates go on.
    worst = int(np.argmax(-contacts.separation / diameter)) if len(contacts) else -1
    if (not second_order and len(overlaps) >= 2 and overlaps[-1] > overlaps[-2]
            and np.isin(progress.found.keys[worst], known)):
        progress.relaxation = 0.5
    # An update that put cells deep into each other (rods crossing: the linearization of a
    # nearly infeasible jam, far outside where it holds) is not kept: back half way to the
    # last iterate and look again (measured: a newborn squeezed in a 27,601-cell colony went
    # from 0.15 to 1.0, rods through each other, and no later linearization separated them).
    if (progress.previous is not None and overlaps[-1] > max(BACKTRACK_OVERLAP, overlaps[-2])
            and progress.backtracks < MAX_BACKTRACKS and iteration < settings.max_iterations):
        progress.impulses = progress.previous + 0.5 * (progress.impulses - progress.previous)
        progress.backtracks += 1
        progress.relaxation = 1.0 if second_order else 0.5
        overlaps.pop()
        return True
    return False


def _solve(progress: _Progress, system: ContactSystem, problem: Problem, cap: np.ndarray, spec: SolverSpec,
           form: str, settings: PositionSettings, ids: np.ndarray, times: dict[str, float], tolerance: float,
           comm: Any = None) -> str:
    """Solve one linearization's QP to ``tolerance`` and take its answer into ``progress``; why
    not, if it was not taken. An answer is taken only when its solver stands by it and it passes the acceptance
    checks of every answer (resolve's, with the bounds): a stalled answer within the acceptance
    limits has still moved cells of a settled layer (docs/performance.md)."""
    key_a, key_b = progress.found.keyed(ids)
    initial = system.from_contact_impulses(progress.last.lookup(key_a, key_b, progress.found.kind)) \
        if spec.warm_start else None
    t0, c0 = time.perf_counter(), time.process_time()
    options = None if comm is None else {"comm": comm}
    if options is not None and system.owned_rows is not None:
        owner = system.split.owner
        assert owner is not None
        options["owners"] = (owner[system.column_cell], owner[system.contacts.cell_a])
    out = solve(problem, settings.solver, "complementarity", form, tolerance=tolerance, initial=initial,
                settings=options)
    times["solve"] += time.perf_counter() - t0
    times["solve_cpu"] += time.process_time() - c0
    progress.solver_iterations += out.iterations or 0
    refused = "" if out.y is None or not out.found else acceptance_failure(
        system, "complementarity", out.y, out.lam, tolerance, problem.lower, problem.upper,
        None if problem.curvature is None else problem.gradient(out.y))
    if not out.found or out.y is None or not np.all(np.isfinite(out.y)) or refused:
        return f"{out.status} {out.error or ''} {refused}".strip()
    lam = system.to_contact_impulses(out.lam) if out.lam is not None else np.zeros(problem.matrix.shape[0])
    progress.last = ContactImpulses(key_a, key_b, progress.found.kind.copy(), lam)
    progress.loose = tolerance > settings.tolerance
    progress.turn_limited, trusting = _turn_limited(system, problem, cap, out.y)
    progress.previous = progress.impulses
    progress.impulses = progress.impulses + progress.relaxation * (system.to_impulses(out.y) - progress.impulses)
    _adapt_trust(progress, progress.previous, trusting, settings)
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
    evaluate the contacts (:func:`track`, :func:`evaluate`), judge the iterate (:func:`_judge`:
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
    if comm is not None and settings.second_order:
        raise InvalidArgumentError("second_order: a step split among processes (comm) is first order")
    step, start_overlap = _begin(cells, dt, drive, planes, planar, settings, spec, ids, motion, parents, comm)
    progress = _Progress(impulses=np.zeros((cells.n, 7)), found=Tracked.empty(),
                         last=ContactImpulses.empty() if warm is None else warm, turned=np.zeros((cells.n, 3)),
                         radius=None if settings.trust is None else np.full(cells.n, settings.trust))
    converged, message, iteration, excess = False, "", 0, 0.0
    for iteration in range(settings.max_iterations + 1):
        now, contacts, diameter, backtracked = _look(step, progress, iteration)
        if backtracked:
            continue
        target = step.floors.targets(progress.found)
        excess = float(np.max((target - contacts.separation) / diameter, initial=0.0))
        converged, message = _verdict(progress, excess, iteration, settings)
        # A second-order step ends with one first-order linearization taken whole (_Progress.polished).
        polish = converged and step.second_order and not progress.polished and iteration < settings.max_iterations
        if polish:
            converged, progress.polished = False, True
        if converged or message:
            break
        t0, c0 = time.perf_counter(), time.process_time()
        pushed = (progress.last.lookup(*progress.found.keyed(ids), progress.found.kind)
                  if step.second_order and not polish else None)
        linear = _linearize(cells, now, contacts, target, settings.aim * diameter, dt, drive,
                            progress.impulses, planar, settings, progress.radius, step.split, pushed, step.family)
        step.times["assemble"] += time.perf_counter() - t0
        step.times["assemble_cpu"] += time.process_time() - c0
        if linear is None:  # nothing asks for a push: the free motion is the answer
            progress.impulses, progress.last, progress.trusting = np.zeros((cells.n, 7)), ContactImpulses.empty(), 0
            progress.loose = False
            continue
        message = _solve(progress, *linear, spec, step.form, settings, ids, step.times, _tolerance(excess, settings),
                         comm)
        if message:
            message = f"{settings.solver} failed at linearization {iteration}: {message}"
            break
    # The loop always ends on a detection at the positions of the impulses it kept.
    step.times["total"] = time.perf_counter() - step.started
    step.times["total_cpu"] = time.process_time() - step.started_cpu
    result = _result(progress, cells, now, contacts, diameter, converged, iteration, excess, start_overlap, ids, dt,
                     drive, message, step.times)
    if not converged and on_failure == "raise":
        raise StepFailedError(f"position step did not converge: {message}; {what_to_try(settings)}", result)
    return result


@dataclass
class _Step:
    """What every linearization of one step shares: the scene, the search and the start's floors."""

    cells: Cells
    dt: float
    drive: np.ndarray
    settings: PositionSettings
    planes: list[Plane]
    planar: bool
    form: str
    reach: float
    span: int
    split: Split
    second_order: bool  # linearizations with the contacts' curvature (PositionSettings.second_order)
    family: object  # what the step's problems share (Problem.family): this step, and no other
    predicted: Cells | None
    candidates: np.ndarray
    floors: Floors
    times: dict[str, float]
    started: float
    started_cpu: float


def _begin(cells: Cells, dt: float, drive: np.ndarray, planes: list[Plane], planar: bool, settings: PositionSettings,
           spec: SolverSpec, ids: np.ndarray, motion: CellMotion | None, parents: np.ndarray | None,
           comm: Any) -> tuple[_Step, float]:
    """The step's set-up: the search's reach, the free motion and the prediction, one broad phase
    for both and the start (:func:`first_pairs`), the floors of the pairs that start overlapping;
    ``(step, start_overlap)``."""
    started, started_cpu = time.perf_counter(), time.process_time()
    form = next(f for f in ("contact", "primal") if f in spec.forms and (not settings.bounded or f in spec.bounds))
    reach = search_margin(settings, planar) * 2.0 * float(np.median(cells.radii)) if cells.n else 0.0
    split, span = Split(comm), cells.n + len(planes) + 1
    split.own(cells)  # the slabs that own the cells (moves, rows, unknowns) for the whole step
    free = split.moved(cells, dt, drive)
    predicted = None if motion is None else motion.predict(cells.replace(lengths=free.lengths), ids, dt, parents)
    candidates = first_pairs(cells, free, predicted, reach, split)
    floors, start_overlap = start_floors(cells, planes, planar, span, settings.relaxation, candidates, split)
    times = {"detect": time.perf_counter() - started, "assemble": 0.0, "solve": 0.0,
             "detect_cpu": time.process_time() - started_cpu, "assemble_cpu": 0.0, "solve_cpu": 0.0}
    second_order = uses_second_order(settings, comm)
    return _Step(cells, dt, drive, settings, planes, planar, form, reach, span, split, second_order, object(),
                 predicted, candidates, floors, times, started, started_cpu), start_overlap


def _look(step: _Step, progress: _Progress, iteration: int) -> tuple[Cells, Contacts, np.ndarray, bool]:
    """Move the cells with the impulses so far, find and evaluate the contacts there and judge
    the iterate (:func:`_judge`); ``(now, contacts, diameter, backtracked)``."""
    now = step.split.moved(step.cells, step.dt, step.drive + progress.impulses)
    t0, c0 = time.perf_counter(), time.process_time()
    known = progress.found.keys
    first = iteration == 0  # the first linearization also searches where the last step's motion goes
    progress.found = track(progress.found, now, step.predicted if first else None, step.planes, step.reach, step.span,
                           step.candidates if first else None, step.split)
    contacts = evaluate(now, progress.found, step.planes, step.planar, step.split)
    diameter = diameters(now, contacts)
    step.times["detect"] += time.perf_counter() - t0
    step.times["detect_cpu"] += time.process_time() - c0
    return now, contacts, diameter, _judge(progress, contacts, diameter, known, iteration, step.settings,
                                           step.second_order)


def _verdict(progress: _Progress, excess: float, iteration: int, settings: PositionSettings) -> tuple[bool, str]:
    """Whether the step is done at this iterate: ``(converged, why it failed)``. The free motion
    itself may be within the tolerance (nothing pushes: nothing to solve, and a solve would be
    ill-posed, its right-hand side ~0); not on an answer solved only to ``early_tolerance``; a
    cell whose turn sat on its trust region would have turned further: up to ``trust_rounds``
    more linearizations."""
    if excess <= settings.overlap_tolerance:
        if progress.loose and iteration < settings.max_iterations:
            return False, ""  # a step ends on an answer solved to its tolerance
        if progress.trusting == 0 or progress.trust_rounds >= settings.trust_rounds:
            return True, ""
        progress.trust_rounds += 1
    if iteration < settings.max_iterations:
        return False, ""
    if excess > settings.overlap_tolerance:
        return False, (f"largest overlap beyond its target {excess:.3g} of a diameter after {iteration} "
                       f"linearizations (tolerance {settings.overlap_tolerance:g})")
    return False, (f"{progress.trusting} cells still turning at the trust region's edge after {iteration} "
                   f"linearizations (trust {settings.trust:g} diameters)")


def _tolerance(excess: float, settings: PositionSettings) -> float:
    """The solver tolerance of a linearization taken at an iterate whose largest overlap beyond
    its target is ``excess`` [diameters]: ``early_tolerance`` while that is more than
    :data:`EARLY_EXCESS` overlap tolerances."""
    early = settings.early_tolerance
    return early if early is not None and excess > EARLY_EXCESS * settings.overlap_tolerance else settings.tolerance


def what_to_try(settings: PositionSettings) -> str:
    """What to change when a position step fails, with the settings' current values (a failed
    step's message ends with it)."""
    other = "mprgp or clarabel" if settings.solver == "ipm" else "ipm"
    return (f"try: a smaller dt (half: each linearization is then nearer to linear), more linearizations "
            f"(max_iterations, now {settings.max_iterations}), a looser solver tolerance (tolerance, now "
            f"{settings.tolerance:g}) or overlap_tolerance (now {settings.overlap_tolerance:g}), or another solver "
            f"(solver, now {settings.solver}: {other})")
