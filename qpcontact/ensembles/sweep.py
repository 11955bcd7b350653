"""``qpcontact sweep``: replicates and parameter sweeps of colony runs, as tasks on Dask.

A sweep is a grid of colony runs (:func:`qpcontact.simulation.run_colony`): seeds × the settings that
vary, each combination of the varied values with each seed (``--zip``: the varied lists taken
side by side, a list of runs, instead of their product)::

    qpcontact sweep --cells 500 --seeds 1,2,3 --vary growth_inertia_ratio=100,1000 --vary position_overlap_tolerance=0.01,0.02

or from a configuration file (``--config sweep.toml``): the tables of ``qpcontact simulate``'s
settings (:mod:`qpcontact.simulation.settings`), and a ``[sweep]`` table with ``seeds = [1, 2, 3]``,
``zip = false`` and ``[sweep.vary]`` lists (``growth_inertia_ratio = [100, 1000]``); flags
override the file. A varied setting is named as its flag without the dashes (underscores or
dashes) or by its path (``position.tolerance``). Every run's settings are merged as
``simulate``'s are (:func:`qpcontact.simulation.settings.merge`: defaults, ``--config``, the flags,
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
from the run's latest snapshot (exactly, :meth:`qpcontact.io.runs.RunFolder.resume`), and one
whose run is finished returns its result. So a worker that dies takes with it only the steps since
its run's last snapshot (Dask gives the task to another worker, up to
``distributed.scheduler.allowed-failures`` = 3 deaths), and ``qpcontact sweep --resume --out DIR``
after a stop (Ctrl-C, a lost scheduler) runs only what is not done. Failed runs are listed by
name with their error at the end and in the summary; the exit status is 1 if any run failed or
did not finish, 130 after Ctrl-C.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from .. import moved
from ..cli import comma_list, non_negative_int, output_folder, positive_int, run_standalone
from ..colony.hooks import load_hook
from ..errors import InvalidArgumentError, OutputFolderError
from ..io.outputs import describe_written, prepare_folder, write_csv, write_text
from ..io.runs import LEFTOVERS, RUN_OUTPUTS, RunFolder
from ..schema import Layer, settings_of
from ..simulation.loop import check_target, founder
from ..simulation.settings import Settings, add_setting_flags, file_layer, flag_layer, merge, refuse_unused
from . import cluster, submit, tasks
from . import grid as grids

__all__ = ["ENSEMBLE_FILE", "FORMAT", "OUTPUTS", "SUMMARY_FILE", "SWEEP_FILE", "Sweep", "add_arguments", "configure",
           "main", "prepare", "progress_of", "report", "run_command"]

SWEEP_FILE = "sweep.json"
SUMMARY_FILE = "summary.csv"
ENSEMBLE_FILE = "ensemble.png"
#: Every file a sweep writes in its folder (glob patterns).
OUTPUTS = (SWEEP_FILE, SUMMARY_FILE, ENSEMBLE_FILE,
           *(f"runs/*/{pattern}" for pattern in (*RUN_OUTPUTS, *LEFTOVERS, tasks.RESULT_FILE, tasks.ATTEMPTS_FILE)))
FORMAT = "qpcontact-sweep"


def __getattr__(name: str) -> Any:
    """The names that moved out of this module (deprecated; :mod:`qpcontact.moved`)."""
    return moved.attribute(__name__, name, moved.NAMES[__name__])


def configure(args: argparse.Namespace) -> tuple[Settings, grids.Grid, list[Layer]]:
    """The base settings, the grid and the layers the settings came from (for
    :func:`qpcontact.simulation.settings.refuse_unused` once the runs are known): later sources
    winning, the defaults, ``--config`` (its ``[sweep]`` table for the grid), the flags."""
    layers: list[Layer] = []
    table: dict[str, Any] = {}
    source = "command line"
    if args.config is not None:
        values, table = grids.read_config(args.config)
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
        field, converted = grids.varied_values(name, values, where)
        vary[field] = converted
    seeds = args.seeds or (list(range(1, args.replicates + 1)) if args.replicates else None) or table.get("seeds")
    if seeds is None:
        seeds = [settings.run.seed]
    if not (isinstance(seeds, list) and seeds and all(isinstance(s, int) and not isinstance(s, bool) and s >= 0
                                                      for s in seeds)):
        raise InvalidArgumentError(f"{source}: seeds must be a non-empty list of integers >= 0, got {seeds!r}")
    zip_ = args.zip or bool(table.get("zip", False))
    return settings, grids.Grid(vary, list(seeds), zip_), layers


# ------------------------------------------------------------------------------------------
# The sweep's own files
# ------------------------------------------------------------------------------------------
class Sweep(tasks.PlanFolder):
    """A sweep's folder: ``sweep.json`` (the runs and their status), the run folders, the
    summary and the ensemble picture."""

    @property
    def varied(self) -> list[str]:
        return list(self.runs[0]["varied"]) if self.runs else []

    @classmethod
    def new(cls, out: Path, runs: list[dict[str, Any]], base: Settings, grid: grids.Grid) -> Sweep:
        document = {"format": FORMAT, "version": 2, "created": datetime.now(UTC).isoformat(timespec="seconds"),
                    "base": base.to_tables(), "vary": grid.vary, "seeds": grid.seeds, "zip": grid.zip, "runs": runs}
        return cls(out, document)

    @classmethod
    def load(cls, out: Path) -> Sweep:
        """The sweep in ``out`` (``--resume``), each run's settings checked again.

        Raises:
            OutputFolderError: no sweep there, or its ``sweep.json`` cannot be read.
        """
        document = tasks.read_json(out / SWEEP_FILE)
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
            result = tasks.read_json(self.folder(run) / tasks.RESULT_FILE)
            if isinstance(result, dict) and result.get("status") == "done":
                self.record(run, result)
            else:
                out.append(run)
        return out

    def record(self, run: dict[str, Any], outcome: Mapping[str, Any]) -> None:
        run.update(status=outcome["status"], error=outcome.get("error", ""),
                   measures={k: outcome[k] for k in tasks.MEASURES if k in outcome})
        if outcome.get("traceback"):
            run["traceback"] = outcome["traceback"]
        else:
            run.pop("traceback", None)

    def counts(self) -> dict[str, int]:
        return {status: sum(run["status"] == status for run in self.runs) for status in ("done", "failed", "pending")}

    # -- summary and picture ------------------------------------------------------------------
    def summary_columns(self) -> tuple[str, ...]:
        return ("name", "status", *self.varied, "step", "growth", *tasks.MEASURES, "error")

    def write_summary(self) -> Path:
        rows = []
        for run in self.runs:
            measures = dict(run.get("measures", {}))
            measures["attempts"] = len(tasks.attempts_of(self.folder(run)))
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
            key = ", ".join(f"{k} = {grids.label(v)}" for k, v in run["varied"].items() if k != "seed") or "all runs"
            groups.setdefault(key, []).append(history)
        if not groups:
            return None
        from ..io.plots import plot_ensemble

        return plot_ensemble(self.out / ENSEMBLE_FILE, groups)


# ------------------------------------------------------------------------------------------
# What it did
# ------------------------------------------------------------------------------------------


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
    if not tasks.attempts_of(folder):
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
    grid.add_argument("--vary", type=grids.parse_vary, action="append", metavar="NAME=LIST",
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
        (out / tasks.STOP_FILE).unlink(missing_ok=True)  # left by a sweep that could not remove it
        return sweep, sweep.to_do()
    base, grid, layers = configure(args)
    runs = grids.plan_runs(base, grid)
    refuse_unused([Settings.from_stored(run["settings"], run["name"]) for run in runs],
                  [*layers, grids.grid_layer("--vary", {name: values[0] for name, values in grid.vary.items()})])
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
    (out / tasks.STOP_FILE).unlink(missing_ok=True)
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
                completed = submit.execute(sweep, client, runs, progress=not args.quiet)
        except KeyboardInterrupt:  # while the cluster started or closed: the runs stay as they are
            completed = False
        if not args.scheduler:  # the local cluster is closed: no task of this sweep can start any more
            (sweep.out / tasks.STOP_FILE).unlink(missing_ok=True)
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


