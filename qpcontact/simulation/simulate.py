"""``qpcontact simulate``: grow a colony from one cell, save snapshots and draw pictures.

Settings: :class:`qpcontact.colony.settings.Settings`, one table per concern (``[model]``,
``[run]``, ``[output]``, ``[position]``, ``[velocity]``), each setting described once with its
unit; the flags, ``config.toml`` and ``--config`` are generated from them, and merged in one
place (:func:`qpcontact.colony.settings.merge`: defaults, the snapshot of ``--start``/``--resume``,
``--config``, the flags). Every setting is checked before the output folder is made: a flag that
does not apply to the run (a velocity-step setting with the default position step, ``--cfl`` with
the growth time step, ``--sink-speed`` in 2D) or a continued run's change of its dimensions or
step is exit status 2 and one line saying why.

Units: lengths in µm, time in doubling times (the time a cell's cylinder length takes to double at
the default rate ln 2; a free cell divides every 1.27 of them: :mod:`qpcontact.colony.settings`),
masses in units of volume. Every step: the model hook, if any (:mod:`qpcontact.colony.hooks`), then
:func:`qpcontact.colony.divide` (every cell that reached its division length), then the run's step
function (:func:`step_function`), whose contact solve clears the overlap the daughters' axis noise
made: every state a run saves or returns is the end of a step, within its overlap tolerance. Two
steps (``--step``):

- ``position`` (default): :func:`qpcontact.colony.grow_position`, non-penetration at the end of
  the step (:mod:`qpcontact.colony.position`; settings ``--position-*``), with a time step set by
  growth (:func:`qpcontact.colony.growth_time_step`: the fastest cell grows ``--growth-per-step``
  of its length); a step that does not reach the overlap tolerance is retried with half the step;
- ``velocity`` (the earlier default, kept for comparison; settings ``--velocity-*``):
  :func:`qpcontact.colony.grow`, contacts stop approaching at the start of the step, with a time
  step that follows the colony's expansion (:func:`qpcontact.colony.expansion_time_step`), and a
  step that turns some cell too fast (or, with ``--velocity-overlap-limit``, leaves too large an
  overlap) is retried with half the step (:func:`grow_with_retries`).

Outputs in ``--out`` (default ``./simulate-out``), checked before the run starts
(:class:`qpcontact.colony.runs.RunFolder`):

- ``config.toml``: the settings that apply to the run, by table (``--config`` reads such a file);
- ``snapshots/step_NNNNNN.npz``: colony snapshots (format: :mod:`qpcontact.colony.snapshots`),
  every ``--snapshot-every`` steps and the last state, written atomically, each with all the
  settings, enough to continue the run exactly (``--resume``);
- ``history.csv``: one row per step, appended as the step completes (time, dt, cells, contacts,
  largest/mean overlap as a fraction of the diameter, solver seconds, step seconds, the velocity
  step's solver residuals, linearizations, the mean and largest cell pressure);
- ``colony.png`` (cells coloured by orientation, or by pressure with ``--color pressure``; a side
  view too in 3D), ``history.png`` (cell count, overlap, solver time, and the solver residuals or
  the linearizations per step, against time), titled with the step, solver and tolerance that
  ran (and the pressure-dependent growth, if on); in 2D ``pressure.png`` (the radial pressure
  profile); with ``--gif`` an animation ``colony.gif``, with ``--vtk`` ParaView files
  (``colony.pvd``, ``vtk/step_NNNNNN.vtu``).

Every snapshot (and ParaView file) carries each cell's pressure and stress over the step that
led to it (:mod:`qpcontact.colony.mechanics`; :func:`step_mechanics`), from the contact forces
of the step: in 2D per footprint area [force/µm], in 3D per volume [force/µm²], where the force
unit is the drive's (mass·µm/doubling time, masses = volumes in µm³: a free cell of volume V
driven by a force f moves at f/V µm per doubling time). With ``--pressure-growth linear`` or
``exponential`` each cell's growth rate is slowed by its pressure of the step before
(:class:`~qpcontact.colony.PressureGrowth`, ``--stall-pressure``).

A step whose contact solve fails is never applied: the run stops there, says why, saves what
it has and exits with status 1. Ctrl-C (or SIGTERM) stops the run cleanly: the state reached,
the history and the pictures are saved, and ``--resume`` continues it (exit status 128 + the
signal's number: 130 for SIGINT, 143 for SIGTERM). A run that stops at ``--max-steps`` short of
``--cells`` says so and exits with status 3 (:data:`EXIT_SHORT`); a target it can never reach
(rate 0 without a hook) is refused before it starts (:func:`check_target`).

Under ``mpiexec -n P`` (the distributed stack: ``scripts/install-mpi``), one colony grows over P
processes: contact detection is shared by region and the contact solve is split among them
(solver ``ipm-petsc``), process 0 writes; :mod:`qpcontact.simulation.ranks`, docs/distributed.md.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import time
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from functools import partial
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..arguments import output_folder, run_standalone
from ..colony.growth import Colony, daughters_share, divide, grow, grow_position
from ..colony.hooks import Hook, apply_hook, load_hook, push
from ..described import Layer, settings_of, show
from ..errors import InvalidArgumentError, ModelHookError, SolverFailedError, StepFailedError
from ..geometry import Cells, capsule_volume
from ..io.runs import HISTORY_FIELDS, Interrupt, RunFolder, is_inside, latest_snapshot, read_toml
from ..io.snapshots import Snapshot, load_snapshot
from ..timestep.mechanics import CellMechanics, PressureGrowth
from ..timestep.position import CellMotion, ContactImpulses, PositionStepResult
from ..timestep.step import StepResult, largest_overlap
from .ranks import CollectiveInterrupt, distributed_settings, processes
from .settings import (
    COLORS,
    Settings,
    add_setting_flags,
    check_continuation,
    file_layer,
    flag_layer,
    merge,
    refuse_unused,
    stored_values,
)

__all__ = ["HISTORY_FIELDS", "Run", "Settings", "StepOutcome", "founder", "grow_with_retries", "run_colony",
           "pressure_growth_of", "step_function", "step_mechanics", "turning_reach"]


# (The functional form keeps the field types real types, not strings, for the API reference.)
StepOutcome = NamedTuple("StepOutcome", [("colony", Colony), ("result", StepResult | PositionStepResult),  # noqa: UP014
                                         ("dt", float), ("rejected", int)])
StepOutcome.__doc__ = """What a run's step function returns (:func:`step_function`).

