"""``qpcontact convergence``: the colony's error against run time, as the step shrinks.

Grows the same colony (``qpcontact simulate``'s settings: the defaults, ``--config``, the setting
flags) at each step size of ``--growth-per-step`` (the growth time step: the fastest cell grows
this fraction of its length per step) with each seed of ``--seeds``, measures each final colony
(:func:`qpcontact.colony.colony_statistics`, docs/statistics.md) and reports every statistic per
step size as its mean and range over the seeds, and its error: the mean less the mean at the
finest step, beside the finest step's own spread over the seeds (an error within that spread
cannot be told from the seed). With each step size: the run time (the sum of the steps' times in
the run's history, so that a run continued after a stop counts once), the steps and the
linearizations of the position step.

Each run is a run of :func:`qpcontact.simulation.run_colony` in its own folder ``runs/<name>/``
(``growth_per_step-0.05__seed-1``), in the format of ``qpcontact simulate`` and run as a sweep's
task (:func:`qpcontact.ensembles.tasks.run_task`): its ``result.json`` once it is finished, and
``statistics.json``, the statistics of its final colony. Runs go one after another in this
process, the cheapest step first. Nothing finished is lost: a study stopped (Ctrl-C, a killed
process) is continued by ``qpcontact convergence --resume --out FOLDER``, which skips the runs
that are finished and continues a run cut short from its latest snapshot (exactly, as a sweep
does; ``--snapshot-every`` sets how much of a run a kill can lose).

Writes into ``--out`` (default ``./convergence-out``): ``convergence.json`` (the study: every
run's settings and status, written as each run ends), ``runs.csv`` (one row per run: step size,
seed, status, run time, steps, linearizations, every statistic), ``convergence.csv`` (one row per
step size: runs, run time, steps and linearizations, and for each statistic of
:data:`TABLED` its mean, min, max and error), ``convergence.png`` (each statistic's error against
the run time, with the seeds' range; the finest step's spread as a band) and prints the table.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from ..cli import comma_list, non_negative_int, output_folder, positive_float, run_standalone
from ..colony.statistics import DEFINITIONS, colony_statistics
from ..ensembles.grid import grid_layer, run_name
from ..ensembles.tasks import ATTEMPTS_FILE, LOCK_FILE, RESULT_FILE, PlanFolder, read_json, run_task
from ..errors import InvalidArgumentError, OutputFolderError
from ..io.outputs import describe_written, prepare_folder, replacing, write_csv, write_text
from ..io.runs import LEFTOVERS, RUN_OUTPUTS, RunFolder
from ..io.snapshots import load_snapshot
from ..schema import Layer, settings_of
from ..simulation.settings import (
    GROWTH_PER_STEP,
    Settings,
    add_setting_flags,
    file_layer,
    flag_layer,
    merge,
    refuse_unused,
)

FORMAT = "qpcontact-convergence"
PLAN_FILE = "convergence.json"
RUNS_FILE = "runs.csv"
TABLE_FILE = "convergence.csv"
PLOT_FILE = "convergence.png"
#: In each run's folder: the statistics of its final colony.
STATISTICS_FILE = "statistics.json"
#: Every file the study writes in its folder (glob patterns).
OUTPUTS = (PLAN_FILE, RUNS_FILE, TABLE_FILE, PLOT_FILE,
           *(f"runs/*/{pattern}" for pattern in (*RUN_OUTPUTS, *LEFTOVERS, RESULT_FILE, STATISTICS_FILE, ATTEMPTS_FILE,
                                                 LOCK_FILE)))
#: The statistics printed and plotted, by dimensions (issue 32's).
REPORTED = {2: ("packing", "contacts_per_cell", "nematic_length", "local_order", "edge_alignment"),
            3: ("bottom_order", "vertical_fraction", "median_height", "bottom_fraction", "xy_radius")}
#: The statistics in ``convergence.csv``, by dimensions.
TABLED = {2: (*REPORTED[2], "order", "length_mean", "length_sd", "aspect_ratio", "xy_radius"),
          3: (*REPORTED[3], "contacts_per_cell", "elevation_mean", "order", "length_mean", "length_sd",
              "aspect_ratio")}
#: What each run costs, from its history.
COSTS = ("run_seconds", "steps", "linearizations")
#: Default step sizes: the run's growth per step (the scene's by default: 0.05 in 2D, 0.00625 in
#: 3D) divided by each of these.
DEFAULT_DIVISORS = (4, 2, 1)


# ------------------------------------------------------------------------------------------
# The plan
# ------------------------------------------------------------------------------------------
def plan_runs(base: Settings, steps: Sequence[float], seeds: Sequence[int]) -> list[dict[str, Any]]:
    """Every run: ``base`` with each step size and seed (:meth:`Settings.updated`), the cheapest
    (largest) step first; ``name``, ``growth_per_step``, ``seed``, ``settings`` (tables),
    ``status``."""
    runs = []
    for step in sorted(steps, reverse=True):
        for seed in seeds:
            varied = {"growth_per_step": step, "seed": seed}
            settings = base.updated(varied, f"run {run_name(varied)}")
            runs.append({"name": run_name(varied), "growth_per_step": step, "seed": seed,
                         "settings": settings.to_tables(), "status": "pending", "error": ""})
    return runs


class Study(PlanFolder):
    """A study's folder: ``convergence.json`` (the plan and each run's status) and the runs'
    folders."""

    @property
    def dimensions(self) -> int:
        return int(self.document["base"]["run"]["dimensions"])

    @classmethod
    def new(cls, out: Path, base: Settings, steps: Sequence[float], seeds: Sequence[int]) -> Study:
        return cls(out, {"format": FORMAT, "version": 1, "created": datetime.now(UTC).isoformat(timespec="seconds"),
                         "base": base.to_tables(), "growth_per_step": sorted(steps), "seeds": list(seeds),
                         "runs": plan_runs(base, steps, seeds)})

    @classmethod
    def load(cls, out: Path) -> Study:
        """The study in ``out`` (``--resume``), each run's settings checked again.

        Raises:
            OutputFolderError: no study there, or its ``convergence.json`` cannot be read.
        """
        document = read_json(out / PLAN_FILE)
        if document is None:
            raise OutputFolderError(f"{out}: holds no convergence study to resume ({PLAN_FILE} is missing or unreadable)")
        if not isinstance(document, dict) or document.get("format") != FORMAT or not isinstance(document.get("runs"), list):
            raise OutputFolderError(f"{out / PLAN_FILE}: not a qpcontact convergence study")
        for run in document["runs"]:
            run["settings"] = Settings.from_stored(run["settings"], f"{out / PLAN_FILE}: run {run['name']}").to_tables()
        return cls(out, document)

    def save(self) -> Path:
        return write_text(self.out / PLAN_FILE, json.dumps(self.document, indent=1, default=float) + "\n")


# ------------------------------------------------------------------------------------------
# One run
# ------------------------------------------------------------------------------------------
def run_one(study: Study, run: dict[str, Any]) -> dict[str, Any]:
    """Run (or continue, or find finished) one run of the study in its folder, and record its
    outcome, costs and statistics in ``run`` (``convergence.json`` is saved). Returns ``run``.
    A run stopped by Ctrl-C raises :class:`KeyboardInterrupt` once its state is saved."""
    folder = study.folder(run)
    outcome = run_task(run["name"], run["settings"], str(folder))
    if outcome["status"] == "stopped":
        raise KeyboardInterrupt
    run.update(status=outcome["status"], error=outcome.get("error", ""))
    if outcome["status"] == "done":
        run.update(costs(folder), statistics=statistics_of(folder, study.dimensions))
    study.save()
    return run


def costs(folder: Path) -> dict[str, float]:
    """A run's run time [s] (its steps' times), steps and linearizations, from its history."""
    history = RunFolder(folder).read_history()
    steps = int(history["step"][-1]) + 1 if history["step"] else 0
    return {"run_seconds": float(np.sum(history["step_seconds"])), "steps": steps,
            "linearizations": int(np.nansum(history["linearizations"]))}


def statistics_of(folder: Path, dimensions: int) -> dict[str, float]:
    """The statistics of a finished run's final colony (its latest snapshot), as numbers by name;
    kept in its folder (``statistics.json``) once measured."""
    path = folder / STATISTICS_FILE
    stored = read_json(path)
    if isinstance(stored, dict):
        return stored
    latest = RunFolder(folder).latest_snapshot()
    if latest is None:
        raise OutputFolderError(f"{folder}: a finished run without a snapshot")
    values = colony_statistics(load_snapshot(latest), dimensions=dimensions).scalars()
    write_text(path, json.dumps(values, indent=1) + "\n")
    return values


# ------------------------------------------------------------------------------------------
# The tables and the picture
# ------------------------------------------------------------------------------------------
def summary(study: Study) -> list[dict[str, Any]]:
    """One row per step size (finest first): ``growth_per_step``, ``runs`` (finished),
    ``failed``, the costs' means, min and max, and for each statistic of :data:`TABLED` its
    ``_mean``, ``_min``, ``_max`` and ``_error`` (mean less the finest step's mean; NaN until
    the finest step has a finished run)."""
    names = TABLED[study.dimensions]
    rows = []
    for step in sorted({run["growth_per_step"] for run in study.runs}):
        runs = [run for run in study.runs if run["growth_per_step"] == step]
        done = [run for run in runs if run["status"] == "done"]
        row: dict[str, Any] = {"growth_per_step": step, "runs": len(done),
                               "failed": sum(run["status"] == "failed" for run in runs)}
        for name, values in [*((c, [run[c] for run in done]) for c in COSTS),
                             *((n, [run["statistics"][n] for run in done]) for n in names)]:
            array = np.asarray(values, dtype=float)
            row.update({f"{name}_mean": float(np.mean(array)) if len(array) else math.nan,
                        f"{name}_min": float(np.min(array)) if len(array) else math.nan,
                        f"{name}_max": float(np.max(array)) if len(array) else math.nan})
        rows.append(row)
    for row in rows:
        for name in names:
            with np.errstate(invalid="ignore"):
                row[f"{name}_error"] = float(row[f"{name}_mean"] - rows[0][f"{name}_mean"])
    return rows


def summary_columns(dimensions: int) -> list[str]:
    columns = ["growth_per_step", "runs", "failed"]
    columns += [f"{c}_{s}" for c in COSTS for s in ("mean", "min", "max")]
    columns += [f"{n}_{s}" for n in TABLED[dimensions] for s in ("mean", "min", "max", "error")]
    return columns


def write_tables(study: Study) -> list[Path]:
    """``runs.csv`` and ``convergence.csv``, atomically."""
    names = [name for name in DEFINITIONS if not name.endswith("_profile")]
    run_rows = [{"name": run["name"], "growth_per_step": run["growth_per_step"], "seed": run["seed"],
                 "status": run["status"], **{c: run.get(c) for c in COSTS}, **run.get("statistics", {}),
                 "error": " ".join(str(run.get("error", "")).split())} for run in study.runs]
    written = []
    for path, rows, columns in (
            (study.out / RUNS_FILE, run_rows, ["name", "growth_per_step", "seed", "status", *COSTS, *names, "error"]),
            (study.out / TABLE_FILE, summary(study), summary_columns(study.dimensions))):
        with replacing(path) as temporary:
            write_csv(rows, temporary, columns, digits=6)
        written.append(path)
    return written


def _spread(row: Mapping[str, Any], name: str, digits: int) -> str:
    mean, low, high = (row[f"{name}_{s}"] for s in ("mean", "min", "max"))
    if math.isnan(mean):
        return "–"
    text = f"{mean:.{digits}f}"
    return text if row["runs"] < 2 else f"{text} ({low:.{digits}f}–{high:.{digits}f})"


def format_table(study: Study) -> str:
    """The study as text: per step size the runs, run time, steps and linearizations, and each
    reported statistic's mean (range over the seeds) and error against the finest step."""
    rows = summary(study)
    names = REPORTED[study.dimensions]
    header = ["growth/step", "runs", "run time [s]", "steps", "linearizations",
              *(f"{n} [{DEFINITIONS[n][0]}]" if DEFINITIONS[n][0] not in ("", "dimensionless") else n for n in names)]
    lines = []
    for row in rows:
        failed = f" +{row['failed']} failed" if row["failed"] else ""
        cells = [f"{row['growth_per_step']:g}", f"{row['runs']}{failed}", _spread(row, "run_seconds", 1),
                 _spread(row, "steps", 0), _spread(row, "linearizations", 0)]
        for name in names:
            error = row[f"{name}_error"]
            shown = _spread(row, name, 3)
            cells.append(shown if math.isnan(error) or row is rows[0] else f"{shown} Δ{error:+.3f}")
        lines.append(cells)
    widths = [max(len(str(c)) for c in column) for column in zip(header, *lines, strict=True)]
    text = ["  ".join(str(c).ljust(w) for c, w in zip(line, widths, strict=True)) for line in [header, *lines]]
    finest = rows[0]["growth_per_step"] if rows else math.nan
    return (f"{study.dimensions}D, {study.document['base']['run']['cells']} cells, seeds "
            f"{', '.join(map(str, study.document['seeds']))}: mean (min–max over the seeds), Δ: error against the "
            f"finest step ({finest:g})\n" + "\n".join(text))


