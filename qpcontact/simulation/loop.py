"""The run loop of a colony: :func:`run_colony` grows a colony until it has its cells (or
reaches its last step), as named phases.

Every step: the model hook, if any (:mod:`qpcontact.colony.hooks`), then
:func:`qpcontact.colony.divide` (every cell that reached its division length), the rates slowed
by pressure (:class:`~qpcontact.colony.PressureGrowth`), the time step and the drive
(:func:`prepare_step`), then the run's step function
(:func:`~qpcontact.simulation.steps.step_function`), whose contact solve clears the overlap the
daughters' axis noise made: every state a run saves or returns is the end of a step, within its
overlap tolerance. :func:`attempt_step` takes a step or ends the run with nothing of it applied
(a signal, a failing hook, contact solve or step); what a step leaves is recorded by
:mod:`qpcontact.simulation.recording`. SIGINT (Ctrl-C) and SIGTERM stop the loop cleanly
(:class:`~qpcontact.simulation.signals.Interrupt`).
"""

from __future__ import annotations

import math
import signal
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..colony.growth import Colony, daughters_share, divide
from ..colony.hooks import Hook, apply_divided, apply_hook, load_hook
from ..colony.pressure import PressureGrowth
from ..errors import InvalidArgumentError, ModelHookError, SolverFailedError, TooManyContactsError
from ..geometry import Cells, Plane, capsule_volume
from ..io.runs import HISTORY_FIELDS, RunFolder
from ..io.snapshots import Snapshot
from ..timestep.mechanics import CellMechanics
from .ranks import CollectiveInterrupt
from .recording import RunState, record_step, save_state
from .settings import Settings
from .signals import Interrupt
from .steps import (
    StepFunction,
    StepOutcome,
    flags_to_try,
    pressure_growth_of,
    sink_drive,
    step_function,
    step_mechanics,
)

__all__ = ["Run", "attempt_step", "check_target", "check_types", "founder", "initial_state", "most_cells",
           "prepare_step", "run_colony", "start_run", "take_one_step"]


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


def initial_state(settings: Settings, start: Colony | Snapshot | None) -> tuple[Colony, int, np.random.Generator,
                                                                                   dict[str, np.ndarray]]:
    """``(colony, step index, random generator, extra state)`` a run starts from: the founder,
    a given colony (step 0), or a snapshot (its step, generator and extra arrays; a snapshot
    without a generator state gets the seed's)."""
    if start is None or isinstance(start, Colony):
        return founder(settings) if start is None else start, 0, np.random.default_rng(settings.run.seed), {}
    rng = start.generator() or np.random.default_rng(settings.run.seed)
    return start.colony, max(start.step, 0), rng, dict(start.extra)


def run_colony(settings: Settings, *, start: Colony | Snapshot | None = None, progress: bool = True,
               folder: RunFolder | None = None, frame_growth: float = 0.0, hook: Hook | None = None,
               pressure_growth: PressureGrowth | None = None, comm: Any = None,
               planes: Sequence[Plane] | None = None) -> Run:
    """Grow a colony until it has ``settings.run.cells`` cells (or reaches step
    ``settings.run.max_steps``).

    Args:
        settings: the run's parameters.
        start: the colony to start from (default: :func:`founder`), or a snapshot
            (:func:`qpcontact.io.snapshots.load_snapshot`) to continue: its step index,
            random-generator state and extra arrays are taken over, so that the run follows the
            trajectory of the run that saved it.
        progress: show a tqdm progress bar (cells reached out of the target).
        folder: where the run writes (:class:`~qpcontact.io.runs.RunFolder`: history rows as
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
        planes: the walls the cells stay on one side of (:class:`qpcontact.Plane`); None: the
            settings' (:meth:`Settings.planes`: the substrate in 3D, none in 2D).

    Returns:
        A :class:`Run`. A failed contact solve, a step that cannot be taken (a cell compressed
        to a negative length) or a failing model hook ends the run early with ``error`` set
        (that step is not applied); SIGINT (Ctrl-C) or SIGTERM end it with ``interrupted`` set
        (:class:`~qpcontact.simulation.signals.Interrupt`).
    """
    from tqdm import tqdm  # the progress bar: only when a colony is run

    state = start_run(settings, start, frame_growth)
    if hook is None and settings.model.hook:
        hook = load_hook(settings.model.hook)
    check_target(settings, state.colony, hook)
    take_step = step_function(settings, state.extra, comm, planes)  # the run's one step function (swap it here)
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
                     type_rates=model.type_rates or None, dividing=control.dividing)
    divided = apply_divided(hook, current, divided, state.step)  # the daughters' own numbers
    stepping = divided
    if pressure_growth is not None:  # slowed for this step only: the colony keeps its rates
        felt = mechanics if current is colony else mechanics.carried_over(colony, current)
        if divided is not current:  # a daughter feels her mother's pressure
            felt = felt.carried_over(current, divided)
        stepping = divided.replace(rates=pressure_growth.rates(divided, felt))
    dt = settings.time_step_of(stepping) if control.dt is None else control.dt
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
    except TooManyContactsError as exc:  # at every halving of the step
        state.error, state.exception = f"{where}: step not applied: {exc}. {flags_to_try(settings)}", exc
    return None
