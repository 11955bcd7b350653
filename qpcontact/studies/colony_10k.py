"""Time per step and overlap for a 10,000-cell 2D colony, OSQP against Clarabel.

Starts from a colony snapshot (``qpcontact simulate --cells N``; the newest snapshot in a folder
when a folder is given) or from ``colony_2d:N``, the packed monolayer of
:func:`qpcontact.studies.scenes.colony_2d` (growth inertia and rates as ``qpcontact simulate``),
and from that same state takes --steps growth steps with each solver (``qpcontact simulate``
settings otherwise).
Records per step: cells, contacts in the system, unknowns, wall time of the step, contact-solve
time (setup + solve), and the largest and mean overlap (fraction of the diameter) of the state
the step starts from; and the overlaps of the final state. Medians over the steps.

    flock /tmp/qpcontact-bench.lock python -m qpcontact.studies.colony_10k colony_2d:10000 SNAPSHOT.npz --out DIR

writes ``DIR/colony_10k.md`` (default ``./colony_10k-out``).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

from ..arguments import add_output_arguments, comma_list, positive_float, positive_int, run_standalone
from ..colony import Colony, Settings, divide, expansion_time_step, grow, load_colony, overlap_fractions
from ..geometry import find_contacts
from ..outputs import describe_written, prepare_folder, write_text
from .scenes import colony_2d

CONFIGS = ["osqp@1e-3", "osqp@1e-4", "clarabel@1e-6", "mprgp@1e-6"]


def solver_at_tolerance(text: str) -> tuple[str, float]:
    """``solver@tolerance``, e.g. ``osqp@1e-3``."""
    solver, at, tolerance = text.partition("@")
    if not (solver and at):
        raise argparse.ArgumentTypeError(f"expected solver@tolerance, got {text!r}")
    return solver, positive_float(tolerance)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("starts", nargs="+", help="snapshot .npz, folder of snapshots, or colony_2d:N")
    parser.add_argument("--steps", type=positive_int, default=5, help="growth steps from each start (default: 5)")
    parser.add_argument("--solvers", type=comma_list(solver_at_tolerance), default=list(map(solver_at_tolerance, CONFIGS)),
                        metavar="LIST", help=f"comma-separated solver@tolerance [dimensionless], each run from the same "
                                             f"start (default: {','.join(CONFIGS)})")
    add_output_arguments(parser, "colony_10k", "the table colony_10k.md")


def main(argv: list[str] | None = None) -> int:
    return run_standalone("python -m qpcontact.studies.colony_10k", add_arguments, run_command, argv,
                          (__doc__ or "").split("\n\n")[0])


def run_command(args: argparse.Namespace) -> int:
    prepare_folder(args.out, ("colony_10k.md",), overwrite=args.overwrite)
    s = Settings()
    lines = [
        f"Measured {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} on {platform.machine()} (2 cores shared with "
        f"other jobs); {args.steps} growth steps with each solver from the same start; medians over the steps.",
        "",
        "| start | solver | tolerance | contacts in system | unknowns | dt | step wall [s] | contact solve [s] | largest overlap (per step, max) | mean overlap | largest overlap after the steps | note |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for spec in args.starts:
        start, label = load_start(spec, s)
        lines += measure(start, label, s, args.steps, args.solvers)
    written = write_text(args.out / "colony_10k.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    print(describe_written([written]))
    return 0


def load_start(spec: str, s: Settings) -> tuple[Colony, str]:
    """The starting colony and a label for the table."""
    if spec.startswith("colony_2d:"):
        n_cells = int(spec.split(":")[1])
        cells = colony_2d(n_cells, seed=0, growth_inertia=s.growth_inertia)
        rates = s.rate * (1.0 + s.rate_noise * np.random.default_rng(0).standard_normal(n_cells))
        return Colony.founder(cells, np.maximum(rates, 0.0)), f"scenes.colony_2d({n_cells}) packed layer"
    path = Path(spec)
    if path.is_dir():
        path = sorted(path.glob("step_*.npz"))[-1]
    colony, _ = load_colony(path)
    return colony, f"grown by `qpcontact simulate` to {colony.cells.n} cells (t = {colony.time:.2f})"


def measure(start: Colony, label: str, s: Settings, steps: int, configs: list[tuple[str, float]]) -> list[str]:
    """Table rows: ``steps`` growth steps from ``start`` with each ``(solver, tolerance)``."""
    lines = []
    for solver, tolerance in configs:
        colony = start
        rng = np.random.default_rng(0)
        rows, error = [], ""
        for _ in range(steps):
            dt = expansion_time_step(colony, max_dt=s.max_dt, cfl=s.cfl, dimensions=2)
            t0 = time.perf_counter()
            try:
                colony, out = grow(colony, dt, planar=True, solver=solver, tolerance=tolerance, margin=s.margin,
                                   position_correction=s.position_correction)
            except Exception as exc:  # reported in the table, never applied
                error = f"{type(exc).__name__}: {exc}"[:160]
                break
            wall = time.perf_counter() - t0
            colony = divide(colony, s.division_length, rng, axis_noise=s.axis_noise, rate_noise=s.rate_noise,
                            base_rate=s.rate, planar=True)
            r = out.result
            rows.append((len(r.contacts), r.n_unknowns, dt, wall, r.times["setup"] + r.times["solve"],
                         out.max_overlap, out.mean_overlap))
            print(solver, tolerance, rows[-1], flush=True)
        final = overlap_fractions(colony.cells, find_contacts(colony.cells, 0.0, planar=True))
        if rows:
            a = np.array(rows)
            med = np.median(a, axis=0)
            lines.append(f"| {label} | {solver} | {tolerance:g} | {med[0]:.0f} | {med[1]:.0f} | {med[2]:.4f} | {med[3]:.2f} | "
                         f"{med[4]:.2f} | {a[:, 5].max():.4f} | {med[6]:.5f} | {final.max(initial=0.0):.4f} | {error} |")
        else:
            lines.append(f"| {label} | {solver} | {tolerance:g} | | | | | | | | | {error} |")
    return lines


if __name__ == "__main__":
    sys.exit(main())
