"""``qpcontact simulate``: grow a colony from one cell, save snapshots and draw pictures.

Units: lengths in µm (cells of radius 0.5 µm dividing at a cylinder length of 4 µm), time in
mean doubling times (growth rate ln 2), masses in arbitrary units (mass = volume, growth inertia
``G`` = ``--growth-inertia`` × mass). Every step: the model hook, if any
(:mod:`qpcontact.colony.hooks`), then :func:`qpcontact.colony.divide` (every cell that reached its
division length), then the run's step function (:func:`step_function`), whose contact solve
clears the overlap the daughters' axis noise made: every state a run saves or returns is the end
of a step, within its overlap tolerance. Two steps (``--step``):

- ``position`` (default): :func:`qpcontact.colony.grow_position`, non-penetration at the end of
  the step (:mod:`qpcontact.colony.position`), with a time step set by growth
  (:func:`qpcontact.colony.growth_time_step`: the fastest cell grows ``--growth-per-step`` of its
  length); a step that does not reach the overlap tolerance is retried with half the step;
- ``velocity`` (the earlier default, kept for comparison): :func:`qpcontact.colony.grow`,
  contacts stop approaching at the start of the step, with a time step that follows the colony's
  expansion (:func:`qpcontact.colony.expansion_time_step`), and a step that turns some cell too
  fast (or, with ``--overlap-limit``, leaves too large an overlap) is retried with half the step
  (:func:`grow_with_retries`).

Outputs in ``--out`` (default ``./simulate-out``), checked before the run starts
(:class:`qpcontact.colony.runs.RunFolder`):

- ``config.toml``: the run's settings (``--config`` reads such a file);
- ``snapshots/step_NNNNNN.npz``: colony snapshots (format: :mod:`qpcontact.colony.snapshots`),
  every ``--snapshot-every`` steps and the last state, written atomically, each enough to
  continue the run exactly (``--resume``);
- ``history.csv``: one row per step, appended as the step completes (time, dt, cells, contacts,
  largest/mean overlap as a fraction of the diameter, solver seconds, step seconds, residuals);
- ``colony.png`` (cells coloured by orientation; a side view too in 3D), ``history.png`` (cell
  count, overlap, solver time and residual against time), with ``--gif`` an animation
  ``colony.gif``, with ``--vtk`` ParaView files (``colony.pvd``, ``vtk/step_NNNNNN.vtu``).

A step whose contact solve fails is never applied: the run stops there, says why, saves what
it has and exits with status 1. Ctrl-C (or SIGTERM) stops the run cleanly: the state reached,
the history and the pictures are saved, and ``--resume`` continues it (exit status 130, or 143).
"""

from __future__ import annotations

import argparse
import dataclasses
import signal
import sys
import time
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from functools import partial
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..arguments import non_negative_float, non_negative_int, positive_float, positive_int, run_standalone
from ..errors import InvalidArgumentError, ModelHookError, QPContactError, SolverFailedError, StepFailedError
from ..geometry import Cells, capsule_volume
from ..geometry.surfaces import substrate
from ..solvers import FORMS, QP_FORMULATIONS, available_solvers, get_solver
from .growth import Colony, daughters_share, divide, expansion_time_step, grow, grow_position, growth_time_step
from .hooks import Hook, apply_hook, load_hook, push
from .position import ContactImpulses, PositionSettings, PositionStepResult
from .runs import HISTORY_FIELDS, Interrupt, RunFolder, is_inside, latest_snapshot, read_toml
from .snapshots import Snapshot, load_snapshot
from .step import StepResult, largest_overlap

__all__ = ["HISTORY_FIELDS", "Run", "Settings", "StepOutcome", "founder", "grow_with_retries", "run_colony",
           "step_function", "turning_reach"]


