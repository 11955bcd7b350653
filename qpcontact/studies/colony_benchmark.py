"""Error against run time over a whole colony run, for each solver and tolerance.

Grows the same 2D colony (``qpcontact simulate`` defaults, seed 1) from one cell to --cells
cells with every configuration below, --repeats times each, and records the wall time of the
whole run (median of the repeats), the contact-solve time, and the overlaps reached: the largest
over the run, the 99th percentile of the per-step largest, and the run's mean (time average of
each step's mean overlap over the overlapping contacts), all as fractions of the diameter.

Writes ``OUT/data/colony_benchmark.csv``, ``OUT/data/colony_benchmark.md`` (table) and
``OUT/img/colony_error_time.png`` (``--out OUT``, default ``./colony_benchmark-out``; ``--out
docs --overwrite`` updates the project's docs). Run it under ``flock /tmp/qpcontact-bench.lock``:

    flock /tmp/qpcontact-bench.lock python -m qpcontact.studies.colony_benchmark --out docs --overwrite
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..arguments import add_output_arguments, comma_list, positive_int, run_standalone
from ..colony import Settings, run_colony
from ..outputs import atomic_write, describe_written, prepare_folder, write_text
from ..solvers import available_solvers

#: A configuration is not repeated further once its runs took this long (the table says how
#: many repeats each row is the median of).
BUDGET_SECONDS = 60.0

#: (label, changes to the default Settings)
CONFIGS: list[tuple[str, dict[str, Any]]] = [
    ("linear", dict(solver="linear")),
    ("osqp 1e-3", dict(solver="osqp", tolerance=1e-3)),
    ("osqp 1e-4", dict(solver="osqp", tolerance=1e-4)),
    ("osqp 1e-6", dict(solver="osqp", tolerance=1e-6)),
    ("clarabel 1e-4", dict(solver="clarabel", tolerance=1e-4)),
    ("clarabel 1e-6", dict(solver="clarabel", tolerance=1e-6)),
    ("clarabel 1e-8", dict(solver="clarabel", tolerance=1e-8)),
    ("piqp 1e-4", dict(solver="piqp", tolerance=1e-4)),
    ("piqp 1e-6", dict(solver="piqp", tolerance=1e-6)),
    ("clarabel 1e-6 without position correction", dict(solver="clarabel", tolerance=1e-6, position_correction=0.0)),
    ("clarabel 1e-6 half step (cfl 0.15)", dict(solver="clarabel", tolerance=1e-6, cfl=0.15)),
]


def measure(label: str, changes: dict[str, Any], cells: int, repeats: int) -> dict[str, Any]:
    """One row: the configuration's whole runs to ``cells`` cells (up to ``repeats`` of them)."""
    walls: list[float] = []
    solves: list[float] = []
    run = None
    for _ in range(max(1, repeats)):
        run = run_colony(dataclasses.replace(Settings(n_cells=cells), **changes), progress=False)
        if run.interrupted:  # Ctrl-C: run_colony stopped cleanly; the benchmark stops too
            raise KeyboardInterrupt
        walls.append(run.wall_seconds)
        solves.append(float(np.sum(run.history["solve_seconds"])))
        if run.error or sum(walls) > BUDGET_SECONDS:
            break
    assert run is not None
    h = {k: np.asarray(v, dtype=float) for k, v in run.history.items()}
    return {
        "config": label,
        "solver": changes.get("solver"),
        "tolerance": changes.get("tolerance", ""),
        "cells": run.colony.cells.n,
        "steps": run.steps,
        "wall_s": float(np.median(walls)),
        "solve_s": float(np.median(solves)),
        "ms_per_step": 1e3 * float(np.median(walls)) / max(run.steps, 1),
        "max_overlap": float(h["max_overlap"].max(initial=0.0)),
        "p99_overlap": float(np.percentile(h["max_overlap"], 99)) if run.steps else 0.0,
        "mean_overlap": float(h["mean_overlap"].mean()) if run.steps else 0.0,
        "repeats": len(walls),
        "error": run.error,
    }


