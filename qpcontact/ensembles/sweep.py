"""``qpcontact sweep``: replicates and parameter sweeps of colony runs, as tasks on Dask.

A sweep is a grid of colony runs (:func:`qpcontact.colony.run_colony`): seeds × the settings that
vary, each combination of the varied values with each seed (``--zip``: the varied lists taken
side by side, a list of runs, instead of their product)::

    qpcontact sweep --cells 500 --seeds 1,2,3 --vary growth_inertia_ratio=100,1000 --vary position_overlap_tolerance=0.01,0.02

or from a configuration file (``--config sweep.toml``): the tables of ``qpcontact simulate``'s
settings (:mod:`qpcontact.colony.settings`), and a ``[sweep]`` table with ``seeds = [1, 2, 3]``,
``zip = false`` and ``[sweep.vary]`` lists (``growth_inertia_ratio = [100, 1000]``); flags
override the file. A varied setting is named as its flag without the dashes (underscores or
dashes) or by its path (``position.tolerance``). Every run's settings are merged as
``simulate``'s are (:func:`qpcontact.colony.settings.merge`: defaults, ``--config``, the flags,
the run's varied values) and checked before anything starts: a bad value, or a setting given that
applies to none of the runs, is exit status 2 and one line.

Each run is one Dask task (:func:`run_task`) on a local cluster (``--workers N`` processes, one
thread each; default one per core) or on an existing one (``--scheduler ADDRESS``; ``--out`` must
then be on a file system the workers share). Outputs in ``--out`` (default ``./sweep-out``):

- ``runs/<name>/``: one folder per run, written as the run goes, in the format of ``qpcontact
  simulate`` (``config.toml``, ``history.csv``, ``snapshots/step_NNNNNN.npz``, ``colony.png``,
  ``history.png``), plus ``result.json`` (its measures, once it is finished) and
  ``attempts.jsonl`` (one line per start of its task: when, where, from which step). The name is
  made of the varied settings and the seed (``growth_inertia_ratio-100__seed-2``);
- ``sweep.json``: the sweep (every run's full settings) and each run's status (``pending``,
  ``done``, ``failed`` with its error), written atomically whenever a run finishes;
- ``summary.csv``: one row per run (its varied settings, the step, solver and tolerance that
  ran, its pressure-dependent growth, :data:`MEASURES`: cells, steps, time, largest overlap, orientational order, times,
  attempts, error), and ``ensemble.png``: cell count and largest
  overlap against time, mean and range across seeds for each combination of settings.

Nothing is lost or redone: a task that starts in a folder that holds part of its run continues
from the run's latest snapshot (exactly, :meth:`qpcontact.colony.runs.RunFolder.resume`), and one
whose run is finished returns its result. So a worker that dies takes with it only the steps since
its run's last snapshot (Dask gives the task to another worker, up to
``distributed.scheduler.allowed-failures`` = 3 deaths), and ``qpcontact sweep --resume --out DIR``
after a stop (Ctrl-C, a lost scheduler) runs only what is not done. Failed runs are listed by
name with their error at the end and in the summary; the exit status is 1 if any run failed or
did not finish, 130 after Ctrl-C.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import json
import os
import re
import socket
import sys
import time
import traceback
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from ..arguments import comma_list, non_negative_int, output_folder, positive_int, run_standalone
from ..colony.growth import Colony
from ..colony.hooks import Hook, load_hook
from ..described import Layer, find_setting, known_names, parse_text, settings_of
from ..errors import InvalidArgumentError, OutputFolderError, QPContactError
from ..io.runs import LEFTOVERS, RUN_OUTPUTS, RunFolder, read_toml
from ..io.snapshots import load_snapshot
from ..outputs import describe_written, prepare_folder, write_csv, write_text
from ..simulation.settings import Settings, add_setting_flags, file_layer, flag_layer, merge, refuse_unused
from ..simulation.simulate import check_target, draw_pictures, founder, run_colony
from . import cluster

SWEEP_FILE = "sweep.json"
SUMMARY_FILE = "summary.csv"
ENSEMBLE_FILE = "ensemble.png"
#: In each run's folder: its measures once it is finished; one line per start of its task.
RESULT_FILE = "result.json"
ATTEMPTS_FILE = "attempts.jsonl"
LOCK_FILE = ".run.lock"
#: In the sweep's folder while it stops: every run stops cleanly at its next step (state saved).
STOP_FILE = ".stop"
#: Seconds a stopping sweep waits for its running runs to save their state.
STOP_WAIT = 30.0
#: Every file a sweep writes in its folder (glob patterns).
OUTPUTS = (SWEEP_FILE, SUMMARY_FILE, ENSEMBLE_FILE,
           *(f"runs/*/{pattern}" for pattern in (*RUN_OUTPUTS, *LEFTOVERS, RESULT_FILE, ATTEMPTS_FILE)))
#: The Dask event topic of runs starting (the progress bar's "running").
EVENT_TOPIC = "qpcontact-sweep"
#: The measures of a run (``summary.csv``, ``result.json``).
MEASURES = ("cells", "steps", "time", "largest_overlap", "overlap_p99", "mean_overlap", "order", "run_seconds",
            "solve_seconds", "task_seconds", "rejected", "attempts", "worker")
FORMAT = "qpcontact-sweep"


# ------------------------------------------------------------------------------------------
# The grid
# ------------------------------------------------------------------------------------------
def parse_vary(text: str) -> tuple[str, list[str]]:
    """``NAME=V1,V2,...`` -> ``(NAME, [V1, V2, ...])`` (the values as text)."""
    name, equals, values = text.partition("=")
    if not equals or not name.strip():
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE,VALUE,..., got {text!r}")
    return name.strip(), comma_list()(values)


def varied_values(name: str, values: Sequence[Any], source: str) -> tuple[str, list[Any]]:
    """``(name, values)``: the setting a varied name means (its one name,
    :attr:`qpcontact.described.Setting.name`) and its values, read from text as its flag reads
    them (values from a TOML file are kept as they are; the merge checks them).

    Raises:
        InvalidArgumentError: an unknown name, the seed (``--seeds`` varies it), a value the
            setting refuses, or no values.
    """
    s = find_setting(Settings, name)
    if s is None:
        raise InvalidArgumentError(f"{source}: unknown setting {name!r} to vary; known: {known_names(Settings)} (by "
                                   "path table.key, or by flag without the dashes)")
    if s.name == "seed":
        raise InvalidArgumentError(f"{source}: vary the seed with --seeds (or seeds = [...] in [sweep])")
    if not isinstance(values, (list, tuple)) or not values:
        raise InvalidArgumentError(f"{source}: {name}: expected a non-empty list of values, got {values!r}")
    out = []
    for value in values:
        try:
            out.append(parse_text(s, value) if isinstance(value, str) and s.kind is not str else value)
        except InvalidArgumentError as exc:
            raise InvalidArgumentError(f"{source}: {name}={value}: {str(exc).split(': ', 1)[1]}") from None
    return s.name, out


def label(value: Any) -> str:
    """A value as it appears in a run's name (file-name safe)."""
    if isinstance(value, float):
        text = f"{value:.6g}"
    elif isinstance(value, (tuple, list)):  # a list setting (type_rates)
        text = "_".join(map(label, value)) or "none"
    else:
        text = str(value)
        if "/" in text or os.sep in text:
            text = Path(text).name
    return re.sub(r"[^A-Za-z0-9.+_-]", "_", text) or "_"


