"""The error of one position step against the same time taken in substeps, from a saved state.

Usage (from the repository root)::

    python benchmarks/step_error.py RUN/snapshots/step_000245.npz --scales 1 0.5 0.25 \\
        --substeps 4 --out step-error.md

From the state, with the run's own settings (``qpcontact simulate``'s, stored in the snapshot;
the 3D sink drive as the run has it), it takes one growth step of ``scale`` times the run's
step, and the same time in ``--substeps`` equal steps (no division in between: both start
from the same cells and end at the same time). Where the substeps agree with each other at a
finer split, they stand for the converged motion, and the one step's departure from them is
the step's error over that time: the colony's spreading (the change of the cells' mean
distance from the colony's axis in the plane), its rise (the mean change of height, 3D), the
cells' end positions (root mean square and largest difference, in diameters) and the
linearizations each took. It is the step-level view of ``qpcontact convergence`` (which
grows whole colonies): minutes instead of hours, one state at a time.

Writes a Markdown table (``--out``) with the date, the machine and its load; prints it too.
"""

from __future__ import annotations

import argparse
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from qpcontact.colony.growth import Colony, grow_position
from qpcontact.io.snapshots import load_snapshot
from qpcontact.simulation import Settings
from qpcontact.simulation.steps import sink_drive
from qpcontact.studies.grown import machine


def advance(colony: Colony, settings: Settings, dt: float, steps: int) -> tuple[Colony, int, float]:
    """``steps`` growth steps of ``dt / steps`` each: ``(colony, linearizations, seconds)``."""
    linearizations, started = 0, time.perf_counter()
    for _ in range(steps):
        colony, out = grow_position(colony, dt / steps, drive=sink_drive(settings, colony), planes=settings.planes(),
                                    settings=settings.position)
        linearizations += out.iterations
    return colony, linearizations, time.perf_counter() - started


def spread(colony: Colony, centre: np.ndarray) -> float:
    """Mean distance of the centres from ``centre`` in the xy-plane [µm]."""
    return float(np.mean(np.linalg.norm(colony.cells.centers[:, :2] - centre, axis=1)))


def compare(colony: Colony, settings: Settings, scale: float, substeps: int) -> dict[str, float]:
    """One step of ``scale`` times the run's step against ``substeps`` steps over the same time."""
    dt = settings.time_step_of(colony) * scale
    one, lin_one, sec_one = advance(colony, settings, dt, 1)
    many, lin_many, sec_many = advance(colony, settings, dt, substeps)
    centre = colony.cells.centers[:, :2].mean(axis=0)
    start_spread = spread(colony, centre)
    spread_one, spread_many = spread(one, centre) - start_spread, spread(many, centre) - start_spread
    rise_one = float(np.mean(one.cells.centers[:, 2] - colony.cells.centers[:, 2]))
    rise_many = float(np.mean(many.cells.centers[:, 2] - colony.cells.centers[:, 2]))
    diameter = 2.0 * float(np.median(colony.cells.radii))
    moved = np.linalg.norm(one.cells.centers - many.cells.centers, axis=1) / diameter
    return dict(scale=scale, dt=dt, spread_one=spread_one, spread_many=spread_many,
                spread_error=spread_one / spread_many - 1.0 if spread_many else float("nan"),
                rise_one=rise_one, rise_many=rise_many, rms=float(np.sqrt(np.mean(moved**2))),
                largest=float(moved.max(initial=0.0)), lin_one=lin_one, lin_many=lin_many,
                seconds_one=sec_one, seconds_many=sec_many)


def table(state: str, cells: int, dimensions: int, growth: float, substeps: int, rows: list[dict[str, float]]) -> str:
    """The Markdown report."""
    lines = [f"# One step against {substeps} substeps ({datetime.now(UTC):%Y-%m-%d %H:%M} UTC)", "",
             f"State: `{Path(state).name}`, {cells} cells, {dimensions}D, the run's growth per step {growth:g}; "
             f"machine: {machine()}.", "",
             "| step [× the run's] | dt | spreading: one step [µm] | substeps [µm] | error | rise: one step [µm] | "
             "substeps [µm] | end positions apart: rms [diameters] | largest | linearizations: one step | substeps | "
             "seconds: one step | substeps |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scale']:g} | {r['dt']:.4g} | {r['spread_one']:.4f} | {r['spread_many']:.4f} | "
                     f"{100 * r['spread_error']:+.1f} % | {r['rise_one']:.4f} | {r['rise_many']:.4f} | {r['rms']:.4f} | "
                     f"{r['largest']:.3f} | {r['lin_one']} | {r['lin_many']} | {r['seconds_one']:.1f} | "
                     f"{r['seconds_many']:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("state", help="a snapshot of a qpcontact simulate run (its settings are used)")
    parser.add_argument("--scales", type=float, nargs="+", default=[1.0, 0.5, 0.25],
                        help="the step to test, in multiples of the run's step (default 1 0.5 0.25)")
    parser.add_argument("--substeps", type=int, default=4, help="substeps of the reference (default 4)")
    parser.add_argument("--out", default="step-error.md", help="the Markdown table (default step-error.md)")
    args = parser.parse_args(argv)
    if args.substeps < 2:
        parser.error("--substeps: at least 2")
    if any(not s > 0 for s in args.scales):
        parser.error("--scales: each > 0")
    snapshot = load_snapshot(args.state)
    settings = Settings.from_stored(snapshot.settings, args.state)
    rows = [compare(snapshot.colony, settings, scale, args.substeps) for scale in args.scales]
    report = table(args.state, snapshot.colony.cells.n, settings.run.dimensions, settings.growth_per_step(),
                   args.substeps, rows)
    Path(args.out).write_text(report)
    print(report)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