@dataclass
class Settings:
    """Everything that defines a colony run (the command-line options, as values). Saved with
    the run (``config.toml``, every snapshot) and read back by ``--config`` and ``--resume``."""

    n_cells: int = 2000
    dimensions: int = 2
    solver: str = "clarabel"
    formulation: str = "complementarity"
    form: str = "auto"
    tolerance: float = 1e-6
    position_correction: float = 0.5
    margin: float = 0.3
    cfl: float = 0.3
    max_dt: float = 0.02
    radius: float = 0.5
    division_length: float = 4.0
    rate: float = float(np.log(2.0))
    rate_noise: float = 0.1
    axis_noise: float = 0.02
    growth_inertia: float = 1000.0
    dynamics: str = "overdamped"
    damping: float = 0.0
    sink_speed: float = 0.5
    seed: int = 1
    #: The run stops at this step index (counted from the founder, across resumed runs).
    max_steps: int = 100_000
    max_halvings: int = 3
    #: Largest overlap (fraction of the diameter) a step may leave; a step leaving more (and more
    #: than before it) is retried with half the step. 0 = off (the default: docs/colony.md
    #: measures the cost, 4.5× the time of a 3D run).
    overlap_limit: float = 0.0
    #: A Python file defining the model hook ``hook(colony, step)`` (:mod:`qpcontact.colony.hooks`);
    #: "" = none.
    model: str = ""
    #: The step: "position" (non-penetration at the end of the step) or "velocity" (the earlier
    #: velocity-level step; solver, formulation, form, tolerance, position_correction, margin,
    #: cfl, max_halvings and overlap_limit are its settings).
    step: str = "position"
    #: The time-step rule: "growth" (the fastest cell grows growth_per_step of its length per
    #: step), "expansion" (the colony's edge moves at most cfl diameters, at most max_dt), or
    #: "auto" (growth for the position step, expansion for the velocity step).
    time_step: str = "auto"
    #: Growth of the fastest cell per step, for time_step "growth" [fraction of its length].
    growth_per_step: float = 0.05
    #: Largest overlap the position step may leave [fraction of the pair's diameter].
    overlap_tolerance: float = 0.01
    #: Largest displacement of a cell's tips by turning in one position step [cell diameters].
    turn_limit: float = 0.2
    #: The solver of the position step's linearizations (it must take bounds: ipm, mprgp, or a
    #: qpsolvers backend in the primal form).
    position_solver: str = "ipm"
    #: Its tolerance [dimensionless, scaled units].
    position_tolerance: float = 1e-3

    def __post_init__(self) -> None:
        """Reject settings no run can use, naming the setting."""
        positive = ("cfl", "max_dt", "radius", "division_length", "growth_inertia", "tolerance", "growth_per_step",
                    "overlap_tolerance", "turn_limit", "position_tolerance")
        non_negative = ("margin", "position_correction", "rate", "rate_noise", "axis_noise", "damping", "sink_speed",
                        "overlap_limit")
        for name in positive + non_negative:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and (value > 0 if name in positive else value >= 0)):
                raise InvalidArgumentError(f"{name}: must be finite and {'> 0' if name in positive else '>= 0'}, got {value!r}")
        for name, least in (("n_cells", 1), ("max_steps", 1), ("max_halvings", 0), ("seed", 0)):
            value = getattr(self, name)
            if not (isinstance(value, int) and not isinstance(value, bool) and value >= least):
                raise InvalidArgumentError(f"{name}: must be an integer >= {least}, got {value!r}")
        if self.dimensions not in (2, 3):
            raise InvalidArgumentError(f"dimensions: must be 2 or 3, got {self.dimensions!r}")
        if not self.position_correction <= 1:
            raise InvalidArgumentError(f"position_correction: must be in [0, 1], got {self.position_correction!r}")
        if self.dynamics not in ("overdamped", "inertial"):
            raise InvalidArgumentError(f"dynamics: must be overdamped or inertial, got {self.dynamics!r}")
        if self.formulation not in QP_FORMULATIONS or self.form not in ("auto", *FORMS):
            raise InvalidArgumentError(f"formulation/form: expected one of {QP_FORMULATIONS} / auto, {', '.join(FORMS)}; "
                                       f"got {self.formulation!r} / {self.form!r}")
        get_solver(self.solver).plan(self.formulation, self.form)  # unknown, not installed or unsuitable: a named error
        if self.step not in ("position", "velocity"):
            raise InvalidArgumentError(f"step: must be position or velocity, got {self.step!r}")
        if self.time_step not in ("auto", "growth", "expansion"):
            raise InvalidArgumentError(f"time_step: must be auto, growth or expansion, got {self.time_step!r}")
        if self.step == "position" and self.dynamics != "overdamped":
            raise InvalidArgumentError("dynamics: the position step is overdamped; use step = velocity for inertial")
        if self.step == "position":
            self.position_settings()  # a solver that cannot bound the unknowns: a named error now

    def position_settings(self) -> PositionSettings:
        """The :class:`~qpcontact.colony.PositionSettings` of the position step.

        Raises:
            InvalidArgumentError: the position solver is unknown, not installed or takes no bounds.
        """
        if not get_solver(self.position_solver).bounds:
            raise InvalidArgumentError(f"position_solver: {self.position_solver!r} takes no bounds on the unknowns "
                                       "(use ipm, mprgp or a qpsolvers backend)")
        return PositionSettings(overlap_tolerance=self.overlap_tolerance, turn_limit=self.turn_limit,
                                solver=self.position_solver, tolerance=self.position_tolerance)

    def time_step_of(self, colony: Colony) -> float:
        """The time step of the next step from this colony (:attr:`time_step`)."""
        rule = self.time_step if self.time_step != "auto" else ("growth" if self.step == "position" else "expansion")
        if rule == "growth":
            return growth_time_step(colony, growth_per_step=self.growth_per_step, still=self.max_dt)
        return expansion_time_step(colony, max_dt=self.max_dt, cfl=self.cfl, dimensions=self.dimensions)

    def to_dict(self) -> dict[str, Any]:
        """The settings as a plain mapping (for ``config.toml`` and snapshots)."""
        return dataclasses.asdict(self)

    def updated(self, values: Mapping[str, Any], source: str) -> Settings:
        """These settings with ``values`` (by field name) replaced, each checked for its type
        (:func:`updated`)."""
        return updated(self, values, source)

    def step_options(self) -> dict[str, Any]:
        """The options a run passes to :func:`qpcontact.colony.grow` and so to
        :func:`qpcontact.step`: solver, formulation, form, tolerance, margin, position
        correction, planes (the substrate in 3D), planar (2D), dynamics (and damping).

        ``step``'s own defaults are those of a single contact solve (no margin, no position
        correction); in your own loop, ``step(cells, dt, **Settings().step_options())`` steps as
        ``qpcontact simulate`` does (overlaps left by a step are then cleared over the next ones).
        """
        planar = self.dimensions == 2
        options: dict[str, Any] = dict(
            solver=self.solver, formulation=self.formulation, form=self.form, tolerance=self.tolerance,
            margin=self.margin, position_correction=self.position_correction, planes=[] if planar else [substrate(0.0)],
            planar=True if planar else None, dynamics=self.dynamics)
        if self.dynamics == "inertial":
            options["damping"] = self.damping
        return options


