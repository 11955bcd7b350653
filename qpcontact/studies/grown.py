"""``qpcontact bench-grown``: the benchmark that counts — colonies grown from one cell.

A benchmark snapshot (:mod:`qpcontact.studies.bench`) is packed once and solved once; a colony
grown by ``qpcontact simulate`` is jammed, nearly incompressible and stepped thousands of times,
and its step costs 13–200 times the snapshot's (docs/performance.md). This benchmark measures that
workload, every step kind side by side in one run on this machine:

1. **Time to grow**: ``qpcontact simulate``'s run (:func:`qpcontact.simulation.run_colony`, seed 1,
   its defaults otherwise) from one cell, for each dimension and step (``position``, the
   default; ``velocity``, the earlier step, stopped at ``--velocity-cells``): the wall time until
   the colony first has each size in ``--sizes``, the steps and linearizations taken, the largest
   overlap over the run (fraction of the diameter), the colony's doubling time over its last
   doubling against the cells' own (growth bought by compressing cells shows here), and the peak
   resident memory of the run's process. Each run is a child process (its memory is its own).
2. **One step of a grown colony**: from the states the position runs reached at each size (saved
   in ``--cache-dir``, reused by later benchmarks), one step with each step kind and solver
   (median of ``--repeats`` steps from the same state): the position step with each of
   ``--position-solvers``, the velocity step with Clarabel at 10⁻⁶ and OSQP at 10⁻³.
3. **The peer**: CellModeller's time to each size from the step log of the project's harness
   (``--peer-log``, the ``steps.json`` written by ``benchmarks/cellmodeller/grow_cellmodeller.py``;
   run it in the same session, see benchmarks/cellmodeller/README.md), with its overlaps where the
   log has them.

Writes ``grown.md`` (the tables, with the date, machine and load), ``grown.json`` (every number)
and ``grown.png`` (cells against wall time) in ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import signal
import sys
import threading
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from ..cli import add_output_arguments, comma_list, positive_float, positive_int, run_standalone
from ..colony import Colony
from ..io import load_colony, save_colony
from ..io.outputs import atomic_write, describe_written, prepare_folder, write_text
from ..simulation import Settings, run_colony
from ..simulation.steps import sink_drive, step_function
from ..timestep import PositionStepResult
from ..timestep.position import SECOND_ORDER_TIGHTEST, uses_second_order
from .bench import machine_description
from .harness import guarded

OUTPUTS = ("grown.md", "grown.json", "grown.png")
#: The velocity step of one step (table 2): (label, settings changes).
VELOCITY_SOLVES = (("velocity, clarabel 1e-6", dict(velocity_solver="clarabel", velocity_tolerance=1e-6)),
                   ("velocity, osqp 1e-3", dict(velocity_solver="osqp", velocity_tolerance=1e-3)))


def _settings(dimensions: int, step: str, n_cells: int, changes: dict[str, Any] | None = None) -> Settings:
    """The run's settings: the defaults with these, by name (:meth:`Settings.updated`)."""
    return Settings().updated({"cells": n_cells, "dimensions": dimensions, "step": step, **(changes or {})},
                              "bench-grown")