Attributes:
    colony: the colony after the step (:func:`run_colony` divides cells before the step).
    result: the step's :class:`~qpcontact.colony.StepResult` (velocity-level: its ``result`` —
        the :class:`qpcontact.Result` of the contact solve, with ``contacts``, ``times`` and
        ``errors`` — and ``max_overlap``, ``mean_overlap`` fill the history) or
        :class:`~qpcontact.colony.PositionStepResult` (position-level).
    dt: the time step taken [doubling times].
    rejected: attempts rejected and retried with half the step.
"""


#: A run's step function: ``take_step(colony, dt, *, drive) -> StepOutcome``.
StepFunction = Callable[..., StepOutcome]


@dataclass
class Run:
    """The outcome of :func:`run_colony`.

    Attributes:
        colony: the state reached.
        history: this call's rows by column (:data:`HISTORY_FIELDS`).
        wall_seconds: wall-clock time of the loop.
        steps: the step index reached (steps from the founder, earlier runs included).
        error: why the run stopped early ("" if it did not fail).
        frames: ``(time, cells)`` frames for an animation.
        first_step: the step index this call started from.
        interrupted: the signal that stopped the run (``signal.SIGINT`` for Ctrl-C), or None.
        exception: the exception behind ``error``, if any (a model hook's has its traceback).
        mechanics: the pressure and stress of ``colony``'s cells over the last step
            (:func:`step_mechanics`).
    """

    colony: Colony
    history: dict[str, list[float]]
    wall_seconds: float
    steps: int
    error: str = ""
    frames: list[tuple[float, Cells]] = field(default_factory=list)
    first_step: int = 0
    interrupted: int | None = None
    exception: BaseException | None = None
    mechanics: CellMechanics | None = None


def founder(settings: Settings) -> Colony:
    """One cell at the origin along x (on the substrate in 3D), half the division length long,
    of mass = its volume and growth inertia ``growth_inertia_ratio`` × that, of type 0 growing at
    ``rate`` (or at ``type_rates[0]`` when given)."""
    model = settings.model
    z = model.radius if settings.run.dimensions == 3 else 0.0
    volume = capsule_volume(model.division_length / 2, model.radius)
    cell = Cells(centers=[[0.0, 0.0, z]], axes=[[1.0, 0.0, 0.0]], lengths=model.division_length / 2,
                 radii=model.radius, masses=volume, growth_inertia=model.growth_inertia_ratio * volume)
    return Colony.founder(cell, model.type_rates[0] if model.type_rates else model.rate)


def check_types(settings: Settings, colony: Colony) -> None:
    """Refuse a start whose cells have types that ``model.type_rates`` gives no rate for (they
    would stop the run at their first division).

    Raises:
        InvalidArgumentError: naming the largest type and the number of rates.
    """
    rates, largest = settings.model.type_rates, int(colony.cell_types.max(initial=0))
    if rates and largest >= len(rates):
        raise InvalidArgumentError(f"type_rates: gives {len(rates)} rates (types 0 to {len(rates) - 1}), but the "
                                   f"colony has cells of type {largest}: give a rate for every type")


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


def step_function(settings: Settings, extra: dict[str, np.ndarray], comm: Any = None) -> StepFunction:
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
    """
    if settings.run.step == "position":
        return position_step_function(settings, extra, comm)
    return partial(grow_with_retries, settings=settings, **settings.step_options())


#: The extra arrays of the position step's warm start (:class:`~qpcontact.colony.ContactImpulses`).
WARM_ARRAYS = ("a", "b", "kind", "impulse")
#: The extra arrays of the position step's predictor (:class:`~qpcontact.colony.CellMotion`).
MOTION_ARRAYS = ("ids", "velocity", "turning")


def position_step_function(settings: Settings, extra: dict[str, np.ndarray], comm: Any = None) -> StepFunction:
    """The position-level step of a run (:func:`qpcontact.colony.grow_position`): the substrate
    in 3D, the planar unknowns in 2D, the contact impulses and the cells' motion of each step kept
    in ``extra`` as the next one's warm start and predictor (and so restored on resume). A step that
    does not reach the overlap tolerance is retried with half the step, up to ``run.max_halvings``
    times; the last failure is raised (:class:`~qpcontact.errors.StepFailedError`), never applied.

    The state a step ends in keeps the overlap tolerance unless overlap present at its start
    exceeded what ``relaxation`` clears in one step (a division's axis noise turning a daughter
    into a neighbour by more than 0.05 of a diameter, or a state from elsewhere): such a step is
    taken once more with the relaxation raised to that start overlap, so that it clears it
    (turning still bounded by ``turn_limit``); if that fails, the first step stands and the
    history shows its overlap."""
    position, halvings = settings.position, settings.run.max_halvings
    planar = settings.run.dimensions == 2
    planes = settings.planes()

    def take_step(colony: Colony, dt: float, *, drive: np.ndarray | None = None) -> StepOutcome:
        warm = ContactImpulses(*(extra[f"warm.{name}"] for name in WARM_ARRAYS)) if "warm.a" in extra else None
        motion = CellMotion(*(extra[f"motion.{name}"] for name in MOTION_ARRAYS)) if "motion.ids" in extra else None
        for attempt in range(halvings + 1):
            try:
                grown, out = grow_position(colony, dt, drive=drive, planes=planes, planar=True if planar else None,
                                           settings=position, warm=warm, motion=motion, comm=comm)
            except StepFailedError:
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


#: Exit status of ``qpcontact simulate`` for a run that stopped at ``--max-steps`` short of its
#: ``--cells`` target (1: the run failed; 2: it could not start; 128 + N: stopped by signal N).
EXIT_SHORT = 3


def most_cells(settings: Settings, colony: Colony) -> float:
    """The most cells a run from ``colony`` can reach without a model hook: no limit when
    newborn cells grow (``rate > 0``); at rate 0 every cell growing now divides at most once,
    since its daughters are born at rate 0 (pressure-dependent growth only slows it)."""
    if settings.model.rate > 0:
        return math.inf
    return colony.cells.n + int(np.count_nonzero(colony.rates > 0))


def check_target(settings: Settings, colony: Colony, hook: Any) -> None:
    """Refuse a ``cells`` target that a run from ``colony`` can never reach (:func:`most_cells`),
    before it starts: it would run ``max_steps`` steps of a colony that does not grow. A model
    hook may set growth rates, so with one nothing is refused.

    Raises:
        InvalidArgumentError: naming the target, the rate and what to change.
    """
    if hook:
        return
    most = most_cells(settings, colony)
    if settings.run.cells > most:
        raise InvalidArgumentError(
            f"cells: the target of {settings.run.cells} cells can never be reached at rate {settings.model.rate:g} "
            f"(cells born now do not grow: at most {int(most)} cell{'s' if most > 1 else ''} from this start); give a rate > 0, or a model "
            "hook that sets growth rates")


def flags_to_try(settings: Settings) -> str:
    """What to change when a run's step fails, as the flags of ``qpcontact simulate`` (and TOML
    keys) with their current values: the end of a failed run's message."""
    run = settings.run
    smaller = (f"--growth-per-step {run.growth_per_step / 2:g}" if settings.time_step_rule() == "growth"
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


def initial_state(settings: Settings, start: Colony | Snapshot | None) -> tuple[Colony, int, np.random.Generator,
                                                                                   dict[str, np.ndarray]]:
    """``(colony, step index, random generator, extra state)`` a run starts from: the founder,
    a given colony (step 0), or a snapshot (its step, generator and extra arrays; a snapshot
    without a generator state gets the seed's)."""
    if start is None or isinstance(start, Colony):
        return founder(settings) if start is None else start, 0, np.random.default_rng(settings.run.seed), {}
    rng = start.generator() or np.random.default_rng(settings.run.seed)
    return start.colony, max(start.step, 0), rng, dict(start.extra)


def history_row(step: int, colony: Colony, outcome: StepOutcome, seconds: float,
                mechanics: CellMechanics | None = None) -> dict[str, Any]:
    """One row of the history (:data:`HISTORY_FIELDS`): the step's index, the state after it and
    what the step did. ``max_overlap``/``mean_overlap``: the velocity-level step's are those of
    the state it starts from; the position step's those of the state it ends in.
    ``penetration``/``complementarity``: the velocity step's solver residuals (scaled,
    dimensionless); the position step checks the true distances at the end of the step instead
    (``max_overlap``), so they are not measured there (NaN), and ``linearizations`` says how many
    solves it took. ``mean_pressure``/``max_pressure``: over the cells of the end of the step
    (the state after it: cells divide at the start of a step), from ``mechanics``
    (:func:`step_mechanics`; NaN without)."""
    out = outcome.result
    pressure = np.array([np.nan]) if mechanics is None else mechanics.pressure
    if pressure.size == 0:  # no cells
        pressure = np.zeros(1)
    common = dict(step=step, time=colony.time, dt=outcome.dt, cells=colony.cells.n, step_seconds=seconds,
                  rejected=outcome.rejected, mean_pressure=float(pressure.mean()), max_pressure=float(pressure.max()))
    if isinstance(out, PositionStepResult):
        overlapping = -out.contacts.separation[out.contacts.separation < 0]
        diameter = 2.0 * float(np.median(colony.cells.radii))
        return dict(common, contacts=len(out.contacts), max_overlap=out.max_overlap,
                    mean_overlap=float(overlapping.mean()) / diameter if overlapping.size else 0.0,
                    solve_seconds=out.times["solve"], penetration=np.nan, complementarity=np.nan,
                    linearizations=out.iterations)
    result = out.result
    return dict(common, contacts=len(result.contacts), max_overlap=out.max_overlap, mean_overlap=out.mean_overlap,
                solve_seconds=result.times["setup"] + result.times["solve"],
                penetration=result.errors.get("penetration", 0.0),
                complementarity=result.errors.get("complementarity", np.nan), linearizations=1)


def step_mechanics(outcome: StepOutcome, settings: Settings) -> CellMechanics:
    """The pressure and stress of the cells at the end of a step (``outcome.colony``, the state
    a run saves) from the step's contact forces (:mod:`qpcontact.colony.mechanics`; 2D stress and
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


def run_colony(settings: Settings, *, start: Colony | Snapshot | None = None, progress: bool = True,
               folder: RunFolder | None = None, frame_growth: float = 0.0, hook: Hook | None = None,
               pressure_growth: PressureGrowth | None = None, comm: Any = None) -> Run:
    """Grow a colony until it has ``settings.run.cells`` cells (or reaches step
    ``settings.run.max_steps``).

    Args:
        settings: the run's parameters.
        start: the colony to start from (default: :func:`founder`), or a snapshot
            (:func:`qpcontact.colony.snapshots.load_snapshot`) to continue: its step index,
            random-generator state and extra arrays are taken over, so that the run follows the
            trajectory of the run that saved it.
        progress: show a tqdm progress bar (cells reached out of the target).
        folder: where the run writes (:class:`~qpcontact.colony.runs.RunFolder`: history rows as
            they come; a snapshot every ``settings.output.snapshot_every`` steps and of the last
            state, always, also after a failure or an interruption; ParaView files); None:
            nothing is written.
        frame_growth: keep a frame for an animation whenever the cell count has grown by this
            factor since the last frame (0: no frames).
        hook: a model hook (:mod:`qpcontact.colony.hooks`); default: that of the file
            ``settings.model.hook``.
        pressure_growth: growth slowed by each cell's pressure of the step before
            (:class:`~qpcontact.colony.PressureGrowth`; a daughter born at the start of a step
            feels her mother's), applied after the hook and the division; default: that of
            ``settings.model.pressure_growth`` and ``settings.model.stall_pressure``
            (:func:`pressure_growth_of`), None when it is ``"off"`` (the run is then what it was
            without pressure-dependent growth, bit for bit).
        comm: the MPI processes this run is split over (mpi4py communicator; every process calls
            with the same arguments, the position solver ``ipm-petsc``, and only one of them
            with a ``folder``: :mod:`qpcontact.simulation.ranks`); None: one process.

    Returns:
        A :class:`Run`. A failed contact solve, a step that cannot be taken (a cell compressed
        to a negative length) or a failing model hook ends the run early with ``error`` set
        (that step is not applied); SIGINT (Ctrl-C) or SIGTERM end it with ``interrupted`` set
        (:class:`~qpcontact.colony.runs.Interrupt`).
    """
    from tqdm import tqdm  # the progress bar: only when a colony is run

    state = start_run(settings, start, frame_growth)
    if hook is None and settings.model.hook:
        hook = load_hook(settings.model.hook)
    check_target(settings, state.colony, hook)
    take_step = step_function(settings, state.extra, comm)  # the run's one step function (swap it here)
    if pressure_growth is None:
        pressure_growth = pressure_growth_of(settings)
    bar = tqdm(total=settings.run.cells, initial=state.colony.cells.n, unit="cell", disable=not progress,
               file=sys.stderr)
    t_start = time.perf_counter()
    with (Interrupt() if comm is None else CollectiveInterrupt(comm)) as interrupt:
        while state.colony.cells.n < settings.run.cells and state.step < settings.run.max_steps \
                and not interrupt.requested:
            t0 = time.perf_counter()
            stepped = attempt_step(state, settings, interrupt, hook, pressure_growth, take_step)
            if stepped is None:
                break
            record_step(state, *stepped, time.perf_counter() - t0, settings, folder, bar, frame_growth)
        bar.close()
        wall = time.perf_counter() - t_start
        save_state(state, settings, folder)  # the state reached, whatever ended the run
    if frame_growth and state.frames[-1][1] is not state.colony.cells:
        state.frames.append((state.colony.time, state.colony.cells))
    return Run(state.colony, state.history, wall, state.step, state.error, state.frames, state.first_step,
               interrupt.signal, state.exception, state.mechanics)


@dataclass
class RunState:
    """A run in progress, what the phases of :func:`run_colony` read and advance.

    Attributes:
        colony: the state reached.
        step: the index of the next step (steps from the founder, earlier runs included).
        rng: the run's random generator (divisions).
        extra: the step function's extra arrays (saved in snapshots; the same dict the step
            function holds).
        mechanics: the cells' pressure and stress over the step that led to ``colony`` (saved
            with it).
        history: this call's rows by column (:data:`HISTORY_FIELDS`).
        frames: ``(time, cells)`` frames for an animation.
        first_step: the step index the call started from.
        saved: the step index of the last snapshot written (-1: none).
        error, exception: why the run stopped early (:func:`attempt_step`).
    """

    colony: Colony
    step: int
    rng: np.random.Generator
    extra: dict[str, np.ndarray]
    mechanics: CellMechanics
    history: dict[str, list[float]]
    frames: list[tuple[float, Cells]]
    first_step: int
    saved: int = -1
    error: str = ""
    exception: BaseException | None = None


def start_run(settings: Settings, start: Colony | Snapshot | None, frame_growth: float) -> RunState:
    """The state a run starts from (:func:`initial_state`), its cell types checked, with the
    stored mechanics of a snapshot (zero for a colony, or a snapshot of the other dimension)."""
    colony, step, rng, extra = initial_state(settings, start)
    check_types(settings, colony)
    planar = settings.run.dimensions == 2
    stored = start.mechanics if isinstance(start, Snapshot) else None
    mechanics = stored if stored is not None and stored.planar == planar else CellMechanics.zero(colony.cells.n, planar)
    return RunState(colony, step, rng, extra, mechanics, {name: [] for name in HISTORY_FIELDS},
                    [(colony.time, colony.cells)] if frame_growth else [], first_step=step)


def save_state(state: RunState, settings: Settings, folder: RunFolder | None) -> None:
    """A snapshot of the state reached into ``folder`` (once per step index)."""
    if folder is not None and state.saved != state.step:
        folder.save_snapshot(state.colony, state.step, settings=settings.to_tables(), rng=state.rng, extra=state.extra,
                             mechanics=state.mechanics)
        state.saved = state.step


def sink_drive(settings: Settings, colony: Colony) -> np.ndarray | None:
    """The drive of the model's sinking in 3D (every free cell pushed down at ``sink_speed``
    towards the substrate), or None (2D, or no sinking): what every step of a run adds."""
    if settings.run.dimensions == 2 or not settings.model.sink_speed:
        return None
    return push(colony, [0.0, 0.0, -settings.model.sink_speed])


def prepare_step(state: RunState, settings: Settings, hook: Hook | None,
                 pressure_growth: PressureGrowth | None) -> tuple[Colony, Colony, float, np.ndarray | None]:
    """What the next step starts from: the model hook's control, the division, the rates slowed
    by pressure, the time step and the drive. ``(divided, stepping, dt, drive)``: ``stepping``
    is ``divided`` with this step's rates (the colony keeps its own)."""
    colony, mechanics, model, planar = state.colony, state.mechanics, settings.model, settings.run.dimensions == 2
    control = apply_hook(hook, colony, state.step, mechanics)
    current = colony if control.colony is None else control.colony
    # Division first, so that the overlap its axis noise makes is cleared by this
    # step's contact solve: every state the run saves or returns is one a step
    # ended in (issue 19: dividing after the step left 0.047 of a diameter in the
    # snapshots of a run whose steps keep 0.01).
    divided = divide(current, model.division_length if control.division_length is None
                     else control.division_length, state.rng, axis_noise=model.axis_noise,
                     rate_noise=model.rate_noise, base_rate=model.rate, planar=planar,
                     type_rates=model.type_rates or None)
    stepping = divided
    if pressure_growth is not None:  # slowed for this step only: the colony keeps its rates
        felt = mechanics if current is colony else mechanics.carried_over(colony, current)
        if divided is not current:  # a daughter feels her mother's pressure
            felt = felt.carried_over(current, divided)
        stepping = divided.replace(rates=pressure_growth.rates(divided, felt))
    dt = settings.time_step_of(stepping)
    drive = sink_drive(settings, divided)
    if control.drive is not None:
        shared = daughters_share(control.drive, current, divided)
        drive = shared if drive is None else drive + shared
    return divided, stepping, dt, drive


