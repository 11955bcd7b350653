"""One timestep around the contact solve: set the momenta, resolve contacts, move the cells.

A step from state ``t`` to ``t + dt`` (velocity-level, semi-implicit Euler):

1. *Momenta before contact.* ``dynamics="overdamped"`` (the usual model for bacteria, as in
   CellModeller): the momenta are reset to the driving terms ``drive`` (growth momentum
   ``g = G·l̇_target`` and any user-given momenta); nothing carries over from the last step.
   ``dynamics="inertial"``: the momenta carry over, linear and angular momentum damped by
   ``exp(−damping·dt)``, and ``drive`` (if given) is added as an external impulse.
2. *Contacts.* Cell–cell contacts (:func:`qpcontact.find_contacts`) plus one-sided contacts with
   static planes (:mod:`qpcontact.geometry.surfaces`), resolved by :func:`qpcontact.resolve` with any
   solver, formulation, form and tolerance; with ``position_correction`` β the solve also
   clears a fraction β of each overlap within the step. With ``margin > 0`` the contacts are
   *speculative*: a pair at a gap ``d > 0`` may approach, but by no more than ``d`` within the
   step (``b = −u − d/dt``), so that cells moving fast do not pass into neighbours they were
   not yet touching. This is done by handing :func:`qpcontact.resolve` those contacts with the
   normal velocity ``u + d/dt`` (the approach that is left after closing the gap).
3. *Move.* Centres by ``v dt``, axes by the exact rotation ``ω dt`` (Rodrigues' formula: axes
   stay unit length), lengths by ``l̇ dt``; the post-contact momenta are kept in the new state.

A solver failure is never applied: :func:`qpcontact.resolve` raises
:class:`~qpcontact.errors.SolverFailedError` and :func:`step` lets it propagate, with the state
unchanged (the caller still holds the old ``cells``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..checks import flag, instance, number, real_array
from ..errors import InvalidArgumentError, InvalidCellsError
from ..geometry.cells import Cells
from ..geometry.contacts import Contacts, concatenate, find_contacts, required_velocity_change
from ..geometry.motion import rotate
from ..geometry.surfaces import plane_contacts
from ..resolve import Result, resolve
from ..solvers import get_solver

DYNAMICS = ("overdamped", "inertial")
#: Contacts separating faster than this many times the largest collision are left out
#: (:func:`drop_fast_separating`).
SEPARATING_CUTOFF = 10.0


@dataclass
class StepResult:
    """The outcome of one :func:`step`.

    Attributes:
        cells: the state at ``t + dt`` (positions moved; momenta are the post-contact ones).
        result: the :class:`qpcontact.Result` of the contact solve (at time ``t``).
        contacts: every contact found at time ``t`` (cell–cell then cell–plane), colliding or not.
        max_overlap: largest overlap at time ``t`` as a fraction of the contact's diameter
            (``max(0, −d)/(ρ_a + ρ_b)``; ``2ρ_a`` against a plane); 0 without contacts.
        mean_overlap: mean of the same fraction over the overlapping contacts (0 if none).
    """

    cells: Cells
    result: Result
    contacts: Contacts
    max_overlap: float
    mean_overlap: float


def advance(cells: Cells, dt: float) -> Cells:
    """The cells moved by ``dt`` with their current velocities: ``c += v dt``,
    ``â ← R(ω dt) â``, ``l += l̇ dt``. Momenta are kept as they are.

    Raises:
        InvalidArgumentError: a length would become negative (the step is too large for how
            fast contacts compress that cell), or a position, turn or length would not be a
            finite number (a huge ``dt``).
    """
    with np.errstate(over="ignore", invalid="ignore"):
        centers = cells.centers + cells.velocities * dt
        turns = cells.angular_velocities * dt
        lengths = cells.lengths + cells.growth_rates * dt
    finite = np.isfinite(centers).all(axis=1) & np.isfinite(turns).all(axis=1) & np.isfinite(lengths)
    if not finite.all():
        i = int(np.flatnonzero(~finite)[0])
        raise InvalidArgumentError(
            f"dt = {dt!r} is too large: cell {i} would move, turn or grow beyond the range of numbers "
            f"(speed {np.linalg.norm(cells.velocities[i]):.3g}, turning rate {np.linalg.norm(cells.angular_velocities[i]):.3g}, "
            f"length rate {cells.growth_rates[i]:.3g}); take a smaller time step")
    negative = lengths < 0
    if negative.any():
        i = int(np.flatnonzero(negative)[0])
        raise InvalidArgumentError(
            f"dt = {dt!r} is too large: cell {i} would reach length {lengths[i]:.3g} < 0 "
            f"(length rate {cells.growth_rates[i]:.3g}); take a smaller time step")
    return cells.replace(centers=centers, axes=rotate(cells.axes, turns), lengths=lengths)


def overlap_fractions(cells: Cells, contacts: Contacts) -> np.ndarray:
    """(K,) ``max(0, −d)/(ρ_a + ρ_b)``: each contact's overlap as a fraction of its diameter
    (``ρ_b = ρ_a`` for a static body)."""
    radius_b = np.where(contacts.cell_b >= 0, cells.radii[np.maximum(contacts.cell_b, 0)], cells.radii[contacts.cell_a])
    return np.maximum(0.0, -contacts.separation) / (cells.radii[contacts.cell_a] + radius_b)


def largest_overlap(cells: Cells, planes: Sequence[Any] = ()) -> float:
    """Largest overlap of two cells, or of a cell and a plane (:mod:`qpcontact.geometry.surfaces`), as a
    fraction of the diameter (:func:`overlap_fractions`; 0 when nothing overlaps)."""
    contacts = concatenate([find_contacts(cells), plane_contacts(cells, planes, 0.0)])
    return float(overlap_fractions(cells, contacts).max(initial=0.0))


def speculative(contacts: Contacts, dt: float) -> Contacts:
    """The contacts with ``u`` replaced by ``u + max(0, d)/dt``: a gap ``d > 0`` may close
    within the step, no more (overlapping contacts are unchanged)."""
    gap = np.maximum(0.0, contacts.separation)
    if not gap.any():
        return contacts
    return dataclasses.replace(contacts, normal_velocity=contacts.normal_velocity + gap / dt)


def drop_fast_separating(contacts: Contacts, position_correction: float, dt: float) -> Contacts:
    """Leave out contacts that separate faster than :data:`SEPARATING_CUTOFF` times the largest
    required velocity change of a colliding contact (``b < −cutoff·max b``): impulses of the size
    the collisions need do not reverse them, and keeping them would set the system's velocity
    scale (``max |b|``) by a contact that plays no part, so that the colliding ones look tiny to
    the solver and its tolerance."""
    b = required_velocity_change(contacts, position_correction=position_correction, dt=dt)
    largest = float(b.max(initial=0.0))
    if largest <= 0:
        return contacts
    return contacts.subset(b >= -SEPARATING_CUTOFF * largest)


def momenta_before_contact(cells: Cells, dt: float, dynamics: str, drive: np.ndarray | None, damping: float) -> Cells:
    """Step 1 of the module docstring: the momenta the contact solve starts from."""
    if drive is not None:
        drive = real_array("drive", drive, InvalidArgumentError)
        if drive.shape != (cells.n, 7):
            raise InvalidArgumentError(f"drive: expected shape ({cells.n}, 7) (p, L, g per cell), got {drive.shape}")
    if dynamics == "overdamped":
        drive = np.zeros((cells.n, 7)) if drive is None else drive
        return cells.replace(momenta=drive[:, 0:3], angular_momenta=drive[:, 3:6], growth_momenta=drive[:, 6])
    keep = np.exp(-damping * dt)
    damped = cells.replace(momenta=cells.momenta * keep, angular_momenta=cells.angular_momenta * keep)
    return damped if drive is None else damped.with_impulses(drive)


def step(
    cells: Cells,
    dt: float,
    *,
    dynamics: str = "overdamped",
    drive: np.ndarray | None = None,
    damping: float = 0.0,
    planes: Sequence[Any] = (),
    margin: float = 0.0,
    planar: bool | None = None,
    position_correction: float = 0.0,
    keep_separating: bool | None = None,
    **resolve_options: Any,
) -> StepResult:
    """Advance the cells by one timestep ``dt`` (see the module docstring).

    The defaults are those of a single contact solve: no margin and no position correction, so
    an overlap that a step leaves (or that the cells start with) is never cleared. A colony run
    wants both: ``qpcontact simulate --step velocity`` steps with ``margin=0.3`` [µm],
    ``position_correction=0.5`` and Clarabel at 1e-6 (its ``[velocity]`` settings);
    ``step(cells, dt, **Settings().step_options())`` (with :class:`qpcontact.colony.Settings`)
    does the same in your own 2D loop, ``Settings().step_options(dimensions=3)`` in a 3D one.

    Args:
        cells: the state at time ``t``.
        dt: the time step [time], > 0.
        dynamics: ``"overdamped"`` (momenta reset to ``drive`` each step) or ``"inertial"``
            (momenta carry over).
        drive: (N, 7) driving generalized momenta ``(p, L, g)`` [momentum units]: overdamped,
            the momenta before contact; inertial, an impulse added before contact. None = 0.
        damping: inertial only: rate γ [1/time] of ``p, L ← exp(−γ dt)·(p, L)``.
        planes: static planes (:class:`qpcontact.geometry.Plane`), one-sided contacts.
        margin: contacts closer than this count [length].
        planar: 2D monolayer mode. True: the scene must stay in the xy-plane and is solved with
            the planar unknowns only (an error if it leaves the plane); None: detected.
        position_correction: β in (0, 1] (0 = off): also clear a fraction β of every overlap
            within the step.
        keep_separating: put every contact within the margin into the system as soon as one
            collides (see :func:`qpcontact.resolve`), so that pushing one neighbour cannot drive
            it into another it was not approaching (contacts separating faster than
            ``SEPARATING_CUTOFF`` times the largest collision are still left out:
            :func:`drop_fast_separating`). None (default): on for the complementarity QPs, off
            for ``solver="linear"`` and ``least_squares`` (which would pull).
        **resolve_options: passed to :func:`qpcontact.resolve` (``solver``, ``formulation``,
            ``form``, ``tolerance``, ``time_limit``, ``solver_settings``, ...).

    Returns:
        A :class:`StepResult`.

    Raises:
        SolverFailedError: the contact solve failed; nothing was applied.
        InvalidArgumentError: bad arguments, or a length would become negative.
    """
    instance("cells", cells, Cells, "qpcontact.Cells", InvalidCellsError)
    dt = number("dt", dt, minimum=0.0, open_minimum=True)
    if dynamics not in DYNAMICS:
        raise InvalidArgumentError(f"dynamics: expected one of {DYNAMICS}, got {dynamics!r}")
    damping = number("damping", damping, minimum=0.0)
    planar = flag("planar", planar, allow_none=True)
    keep_separating = flag("keep_separating", keep_separating, allow_none=True)
    margin = number("margin", margin, minimum=0.0)
    if dynamics == "overdamped" and damping:
        raise InvalidArgumentError("damping applies to dynamics='inertial' only (overdamped momenta are reset each step)")
    if "contacts" in resolve_options:
        raise InvalidArgumentError("step finds its own contacts; pass planes= for static bodies")
    if planar and cells.n:  # (no cells: nothing is out of the plane)
        out_of_plane = (np.abs(cells.centers[:, 2] - cells.centers[0, 2]) > 0) | (cells.axes[:, 2] != 0)
        if out_of_plane.any():
            raise InvalidCellsError(f"planar=True, but cell {int(np.flatnonzero(out_of_plane)[0])} is not in the plane of cell 0")
    if keep_separating is None:
        defaults = {**(resolve.__kwdefaults__ or {}), **resolve_options}
        planned, _ = get_solver(defaults["solver"]).plan(defaults["formulation"], defaults["form"])
        keep_separating = planned == "complementarity"
    moving = momenta_before_contact(cells, dt, dynamics, drive, damping)
    contacts = concatenate([find_contacts(moving, margin, planar=planar),
                            plane_contacts(moving, planes, margin)])
    candidates = speculative(contacts, dt)
    if keep_separating:
        candidates = drop_fast_separating(candidates, position_correction, dt)
    result = resolve(moving, contacts=candidates, margin=margin, planar=planar,
                     position_correction=position_correction, dt=dt, keep_separating=keep_separating,
                     on_failure="raise", **resolve_options)
    fractions = overlap_fractions(cells, contacts)
    overlapping = fractions[fractions > 0]
    return StepResult(
        cells=advance(result.cells, dt),
        result=result,
        contacts=contacts,
        max_overlap=float(fractions.max(initial=0.0)),
        mean_overlap=float(overlapping.mean()) if overlapping.size else 0.0,
    )