def grow_once(settings: dict[str, Any], sizes: list[int], save_dir: str | None,
              time_limit: float | None = None) -> dict[str, Any]:
    """Grow one colony (``settings``: :meth:`Settings.to_tables`) from one cell to the largest of
    ``sizes`` and time it (run in a child process by :func:`run_growth`). The state at each size
    is saved in ``save_dir`` (when given) as ``{dimensions}d-{size}.npz``. After ``time_limit``
    seconds the run is stopped as by SIGTERM (the step under way abandoned) and what it reached
    is reported, with ``stopped`` set."""
    run_settings = Settings.from_stored(settings, "bench-grown")
    reached: dict[int, dict[str, float]] = {}
    start = time.perf_counter()

    def note(colony: Colony, step: int) -> None:
        for size in sizes:
            if colony.cells.n >= size and size not in reached:
                reached[size] = dict(seconds=time.perf_counter() - start, step=step, time=colony.time,
                                     cells=colony.cells.n)
                if save_dir is not None:
                    save_colony(Path(save_dir) / f"{run_settings.run.dimensions}d-{size}.npz", colony, step)

    # The clean stop of a run (SIGTERM), so that a colony short of its target still reports the
    # sizes it reached; the parent's hard limit (run_growth) is only for a run that hangs.
    timer = None if time_limit is None else threading.Timer(time_limit, os.kill, (os.getpid(), signal.SIGTERM))
    if timer is not None:
        timer.daemon = True
        timer.start()
    try:
        run = run_colony(run_settings, progress=False, hook=note)
    finally:
        if timer is not None:
            timer.cancel()
    note(run.colony, run.steps)  # the last state, which no hook call sees
    history = run.history
    cells, times = np.asarray(history["cells"], float), np.asarray(history["time"], float)
    doubling = np.nan
    if cells.size and cells[-1] >= 4:
        half = np.flatnonzero(cells >= cells[-1] / 2)[0]
        if cells[-1] > cells[half]:
            doubling = float((times[-1] - times[half]) / np.log2(cells[-1] / cells[half]))
    seconds = np.asarray(history["step_seconds"], float)
    stopped = f"time limit {time_limit:g} s" if run.interrupted == signal.SIGTERM and time_limit is not None else ""
    return dict(reached=reached, steps=run.steps, wall=run.wall_seconds, error=run.error, stopped=stopped,
                slope=step_time_slope(cells, seconds, sizes), step_cells=cells.tolist(), step_seconds=seconds.tolist(),
                max_overlap=float(max(history["max_overlap"], default=0.0)),
                linearizations=int(np.sum(history["linearizations"])), cells=int(run.colony.cells.n),
                own_doubling=float(np.log(2.0) / run_settings.model.rate), doubling=doubling,
                peak_bytes=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)


#: The log-log slope of step time against cells is fitted over the steps in this range of colony
#: sizes (the target of issue 22: 2·10³ to 2·10⁴ cells in 2D), or up to the run's largest size.
SLOPE_RANGE = (2000, 20000)


def step_time_slope(cells: np.ndarray, seconds: np.ndarray, sizes: list[int]) -> float:
    """The slope of ``log(step seconds)`` against ``log(cells)`` over the steps of a growth run
    with colony sizes in :data:`SLOPE_RANGE` (least squares; NaN with fewer than 5 such steps or
    a range of less than a doubling). Each step's size is the colony's after it."""
    cells, seconds = np.asarray(cells, float), np.asarray(seconds, float)
    use = (cells >= SLOPE_RANGE[0]) & (cells <= min(SLOPE_RANGE[1], max(sizes))) & (seconds > 0)
    if use.sum() < 5 or cells[use].max() < 2 * cells[use].min():
        return float("nan")
    return float(np.polyfit(np.log(cells[use]), np.log(seconds[use]), 1)[0])


#: The tolerance of the reference step the one-step table compares each position step with.
REFERENCE_TOLERANCE = 1e-8


def reference_changes(settings: Settings) -> dict[str, Any]:
    """The settings of the tight step a position step is compared with: its own method at
    :data:`REFERENCE_TOLERANCE`, or, for a second-order step, second order at the tightest
    tolerance its solves reach (a first-order reference takes another path of linearizations,
    and the step stops at the first one within the overlap tolerance: its end is another point
    of that tolerance, up to 0.17 of a diameter away on a grown colony of 400 cells)."""
    if uses_second_order(settings.position):
        return {"position_tolerance": SECOND_ORDER_TIGHTEST, "position_second_order": True}
    return {"position_tolerance": REFERENCE_TOLERANCE}


def end_difference(a: Colony, b: Colony) -> float:
    """Largest distance between the same cell's centres or tips in two states [diameters]."""
    ca, cb = a.cells, b.cells
    tips = [ca.centers + s * 0.5 * ca.lengths[:, None] * ca.axes - (cb.centers + s * 0.5 * cb.lengths[:, None] * cb.axes)
            for s in (-1.0, 0.0, 1.0)]
    return float(max(np.linalg.norm(t, axis=1).max(initial=0.0) for t in tips) / (2.0 * np.median(ca.radii)))


