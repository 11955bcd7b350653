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

from .. import moved
from ..checks import flag, instance, number, real_array
from ..errors import InvalidArgumentError, InvalidCellsError
from ..geometry.cells import Cells
from ..geometry.contacts import Contacts, concatenate, find_contacts, required_velocity_change
from ..geometry.motion import move
from ..geometry.overlap import overlap_fractions
from ..geometry.surfaces import plane_contacts
from ..resolve import Result, resolve
from ..schema import check_fields, documented, setting
from ..solvers import FORMS, QP_FORMULATIONS, get_solver


def __getattr__(name: str) -> Any:
    """The names that moved out of this module (deprecated; :mod:`qpcontact.moved`)."""
    return moved.attribute(__name__, name, moved.NAMES[__name__])

DYNAMICS = ("overdamped", "inertial")
#: Contacts separating faster than this many times the largest collision are left out
#: (:func:`drop_fast_separating`).
SEPARATING_CUTOFF = 10.0


@documented
@dataclass(frozen=True)
class VelocitySettings:
    """The parameters of the velocity-level :func:`step` as a colony run takes it: contacts stop
    approaching at the start of each step. The ``[velocity]`` table of a run's settings
    (:class:`qpcontact.simulation.Settings`, ``--step velocity``), flags ``--velocity-*``; each
    field described once with its unit (:func:`~qpcontact.schema.setting`). ``overlap_limit``
    is the run's retry rule (:func:`qpcontact.simulation.steps.grow_with_retries`); :func:`step`
    reads the others. :meth:`single_solve` gives the settings of one plain contact solve (what
    :func:`step` does without settings)."""

    solver: str = setting("clarabel", unit="",
                          help="the contact solver: linear, mprgp, ipm or an installed qpsolvers backend (clarabel, "
                               "osqp, ...)")
    formulation: str = setting("complementarity", unit="", choices=QP_FORMULATIONS,
                               help="the QP formulation (a plain solver such as linear solves the plain problem)")
    form: str = setting("auto", unit="", choices=("auto", *FORMS), help="the QP form handed to the solver")
    tolerance: float = setting(
        1e-6, unit="dimensionless, scaled", above=0, below=1,
        help="the solver's tolerance: an accepted answer's penetration and complementarity residual are at most "
             "min(100 × tolerance, 0.1) of the fastest approach")
    margin: float = setting(0.3, unit="µm", at_least=0, help="speculative contact margin: pairs this close are "
                                                              "constraints")
    position_correction: float = setting(0.5, unit="dimensionless", at_least=0, at_most=1,
                                         help="fraction of each overlap cleared per step (0: off)")
    overlap_limit: float = setting(
        0.0, unit="fraction of the diameter", at_least=0,
        help="retry a step with half the step when it leaves a larger overlap than this and than before it (0: off; "
             "it cost 4.5 times the time of a 3D run, docs/colony.md)")
    dynamics: str = setting("overdamped", unit="", choices=("overdamped", "inertial"),
                            help="overdamped: the momenta are reset to the drive every step; inertial: they carry over")
    damping: float = setting(0.0, unit="1/doubling time", at_least=0,
                             help="inertial dynamics: damping rate of the momenta")

    def __post_init__(self) -> None:
        check_fields(self)

    @classmethod
    def single_solve(cls, **changes: Any) -> VelocitySettings:
        """The settings of one plain contact solve, :func:`step`'s default: :func:`qpcontact.resolve`'s
        solver and tolerance, no margin, no position correction (an overlap a step leaves is
        never cleared), overdamped; ``changes`` by field name."""
        return cls(**{**SINGLE_SOLVE, **changes})


#: The fields of :class:`VelocitySettings` for one plain contact solve (:meth:`VelocitySettings.single_solve`):
#: :func:`qpcontact.resolve`'s own solver, formulation, form and tolerance, no margin, no position correction.
SINGLE_SOLVE: dict[str, Any] = dict(solver="osqp", formulation="complementarity", form="auto", tolerance=1e-6,
                                    margin=0.0, position_correction=0.0, dynamics="overdamped", damping=0.0)


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


#: The keyword arguments of :func:`step` that are fields of :class:`VelocitySettings` (given
#: without ``settings``, they change :meth:`VelocitySettings.single_solve`).
SETTING_KEYWORDS = ("solver", "formulation", "form", "tolerance", "margin", "position_correction", "dynamics",
                    "damping")


def step_settings(settings: VelocitySettings | None, options: dict[str, Any]) -> tuple[VelocitySettings, dict[str, Any]]:
    """``(settings, the other options for qpcontact.resolve)`` of a :func:`step` call: the given
    settings, or the single solve's changed by the keyword arguments that name its fields.

    Raises:
        InvalidArgumentError: settings that are not a :class:`VelocitySettings`, or given together
            with keyword arguments that name its fields (one source for each value).
    """
    given = {name: options.pop(name) for name in SETTING_KEYWORDS if name in options}
    if settings is None:
        if given.get("dynamics", "overdamped") not in DYNAMICS:
            raise InvalidArgumentError(f"dynamics: expected one of {DYNAMICS}, got {given['dynamics']!r}")
        return VelocitySettings.single_solve(**given), options
    instance("settings", settings, VelocitySettings, "qpcontact.timestep.VelocitySettings")
    if given:
        raise InvalidArgumentError(f"{', '.join(given)}: given together with settings; set them in the settings "
                                   "(dataclasses.replace(settings, ...))")
    return settings, options