def run_name(varied: Mapping[str, Any]) -> str:
    """The run's folder name: ``name-value`` of each varied setting (the seed last), joined by
    ``__``."""
    return "__".join(f"{name}-{label(value)}" for name, value in varied.items())


@dataclass
class Grid:
    """What varies in a sweep: ``vary`` (setting -> values, in order), ``seeds``, ``zip`` (the
    lists side by side instead of their product)."""

    vary: dict[str, list[Any]]
    seeds: list[int]
    zip: bool = False

    def combinations(self) -> list[dict[str, Any]]:
        """Each run's varied values (the seed last)."""
        names = list(self.vary)
        lists = [self.vary[name] for name in names]
        if self.zip:
            if len({len(values) for values in lists}) > 1:
                raise InvalidArgumentError("--zip: the varied lists must have the same length, got "
                                           + ", ".join(f"{n}: {len(v)}" for n, v in self.vary.items()))
            rows = list(zip(*lists, strict=True)) if lists else [()]
        else:
            rows = list(itertools.product(*lists))
        return [{**dict(zip(names, row, strict=True)), "seed": seed} for row in rows for seed in self.seeds]


def plan_runs(base: Settings, grid: Grid) -> list[dict[str, Any]]:
    """Every run of the sweep (``name``, ``varied``, ``settings`` as tables), each run's settings
    ``base`` merged with its varied values (:func:`qpcontact.colony.settings.merge`) and checked.

    Raises:
        InvalidArgumentError: a combination the settings refuse (naming the run), or two runs of
            the same name.
    """
    runs: list[dict[str, Any]] = []
    seen: dict[str, dict[str, Any]] = {}
    for varied in grid.combinations():
        name = run_name(varied)
        if name in seen:
            raise InvalidArgumentError(f"the grid has two runs named {name!r} ({seen[name]} and {varied}); vary "
                                       "distinct values")
        seen[name] = varied
        settings = merge([grid_layer(f"run {name}", varied)], base=base)
        runs.append({"name": name, "varied": varied, "settings": settings.to_tables(), "status": "pending", "error": ""})
    return runs