def plot(study: Study) -> Path | None:
    """``convergence.png``: each reported statistic's error (mean less the finest step's mean,
    bars: the seeds' range) against the run time, the finest step's spread as a band; and the
    run time against the step size. None if no step size has a finished run."""
    from matplotlib.figure import Figure

    rows = [row for row in summary(study) if row["runs"]]
    if not rows:
        return None
    fig = Figure(figsize=(13, 7.5), dpi=110, layout="constrained")
    axes = fig.subplots(2, 3).ravel()
    finest = summary(study)[0]
    for ax, name in zip(axes, REPORTED[study.dimensions], strict=False):
        base = finest[f"{name}_mean"]
        if np.isfinite(base):
            ax.axhspan(finest[f"{name}_min"] - base, finest[f"{name}_max"] - base, color="0.85",
                       label=f"finest step's seeds ({finest['growth_per_step']:g})")
        shown = [r for r in rows if np.isfinite(r[f"{name}_error"]) and np.isfinite(r[f"{name}_mean"])]
        x = np.array([r["run_seconds_mean"] for r in shown])
        y = np.array([r[f"{name}_error"] for r in shown])
        low = np.array([r[f"{name}_mean"] - r[f"{name}_min"] for r in shown])
        high = np.array([r[f"{name}_max"] - r[f"{name}_mean"] for r in shown])
        ax.errorbar(x, y, yerr=[low, high], fmt="o-", capsize=3)
        for r, xi, yi in zip(shown, x, y, strict=True):
            ax.annotate(f"{r['growth_per_step']:g}", (xi, yi), textcoords="offset points", xytext=(4, 4), fontsize=8)
        unit = DEFINITIONS[name][0]
        ax.set(xscale="log", xlabel="run time [s]", title=name,
               ylabel=f"error against the finest step{'' if unit in ('', 'dimensionless') else f' [{unit}]'}")
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.grid(alpha=0.3)
        if np.isfinite(base):
            ax.legend(fontsize="small")
    ax = axes[-1]
    ax.plot([r["growth_per_step"] for r in rows], [r["run_seconds_mean"] for r in rows], "o-")
    ax.set(xscale="log", yscale="log", xlabel="growth per step [fraction of the length]", ylabel="run time [s]",
           title="run time (mean over the seeds)")
    ax.grid(alpha=0.3)
    fig.suptitle(f"Error against run time: {study.dimensions}D colony of {study.document['base']['run']['cells']} "
                 "cells, each statistic's mean over the seeds less the finest step's")
    path = study.out / PLOT_FILE
    with replacing(path) as temporary:
        fig.savefig(temporary, format="png")
    return path


