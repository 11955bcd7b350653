"""What a colony run records as it goes: the run in progress (:class:`RunState`), one history
row per step (:func:`history_row`, :data:`~qpcontact.io.runs.HISTORY_FIELDS`), snapshots
(:func:`save_state`) and the frames of an animation (:func:`record_step`). The files are
written by :class:`~qpcontact.io.runs.RunFolder`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..colony.growth import Colony
from ..geometry import Cells
from ..io.runs import HISTORY_FIELDS, RunFolder
from ..timestep.mechanics import CellMechanics
from ..timestep.position import PositionStepResult
from .settings import Settings
from .steps import StepOutcome

__all__ = ["RunState", "history_row", "record_step", "save_state"]


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


def save_state(state: RunState, settings: Settings, folder: RunFolder | None) -> None:
    """A snapshot of the state reached into ``folder`` (once per step index)."""
    if folder is not None and state.saved != state.step:
        folder.save_snapshot(state.colony, state.step, settings=settings.to_tables(), rng=state.rng, extra=state.extra,
                             mechanics=state.mechanics)
        state.saved = state.step


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