def step_once(state: str, dimensions: int, label: str, step: str, changes: dict[str, Any],
              repeats: int) -> dict[str, Any]:
    """Time ``repeats`` steps of kind ``step`` from the saved colony ``state`` (run in a child
    process by :func:`run_step`): median seconds, linearizations, contacts, largest overlap after."""
    colony, _ = load_colony(state)
    settings = _settings(dimensions, step, 10**9, changes)
    seconds, outcome = [], None
    for _ in range(repeats):
        extra: dict[str, np.ndarray] = {}
        take_step = step_function(settings, extra)
        dt = settings.time_step_of(colony)
        drive = sink_drive(settings, colony)
        t0 = time.perf_counter()
        outcome = take_step(colony, dt, drive=drive)
        seconds.append(time.perf_counter() - t0)
    assert outcome is not None
    result = outcome.result
    common = dict(label=label, seconds=float(np.median(seconds)), cells=colony.cells.n, dt=outcome.dt)
    if isinstance(result, PositionStepResult):
        # The same step at a tight solver tolerance: how far the end positions are from its.
        tight = _settings(dimensions, step, 10**9, {**changes, **reference_changes(settings)})
        reference = step_function(tight, {})(colony, outcome.dt, drive=drive)
        return dict(common, contacts=len(result.contacts), linearizations=result.iterations,
                    solver_iterations=result.solver_iterations, max_overlap=result.max_overlap,
                    difference=end_difference(outcome.colony, reference.colony))
    return dict(common, contacts=len(result.result.contacts), linearizations=1, max_overlap=None)


def run_growth(dimensions: int, step: str, sizes: list[int], n_cells: int, save_dir: Path | None,
               timeout: float, changes: dict[str, Any] | None = None) -> dict[str, Any]:
    """:func:`grow_once` in a child process with a time limit; the failure said, not hidden."""
    settings = _settings(dimensions, step, n_cells, changes).to_tables()
    # The run stops itself at `timeout`; the hard limit, a little later, catches one that hangs.
    status, value = guarded(grow_once, (settings, sizes, None if save_dir is None else str(save_dir), timeout),
                            timeout + max(120.0, 0.05 * timeout))
    record = dict(dimensions=dimensions, step=step, target=n_cells, changes=changes or {})
    if status == "ok":
        return {**record, **value}
    return {**record, "error": f"{status}: {value}" if value is not None else status}


def run_step(state: Path, dimensions: int, label: str, step: str, changes: dict[str, Any], repeats: int,
             timeout: float) -> dict[str, Any]:
    status, value = guarded(step_once, (str(state), dimensions, label, step, changes, repeats), timeout)
    if status == "ok":
        return {**value, "dimensions": dimensions}
    return dict(label=label, dimensions=dimensions, error=f"{status}: {value}" if value is not None else status)


def peer_times(log_path: Path, sizes: list[int]) -> dict[str, Any]:
    """CellModeller's wall time (sum of its steps' ``t_sim``) to each size, and its overlaps,
    from a step log (``{"log": [{"step", "n", "t_sim", "max_overlap"?}, ...]}``, as
    ``benchmarks/cellmodeller/grow_cellmodeller.py`` writes it)."""
    log = json.loads(Path(log_path).read_text())["log"]
    total, reached = 0.0, {}
    worst = 0.0
    for row in log:
        total += float(row["t_sim"])
        worst = max(worst, float(row.get("max_overlap", 0.0) or 0.0))
        for size in sizes:
            if row["n"] >= size and size not in reached:
                reached[size] = dict(seconds=total, step=row["step"], cells=row["n"], max_overlap=worst)
    return dict(reached=reached, steps=len(log))


def machine() -> str:
    """:func:`~qpcontact.studies.bench.machine_description` and the load average now."""
    load = os.getloadavg()
    return f"{machine_description()}, load average {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} (1 / 5 / 15 min)"


def _fmt(value: Any, digits: int = 1) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "–"
    return f"{value:.{digits}f}" if isinstance(value, float) else str(value)