# ------------------------------------------------------------------------------------------
# Command
# ------------------------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``qpcontact convergence``."""
    parser.description = (
        "The colony's error against run time: grows the same colony (qpcontact simulate's settings) at each step size "
        "of --growth-per-step with each seed of --seeds, measures each final colony (packing, contacts per cell, "
        "nematic correlation length, local order, edge alignment; 3D: the biofilm's layers; docs/statistics.md) and "
        "reports each statistic's mean and range over the seeds and its error against the finest step, with the run "
        "time, steps and linearizations of each. Writes into --out: runs/NAME/ (each run, as qpcontact simulate), "
        "convergence.json, runs.csv, convergence.csv and convergence.png; prints the table. Stopped, it is continued "
        "with --resume.\n\n"
        "Example: qpcontact convergence --cells 5000 --growth-per-step 0.00625,0.0125,0.025,0.05 --seeds 1,2,3")
    # "resolve": the study's --growth-per-step (a list), added last, replaces the setting's flag
    study = parser.add_argument_group("the study", conflict_handler="resolve")
    study.add_argument("--seeds", type=comma_list(non_negative_int), metavar="LIST",
                       help="comma-separated random seeds, one run each per step size (default: --seed's)")
    study.add_argument("--config", type=Path, metavar="FILE",
                       help="settings in the tables of the config.toml of qpcontact simulate; flags override it")
    study.add_argument("--resume", action="store_true",
                       help="continue the study in --out: the runs not finished (a run cut short from its latest "
                            "snapshot); no other settings then")
    study.add_argument("--out", type=output_folder, default=Path("convergence-out"), metavar="FOLDER",
                       help="output folder (default: ./convergence-out); checked before anything starts")
    study.add_argument("--overwrite", action="store_true",
                       help="replace the study already in --out (its files are removed first; default: refuse)")
    add_setting_flags(parser, " (every run's, as in qpcontact simulate)")
    study.add_argument("--growth-per-step", dest="steps", type=comma_list(positive_float), metavar="LIST",
                       help="comma-separated growth time steps (growth of the fastest cell per step, a fraction of "
                            "its length), two or more; the finest is the reference (default: the run's growth per "
                            "step and two halvings: " + "; ".join(
                                f"{','.join(f'{step / k:g}' for k in DEFAULT_DIVISORS)} in {d}D"
                                for d, step in GROWTH_PER_STEP.items()) + ")")