def take_one_step(state: RunState, settings: Settings, hook: Hook | None, pressure_growth: PressureGrowth | None,
                  take_step: StepFunction) -> tuple[StepOutcome, CellMechanics]:
    """The next step (:func:`prepare_step`, then the step function): its outcome, with the
    colony's own rates, and the mechanics of the state it ends in (:func:`step_mechanics`)."""
    divided, stepping, dt, drive = prepare_step(state, settings, hook, pressure_growth)
    outcome = take_step(stepping, dt, drive=drive)
    if stepping is not divided:
        outcome = outcome._replace(colony=outcome.colony.replace(rates=divided.rates))
    return outcome, step_mechanics(outcome, settings)


def attempt_step(state: RunState, settings: Settings, interrupt: Interrupt, hook: Hook | None,
                 pressure_growth: PressureGrowth | None,
                 take_step: StepFunction) -> tuple[StepOutcome, CellMechanics] | None:
    """:func:`take_one_step`, or None when the run ends here with nothing of the step applied:
    a signal (the random generator and the extra arrays put back as they were), or a failing
    model hook, contact solve or step (``state.error`` and ``state.exception`` set)."""
    where = f"step {state.step} (t = {state.colony.time:.4g}, {state.colony.cells.n} cells)"
    rng_state, extra_before = state.rng.bit_generator.state, dict(state.extra)
    try:
        with interrupt.armed():  # a signal now abandons the step: nothing of it is applied
            return take_one_step(state, settings, hook, pressure_growth, take_step)
    except KeyboardInterrupt:
        state.rng.bit_generator.state = rng_state
        state.extra.clear()
        state.extra.update(extra_before)
        interrupt.signal = interrupt.signal or signal.SIGINT  # Python's own (outside the main thread)
    except ModelHookError as exc:
        state.error, state.exception = f"{where}: {exc}", exc
    except SolverFailedError as exc:
        state.error, state.exception = f"{where}: contact solve failed, not applied: {exc}. {flags_to_try(settings)}", exc
    except InvalidArgumentError as exc:  # e.g. contacts compressed a cell to a negative length
        state.error, state.exception = f"{where}: step not applied: {exc}", exc
    return None