def updated(values_of: Any, values: Mapping[str, Any], source: str) -> Any:
    """A copy of the dataclass ``values_of`` with ``values`` (by field name) replaced, each checked
    for the type of its default (an integer is a number too).

    Raises:
        InvalidArgumentError: an unknown name or a value of the wrong type, naming ``source``
            (e.g. the configuration file); or a value the dataclass refuses.
    """
    fields = {f.name: type(getattr(values_of, f.name)) for f in dataclasses.fields(values_of)}
    words = {str: "a string", bool: "true or false", int: "an integer", float: "a number"}
    changes = {}
    for name, value in values.items():
        if name not in fields:
            raise InvalidArgumentError(f"{source}: unknown setting {name!r}; known: {', '.join(fields)}")
        kind = fields[name]
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, kind) or (isinstance(value, bool) and kind is not bool):
            raise InvalidArgumentError(f"{source}: {name} must be {words[kind]}, got {value!r}")
        changes[name] = value
    try:
        return dataclasses.replace(values_of, **changes)
    except QPContactError as exc:
        raise type(exc)(f"{source}: {exc}") from None


@dataclass
class RunOptions:
    """What ``qpcontact simulate`` writes besides the history and the final state (they do not
    change the trajectory). Saved in ``config.toml`` with the settings, so that ``--resume``
    keeps them."""

    #: Save a snapshot every this many steps (0: only the last state).
    snapshot_every: int = 100
    #: ParaView files with each snapshot.
    vtk: bool = False
    #: An animation colony.gif.
    gif: bool = False

    def __post_init__(self) -> None:
        if self.snapshot_every < 0:
            raise InvalidArgumentError(f"snapshot_every: must be an integer >= 0, got {self.snapshot_every!r}")


# (The functional form keeps the field types real types, not strings, for the API reference.)
StepOutcome = NamedTuple("StepOutcome", [("colony", Colony), ("result", StepResult | PositionStepResult),  # noqa: UP014
                                         ("dt", float), ("rejected", int)])