def configure(args: argparse.Namespace) -> tuple[Settings, list[float], list[int]]:
    """The base settings (the defaults, ``--config``, the flags: merged as ``qpcontact simulate``
    merges them), the step sizes and the seeds, every run's settings checked.

    Raises:
        InvalidArgumentError: fewer than two step sizes, repeated ones, a setting no run uses
            (the growth per step with another time step rule), bad settings.
    """
    layers: list[Layer] = []
    if args.config is not None:
        layers.append(file_layer(args.config))
    layers.append(flag_layer(args))
    base = merge(layers)
    if base.output.snapshot_every == 0:
        raise InvalidArgumentError("--snapshot-every 0: a run cut short continues from its latest snapshot; give a "
                                   "number of steps >= 1")
    steps = list(args.steps or [base.growth_per_step() / k for k in DEFAULT_DIVISORS])
    if len(steps) < 2 or len(set(steps)) != len(steps):
        raise InvalidArgumentError(f"--growth-per-step: expected two or more different step sizes (the finest is the "
                                   f"reference), got {','.join(map(str, steps))}")
    seeds = list(args.seeds or [base.run.seed])
    if len(set(seeds)) != len(seeds):
        raise InvalidArgumentError(f"--seeds: each seed once, got {','.join(map(str, seeds))}")
    runs = [base.updated({"growth_per_step": step, "seed": seed}, "--growth-per-step") for step in steps for seed in seeds]
    refuse_unused(runs, [*layers, grid_layer("--growth-per-step", {"growth_per_step": steps[0]})])
    return base, steps, seeds