def record_step(state: RunState, outcome: StepOutcome, mechanics: CellMechanics, seconds: float, settings: Settings,
                folder: RunFolder | None, bar: Any, frame_growth: float) -> None:
    """A step taken: the state advanced, its history row kept (and appended to ``folder``), the
    progress bar, a snapshot every ``snapshot_every`` steps, a frame when the colony has grown
    by ``frame_growth``."""
    state.colony, state.mechanics = outcome.colony, mechanics
    row = history_row(state.step, state.colony, outcome, seconds, mechanics)
    for name in HISTORY_FIELDS:
        state.history[name].append(row[name])
    if folder is not None:
        folder.append_history(row)
    state.step += 1
    bar.update(state.colony.cells.n - bar.n)
    bar.set_postfix(t=f"{state.colony.time:.2f}", overlap=f"{outcome.result.max_overlap:.3f}", refresh=False)
    snapshot_every = settings.output.snapshot_every
    if snapshot_every and state.step % snapshot_every == 0:
        save_state(state, settings, folder)
    if frame_growth and state.colony.cells.n >= frame_growth * state.frames[-1][1].n:
        state.frames.append((state.colony.time, state.colony.cells))


# ------------------------------------------------------------------------------------------
# Command line
# ------------------------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``qpcontact simulate``: where the run starts and writes, then a flag per
    setting (:func:`qpcontact.colony.settings.add_setting_flags`)."""
    parser.description = (
        "Grow a colony from one cell (or from a snapshot), with snapshots, history, pictures and, with --vtk, ParaView "
        "files.\n\nUnits: lengths in µm, time in doubling times (the time a cell's cylinder length takes to double at "
        "the default rate ln 2; a cell growing freely divides every 1.27 of them). Settings come from (later wins): "
        "the defaults, the snapshot of --start/--resume, --config, the flags; every one is checked before the run "
        "starts, and a flag that does not apply to the run (e.g. a --velocity-* flag with the default position step) "
        "is refused.\nCtrl-C stops cleanly: the state, history and pictures are saved; --resume continues.")
    group = parser.add_argument_group("start and output folder")
    group.add_argument("--config", type=Path, metavar="FILE",
                       help="read settings from a TOML file with the tables of the config.toml a run saves ([model], "
                            "[run], [output], [position], [velocity]; the flat files of earlier versions too); paths "
                            "in it are relative to its folder; flags override it")
    start = group.add_mutually_exclusive_group()
    start.add_argument("--start", type=Path, metavar="SNAPSHOT",
                       help="start from this snapshot (.npz): its state, step index, random state and settings. A "
                            "snapshot of --out's own run continues that run (history appended)")
    start.add_argument("--resume", action="store_true", help="continue the run in --out from its latest snapshot")
    group.add_argument("--out", type=output_folder, default=Path("simulate-out"), metavar="FOLDER",
                       help="output folder (default: ./simulate-out); checked before the run starts")
    group.add_argument("--overwrite", action="store_true",
                       help="replace the run already in --out (its files are removed first; default: refuse); with "
                            "--start/--resume of an earlier snapshot of --out, drop the later ones")
    group.add_argument("--quiet", action="store_true", help="no progress bar")
    add_setting_flags(parser, " (a table of --config and config.toml)")


def settings_layers(args: argparse.Namespace, snapshot: Snapshot | None, in_place: bool) -> list[Layer]:
    """The sources of the run's settings, in order: the snapshot's settings, ``--config``, the
    flags. (A snapshot of an earlier version carries no output settings: a run continued in
    its own folder takes them from its ``config.toml``.)"""
    layers = []
    if snapshot is not None and snapshot.settings is not None:
        source = f"{snapshot.path} (settings)"
        state = stored_values(snapshot.settings, source)
        earlier = args.out / "config.toml"
        if in_place and not any(path.startswith("output.") for path in state) and earlier.exists():
            state.update({p: v for p, v in stored_values(read_toml(earlier), str(earlier)).items()
                          if p.startswith("output.")})
        layers.append(Layer(source, state, "state"))
    if args.config is not None:
        layers.append(file_layer(args.config))
    layers.append(flag_layer(args))
    return layers


def configure(args: argparse.Namespace, snapshot: Snapshot | None, in_place: bool) -> Settings:
    """The run's settings (:func:`qpcontact.colony.settings.merge` of :func:`settings_layers`),
    with every check that needs the whole run: given settings that do not apply refused, and
    the changes a continued run cannot take."""
    layers = settings_layers(args, snapshot, in_place)
    settings = merge(layers)
    refuse_unused([settings], layers)
    if snapshot is not None and snapshot.settings is not None:
        check_continuation(merge(layers[:1]), layers[1:], in_place=in_place,
                           has_generator=snapshot.rng_state is not None)
    return settings


def open_run(args: argparse.Namespace, comm: Any = None) -> tuple[Settings, Snapshot | None, RunFolder | None, str]:
    """Read the start, settle the settings and open the output folder: every check a run needs
    before it starts (so that nothing fails at its end). Over MPI processes (``comm``), every
    process reads the start and settles the settings (:func:`~.ranks.distributed_settings`, whose
    note is returned), then process 0 alone opens the folder (the others get None)."""
    path = latest_snapshot(args.out) if args.resume else args.start
    snapshot = None if path is None else load_snapshot(path)
    in_place = snapshot is not None and is_inside(Path(path), args.out)
    settings = configure(args, snapshot, in_place)
    if snapshot is not None:
        check_types(settings, snapshot.colony)
    if settings.output.vtk:
        from ..io.paraview import _meshio

        _meshio()  # a named error now if meshio is missing
    if settings.model.hook:
        load_hook(settings.model.hook)
    check_target(settings, initial_state(settings, snapshot)[0], settings.model.hook)
    note = ""
    if comm is not None:
        settings, note = distributed_settings(settings, comm)
        comm.Barrier()  # every process has read the start before process 0 opens the folder
        if comm.Get_rank() != 0:
            if not comm.bcast(None, root=0):
                raise InvalidArgumentError("process 0 could not open the output folder (its message says why)")
            return settings, snapshot, None, note
    folder = None
    try:
        if snapshot is not None and in_place:
            folder = RunFolder.resume(args.out, snapshot, overwrite=args.overwrite, vtk=settings.output.vtk)
        else:
            folder = RunFolder.create(args.out, overwrite=args.overwrite, vtk=settings.output.vtk,
                                      first_step=0 if snapshot is None else max(snapshot.step, 0))
    finally:
        if comm is not None:  # the other processes wait for it (and stop if it failed)
            comm.bcast(folder is not None, root=0)
    return settings, snapshot, folder, note


def describe_changes(before: Mapping[str, Any] | None, after: Settings) -> str:
    """The settings that differ from a snapshot's, as ``name: old -> new`` ("" if none)."""
    if before is None:
        return ""
    old = merge([Layer("snapshot", stored_values(before, "snapshot"), "state")])
    changed = []
    for s in settings_of(Settings):
        was, now = getattr(getattr(old, s.table), s.key), getattr(getattr(after, s.table), s.key)
        if was != now:
            changed.append(f"{s.name}: {show(was)} -> {show(now)}")
    return "; ".join(changed)