StepOutcome.__doc__ = """What a run's step function returns (:func:`step_function`).

Attributes:
    colony: the colony after the step, before division.
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


def founder(settings: Settings) -> Colony:
    """One cell at the origin along x (on the substrate in 3D), half the division length long."""
    z = settings.radius if settings.dimensions == 3 else 0.0
    volume = capsule_volume(settings.division_length / 2, settings.radius)
    cell = Cells(centers=[[0.0, 0.0, z]], axes=[[1.0, 0.0, 0.0]], lengths=settings.division_length / 2,
                 radii=settings.radius, masses=volume, growth_inertia=settings.growth_inertia * volume)
    return Colony.founder(cell, settings.rate)


def grow_with_retries(colony: Colony, dt: float, settings: Settings, **grow_options: Any) -> StepOutcome:
    """:func:`qpcontact.colony.grow` by ``dt``, rejected and retried with half the step (up to
    ``max_halvings`` times; the last attempt is kept) when

    - the contact solve turns some cell so fast that its tips would move more than ``cfl``
      diameters in the step (:func:`turning_reach`): the contact constraints hold to first
      order in the step, and a fast-turning short cell (a newborn squeezed between neighbours)
      is where the second-order error shows as overlap;
    - ``overlap_limit > 0`` and the new state's largest overlap exceeds both that limit and the
      largest overlap before the step (:func:`largest_overlap`).

    Returns a :class:`StepOutcome` ``(colony, step_result, dt_taken, rejected_attempts)``."""
    reach_limit = settings.cfl * 2.0 * float(np.median(colony.cells.radii))
    for attempt in range(settings.max_halvings + 1):
        grown, out = grow(colony, dt, **grow_options)
        accept = turning_reach(out.result.cells, dt) <= reach_limit
        if accept and settings.overlap_limit > 0:
            # out.max_overlap is the overlap of the state the step starts from.
            bound = max(settings.overlap_limit, out.max_overlap)
            accept = largest_overlap(grown.cells, grow_options.get("planes", ())) <= bound
        if attempt == settings.max_halvings or accept:
            return StepOutcome(grown, out, dt, attempt)
        dt /= 2.0
    raise AssertionError("unreachable")


def turning_reach(cells: Cells, dt: float) -> float:
    """Largest distance a cell tip moves by the cell's turning alone in ``dt``:
    ``max |ω| (l/2 + ρ) dt`` [length]."""
    speed = np.linalg.norm(cells.angular_velocities, axis=1) * (cells.lengths / 2 + cells.radii)
    return float(speed.max(initial=0.0)) * dt


def step_function(settings: Settings, extra: dict[str, np.ndarray]) -> StepFunction:
    """The function :func:`run_colony` advances the colony with, once per step:
    ``take_step(colony, dt, drive=drive) -> StepOutcome`` (the colony after the step, before
    division; the step's result; the step taken; the rejected attempts).

    ``extra`` is the run's extra state: saved in every snapshot (its "extra arrays") and restored
    from the snapshot a run resumes from, so that a step function can carry data from step to
    step exactly across an interruption (e.g. a solver's warm start). Replace its arrays, do not
    change them in place: an interrupted step's changes are undone by restoring the mapping.
    The velocity-level step with retries (:func:`grow_with_retries`) keeps none; the position
    step (:func:`position_step_function`) keeps its contact impulses (``warm.*``).
    """
    if settings.step == "position":
        return position_step_function(settings, extra)
    return partial(grow_with_retries, settings=settings, **settings.step_options())


#: The extra arrays of the position step's warm start (:class:`~qpcontact.colony.ContactImpulses`).
WARM_ARRAYS = ("a", "b", "kind", "impulse")


def position_step_function(settings: Settings, extra: dict[str, np.ndarray]) -> StepFunction:
    """The position-level step of a run (:func:`qpcontact.colony.grow_position`): the substrate
    in 3D, the planar unknowns in 2D, the contact impulses of each step kept in ``extra`` as the
    next one's warm start (and so restored on resume). A step that does not reach the overlap
    tolerance is retried with half the step, up to ``max_halvings`` times; the last failure is
    raised (:class:`~qpcontact.errors.StepFailedError`), never applied.

    The state a step ends in keeps the overlap tolerance unless overlap present at its start
    exceeded what ``relaxation`` clears in one step (a division's axis noise turning a daughter
    into a neighbour by more than 0.05 of a diameter, or a state from elsewhere): such a step is
    taken once more with the relaxation raised to that start overlap, so that it clears it
    (turning still bounded by ``turn_limit``); if that fails, the first step stands and the
    history shows its overlap."""
    position = settings.position_settings()
    planar = settings.dimensions == 2
    planes = [] if planar else [substrate(0.0)]

    def take_step(colony: Colony, dt: float, *, drive: np.ndarray | None = None) -> StepOutcome:
        warm = ContactImpulses(*(extra[f"warm.{name}"] for name in WARM_ARRAYS)) if "warm.a" in extra else None
        for attempt in range(settings.max_halvings + 1):
            try:
                grown, out = grow_position(colony, dt, drive=drive, planes=planes, planar=True if planar else None,
                                           settings=position, warm=warm)
            except StepFailedError:
                if attempt == settings.max_halvings:
                    raise
                dt /= 2.0
                continue
            if out.max_overlap > position.overlap_tolerance and out.start_overlap > position.relaxation:
                clearing = dataclasses.replace(position, relaxation=out.start_overlap)
                try:
                    grown, out = grow_position(colony, dt, drive=drive, planes=planes,
                                               planar=True if planar else None, settings=clearing, warm=warm)
                except StepFailedError:
                    pass  # the first answer stands: converged, only above the bound
            extra.update({f"warm.{name}": getattr(out.warm, name) for name in WARM_ARRAYS})
            return StepOutcome(grown, out, dt, attempt)
        raise AssertionError("unreachable")

    return take_step


def initial_state(settings: Settings, start: Colony | Snapshot | None) -> tuple[Colony, int, np.random.Generator,
                                                                                   dict[str, np.ndarray]]:
    """``(colony, step index, random generator, extra state)`` a run starts from: the founder,
    a given colony (step 0), or a snapshot (its step, generator and extra arrays; a snapshot
    without a generator state gets the seed's)."""
    if start is None or isinstance(start, Colony):
        return founder(settings) if start is None else start, 0, np.random.default_rng(settings.seed), {}
    rng = start.generator() or np.random.default_rng(settings.seed)
    return start.colony, max(start.step, 0), rng, dict(start.extra)


def history_row(step: int, colony: Colony, outcome: StepOutcome, seconds: float) -> dict[str, Any]:
    """One row of the history (:data:`HISTORY_FIELDS`): the step's index, the state after it and
    what the step did. ``max_overlap``/``mean_overlap``: the velocity-level step's are those of
    the state it starts from; the position step's those of the state it ends in (its
    ``penetration`` is its largest shortfall below a contact's target, its ``complementarity``
    is not measured)."""
    out = outcome.result
    common = dict(step=step, time=colony.time, dt=outcome.dt, cells=colony.cells.n, step_seconds=seconds,
                  rejected=outcome.rejected)
    if isinstance(out, PositionStepResult):
        overlapping = -out.contacts.separation[out.contacts.separation < 0]
        diameter = 2.0 * float(np.median(colony.cells.radii))
        return dict(common, contacts=len(out.contacts), max_overlap=out.max_overlap,
                    mean_overlap=float(overlapping.mean()) / diameter if overlapping.size else 0.0,
                    solve_seconds=out.times["solve"], penetration=out.excess, complementarity=np.nan,
                    linearizations=out.iterations)
    result = out.result
    return dict(common, contacts=len(result.contacts), max_overlap=out.max_overlap, mean_overlap=out.mean_overlap,
                solve_seconds=result.times["setup"] + result.times["solve"],
                penetration=result.errors.get("penetration", 0.0),
                complementarity=result.errors.get("complementarity", np.nan), linearizations=1)


def run_colony(settings: Settings, *, start: Colony | Snapshot | None = None, progress: bool = True,
               folder: RunFolder | None = None, snapshot_every: int = 0, frame_growth: float = 0.0,
               hook: Hook | None = None) -> Run:
    """Grow a colony until it has ``settings.n_cells`` cells (or reaches step ``max_steps``).

    Args:
        settings: the run's parameters.
        start: the colony to start from (default: :func:`founder`), or a snapshot
            (:func:`qpcontact.colony.snapshots.load_snapshot`) to continue: its step index,
            random-generator state and extra arrays are taken over, so that the run follows the
            trajectory of the run that saved it.
        progress: show a tqdm progress bar (cells reached out of the target).
        folder: where the run writes (:class:`~qpcontact.colony.runs.RunFolder`: history rows as
            they come, snapshots, ParaView files); None: nothing is written.
        snapshot_every: save a snapshot every this many steps (0: only the last state, which is
            always saved, also after a failure or an interruption).
        frame_growth: keep a frame for an animation whenever the cell count has grown by this
            factor since the last frame (0: no frames).
        hook: a model hook (:mod:`qpcontact.colony.hooks`); default: ``settings.model``'s.

    Returns:
        A :class:`Run`. A failed contact solve, a step that cannot be taken (a cell compressed
        to a negative length) or a failing model hook ends the run early with ``error`` set
        (that step is not applied); SIGINT (Ctrl-C) or SIGTERM end it with ``interrupted`` set
        (:class:`~qpcontact.colony.runs.Interrupt`).
    """
    from tqdm import tqdm  # the progress bar: only when a colony is run

    colony, step, rng, extra = initial_state(settings, start)
    first_step = step
    if hook is None and settings.model:
        hook = load_hook(settings.model)
    take_step = step_function(settings, extra)  # the run's one step function (swap it here)
    planar = settings.dimensions == 2
    history: dict[str, list[float]] = {name: [] for name in HISTORY_FIELDS}
    frames = [(colony.time, colony.cells)] if frame_growth else []
    bar = tqdm(total=settings.n_cells, initial=colony.cells.n, unit="cell", disable=not progress, file=sys.stderr)
    error, saved = "", -1
    exception: BaseException | None = None

    def save() -> None:
        nonlocal saved
        if folder is not None and saved != step:
            folder.save_snapshot(colony, step, settings=settings.to_dict(), rng=rng, extra=extra)
            saved = step

    t_start = time.perf_counter()
    with Interrupt() as interrupt:
        while colony.cells.n < settings.n_cells and step < settings.max_steps and not interrupt.requested:
            where = f"step {step} (t = {colony.time:.4g}, {colony.cells.n} cells)"
            rng_state, extra_before = rng.bit_generator.state, dict(extra)
            t0 = time.perf_counter()
            try:
                with interrupt.armed():  # a signal now abandons the step: nothing of it is applied
                    control = apply_hook(hook, colony, step)
                    current = colony if control.colony is None else control.colony
                    # Division first, so that the overlap its axis noise makes is cleared by this
                    # step's contact solve: every state the run saves or returns is one a step
                    # ended in (issue 19: dividing after the step left 0.047 of a diameter in the
                    # snapshots of a run whose steps keep 0.01).
                    divided = divide(current, settings.division_length if control.division_length is None
                                     else control.division_length, rng, axis_noise=settings.axis_noise,
                                     rate_noise=settings.rate_noise, base_rate=settings.rate, planar=planar)
                    dt = settings.time_step_of(divided)
                    drive = push(divided, [0.0, 0.0, -settings.sink_speed]) if not planar and settings.sink_speed else None
                    if control.drive is not None:
                        shared = daughters_share(control.drive, current, divided)
                        drive = shared if drive is None else drive + shared
                    outcome = take_step(divided, dt, drive=drive)
            except KeyboardInterrupt:
                rng.bit_generator.state = rng_state
                extra.clear()
                extra.update(extra_before)
                interrupt.signal = interrupt.signal or signal.SIGINT  # Python's own (outside the main thread)
                break
            except ModelHookError as exc:
                error, exception = f"{where}: {exc}", exc
                break
            except SolverFailedError as exc:
                error, exception = f"{where}: contact solve failed, not applied: {exc}", exc
                break
            except InvalidArgumentError as exc:  # e.g. contacts compressed a cell to a negative length
                error, exception = f"{where}: step not applied: {exc}", exc
                break
            colony = outcome.colony
            row = history_row(step, colony, outcome, time.perf_counter() - t0)
            for name in HISTORY_FIELDS:
                history[name].append(row[name])
            if folder is not None:
                folder.append_history(row)
            step += 1
            bar.update(colony.cells.n - bar.n)
            bar.set_postfix(t=f"{colony.time:.2f}", overlap=f"{outcome.result.max_overlap:.3f}", refresh=False)
            if snapshot_every and step % snapshot_every == 0:
                save()
            if frame_growth and colony.cells.n >= frame_growth * frames[-1][1].n:
                frames.append((colony.time, colony.cells))
        bar.close()
        wall = time.perf_counter() - t_start
        save()  # the state reached, whatever ended the run
    if frame_growth and frames[-1][1] is not colony.cells:
        frames.append((colony.time, colony.cells))
    return Run(colony, history, wall, step, error, frames, first_step, interrupt.signal, exception)


# ------------------------------------------------------------------------------------------
# Command line
# ------------------------------------------------------------------------------------------
#: The settings on the command line: flag, Settings field, value type, help (with units), choices.
SETTING_FLAGS: tuple[tuple[str, str, Callable[[str], Any], str, tuple[Any, ...] | None], ...] = (
    ("--cells", "n_cells", positive_int, "grow until the colony has this many cells", None),
    ("--dimensions", "dimensions", int, "2: a monolayer in the xy-plane (planar unknowns only); 3: a biofilm on a "
     "substrate plane z = 0", (2, 3)),
    ("--solver", "solver", str, f"contact solver, one of the installed: {', '.join(available_solvers())}", None),
    ("--formulation", "formulation", str, "QP formulation (a plain solver such as linear solves the plain problem)",
     QP_FORMULATIONS),
    ("--form", "form", str, "QP form handed to the solver", ("auto", *FORMS)),
    ("--tolerance", "tolerance", positive_float, "solver tolerance [dimensionless, scaled units]", None),
    ("--position-correction", "position_correction", non_negative_float,
     "fraction of each overlap cleared per step, in [0, 1] (0 = off) [dimensionless]", None),
    ("--margin", "margin", non_negative_float, "speculative contact margin [µm]", None),
    ("--cfl", "cfl", positive_float, "edge displacement per step [cell diameters]", None),
    ("--max-dt", "max_dt", positive_float, "largest time step [doubling times]", None),
    ("--radius", "radius", positive_float, "cell radius [µm]", None),
    ("--division-length", "division_length", positive_float, "cylinder length at division [µm]", None),
    ("--rate", "rate", non_negative_float, "mean growth rate [1/doubling time]", None),
    ("--rate-noise", "rate_noise", non_negative_float, "relative spread of newborn growth rates [dimensionless]", None),
    ("--axis-noise", "axis_noise", non_negative_float, "daughter axis turn at division, standard deviation [rad]", None),
    ("--growth-inertia", "growth_inertia", positive_float,
     "G/m: how hard contacts find it to compress growth [dimensionless]", None),
    ("--dynamics", "dynamics", str, "overdamped: momenta reset every step; inertial: they carry over",
     ("overdamped", "inertial")),
    ("--damping", "damping", non_negative_float, "inertial only: damping rate [1/doubling time]", None),
    ("--sink-speed", "sink_speed", non_negative_float,
     "3D only: every cell is driven towards the substrate at this speed [µm/doubling time]", None),
    ("--max-halvings", "max_halvings", non_negative_int,
     "a step that turns a cell's tips by more than --cfl diameters (or leaves more overlap than --overlap-limit) is "
     "retried with half the step, at most this many times (0: never)", None),
    ("--overlap-limit", "overlap_limit", non_negative_float,
     "retry a step that leaves a larger overlap than this and than before the step [fraction of the diameter] "
     "(0: off)", None),
    ("--seed", "seed", non_negative_int, "random seed of the division noise", None),
    ("--max-steps", "max_steps", positive_int, "stop at this step index (counted from the founder)", None),
    ("--model", "model", str, "a Python file defining hook(colony, step), called every step (examples/model_hook.py)",
     None),
    ("--step", "step", str, "position: no overlap at the end of each step (default); velocity: contacts stop "
     "approaching at its start (the earlier step; --solver, --tolerance, --margin, --position-correction, --cfl and "
     "--overlap-limit are its settings)", ("position", "velocity")),
    ("--time-step", "time_step", str, "growth: the fastest cell grows --growth-per-step per step; expansion: the "
     "colony's edge moves --cfl diameters per step (at most --max-dt); auto: growth for the position step, expansion "
     "for the velocity step", ("auto", "growth", "expansion")),
    ("--growth-per-step", "growth_per_step", positive_float,
     "growth of the fastest cell per step [fraction of its length]", None),
    ("--overlap-tolerance", "overlap_tolerance", positive_float,
     "largest overlap a position step may leave [fraction of the pair's diameter]", None),
    ("--turn-limit", "turn_limit", positive_float,
     "largest displacement of a cell's tips by turning in one position step [cell diameters]", None),
    ("--position-solver", "position_solver", str, "solver of the position step (it must take bounds: ipm, mprgp, or a "
     "qpsolvers backend)", None),
    ("--position-tolerance", "position_tolerance", positive_float,
     "tolerance of the position step's solver [dimensionless, scaled units]", None),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``qpcontact simulate``."""
    parser.description = ("Grow a colony from one cell (or from a snapshot), with snapshots, history, pictures and, with "
                          "--vtk, ParaView files.\n\nUnits: lengths in µm, time in mean doubling times. Settings come "
                          "from (later wins): the defaults, the snapshot of --start/--resume, --config, the flags.\n"
                          "Ctrl-C stops cleanly: the state, history and pictures are saved; --resume continues.")
    run = parser.add_argument_group("run")
    run.add_argument("--config", type=Path, metavar="FILE", help="read settings (and snapshot_every, vtk, gif) from a "
                     "TOML file: name = value lines, names as in the config.toml a run saves; flags override it")
    start = run.add_mutually_exclusive_group()
    start.add_argument("--start", type=Path, metavar="SNAPSHOT",
                       help="start from this snapshot (.npz): its state, step index, random state and settings. A "
                            "snapshot of --out's own run continues that run (history appended)")
    start.add_argument("--resume", action="store_true", help="continue the run in --out from its latest snapshot")
    run.add_argument("--out", type=Path, default=Path("simulate-out"), metavar="FOLDER",
                     help="output folder (default: ./simulate-out); checked before the run starts")
    run.add_argument("--overwrite", action="store_true",
                     help="replace the run already in --out (its files are removed first; default: refuse); with "
                          "--start/--resume of an earlier snapshot of --out, drop the later ones")
    run.add_argument("--snapshot-every", dest="snapshot_every", type=non_negative_int, default=argparse.SUPPRESS,
                     metavar="N", help="save a snapshot every N steps (0: only the last state; default: 100)")
    run.add_argument("--vtk", action="store_true", default=argparse.SUPPRESS,
                     help="with each snapshot, a ParaView file (vtk/step_N.vtu, listed in colony.pvd with its time); "
                          "needs meshio: pip install 'qpcontact[vtk]'")
    run.add_argument("--gif", action="store_true", default=argparse.SUPPRESS, help="also write an animation colony.gif")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    add_setting_flags(parser.add_argument_group("model settings (also in --config; saved in config.toml)"))


def add_setting_flags(group: Any) -> None:
    """The flags of :data:`SETTING_FLAGS` (a flag not given is absent from the parsed arguments:
    :func:`flags_given`)."""
    defaults = Settings()
    for flag, name, kind, help_, choices in SETTING_FLAGS:
        default = getattr(defaults, name)
        metavar = None if choices else {int: "N", float: "X"}.get(type(default), "FILE" if name == "model" else "NAME")
        group.add_argument(flag, dest=name, type=kind, choices=choices, default=argparse.SUPPRESS, metavar=metavar,
                           help=f"{help_} (default: {default!r})")


def flags_given(args: argparse.Namespace, values_of: Any) -> dict[str, Any]:
    """The flags given on the command line for the fields of the dataclass ``values_of``."""
    return {f.name: getattr(args, f.name) for f in dataclasses.fields(values_of) if hasattr(args, f.name)}


def configure(args: argparse.Namespace, snapshot: Snapshot | None, in_place: bool) -> tuple[Settings, RunOptions]:
    """The run's settings and options, later sources winning: the defaults; the snapshot's
    settings (``--start``/``--resume``); the options of the run continued in place (its
    ``config.toml``); ``--config``; the flags given."""
    settings, options = Settings(), RunOptions()
    if snapshot is not None and snapshot.settings is not None:
        settings = settings.updated(snapshot.settings, f"{snapshot.path} (settings)")
    earlier = args.out / "config.toml"
    if in_place and earlier.exists():
        values = read_toml(earlier)
        options = updated(options, {k: v for k, v in values.items() if k in RUN_OPTION_NAMES}, str(earlier))
    if args.config is not None:
        values = read_toml(args.config)
        options = updated(options, {k: v for k, v in values.items() if k in RUN_OPTION_NAMES}, str(args.config))
        settings = settings.updated({k: v for k, v in values.items() if k not in RUN_OPTION_NAMES}, str(args.config))
    return (settings.updated(flags_given(args, settings), "command line"),
            updated(options, flags_given(args, options), "command line"))


RUN_OPTION_NAMES = tuple(f.name for f in dataclasses.fields(RunOptions))


def open_run(args: argparse.Namespace) -> tuple[Settings, RunOptions, Snapshot | None, RunFolder]:
    """Read the start, settle the settings and open the output folder: every check a run needs
    before it starts (so that nothing fails at its end)."""
    path = latest_snapshot(args.out) if args.resume else args.start
    snapshot = None if path is None else load_snapshot(path)
    in_place = snapshot is not None and is_inside(Path(path), args.out)
    settings, options = configure(args, snapshot, in_place)
    if options.vtk:
        from .paraview import _meshio

        _meshio()  # a named error now if meshio is missing
    if settings.model:
        load_hook(settings.model)
    if snapshot is not None and in_place:
        folder = RunFolder.resume(args.out, snapshot, overwrite=args.overwrite, vtk=options.vtk)
    else:
        folder = RunFolder.create(args.out, overwrite=args.overwrite, vtk=options.vtk,
                                  first_step=0 if snapshot is None else max(snapshot.step, 0))
    return settings, options, snapshot, folder


def describe_changes(before: Mapping[str, Any] | None, after: Settings) -> str:
    """The settings that differ from a snapshot's, as ``name: old -> new`` ("" if none)."""
    if before is None:
        return ""
    changed = [f"{name}: {before.get(name)!r} -> {value!r}" for name, value in after.to_dict().items()
               if before.get(name, value) != value]
    return "; ".join(changed)


def run_command(args: argparse.Namespace) -> int:
    from ..outputs import describe_written

    try:
        settings, options, snapshot, folder = open_run(args)  # a QPContactError here: exit 2 (run_checked)
    except KeyboardInterrupt:
        print("qpcontact simulate: interrupted before the run started", file=sys.stderr)
        return 130
    folder.write_config({**settings.to_dict(), **dataclasses.asdict(options)}, f"qpcontact simulate settings, {datetime.now(UTC):%Y-%m-%d %H:%M} UTC"
                        + (f"\nstarted from {snapshot.path} (step {snapshot.step})" if snapshot else "")
                        + "\nrun again: qpcontact simulate --config config.toml --out ANOTHER_FOLDER")
    if snapshot is not None:
        changes = describe_changes(snapshot.settings, settings)
        print(f"continuing from {snapshot.path} (step {snapshot.step}, t = {snapshot.colony.time:.4g}, "
              f"{snapshot.colony.cells.n} cells)" + (f"; settings changed: {changes}" if changes else ""), file=sys.stderr)
    result = run_colony(settings, start=snapshot, progress=not args.quiet, folder=folder,
                        snapshot_every=options.snapshot_every, frame_growth=1.08 if options.gif else 0.0)
    try:
        draw_pictures(folder, settings, result, gif=options.gif)
    except KeyboardInterrupt:
        print("qpcontact simulate: interrupted while drawing; the snapshot and the history are saved", file=sys.stderr)
        return 130
    history = folder.read_history()
    print(f"{result.colony.cells.n} cells at step {result.steps}, t = {result.colony.time:.3f} doubling times; this run: "
          f"{result.steps - result.first_step} steps in {result.wall_seconds:.1f} s; largest overlap "
          f"{max(history['max_overlap'], default=0.0):.4f} of a diameter; contact solve "
          f"{np.sum(result.history['solve_seconds']):.1f} s")
    print(describe_written(folder.written))
    if result.interrupted:
        print(f"qpcontact simulate: stopped by signal {result.interrupted} at step {result.steps}; continue with: "
              f"qpcontact simulate --resume --out {folder.path}", file=sys.stderr)
        return 128 + result.interrupted
    if result.error:
        if isinstance(result.exception, ModelHookError) and result.exception.__cause__ is not None:
            traceback.print_exception(result.exception.__cause__, file=sys.stderr)
        print(f"qpcontact simulate: {result.error}", file=sys.stderr)
        return 1
    return 0


def draw_pictures(folder: RunFolder, settings: Settings, result: Run, *, gif: bool) -> None:
    """``colony.png`` (and a side view in 3D), ``history.png`` of the whole run (earlier
    attempts of a resumed run included), ``colony.gif`` from this run's frames."""
    from .plots import animate, plot_history, save_colony_picture  # matplotlib only when drawing

    label = f"{settings.dimensions}D, {settings.solver}/{settings.formulation}, tol {settings.tolerance:g}"
    cells = result.colony.cells
    folder.note(save_colony_picture(folder.path / "colony.png", cells,
                                    f"{cells.n} cells at t = {result.colony.time:.2f} doubling times ({label})",
                                    side_view=settings.dimensions == 3, planes=settings.step_options()["planes"]))
    history = folder.read_history()
    if history["step"]:
        folder.note(plot_history(folder.path / "history.png", history, label))
    if gif and len(result.frames) > 1:
        folder.note(animate(folder.path / "colony.gif", result.frames))


def main(argv: list[str] | None = None) -> int:
    return run_standalone("qpcontact simulate", add_arguments, run_command, argv)
