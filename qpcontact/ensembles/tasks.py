"""One run of a sweep, as a Dask task (:func:`run_task`), in its own folder: idempotent and
never lost.

A task that starts in a folder that holds part of its run continues from the run's latest
snapshot (exactly, :meth:`qpcontact.io.runs.RunFolder.resume`), and one whose run is finished
returns its result (``result.json``); each start is a line of ``attempts.jsonl`` (when, where,
from which step). Two tasks of one run never write its folder at once (:func:`run_lock`); a
sweep that stops leaves a flag every run sees before its next step (:func:`stoppable`). The
measures of a finished run: :data:`MEASURES` (:func:`run_measures`, with the orientational order
:func:`nematic_order`).
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
import traceback
from collections.abc import Iterator, Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from ..colony.growth import Colony
from ..colony.hooks import Hook, load_hook
from ..errors import QPContactError
from ..io.outputs import write_text
from ..io.runs import RunFolder
from ..io.snapshots import load_snapshot
from ..simulation.loop import run_colony
from ..simulation.picture import draw_pictures
from ..simulation.settings import Settings

__all__ = ["ATTEMPTS_FILE", "EVENT_TOPIC", "LOCK_FILE", "MEASURES", "RESULT_FILE", "STOP_FILE", "attempts_of",
           "nematic_order", "open_folder", "read_json", "run_lock", "run_measures", "run_task", "stoppable"]

#: In each run's folder: its measures once it is finished; one line per start of its task.
RESULT_FILE = "result.json"
ATTEMPTS_FILE = "attempts.jsonl"
LOCK_FILE = ".run.lock"
#: In the sweep's folder while it stops: every run stops cleanly at its next step (state saved).
STOP_FILE = ".stop"
#: The Dask event topic of runs starting (the progress bar's "running").
EVENT_TOPIC = "qpcontact-sweep"
#: The measures of a run (``summary.csv``, ``result.json``).
MEASURES = ("cells", "steps", "time", "largest_overlap", "overlap_p99", "mean_overlap", "order", "run_seconds",
            "solve_seconds", "task_seconds", "rejected", "attempts", "worker")


def nematic_order(axes: np.ndarray, dimensions: int) -> float:
    """The orientational order ``S`` of the cells' axes: the largest eigenvalue of
    ``Q = (d⟨a aᵀ⟩ − I)/(d − 1)`` over the ``d`` dimensions of the colony (1: all parallel, 0:
    isotropic)."""
    a = np.asarray(axes, dtype=float)[:, :dimensions]
    if len(a) == 0:
        return float("nan")
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    q = (dimensions * (a.T @ a) / len(a) - np.eye(dimensions)) / (dimensions - 1)
    return float(np.linalg.eigvalsh(q)[-1])


def run_measures(history: Mapping[str, Sequence[float]], axes: np.ndarray, cells: int, time_: float,
                 dimensions: int) -> dict[str, Any]:
    """The measures of a run from its whole history (``history.csv``) and its final state."""
    largest = np.asarray(history["max_overlap"], dtype=float)
    steps = len(history["step"])
    return {"cells": cells, "steps": int(history["step"][-1]) + 1 if steps else 0, "time": time_,
            "largest_overlap": float(largest.max(initial=0.0)),
            "overlap_p99": float(np.percentile(largest, 99)) if steps else 0.0,
            "mean_overlap": float(np.mean(history["mean_overlap"])) if steps else 0.0,
            "order": nematic_order(axes, dimensions), "run_seconds": float(np.sum(history["step_seconds"])),
            "solve_seconds": float(np.sum(history["solve_seconds"])), "rejected": int(np.sum(history["rejected"]))}


def _event(name: str, what: str) -> None:
    """Tell the sweep's client that run ``name`` ``what`` (through the scheduler; nothing outside
    a Dask worker)."""
    try:
        from distributed import get_worker

        get_worker().log_event(EVENT_TOPIC, {"run": name, "event": what})
    except (ImportError, ValueError):
        pass


def read_json(path: Path) -> Any:
    """A JSON file, or None if it is missing or unreadable."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def attempts_of(folder: Path) -> list[dict[str, Any]]:
    """The starts of a run's task (``attempts.jsonl``)."""
    try:
        lines = (folder / ATTEMPTS_FILE).read_text().splitlines()
    except OSError:
        return []
    out = []
    for line in lines:
        try:
            out.append(json.loads(line))
        except ValueError:  # a line cut by a killed process
            continue
    return out


def open_folder(path: Path, vtk: bool = False) -> tuple[RunFolder, Any]:
    """The run's folder, continued from its latest snapshot if it has one (``(folder, snapshot)``),
    or started afresh (``(folder, None)``) if it has none or it cannot be continued; ``vtk``:
    ParaView files with each snapshot."""
    latest = RunFolder(path).latest_snapshot() if path.is_dir() else None
    if latest is not None:
        try:
            snapshot = load_snapshot(latest)
            return RunFolder.resume(path, snapshot, overwrite=True, vtk=vtk), snapshot
        except QPContactError:
            pass  # a folder that cannot be continued is started again: nothing of it is kept
    return RunFolder.create(path, overwrite=True, vtk=vtk), None