def run_command(args: argparse.Namespace) -> int:
    from ..outputs import describe_written

    comm = processes()  # None unless launched on several MPI processes
    try:
        settings, snapshot, folder, note = open_run(args, comm)  # a QPContactError here: exit 2 (run_checked)
    except KeyboardInterrupt:
        print("qpcontact simulate: interrupted before the run started", file=sys.stderr)
        return 130
    if folder is None:  # a process of a distributed run other than the first: it steps, process 0 writes
        return exit_status(run_colony(settings, start=snapshot, progress=False, comm=comm), settings)
    if note:
        print(note, file=sys.stderr)
    folder.write_config(settings.to_tables(applying=True),
                        f"qpcontact simulate settings, {datetime.now(UTC):%Y-%m-%d %H:%M} UTC: those that apply to "
                        "this run (every snapshot holds them all)"
                        + (f"\nstarted from {snapshot.path} (step {snapshot.step})" if snapshot else "")
                        + "\nrun again: qpcontact simulate --config config.toml --out ANOTHER_FOLDER")
    if snapshot is not None:
        changes = describe_changes(snapshot.settings, settings)
        print(f"continuing from {snapshot.path} (step {snapshot.step}, t = {snapshot.colony.time:.4g}, "
              f"{snapshot.colony.cells.n} cells)" + (f"; settings changed: {changes}" if changes else ""), file=sys.stderr)
    result = run_colony(settings, start=snapshot, progress=not args.quiet, folder=folder,
                        frame_growth=1.08 if settings.output.gif else 0.0, comm=comm)
    try:
        if not (result.interrupted and comm is not None):  # mpiexec kills its processes soon after a signal
            draw_pictures(folder, settings, result, gif=settings.output.gif, color=settings.output.color)
    except KeyboardInterrupt:
        print("qpcontact simulate: interrupted while drawing; the snapshot and the history are saved", file=sys.stderr)
        return 130
    history = folder.read_history()
    cycle = settings.model.cycle_time()
    print(f"{result.colony.cells.n} cells at step {result.steps}, t = {result.colony.time:.3f} doubling times "
          f"(= {result.colony.time / cycle:.1f} cycles of a free cell, {cycle:.2f} each); this run: "
          f"{result.steps - result.first_step} steps in {result.wall_seconds:.1f} s; largest overlap "
          f"{max(history['max_overlap'], default=0.0):.4f} of a diameter; {settings.describe_step()}"
          f"{'' if comm is None else f' on {comm.Get_size()} MPI processes'}: contact solve "
          f"{np.sum(result.history['solve_seconds']):.1f} s; {settings.describe_growth()}")
    print(describe_written(folder.written))
    status = exit_status(result, settings)
    if result.interrupted:
        print(f"qpcontact simulate: stopped by signal {result.interrupted} at step {result.steps}; continue with: "
              f"qpcontact simulate --resume --out {folder.path}", file=sys.stderr)
    elif result.error:
        if isinstance(result.exception, ModelHookError) and result.exception.__cause__ is not None:
            traceback.print_exception(result.exception.__cause__, file=sys.stderr)
        print(f"qpcontact simulate: {result.error}", file=sys.stderr)
    elif status == EXIT_SHORT:
        print(f"qpcontact simulate: stopped at step {result.steps} (--max-steps {settings.run.max_steps}) with "
              f"{result.colony.cells.n} of the {settings.run.cells} cells of --cells; continue with: qpcontact simulate "
              f"--resume --max-steps N --out {folder.path} (exit status {EXIT_SHORT})", file=sys.stderr)
    return status