def prepare(args: argparse.Namespace) -> Study:
    """Every check before the work: the settings, the output folder; the study (new, or the one
    in ``--out`` with ``--resume``)."""
    out = args.out.resolve()
    if args.resume:
        given = [flag for flag, value in (("--growth-per-step", args.steps), ("--seeds", args.seeds),
                                          ("--config", args.config), ("--overwrite", args.overwrite)) if value]
        flag_of = {s.path: s.flag for s in settings_of(Settings)}
        given += [flag_of[path] for path in flag_layer(args).values]
        if given:
            raise InvalidArgumentError(f"--resume continues the study in {args.out} as it was planned; drop "
                                       f"{', '.join(given)}")
        study = Study.load(out)
        prepare_folder(out)
        return study
    base, steps, seeds = configure(args)
    if (out / PLAN_FILE).exists() and not args.overwrite:
        raise OutputFolderError(f"{args.out} holds a convergence study ({PLAN_FILE}); continue it with --resume, or "
                                "pass --overwrite to replace it")
    prepare_folder(out, OUTPUTS, overwrite=args.overwrite)
    study = Study.new(out, base, steps, seeds)
    study.save()
    return study


def run_command(args: argparse.Namespace) -> int:
    study = prepare(args)  # a QPContactError here: exit 2, nothing started
    to_do = [run for run in study.runs if run["status"] != "done"]
    print(f"convergence study of {len(study.runs)} runs into {args.out}"
          + (f"; {len(to_do)} to do" if args.resume else ""), file=sys.stderr)
    interrupted = False
    try:
        for run in to_do:
            run_one(study, run)
            said = (f"{run['run_seconds']:.1f} s, {run['steps']} steps, {run['linearizations']} linearizations"
                    if run["status"] == "done" else run["error"])
            print(f"  {run['name']}: {run['status']}: {said}", file=sys.stderr)
    except KeyboardInterrupt:
        interrupted = True
    written = [study.save(), *write_tables(study)]
    picture = plot(study)
    if picture is not None:
        written.append(picture)
    print(format_table(study))
    print(describe_written(written))
    if interrupted:
        print(f"qpcontact convergence: interrupted; continue with: qpcontact convergence --resume --out {args.out}",
              file=sys.stderr)
        return 130
    failed = [run for run in study.runs if run["status"] != "done"]
    for run in failed:
        print(f"qpcontact convergence: {run['name']}: {run['status']}: {run['error']}", file=sys.stderr)
    return 1 if failed else 0


def main(argv: list[str] | None = None) -> int:
    return run_standalone("qpcontact convergence", add_arguments, run_command, argv)


if __name__ == "__main__":
    sys.exit(main())