def grid_layer(source: str, varied: Mapping[str, Any]) -> Layer:
    """Varied values by name as a layer of the merge."""
    paths = {}
    for name, value in varied.items():
        s = find_setting(Settings, name)
        assert s is not None, name  # names come from varied_values
        paths[s.path] = value
    return Layer(source, paths, "grid")


def read_config(path: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(the settings' tables, the [sweep] table)`` of a configuration file."""
    values = read_toml(path)
    table = values.pop("sweep", {})
    if not isinstance(table, dict):
        raise InvalidArgumentError(f"{path}: sweep must be a table ([sweep])")
    unknown = set(table) - {"seeds", "vary", "zip"}
    if unknown:
        raise InvalidArgumentError(f"{path}: [sweep] has unknown keys {', '.join(sorted(unknown))}; known: seeds, vary, "
                                   "zip")
    return values, table


def configure(args: argparse.Namespace) -> tuple[Settings, Grid, list[Layer]]:
    """The base settings, the grid and the layers the settings came from (for
    :func:`qpcontact.colony.settings.refuse_unused` once the runs are known): later sources
    winning, the defaults, ``--config`` (its ``[sweep]`` table for the grid), the flags."""
    layers: list[Layer] = []
    table: dict[str, Any] = {}
    source = "command line"
    if args.config is not None:
        values, table = read_config(args.config)
        layers.append(file_layer(args.config, values))
        source = f"{args.config} [sweep]"
    layers.append(flag_layer(args))
    settings = merge(layers)
    if settings.output.gif:
        raise InvalidArgumentError("gif: a sweep writes no animations; set gif = false")
    if settings.output.snapshot_every == 0:
        raise InvalidArgumentError("snapshot_every: a sweep's run continues from its latest snapshot when its worker "
                                   "dies; give a number of steps >= 1")
    vary: dict[str, list[Any]] = {}
    table_vary = table.get("vary", {})
    if not isinstance(table_vary, dict):
        raise InvalidArgumentError(f"{source}: vary must be a table of lists ([sweep.vary])")
    for name, values, where in [*((n, v, source) for n, v in table_vary.items()),
                                *((n, v, "--vary") for n, v in args.vary or [])]:
        field, converted = varied_values(name, values, where)
        vary[field] = converted
    seeds = args.seeds or (list(range(1, args.replicates + 1)) if args.replicates else None) or table.get("seeds")
    if seeds is None:
        seeds = [settings.run.seed]
    if not (isinstance(seeds, list) and seeds and all(isinstance(s, int) and not isinstance(s, bool) and s >= 0
                                                      for s in seeds)):
        raise InvalidArgumentError(f"{source}: seeds must be a non-empty list of integers >= 0, got {seeds!r}")
    zip_ = args.zip or bool(table.get("zip", False))
    return settings, Grid(vary, list(seeds), zip_), layers


# ------------------------------------------------------------------------------------------
# One run (a Dask task)
# ------------------------------------------------------------------------------------------
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
    :func:`~qpcontact.colony.run_colony`'s clean stop: nothing of the step applied, the state
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


# ------------------------------------------------------------------------------------------
# The sweep's own files
# ------------------------------------------------------------------------------------------
class Sweep:
    """A sweep's folder: ``sweep.json`` (the runs and their status), the run folders, the
    summary and the ensemble picture."""

    def __init__(self, out: Path, document: dict[str, Any]):
        self.out = out
        self.document = document

    @property
    def runs(self) -> list[dict[str, Any]]:
        return self.document["runs"]

    @property
    def varied(self) -> list[str]:
        return list(self.runs[0]["varied"]) if self.runs else []

    def folder(self, run: Mapping[str, Any]) -> Path:
        return self.out / "runs" / run["name"]

    @classmethod
    def new(cls, out: Path, runs: list[dict[str, Any]], base: Settings, grid: Grid) -> Sweep:
        document = {"format": FORMAT, "version": 2, "created": datetime.now(UTC).isoformat(timespec="seconds"),
                    "base": base.to_tables(), "vary": grid.vary, "seeds": grid.seeds, "zip": grid.zip, "runs": runs}
        return cls(out, document)

    @classmethod
    def load(cls, out: Path) -> Sweep:
        """The sweep in ``out`` (``--resume``), each run's settings checked again.

        Raises:
            OutputFolderError: no sweep there, or its ``sweep.json`` cannot be read.
        """
        document = read_json(out / SWEEP_FILE)
        if document is None:
            raise OutputFolderError(f"{out}: holds no sweep to resume ({SWEEP_FILE} is missing or unreadable)")
        if not isinstance(document, dict) or document.get("format") != FORMAT or not isinstance(document.get("runs"), list):
            raise OutputFolderError(f"{out / SWEEP_FILE}: not a qpcontact sweep")
        for run in document["runs"]:  # a sweep of version 1 stored flat settings, snapshot_every apart
            values = run["settings"]
            if "snapshot_every" in document and not any(isinstance(v, Mapping) for v in values.values()):
                values = {**values, "snapshot_every": document["snapshot_every"]}
            run["settings"] = Settings.from_stored(values, f"{out / SWEEP_FILE}: run {run['name']}").to_tables()
        return cls(out, document)

    def save(self) -> Path:
        return write_text(self.out / SWEEP_FILE, json.dumps(self.document, indent=1, default=float) + "\n")

    def to_do(self) -> list[dict[str, Any]]:
        """The runs not done. A run is done when its folder's ``result.json`` says so (the task's
        own record: a run that finished while the sweep was stopping is done, one marked done
        whose result is missing is not)."""
        out = []
        for run in self.runs:
            result = read_json(self.folder(run) / RESULT_FILE)
            if isinstance(result, dict) and result.get("status") == "done":
                self.record(run, result)
            else:
                out.append(run)
        return out

    def record(self, run: dict[str, Any], outcome: Mapping[str, Any]) -> None:
        run.update(status=outcome["status"], error=outcome.get("error", ""),
                   measures={k: outcome[k] for k in MEASURES if k in outcome})
        if outcome.get("traceback"):
            run["traceback"] = outcome["traceback"]
        else:
            run.pop("traceback", None)

    def counts(self) -> dict[str, int]:
        return {status: sum(run["status"] == status for run in self.runs) for status in ("done", "failed", "pending")}

    # -- summary and picture ------------------------------------------------------------------
    def summary_columns(self) -> tuple[str, ...]:
        return ("name", "status", *self.varied, "step", "growth", *MEASURES, "error")

    def write_summary(self) -> Path:
        rows = []
        for run in self.runs:
            measures = dict(run.get("measures", {}))
            measures["attempts"] = len(attempts_of(self.folder(run)))
            error = " ".join(str(run.get("error", "")).split())  # one line per run
            ran = Settings.from_stored(run["settings"], run["name"])
            rows.append({"name": run["name"], "status": run["status"], **run["varied"], "step": ran.describe_step(),
                         "growth": ran.describe_growth(), **measures, "error": error})
        path = self.out / SUMMARY_FILE
        write_csv(rows, path, self.summary_columns(), digits=6)
        return path

    def write_ensemble(self) -> Path | None:
        """``ensemble.png`` from the histories of the runs done (None if none is)."""
        groups: dict[str, list[dict[str, list[float]]]] = {}
        for run in self.runs:
            if run["status"] != "done":
                continue
            history = RunFolder(self.folder(run)).read_history()
            if not history["step"]:
                continue
            key = ", ".join(f"{k} = {label(v)}" for k, v in run["varied"].items() if k != "seed") or "all runs"
            groups.setdefault(key, []).append(history)
        if not groups:
            return None
        return plot_ensemble(self.out / ENSEMBLE_FILE, groups)


def plot_ensemble(path: Path, groups: Mapping[str, Sequence[Mapping[str, Sequence[float]]]]) -> Path:
    """Cell count and largest overlap against time: for each group of runs (the same settings,
    different seeds) the mean across the runs (a line) and their range (a band), each run's
    history taken at common times up to its own end."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.5), dpi=110, layout="constrained")
    ax_cells, ax_overlap = fig.subplots(1, 2)
    for index, (name, histories) in enumerate(groups.items()):
        color = f"C{index % 10}"
        end = max(h["time"][-1] for h in histories)
        times = np.linspace(0.0, end, 300)
        for ax, column in ((ax_cells, "cells"), (ax_overlap, "max_overlap")):
            values = np.full((len(histories), len(times)), np.nan)
            for row, history in enumerate(histories):
                t = np.asarray(history["time"])
                inside = times <= t[-1]
                values[row, inside] = np.interp(times[inside], t, np.asarray(history[column]))
            counted = np.sum(np.isfinite(values), axis=0) > 0
            with np.errstate(all="ignore"):
                mean = np.nanmean(values[:, counted], axis=0)
                low, high = np.nanmin(values[:, counted], axis=0), np.nanmax(values[:, counted], axis=0)
            ax.plot(times[counted], mean, color=color, lw=1.5,
                    label=f"{name} ({len(histories)} run{'s' if len(histories) > 1 else ''})")
            ax.fill_between(times[counted], low, high, color=color, alpha=0.2, lw=0)
    ax_cells.set(xlabel="time [doubling times]", ylabel="cells", yscale="log", title="cell count: mean and range")
    ax_overlap.set(xlabel="time [doubling times]", ylabel="largest overlap [fraction of the diameter]",
                   title="largest overlap per step: mean and range")
    ax_cells.legend(fontsize="small")
    for ax in (ax_cells, ax_overlap):
        ax.grid(alpha=0.3)
    fig.savefig(path)
    return path


# ------------------------------------------------------------------------------------------
# Running it
# ------------------------------------------------------------------------------------------
def execute(sweep: Sweep, client: Any, runs: list[dict[str, Any]], *, progress: bool = True) -> bool:
    """Submit ``runs`` to the client, record each as it finishes (``sweep.json``), with a progress
    bar of runs done / running / failed. Returns False if interrupted (Ctrl-C: the runs not
    finished are cancelled and stay pending)."""
    from tqdm import tqdm

    running: set[str] = set()

    def on_event(event: tuple[float, Mapping[str, Any]]) -> None:
        message = event[1]
        (running.add if message.get("event") == "started" else running.discard)(message.get("run", ""))

    client.subscribe_topic(EVENT_TOPIC, on_event)
    # A task writes its start to its folder before its first step, where the stop can see it even
    # when the "started" event has not reached this client yet (issue 19: a run stopped within a
    # second of its start was taken for one not started and cancelled, which cannot stop it).
    starts_before = {run["name"]: len(attempts_of(sweep.folder(run))) for run in runs}

    def started(run: Mapping[str, Any]) -> bool:
        return run["name"] in running or len(attempts_of(sweep.folder(run))) > starts_before[run["name"]]

    pending = {client.submit(run_task, run["name"], run["settings"], str(sweep.folder(run)),
                             key=f"sweep-{run['name']}-{os.urandom(4).hex()}", pure=False): run for run in runs}
    bar = tqdm(total=len(sweep.runs), initial=len(sweep.runs) - len(runs), unit="run", desc="sweep",
               disable=not progress, file=sys.stderr, dynamic_ncols=True)
    for run in runs:  # a run being redone is pending until it finishes again
        run.update(status="pending", error="")
    shown: dict[str, int] = {}

    def collect() -> bool:
        """Record the runs finished since the last call; whether there were any."""
        finished = [future for future in pending if future.done()]
        for future in finished:
            run = pending.pop(future)
            running.discard(run["name"])
            if future.status == "finished" and future.result()["status"] == "stopped":
                run.update(status="pending", error=future.result()["error"])
                continue
            if future.status == "finished":
                sweep.record(run, future.result())
            elif future.status == "error":
                exc = future.exception()
                sweep.record(run, {"status": "failed", "error": f"{type(exc).__name__}: {exc}"})
            else:  # cancelled: the scheduler lost it
                run.update(status="pending", error=f"task {future.status} (the scheduler lost it); resume the sweep")
                continue
            sweep.save()
            bar.update()
        return bool(finished)

    try:
        while pending:
            finished = collect()
            counts = sweep.counts()
            postfix = {"done": counts["done"], "running": len(running & {r["name"] for r in pending.values()}),
                       "failed": counts["failed"]}
            if postfix != shown:
                bar.set_postfix(postfix)
                shown = postfix
            if not finished:
                time.sleep(0.2)
    except KeyboardInterrupt:
        stop(sweep, client, pending, collect, started)
        return False
    finally:
        bar.close()
        with_unsubscribe(client)
        sweep.save()
    return True


def stop(sweep: Sweep, client: Any, pending: dict[Any, Any], collect: Callable[[], bool],
         started: Callable[[Mapping[str, Any]], bool]) -> None:
    """Stop a sweep: the runs not started are cancelled; the running ones see the stop flag and
    save their state at their next step (waited for up to :data:`STOP_WAIT` seconds; a second
    Ctrl-C does not wait). The flag stays until the sweep's client is closed (:func:`run_command`):
    a task that starts all the same (a cancellation racing its start) stops at once; the next
    sweep in the folder removes a flag left behind."""
    flag = sweep.out / STOP_FILE
    flag.touch()
    try:
        waiting = [future for future, run in pending.items() if not started(run)]
        client.cancel(waiting)
        for future in waiting:  # not started: they stay pending
            pending.pop(future)
        deadline = time.monotonic() + STOP_WAIT
        while pending and time.monotonic() < deadline:
            collect()
            time.sleep(0.1)
    finally:
        client.cancel(list(pending))


def with_unsubscribe(client: Any) -> None:
    try:
        client.unsubscribe_topic(EVENT_TOPIC)
    except Exception:  # noqa: BLE001 - a client that lost its scheduler
        pass


def report(sweep: Sweep) -> str:
    """What the sweep did: counts, then every run not done by name with its error."""
    counts = sweep.counts()
    lines = [f"{len(sweep.runs)} runs: {counts['done']} done, {counts['failed']} failed, {counts['pending']} not finished"]
    for run in sweep.runs:
        if run["status"] != "done":
            error = str(run.get("error") or progress_of(sweep.folder(run))).splitlines()
            lines.append(f"  {run['status']}: {run['name']}: {error[-1] if error else ''}")
    return "\n".join(lines)


def progress_of(folder: Path) -> str:
    """What a run not finished and without an error got to, from its folder: ``"not started"``,
    or ``"started, cut short; its latest snapshot: step N"`` (what ``--resume`` continues from;
    a run stopped before its first snapshot starts again)."""
    if not attempts_of(folder):
        return "not started"
    latest = RunFolder(folder).latest_snapshot()
    return "started, cut short; " + ("no snapshot yet" if latest is None else
                                     f"its latest snapshot: step {int(latest.stem.split('_')[-1])}")


# ------------------------------------------------------------------------------------------
# Command
# ------------------------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``qpcontact sweep``."""
    parser.description = (
        "Replicates and parameter sweeps of colony runs (qpcontact simulate), each run a task on Dask: a local "
        "cluster by default, --scheduler for an existing one. Runs: every seed of --seeds with every combination of "
        "the --vary lists (or [sweep] in --config); every run's settings are checked before any starts. Writes into "
        "--out: runs/NAME/ (each run's snapshots, history, pictures, as qpcontact simulate), sweep.json (the runs and "
        "their status), summary.csv (one row per run) and ensemble.png (mean and range across seeds against time). "
        "Ctrl-C or a lost worker loses no finished run: --resume continues, redoing only what is not done.\n\n"
        "Example: qpcontact sweep --cells 500 --seeds 1,2,3 --vary growth_inertia_ratio=100,1000 --vary "
        "position_overlap_tolerance=0.01,0.02")
    grid = parser.add_argument_group("the grid")
    grid.add_argument("--config", type=Path, metavar="FILE",
                      help="settings in the tables of the config.toml of qpcontact simulate ([model], [run], ...) and "
                           "a [sweep] table: seeds = [1, 2], zip = false, [sweep.vary] name = [values]; flags override "
                           "it")
    seeds = grid.add_mutually_exclusive_group()
    seeds.add_argument("--seeds", type=comma_list(non_negative_int), metavar="LIST",
                       help="comma-separated random seeds, one run each per combination (default: --seed's)")
    seeds.add_argument("--replicates", type=positive_int, metavar="N", help="the seeds 1, 2, ..., N")
    grid.add_argument("--vary", type=parse_vary, action="append", metavar="NAME=LIST",
                      help="a setting and its comma-separated values (repeat for several; a setting is named by its "
                           "flag without the dashes, or table.key: growth_inertia_ratio=100,1000, cells=500,2000, "
                           "position_solver=ipm,mprgp, velocity.tolerance=1e-4,1e-6)")
    grid.add_argument("--zip", action="store_true",
                      help="take the --vary lists side by side (a list of runs; equal lengths) instead of every "
                           "combination")
    run = parser.add_argument_group("the sweep")
    run.add_argument("--resume", action="store_true",
                     help="continue the sweep in --out: run what is not done, continue the runs that were cut short "
                          "from their latest snapshot (no grid or setting flags then)")
    run.add_argument("--out", type=output_folder, default=Path("sweep-out"), metavar="FOLDER",
                     help="output folder (default: ./sweep-out); checked before anything starts")
    run.add_argument("--overwrite", action="store_true",
                     help="replace the sweep already in --out (its files are removed first; default: refuse)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    cluster.add_cluster_arguments(parser, local_by_default=True)
    add_setting_flags(parser, " (every run's, as in qpcontact simulate; a varied one is replaced)")


def _grid_flags(args: argparse.Namespace) -> list[str]:
    flag_of = {s.path: s.flag for s in settings_of(Settings)}
    given = [flag_of[path] for path in flag_layer(args).values]
    for flag, value in (("--config", args.config), ("--seeds", args.seeds), ("--replicates", args.replicates),
                        ("--vary", args.vary), ("--zip", args.zip), ("--overwrite", args.overwrite)):
        if value:
            given.append(flag)
    return given


def prepare(args: argparse.Namespace) -> tuple[Sweep, list[dict[str, Any]]]:
    """Every check before the work: the grid and each run's settings, the model hooks, the
    output folder; ``(sweep, the runs to do)``."""
    cluster.require_distributed()
    out = args.out.resolve()
    if args.resume:
        given = _grid_flags(args)
        if given:
            raise InvalidArgumentError(f"--resume continues the sweep of {args.out} as it was planned; drop "
                                       f"{', '.join(given)}")
        sweep = Sweep.load(out)
        prepare_folder(out)
        (out / STOP_FILE).unlink(missing_ok=True)  # left by a sweep that could not remove it
        return sweep, sweep.to_do()
    base, grid, layers = configure(args)
    runs = plan_runs(base, grid)
    refuse_unused([Settings.from_stored(run["settings"], run["name"]) for run in runs],
                  [*layers, grid_layer("--vary", {name: values[0] for name, values in grid.vary.items()})])
    for hook in sorted({run["settings"]["model"]["hook"] for run in runs} - {""}):
        load_hook(hook)
    for run in runs:  # a target no run can reach (rate 0, no hook): refused now, not after max_steps
        settings = Settings.from_stored(run["settings"], run["name"])
        try:
            check_target(settings, founder(settings), settings.model.hook)
        except InvalidArgumentError as exc:
            raise InvalidArgumentError(f"run {run['name']}: {exc}") from None
    if (out / SWEEP_FILE).exists() and not args.overwrite:
        raise OutputFolderError(f"{args.out} holds a sweep ({SWEEP_FILE}); continue it with --resume, or pass "
                                "--overwrite to replace it")
    prepare_folder(out, OUTPUTS, overwrite=args.overwrite)
    (out / STOP_FILE).unlink(missing_ok=True)
    sweep = Sweep.new(out, runs, base, grid)
    sweep.save()
    return sweep, list(sweep.runs)


def run_command(args: argparse.Namespace) -> int:
    sweep, runs = prepare(args)  # a QPContactError here: exit 2, nothing started
    print(f"sweep of {len(sweep.runs)} runs into {args.out}" + (f"; {len(runs)} to do" if args.resume else "")
          + (f" on {args.scheduler}" if args.scheduler else ""), file=sys.stderr)
    completed = True
    if runs:
        try:
            with cluster.open_client(args.scheduler, args.workers or min(len(runs), os.cpu_count() or 1)) as client:
                cluster.check_workers_can_write(client, sweep.out)
                completed = execute(sweep, client, runs, progress=not args.quiet)
        except KeyboardInterrupt:  # while the cluster started or closed: the runs stay as they are
            completed = False
        if not args.scheduler:  # the local cluster is closed: no task of this sweep can start any more
            (sweep.out / STOP_FILE).unlink(missing_ok=True)
    sweep.to_do()  # runs that finished while the sweep stopped, or whose answer was lost, are done
    written = [sweep.save(), sweep.write_summary()]
    ensemble = sweep.write_ensemble()
    if ensemble is not None:
        written.append(ensemble)
    written += [sweep.folder(run) for run in sweep.runs if sweep.folder(run).is_dir()]
    print(report(sweep))
    print(describe_written(written))
    if not completed:
        print(f"qpcontact sweep: interrupted; continue with: qpcontact sweep --resume --out {args.out}", file=sys.stderr)
        return 130
    counts = sweep.counts()
    if counts["failed"] or counts["pending"]:
        print(f"qpcontact sweep: {counts['failed']} runs failed, {counts['pending']} did not finish (listed above); "
              f"--resume --out {args.out} runs them again", file=sys.stderr)
        return 1
    return 0


def main(argv: list[str] | None = None) -> int:
    return run_standalone("qpcontact sweep", add_arguments, run_command, argv)


if __name__ == "__main__":
    sys.exit(main())