def exit_status(result: Run, settings: Settings) -> int:
    """The exit status of a run: 128 + the signal that stopped it, 1 after an error,
    :data:`EXIT_SHORT` when it stopped short of its cells, else 0."""
    if result.interrupted:
        return 128 + result.interrupted
    if result.error:
        return 1
    return EXIT_SHORT if result.colony.cells.n < settings.run.cells else 0


def describe_run(settings: Settings) -> str:
    """What ran, for the pictures' titles: ``"2D, position step, ipm at tolerance 0.001,
    overlap ≤ 0.01"`` (:meth:`Settings.describe_step`), with the pressure-dependent growth on a
    second line if it is on (:meth:`Settings.describe_growth`)."""
    label = f"{settings.run.dimensions}D, {settings.describe_step()}"
    return label if settings.model.pressure_growth == "off" else f"{label}\n{settings.describe_growth()}"


def colony_picture(path: Path, colony: Colony, mechanics: CellMechanics | None, settings: Settings, color: str,
                   title: str) -> Path:
    """The picture of a colony as a run draws it (``colony.png``): from above, and from the side
    too in 3D, with the run's planes, coloured as ``color`` says
    (:func:`~qpcontact.colony.plots.colony_colors`: orientation, pressure, cell_type, or a
    ``cell_data`` array's name)."""
    from ..io.plots import colony_colors, save_colony_picture

    planar = settings.run.dimensions == 2
    return save_colony_picture(path, colony.cells, title, side_view=not planar, planes=settings.planes(),
                               **colony_colors(color, colony, mechanics, planar))