def step(
    cells: Cells,
    dt: float,
    *,
    settings: VelocitySettings | None = None,
    drive: np.ndarray | None = None,
    planes: Sequence[Any] = (),
    planar: bool | None = None,
    keep_separating: bool | None = None,
    **options: Any,
) -> StepResult:
    """Advance the cells by one timestep ``dt`` (see the module docstring).

    Without ``settings`` the step is a single contact solve
    (:meth:`VelocitySettings.single_solve`): no margin and no position correction, so an overlap
    that a step leaves (or that the cells start with) is never cleared. A colony run wants both:
    ``qpcontact simulate --step velocity`` steps with ``VelocitySettings()`` (margin 0.3 µm,
    position correction 0.5, Clarabel at 1e-6), so ``step(cells, dt, settings=VelocitySettings(),
    planar=True)`` does the same in your own 2D loop, with ``planes=[qpcontact.substrate(0.0)]``
    instead of ``planar`` in a 3D one. :func:`qpcontact.position_step` takes its
    :class:`~qpcontact.timestep.PositionSettings` the same way.

    Args:
        cells: the state at time ``t``.
        dt: the time step [time], > 0.
        settings: :class:`VelocitySettings`: solver, formulation, form, tolerance, margin
            [length], position correction β in [0, 1] (0 = off: also clear a fraction β of every
            overlap within the step), dynamics (``"overdamped"``: momenta reset to ``drive``
            each step; ``"inertial"``: momenta carry over) and damping (inertial only: rate γ
            [1/time] of ``p, L ← exp(−γ dt)·(p, L)``). None: the single solve.
        drive: (N, 7) driving generalized momenta ``(p, L, g)`` [momentum units]: overdamped,
            the momenta before contact; inertial, an impulse added before contact. None = 0.
        planes: static planes (:class:`qpcontact.geometry.Plane`), one-sided contacts.
        planar: 2D monolayer mode. True: the scene must stay in the xy-plane and is solved with
            the planar unknowns only (an error if it leaves the plane); None: detected.
        keep_separating: put every contact within the margin into the system as soon as one
            collides (see :func:`qpcontact.resolve`), so that pushing one neighbour cannot drive
            it into another it was not approaching (contacts separating faster than
            ``SEPARATING_CUTOFF`` times the largest collision are still left out:
            :func:`drop_fast_separating`). None (default): on for the complementarity QPs, off
            for ``solver="linear"`` and ``least_squares`` (which would pull).
        **options: passed to :func:`qpcontact.resolve` (``time_limit``, ``solver_settings``,
            ...); without ``settings``, also the fields of :class:`VelocitySettings` by name
            (``solver=``, ``tolerance=``, ``margin=``, ``position_correction=``, ``dynamics=``,
            ``damping=``, ...: the keyword arguments of earlier versions).

    Returns:
        A :class:`StepResult`.

    Raises:
        SolverFailedError: the contact solve failed; nothing was applied.
        InvalidArgumentError: bad arguments, or a length would become negative.
    """
    instance("cells", cells, Cells, "qpcontact.Cells", InvalidCellsError)
    dt = number("dt", dt, minimum=0.0, open_minimum=True)
    v, options = step_settings(settings, dict(options))
    planar = flag("planar", planar, allow_none=True)
    keep_separating = flag("keep_separating", keep_separating, allow_none=True)
    if v.dynamics == "overdamped" and v.damping:
        raise InvalidArgumentError("damping applies to dynamics='inertial' only (overdamped momenta are reset each step)")
    if "contacts" in options:
        raise InvalidArgumentError("step finds its own contacts; pass planes= for static bodies")
    check_planar(cells, planar)
    if keep_separating is None:
        planned, _ = get_solver(v.solver).plan(v.formulation, v.form)
        keep_separating = planned == "complementarity"
    moving = momenta_before_contact(cells, dt, v.dynamics, drive, v.damping)
    contacts = concatenate([find_contacts(moving, v.margin, planar=planar),
                            plane_contacts(moving, planes, v.margin)])
    candidates = speculative(contacts, dt)
    if keep_separating:
        candidates = drop_fast_separating(candidates, v.position_correction, dt)
    result = resolve(moving, contacts=candidates, margin=v.margin, planar=planar, solver=v.solver,
                     formulation=v.formulation, form=v.form, tolerance=v.tolerance,
                     position_correction=v.position_correction, dt=dt, keep_separating=keep_separating,
                     on_failure="raise", **options)
    fractions = overlap_fractions(cells, contacts)
    overlapping = fractions[fractions > 0]
    return StepResult(
        cells=move(result.cells, dt),
        result=result,
        contacts=contacts,
        max_overlap=float(fractions.max(initial=0.0)),
        mean_overlap=float(overlapping.mean()) if overlapping.size else 0.0,
    )


def check_planar(cells: Cells, planar: bool | None) -> None:
    """With ``planar=True``, every cell in the plane of cell 0 (no cells: nothing is out of it).

    Raises:
        InvalidCellsError: naming the first cell out of the plane.
    """
    if planar and cells.n:
        out_of_plane = (np.abs(cells.centers[:, 2] - cells.centers[0, 2]) > 0) | (cells.axes[:, 2] != 0)
        if out_of_plane.any():
            raise InvalidCellsError(f"planar=True, but cell {int(np.flatnonzero(out_of_plane)[0])} is not in the plane of cell 0")
