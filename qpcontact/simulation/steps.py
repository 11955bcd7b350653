"""The step policy of a colony run: which step advances the colony, and what a run does when a
step fails.

- :func:`step_function`: the run's one step function, ``take_step(colony, dt, *, drive) ->
  StepOutcome``, from its settings (``run.step``):

  - ``position`` (default): :func:`position_step_function`,
    :func:`qpcontact.colony.grow_position` with non-penetration at the end of the step; a step
    that does not reach the overlap tolerance is retried with half the step, and one that starts
    with more overlap than ``relaxation`` clears is taken once more with the relaxation raised;
  - ``velocity``: :func:`grow_with_retries`, :func:`qpcontact.colony.grow` retried with half the
    step when it turns some cell too fast (:func:`turning_reach`) or, with
    ``velocity.overlap_limit``, leaves too large an overlap;

- :func:`flags_to_try`: what to change when a step fails, as flags;
- what every step adds or measures: :func:`sink_drive` (the sinking towards the substrate in
  3D), :func:`step_mechanics` (each cell's pressure and stress from the step's contact forces),
  :func:`pressure_growth_of` (the growth law slowed by pressure, from the settings).

The loop that calls the step function is :mod:`qpcontact.simulation.loop`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from functools import partial
from typing import Any, NamedTuple

import numpy as np

from ..colony.growth import Colony, grow, grow_position
from ..colony.hooks import push
from ..colony.pressure import PressureGrowth
from ..errors import StepFailedError, TooManyContactsError
from ..geometry import Cells, Plane
from ..geometry.overlap import largest_overlap
from ..timestep.mechanics import CellMechanics
from ..timestep.position import CellMotion, ContactImpulses, PositionStepResult
from ..timestep.step import StepResult
from .settings import Settings

__all__ = ["MOTION_ARRAYS", "WARM_ARRAYS", "StepFunction", "StepOutcome", "flags_to_try", "grow_with_retries",
           "position_step_function", "pressure_growth_of", "sink_drive", "step_function", "step_mechanics",
           "turning_reach"]


# (The functional form keeps the field types real types, not strings, for the API reference.)
StepOutcome = NamedTuple("StepOutcome", [("colony", Colony), ("result", StepResult | PositionStepResult),  # noqa: UP014
                                         ("dt", float), ("rejected", int)])
StepOutcome.__doc__ = """What a run's step function returns (:func:`step_function`).

Attributes:
    colony: the colony after the step (:func:`~qpcontact.simulation.run_colony` divides cells before the step).
    result: the step's :class:`~qpcontact.timestep.StepResult` (velocity-level: its ``result`` —
        the :class:`qpcontact.Result` of the contact solve, with ``contacts``, ``times`` and
        ``errors`` — and ``max_overlap``, ``mean_overlap`` fill the history) or
        :class:`~qpcontact.timestep.PositionStepResult` (position-level).
    dt: the time step taken [doubling times].
    rejected: attempts rejected and retried with half the step.