#: The files written, relative to ``--out``.
OUTPUTS = ("data/colony_benchmark.csv", "data/colony_benchmark.md", "img/colony_error_time.png")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cells", type=positive_int, default=500, help="grow each colony to this many cells (default: 500)")
    parser.add_argument("--repeats", type=positive_int, default=3, help="whole runs per configuration, median time "
                        "kept (default: 3)")
    parser.add_argument("--configs", type=comma_list(choices=[label for label, _ in CONFIGS]), metavar="LIST",
                        help=f"comma-separated configurations (default: all: {', '.join(label for label, _ in CONFIGS)})")
    add_output_arguments(parser, "colony_benchmark", "data/colony_benchmark.csv, data/colony_benchmark.md and "
                         "img/colony_error_time.png")


def main(argv: list[str] | None = None) -> int:
    return run_standalone("python -m qpcontact.studies.colony_benchmark", add_arguments, run_command, argv,
                          (__doc__ or "").split("\n\n")[0])


def run_command(args: argparse.Namespace) -> int:
    prepare_folder(args.out, OUTPUTS, overwrite=args.overwrite)
    installed = available_solvers()
    rows = []
    for label, changes in CONFIGS:
        if args.configs and label not in args.configs:
            continue
        if changes["solver"] not in installed:
            print(f"{label}: solver not installed, skipped")
            continue
        t0 = time.perf_counter()
        row = measure(label, changes, args.cells, args.repeats)
        rows.append(row)
        print(f"{label:40s} wall {row['wall_s']:7.2f} s  solve {row['solve_s']:7.2f} s  steps {row['steps']}  "
              f"max {row['max_overlap']:.4f}  p99 {row['p99_overlap']:.4f}  mean {row['mean_overlap']:.5f}  "
              f"{row['error'][:80]}  ({time.perf_counter() - t0:.0f} s)", flush=True)

    if not rows:
        print("no configuration ran")
        return 1
    def write_rows(handle: Any) -> None:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)

    atomic_write(args.out / "data" / "colony_benchmark.csv", write_rows, text=True)
    stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    lines = [
        f"Measured {stamp} on {platform.machine()} (2 cores; load average {os.getloadavg()[0]:.1f} at the end of the run), Python {platform.python_version()}; "
        f"2D colony grown from 1 cell to {args.cells} cells (seed 1, `qpcontact simulate` defaults otherwise); "
        f"wall and solve times are medians of up to {args.repeats} repeats (fewer once a configuration's runs "
        f"took {BUDGET_SECONDS:.0f} s; column 'repeats'); the trajectories are deterministic, so the overlaps are the "
        "same in every repeat.",
        "",
        "| configuration | steps | repeats | wall [s] | contact solve [s] | ms/step | largest overlap | 99th pct of per-step largest | mean overlap | note |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        note = f"FAILED: {r['error']}" if r["error"] else ""
        lines.append(f"| {r['config']} | {r['steps']} | {r['repeats']} | {r['wall_s']:.1f} | {r['solve_s']:.1f} | {r['ms_per_step']:.1f} | "
                     f"{r['max_overlap']:.4f} | {r['p99_overlap']:.4f} | {r['mean_overlap']:.5f} | {note} |")
    write_text(args.out / "data" / "colony_benchmark.md", "\n".join(lines) + "\n")
    plot(rows, args.out / "img" / "colony_error_time.png", args.cells)
    print(describe_written(args.out / name for name in OUTPUTS))
    return 0


def plot(rows: list[dict[str, Any]], path: Path, cells: int) -> None:
    """Largest and mean overlap against the wall time of the whole run, one point per row."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.5), dpi=110)
    axes = fig.subplots(1, 2)
    for ax, key, name in ((axes[0], "max_overlap", "largest overlap over the run"),
                          (axes[1], "mean_overlap", "mean overlap over the run")):
        for r in rows:
            marker = "x" if r["error"] else "o"
            ax.loglog(r["wall_s"], max(r[key], 1e-6), marker, ms=7)
            ax.annotate(r["config"], (r["wall_s"], max(r[key], 1e-6)), fontsize=7, xytext=(4, 2), textcoords="offset points")
        ax.set_xlabel(f"wall time of the whole run to {cells} cells [s]")
        ax.set_ylabel(f"{name} [fraction of diameter]")
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle("Error against run time over a whole 2D colony run (x = run failed)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)


if __name__ == "__main__":
    sys.exit(main())