@contextlib.contextmanager
def run_lock(folder: Path) -> Iterator[None]:
    """Hold the run folder's lock (``.run.lock``; released when the process ends, killed or not),
    so that two tasks of one run never write its folder at once: Dask may start a task again
    while the first is still running (a cancelled task on an existing cluster runs to its end).
    No lock where :mod:`fcntl` is missing (Windows)."""
    folder.mkdir(parents=True, exist_ok=True)
    try:
        import fcntl
    except ImportError:
        yield
        return
    with open(folder / LOCK_FILE, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def run_task(name: str, values: Mapping[str, Any], folder: str) -> dict[str, Any]:
    """One run of a sweep, in its folder: idempotent (module docstring), one task at a time per
    run (:func:`run_lock`); ``values``: its settings as tables (:meth:`Settings.to_tables`).
    Returns its outcome: ``name``, ``status`` (``done``, ``failed``, or
    ``stopped`` by the sweep's stop flag, :func:`stoppable`), ``error``, ``traceback`` and the
    :data:`MEASURES`; it raises only what opening the folder raises."""
    with run_lock(Path(folder)):
        return _run(name, values, Path(folder))


def stoppable(hook: Hook | None, flag: Path) -> Hook:
    """The run's model hook (or none), preceded by a look at the sweep's stop flag: once it
    exists the run stops cleanly before its next step (``KeyboardInterrupt`` in a step is
    :func:`~qpcontact.simulation.run_colony`'s clean stop: nothing of the step applied, the state
    saved), whatever thread or process the run is in."""

    def checked(colony: Colony, step: int) -> Any:
        if flag.exists():
            raise KeyboardInterrupt
        return None if hook is None else hook(colony, step)

    return checked


def _run(name: str, values: Mapping[str, Any], path: Path) -> dict[str, Any]:
    finished = read_json(path / RESULT_FILE)
    if isinstance(finished, dict) and finished.get("status") == "done":
        return finished
    _event(name, "started")
    t0 = time.perf_counter()
    settings = Settings.from_stored(values, f"run {name}")
    run_folder, snapshot = open_folder(path, vtk=settings.output.vtk)
    start_step = 0 if snapshot is None else max(snapshot.step, 0)
    worker = f"{socket.gethostname()}:{os.getpid()}"
    attempt = {"started": datetime.now(UTC).isoformat(timespec="seconds"), "worker": worker, "pid": os.getpid(),
               "from_step": start_step}
    with (path / ATTEMPTS_FILE).open("a") as fh:
        fh.write(json.dumps(attempt) + "\n")
    run_folder.write_config(settings.to_tables(applying=True),
                            f"qpcontact sweep run {name}, {datetime.now(UTC):%Y-%m-%d %H:%M} UTC"
                            + (f"\ncontinued from step {start_step}" if snapshot is not None else ""))
    outcome: dict[str, Any] = {"name": name, "status": "failed", "error": "", "traceback": ""}
    try:
        hook = stoppable(load_hook(settings.model.hook) if settings.model.hook else None,
                         path.parent.parent / STOP_FILE)
        run = run_colony(settings, start=snapshot, progress=False, folder=run_folder, hook=hook)
        if run.interrupted:
            _event(name, "finished")
            return {**outcome, "status": "stopped", "error": f"stopped at step {run.steps}"}
        draw_pictures(run_folder, settings, run, gif=False, color=settings.output.color)
        measures = run_measures(run_folder.read_history(), run.colony.cells.axes, run.colony.cells.n, run.colony.time,
                                settings.run.dimensions)
        error = run.error
        if run.exception is not None and run.exception.__cause__ is not None:  # a model hook's own traceback
            outcome["traceback"] = "".join(traceback.format_exception(run.exception.__cause__))
        outcome.update(measures, status="failed" if error else "done", error=error)
    except Exception as exc:  # recorded as the run's failure, with its traceback
        outcome.update(error=f"{type(exc).__name__}: {exc}", traceback=traceback.format_exc())
    outcome.update(task_seconds=time.perf_counter() - t0, attempts=len(attempts_of(path)), worker=worker)
    write_text(path / RESULT_FILE, json.dumps(outcome, indent=1, default=float) + "\n")
    _event(name, "finished")
    return outcome


class PlanFolder:
    """A folder of runs planned in one JSON document (``document["runs"]``, each with its
    ``name``), each run in ``runs/NAME/``: what a sweep (:class:`~.sweep.Sweep`) and a convergence
    study (:class:`qpcontact.studies.convergence.Study`) share."""

    def __init__(self, out: Path, document: dict[str, Any]):
        self.out = out
        self.document = document

    @property
    def runs(self) -> list[dict[str, Any]]:
        return self.document["runs"]

    def folder(self, run: Mapping[str, Any]) -> Path:
        """The folder of one of the runs."""
        return self.out / "runs" / run["name"]