def draw_pictures(folder: RunFolder, settings: Settings, result: Run, *, gif: bool, color: str = "orientation") -> None:
    """``colony.png`` (and a side view in 3D, :func:`colony_picture`), coloured by the cells'
    orientation or, with ``color="pressure"``, by their pressure of the last step
    (:attr:`Run.mechanics`, with a colour bar in its units), or with ``"cell_type"`` by their
    type; ``history.png`` of the whole run (earlier attempts of a resumed run
    included); in 2D ``pressure.png``, the radial pressure profile
    (:func:`~qpcontact.colony.plots.plot_pressure_profile`); ``colony.gif`` from this run's
    frames. Titled with what ran (:func:`describe_run`).

    Raises:
        InvalidArgumentError: ``color`` is not one of :data:`COLORS`.
    """
    from ..io.plots import animate, plot_history, plot_pressure_profile

    if color not in COLORS:
        raise InvalidArgumentError(f"color: expected one of {', '.join(COLORS)}, got {color!r}")
    label = describe_run(settings)
    cells, planar = result.colony.cells, settings.run.dimensions == 2
    mechanics = result.mechanics or CellMechanics.zero(cells.n, planar)
    when = f"{cells.n} cells at t = {result.colony.time:.2f} doubling times"
    folder.note(colony_picture(folder.path / "colony.png", result.colony, mechanics, settings, color,
                               f"{when} ({label})"))
    if planar and cells.n:
        folder.note(plot_pressure_profile(folder.path / "pressure.png", cells, mechanics.pressure,
                                          f"{when}: pressure over the last step\n{label}"))
    history = folder.read_history()
    if history["step"]:
        folder.note(plot_history(folder.path / "history.png", history, label))
    if gif and len(result.frames) > 1:
        folder.note(animate(folder.path / "colony.gif", result.frames))


def main(argv: list[str] | None = None) -> int:
    return run_standalone("qpcontact simulate", add_arguments, run_command, argv)