def markdown(growth: list[dict[str, Any]], steps: list[dict[str, Any]], peer: dict[str, Any] | None,
             sizes: list[int], meta: dict[str, Any]) -> str:
    lines = [f"Measured {meta['date']} on {meta['machine']}; `{meta['command']}`.", "",
             "**Time to grow from one cell** (wall seconds until the colony first has that many cells):", "",
             "| dims | step | " + " | ".join(f"{s:,}" for s in sizes) + " | steps | linearizations | largest overlap "
             f"| colony doubling / cells' own | peak memory | slope of step time ({SLOPE_RANGE[0]:,}–{SLOPE_RANGE[1]:,} cells) |",
             "|---|---|" + "---|" * len(sizes) + "---|---|---|---|---|---|"]
    notes: list[str] = []
    for r in growth:
        if "error" in r and r.get("reached") is None:
            lines.append(f"| {r['dimensions']}D | {r['step']} | failed: {r['error'].splitlines()[0][:80]} |")
            continue
        cells = [_fmt(r["reached"].get(s, r["reached"].get(str(s), {})).get("seconds")) for s in sizes]
        ratio = r["doubling"] / r["own_doubling"] if r["doubling"] == r["doubling"] else None
        lines.append(f"| {r['dimensions']}D | {r['step']} | " + " | ".join(cells) +
                     f" | {r['steps']} | {r['linearizations']} | {r['max_overlap']:.4f} | {_fmt(ratio, 2)} | "
                     f"{r['peak_bytes'] / 2**30:.2f} GiB | {_fmt(r.get('slope'), 2)} |"
                     + (f" stopped: {r['error'][:60]}" if r.get("error") else ""))
        if r.get("stopped"):
            notes.append(f"The {r['dimensions']}D {r['step']} run stopped at the {r['stopped']}: {r['cells']:,} cells.")
    if peer is not None:
        cells = [_fmt(peer["reached"].get(s, peer["reached"].get(str(s), {})).get("seconds")) for s in sizes]
        worst = max((v.get("max_overlap", 0.0) for v in peer["reached"].values()), default=0.0)
        lines.append("| 2D | CellModeller (peer) | " + " | ".join(cells) +
                     f" | {peer['steps']} | – | {worst / 1.0:.4f} µm | – | – |")
    if notes:
        lines += [""] + notes
    lines += ["", "**One step of a grown colony** (median seconds of the same step from the state the position run "
              "reached; linearizations and solver iterations of the position step; largest overlap after it; the "
              "largest distance of a centre or tip from where the same step at solver tolerance "
              f"{REFERENCE_TOLERANCE:g} puts it, in diameters):", "",
              "| dims | cells | step | seconds | contacts | linearizations | solver iterations | largest overlap "
              "| end positions against the tight step |", "|---|---|---|---|---|---|---|---|---|"]
    for r in steps:
        if "error" in r:
            lines.append(f"| {r['dimensions']}D | | {r['label']} | failed: {r['error'].splitlines()[0][:80]} | | | | | |")
            continue
        lines.append(f"| {r['dimensions']}D | {r['cells']:,} | {r['label']} | {r['seconds']:.3f} | {r['contacts']:,} | "
                     f"{r['linearizations']} | {_fmt(r.get('solver_iterations'))} | {_fmt(r['max_overlap'], 4)} | "
                     f"{_fmt(r.get('difference'), 5)} |")
    return "\n".join(lines) + "\n"