"""


#: A run's step function: ``take_step(colony, dt, *, drive) -> StepOutcome``.
StepFunction = Callable[..., StepOutcome]


def grow_with_retries(colony: Colony, dt: float, settings: Settings, **grow_options: Any) -> StepOutcome:
    """:func:`qpcontact.colony.grow` by ``dt``, rejected and retried with half the step (up to
    ``run.max_halvings`` times; the last attempt is kept) when

    - the contact solve turns some cell so fast that its tips would move more than ``run.cfl``
      diameters in the step (:func:`turning_reach`): the contact constraints hold to first
      order in the step, and a fast-turning short cell (a newborn squeezed between neighbours)
      is where the second-order error shows as overlap;
    - ``velocity.overlap_limit > 0`` and the new state's largest overlap exceeds both that limit
      and the largest overlap before the step (:func:`largest_overlap`).

    Returns a :class:`StepOutcome` ``(colony, step_result, dt_taken, rejected_attempts)``."""
    reach_limit = settings.run.cfl * 2.0 * float(np.median(colony.cells.radii))
    limit, halvings = settings.velocity.overlap_limit, settings.run.max_halvings
    for attempt in range(halvings + 1):
        grown, out = grow(colony, dt, **grow_options)
        accept = turning_reach(out.result.cells, dt) <= reach_limit
        if accept and limit > 0:
            # out.max_overlap is the overlap of the state the step starts from.
            accept = largest_overlap(grown.cells, grow_options.get("planes", ())) <= max(limit, out.max_overlap)
        if attempt == halvings or accept:
            return StepOutcome(grown, out, dt, attempt)
        dt /= 2.0
    raise AssertionError("unreachable")


def turning_reach(cells: Cells, dt: float) -> float:
    """Largest distance a cell tip moves by the cell's turning alone in ``dt``:
    ``max |ω| (l/2 + ρ) dt`` [length]."""
    speed = np.linalg.norm(cells.angular_velocities, axis=1) * (cells.lengths / 2 + cells.radii)
    return float(speed.max(initial=0.0)) * dt


def step_function(settings: Settings, extra: dict[str, np.ndarray], comm: Any = None,
                  planes: Sequence[Plane] | None = None) -> StepFunction:
    """The function :func:`run_colony` advances the colony with, once per step:
    ``take_step(colony, dt, drive=drive) -> StepOutcome`` (the colony after the step, whose
    cells divided before it; the step's result; the step taken; the rejected attempts).

    ``extra`` is the run's extra state: saved in every snapshot (its "extra arrays") and restored
    from the snapshot a run resumes from, so that a step function can carry data from step to
    step exactly across an interruption (e.g. a solver's warm start). Replace its arrays, do not
    change them in place: an interrupted step's changes are undone by restoring the mapping.
    The velocity-level step with retries (:func:`grow_with_retries`) keeps none; the position
    step (:func:`position_step_function`) keeps its contact impulses (``warm.*``). ``comm``: the
    MPI processes the position step is shared among (:func:`~qpcontact.timestep.position_step`).
    ``planes``: the walls of the run (None: :meth:`Settings.planes`, the substrate in 3D).
    """
    if settings.run.step == "position":
        return position_step_function(settings, extra, comm, planes)
    options = settings.step_options()
    if planes is not None:
        options["planes"] = list(planes)
    return partial(grow_with_retries, settings=settings, **options)


#: The extra arrays of the position step's warm start (:class:`~qpcontact.timestep.ContactImpulses`).
WARM_ARRAYS = ("a", "b", "kind", "impulse")


#: The extra arrays of the position step's predictor (:class:`~qpcontact.timestep.CellMotion`).
MOTION_ARRAYS = ("ids", "velocity", "turning")


def position_step_function(settings: Settings, extra: dict[str, np.ndarray], comm: Any = None,
                           planes: Sequence[Plane] | None = None) -> StepFunction:
    """The position-level step of a run (:func:`qpcontact.colony.grow_position`): the substrate
    in 3D, the planar unknowns in 2D, the contact impulses and the cells' motion of each step kept
    in ``extra`` as the next one's warm start and predictor (and so restored on resume). A step that
    does not reach the overlap tolerance, or whose cells would move so far that the contact search
    finds more candidate pairs than it allows (:class:`~qpcontact.errors.TooManyContactsError`), is
    retried with half the step, up to ``run.max_halvings`` times; the last failure is raised, never
    applied.

    The state a step ends in keeps the overlap tolerance unless overlap present at its start
    exceeded what ``relaxation`` clears in one step (a division's axis noise turning a daughter
    into a neighbour by more than 0.05 of a diameter, or a state from elsewhere): such a step is
    taken once more with the relaxation raised to that start overlap, so that it clears it
    if that fails, the first step stands and the history shows its overlap."""
    position, halvings = settings.position, settings.run.max_halvings
    planar = settings.run.dimensions == 2
    planes = settings.planes() if planes is None else list(planes)

    def take_step(colony: Colony, dt: float, *, drive: np.ndarray | None = None) -> StepOutcome:
        warm = ContactImpulses(*(extra[f"warm.{name}"] for name in WARM_ARRAYS)) if "warm.a" in extra else None
        motion = CellMotion(*(extra[f"motion.{name}"] for name in MOTION_ARRAYS)) if "motion.ids" in extra else None
        for attempt in range(halvings + 1):
            try:
                grown, out = grow_position(colony, dt, drive=drive, planes=planes, planar=True if planar else None,
                                           settings=position, warm=warm, motion=motion, comm=comm)
            except (StepFailedError, TooManyContactsError):
                if attempt == halvings:
                    raise
                dt /= 2.0
                continue
            if out.max_overlap > position.overlap_tolerance and out.start_overlap > position.relaxation:
                clearing = replace(position, relaxation=out.start_overlap)
                try:
                    grown, out = grow_position(colony, dt, drive=drive, planes=planes,
                                               planar=True if planar else None, settings=clearing, warm=warm,
                                               motion=motion, comm=comm)
                except StepFailedError:
                    pass  # the first answer stands: converged, only above the bound
            extra.update({f"warm.{name}": getattr(out.warm, name) for name in WARM_ARRAYS})
            extra.update({f"motion.{name}": getattr(out.motion, name) for name in MOTION_ARRAYS})
            return StepOutcome(grown, out, dt, attempt)
        raise AssertionError("unreachable")

    return take_step


def flags_to_try(settings: Settings) -> str:
    """What to change when a run's step fails, as the flags of ``qpcontact simulate`` (and TOML
    keys) with their current values: the end of a failed run's message."""
    run = settings.run
    smaller = (f"--growth-per-step {settings.growth_per_step() / 2:g}" if settings.time_step_rule() == "growth"
               else f"--max-dt {run.max_dt / 2:g}")
    if run.step == "position":
        p = settings.position
        return (f"To try: smaller steps ({smaller}, or --max-halvings {run.max_halvings + 2}: each failed step "
                f"is retried with half the step that many times), more linearizations (--position-max-iterations "
                f"{2 * p.max_iterations}), a looser --position-tolerance (now {p.tolerance:g}) or "
                f"--position-overlap-tolerance (now {p.overlap_tolerance:g}), or another --position-solver (now "
                f"{p.solver}: {'mprgp or clarabel' if p.solver == 'ipm' else 'ipm'}); continue with --resume")
    v = settings.velocity
    return (f"To try: smaller steps ({smaller}), a looser --velocity-tolerance (now {v.tolerance:g}), or another "
            f"--velocity-solver (now {v.solver}); continue with --resume")


def sink_drive(settings: Settings, colony: Colony) -> np.ndarray | None:
    """The drive of the model's sinking in 3D (every free cell pushed down at ``sink_speed``
    towards the substrate), or None (2D, or no sinking): what every step of a run adds."""
    if settings.run.dimensions == 2 or not settings.model.sink_speed:
        return None
    return push(colony, [0.0, 0.0, -settings.model.sink_speed])


def step_mechanics(outcome: StepOutcome, settings: Settings) -> CellMechanics:
    """The pressure and stress of the cells at the end of a step (``outcome.colony``, the state
    a run saves) from the step's contact forces (:mod:`qpcontact.timestep.mechanics`; 2D stress and
    pressure for ``dimensions`` 2).

    The position step's forces are its ``contact_forces``. The velocity step's contact impulses
    are read as forces the same way (overdamped, a cell moves by ``dt·W·(drive + impulses)``;
    inertial, the impulse over the step ``/dt``); its contacts are those of the start of the step
    and its impulses include the push that clears overlap (position correction)."""
    out, planar, cells = outcome.result, settings.run.dimensions == 2, outcome.colony.cells
    if isinstance(out, PositionStepResult):
        return CellMechanics.of(cells, out.contacts, out.contact_forces, planar=planar)
    contacts, impulses = out.result.contacts, out.result.contact_impulses
    inertial = settings.velocity.dynamics == "inertial"
    forces = np.zeros(len(contacts)) if impulses is None else impulses / (outcome.dt if inertial else 1.0)
    return CellMechanics.of(cells, contacts, forces, planar=planar)


def pressure_growth_of(settings: Settings) -> PressureGrowth | None:
    """The run's pressure-dependent growth from its settings (``model.pressure_growth``, the law,
    and ``model.stall_pressure``), None when it is ``"off"``."""
    model = settings.model
    return None if model.pressure_growth == "off" else PressureGrowth(model.pressure_growth, model.stall_pressure)