def plot(growth: list[dict[str, Any]], peer: dict[str, Any] | None, path: Path) -> None:
    from matplotlib.figure import Figure

    figure = Figure(figsize=(6.5, 4.2))
    ax = figure.add_subplot()
    for r in growth:
        if not r.get("reached"):
            continue
        points = sorted((int(k), v["seconds"]) for k, v in r["reached"].items())
        ax.loglog([p[1] for p in points], [p[0] for p in points], "o-", label=f"{r['dimensions']}D {r['step']}")
    if peer is not None and peer["reached"]:
        points = sorted((int(k), v["seconds"]) for k, v in peer["reached"].items())
        ax.loglog([p[1] for p in points], [p[0] for p in points], "s--", label="2D CellModeller")
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("cells")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=120)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--dimensions", type=comma_list(int, choices=("2", "3")), default=[2], metavar="LIST",
                        help="comma-separated dimensions (default: 2)")
    parser.add_argument("--sizes", type=comma_list(positive_int), default=[1000, 2000, 5000, 10000], metavar="LIST",
                        help="comma-separated colony sizes to time and save [cells] (default: 1000,2000,5000,10000)")
    parser.add_argument("--steps", type=comma_list(choices=("position", "velocity")), default=["position", "velocity"],
                        metavar="LIST", help="step kinds to grow with (default: position,velocity)")
    parser.add_argument("--velocity-cells", type=positive_int, default=2000, metavar="N",
                        help="grow with the velocity step to this size only (default: 2000; it took 47 min to 10^4)")
    parser.add_argument("--position-solvers", type=comma_list(str), default=["ipm"], metavar="LIST",
                        help="solvers of the position step in the one-step table (default: ipm)")
    parser.add_argument("--repeats", type=positive_int, default=3, help="steps timed per configuration in the one-step "
                        "table, median kept (default: 3)")
    parser.add_argument("--time-limit", type=positive_float, default=7200.0, metavar="S",
                        help="wall-time limit of one growth run [s]: the run stops there and reports the sizes it "
                        "reached (default: 7200)")
    parser.add_argument("--peer-log", type=Path, metavar="FILE",
                        help="CellModeller's step log (steps.json of benchmarks/cellmodeller/grow_cellmodeller.py) to put "
                        "in the table")
    parser.add_argument("--cache-dir", type=Path, metavar="FOLDER",
                        default=Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "qpcontact-grown",
                        help="where grown states are saved and reused (default: ~/.cache/qpcontact-grown)")
    parser.add_argument("--reuse", action="store_true", help="take the one-step table's states from --cache-dir "
                        "without growing (the time-to-grow table is then left out)")
    parser.add_argument("--no-step-table", action="store_true", help="time the growth only (the one-step table, "
                        "with its tight reference steps and velocity-step solves, is left out)")
    add_output_arguments(parser, "bench-grown", "grown.md, grown.json and grown.png")


def run_command(args: argparse.Namespace) -> int:
    out = prepare_folder(args.out, OUTPUTS, overwrite=args.overwrite)
    args.cache_dir.mkdir(parents=True, exist_ok=True)
    sizes = sorted(set(args.sizes))
    growth: list[dict[str, Any]] = []
    if not args.reuse:
        for dimensions in args.dimensions:
            for step in args.steps:
                target = sizes[-1] if step == "position" else min(sizes[-1], args.velocity_cells)
                marks = [s for s in sizes if s <= target]
                print(f"growing {dimensions}D with the {step} step to {target:,} cells ...", flush=True)
                record = run_growth(dimensions, step, marks, target,
                                    args.cache_dir if step == "position" else None, args.time_limit)
                print("   " + ("failed: " + record["error"] if "error" in record and "reached" not in record
                               else f"{record['wall']:.1f} s, {record['steps']} steps, {record['cells']:,} cells, "
                                    f"largest overlap {record['max_overlap']:.4f}"
                                    + (f", stopped at the {record['stopped']}" if record.get("stopped") else "")),
                      flush=True)
                growth.append(record)
    steps: list[dict[str, Any]] = []
    kinds = [(f"position, {name}", "position", dict(position_solver=name)) for name in args.position_solvers]
    kinds += [(label, "velocity", changes) for label, changes in VELOCITY_SOLVES]
    for dimensions in [] if args.no_step_table else args.dimensions:
        for size in sizes:
            state = args.cache_dir / f"{dimensions}d-{size}.npz"
            if not state.exists():
                continue
            for label, step, changes in kinds:
                print(f"one step of the grown {dimensions}D colony of {size:,} cells: {label} ...", flush=True)
                steps.append(run_step(state, dimensions, label, step, changes, args.repeats, args.time_limit))
    peer = peer_times(args.peer_log, sizes) if args.peer_log else None
    meta = dict(date=datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"), machine=machine(),
                command="qpcontact bench-grown " + " ".join(sys.argv[2:] if sys.argv[1:2] == ["bench-grown"] else []))
    written = [write_text(out / "grown.md", markdown(growth, steps, peer, sizes, meta)),
               atomic_write(out / "grown.json", lambda fh: json.dump(dict(meta=meta, growth=growth, steps=steps,
                                                                           peer=peer), fh, indent=1, default=float),
                            text=True)]
    plot(growth, peer, out / "grown.png")
    written.append(out / "grown.png")
    print((out / "grown.md").read_text())
    print(describe_written(written))
    return 0


def main(argv: list[str] | None = None) -> int:
    return run_standalone("qpcontact bench-grown", add_arguments, run_command, argv, (__doc__ or "").split("\n\n")[0])
