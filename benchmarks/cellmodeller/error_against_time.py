"""The colony's error against run time, CellModeller beside qpcontact: each simulator's 2D colony
at one size, grown at several time steps and seeds, measured with qpcontact's colony statistics
(:func:`qpcontact.colony.colony_statistics`, docs/statistics.md), each step's statistics against
that simulator's own finest step, with the wall time to that size.

Both simulators' colonies change with their time step; a time to grow means something only with
the error it was grown at. This puts the two on one footing: for each simulator and step, the
mean (and range over the seeds) of each statistic of issue 32, its error (the mean less the mean
at that simulator's finest step) and the time to the size. The two models differ (CellModeller's
cells overlap by up to a tenth of a diameter and its contacts are springs solved by conjugate
gradients; qpcontact's do not overlap), so each is measured against its own limit, not against
the other.

Inputs: CellModeller's folders from ``grow_cellmodeller.py --dt DT --seed S --targets ...,N``
(its ``steps.json`` names the step and seed; the state is ``cellmodeller_<N>.npz``; the time is
the sum of its steps' ``t_sim`` up to the first step with at least N cells), and qpcontact's run
folders from ``qpcontact simulate --cells N --seed S --growth-per-step G`` (the step and seed from
each run's settings; the state is the first snapshot with at least N cells, the time the sum of
its history's step times up to there). Prints a Markdown table and writes it to ``--out``, and
draws each statistic's error against the time into ``--plot``::

    python benchmarks/cellmodeller/error_against_time.py --size 5000 \\
        --cellmodeller cm-dt0.05-s1 cm-dt0.05-s2 cm-dt0.0125-s1 ... --qpcontact qp-g0.05-s1 ... \\
        --out error-against-time.md --plot error-against-time.png
"""

from __future__ import annotations

import argparse
import json
import math
from collections import defaultdict
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from qpcontact.colony import colony_statistics
from qpcontact.colony.statistics import DEFINITIONS
from qpcontact.geometry import Cells
from qpcontact.io.runs import RunFolder
from qpcontact.io.snapshots import load_snapshot
from qpcontact.simulation import Settings
from qpcontact.studies.convergence import REPORTED
from qpcontact.studies.grown import machine

#: One grown colony: (simulator, its step, seed, wall seconds to the size, statistics by name).
Run = tuple[str, float, int, float, dict[str, float]]


def cellmodeller_run(folder: Path, size: int) -> Run:
    """A CellModeller folder's colony at ``size`` and its time to it."""
    document = json.loads((folder / "steps.json").read_text())
    wall = 0.0
    for row in document["log"]:
        wall += row["t_sim"]
        if row["n"] >= size:
            break
    else:
        raise SystemExit(f"{folder}: never reached {size} cells")
    data = np.load(folder / f"cellmodeller_{size}.npz")
    cells = Cells(centers=data["centers"], axes=data["axes"], lengths=data["lengths"], radii=data["radii"],
                  normalize_axes=True)
    args = document["args"]
    return "CellModeller", float(args["dt"]), int(args["seed"]), wall, colony_statistics(cells, dimensions=2).scalars()


def qpcontact_run(folder: Path, size: int) -> Run:
    """A qpcontact run folder's colony at ``size`` (its first snapshot that large) and its time to it."""
    run = RunFolder(folder)
    history = run.read_history()
    reached = next((i for i, n in enumerate(history["cells"]) if n >= size), None)
    if reached is None:
        raise SystemExit(f"{folder}: never reached {size} cells")
    wall = float(np.sum(history["step_seconds"][:reached + 1]))
    snapshots = sorted((folder / "snapshots").glob("step_*.npz"))
    snapshot = next((s for s in map(load_snapshot, snapshots) if s.colony.cells.n >= size), None)
    if snapshot is None:
        raise SystemExit(f"{folder}: no snapshot with {size} cells")
    settings = Settings.from_stored(snapshot.settings, str(folder))
    return ("qpcontact", settings.growth_per_step(), settings.run.seed, wall,
            colony_statistics(snapshot, dimensions=2).scalars())


def table(runs: list[Run], size: int) -> str:
    """The Markdown table (module docstring): one row per simulator and step, finest first."""
    names = REPORTED[2]
    groups: dict[tuple[str, float], list[Run]] = defaultdict(list)
    for run in runs:
        groups[run[0], run[1]].append(run)
    header = ["simulator", "step", "seeds", f"time to {size:,} cells [s]",
              *(f"{n} [{DEFINITIONS[n][0]}]" if DEFINITIONS[n][0] not in ("", "dimensionless") else n for n in names)]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for simulator in sorted({key[0] for key in groups}):
        steps = sorted(step for name, step in groups if name == simulator)
        finest = {n: float(np.mean([r[4][n] for r in groups[simulator, steps[0]]])) for n in names}
        for step in steps:
            group = groups[simulator, step]
            times = [r[3] for r in group]
            spread = f" ({min(times):.1f}–{max(times):.1f})" if len(times) > 1 else ""
            cells = [simulator, f"{'dt' if simulator == 'CellModeller' else 'growth'} {step:g}",
                     ", ".join(str(r[2]) for r in sorted(group, key=lambda r: r[2])),
                     f"{np.median(times):.1f}{spread}"]
            for name in names:
                values = np.array([r[4][name] for r in group])
                mean = float(np.mean(values))
                text = f"{mean:.3f} ({values.min():.3f}–{values.max():.3f})" if values.size > 1 else f"{mean:.3f}"
                if step != steps[0] and math.isfinite(mean):
                    text += f" Δ{mean - finest[name]:+.3f}"
                cells.append(text)
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(runs: list[Run], size: int, path: Path) -> None:
    """Each statistic's error (the mean over the seeds less the same simulator's finest step's)
    against the median time to ``size``, one line per simulator, each point labelled with its step."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13, 7.5), dpi=110, layout="constrained")
    axes = fig.subplots(2, 3).ravel()
    for ax in axes[len(REPORTED[2]):]:
        ax.set_visible(False)
    for ax, name in zip(axes, REPORTED[2], strict=False):
        for simulator in sorted({r[0] for r in runs}):
            steps = sorted({r[1] for r in runs if r[0] == simulator})
            mean = {step: float(np.mean([r[4][name] for r in runs if r[0] == simulator and r[1] == step]))
                    for step in steps}
            time = [float(np.median([r[3] for r in runs if r[0] == simulator and r[1] == step])) for step in steps]
            error = [mean[step] - mean[steps[0]] for step in steps]
            ax.plot(time, error, "o-", label=simulator)
            for step, x, y in zip(steps, time, error, strict=True):
                ax.annotate(f"{step:g}", (x, y), textcoords="offset points", xytext=(4, 4), fontsize=8)
        unit = DEFINITIONS[name][0]
        ax.set(xscale="log", xlabel=f"time to {size:,} cells [s]", title=name,
               ylabel=f"error against the finest step{'' if unit in ('', 'dimensionless') else f' [{unit}]'}")
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.xaxis.set_minor_formatter("")  # the decades only: the minor labels overlap
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    fig.suptitle(f"Error against run time, {size:,} cells: each simulator against its own finest step")
    fig.savefig(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--size", type=int, default=5000, help="the colony size compared (default 5000)")
    parser.add_argument("--cellmodeller", type=Path, nargs="*", default=[], help="grow_cellmodeller.py's folders")
    parser.add_argument("--qpcontact", type=Path, nargs="*", default=[], help="qpcontact simulate's run folders")
    parser.add_argument("--out", type=Path, help="also write the table (Markdown) to this file")
    parser.add_argument("--plot", type=Path, help="also draw each statistic's error against the time (PNG)")
    args = parser.parse_args(argv)
    if not args.cellmodeller and not args.qpcontact:
        parser.error("give --cellmodeller or --qpcontact folders")
    runs = [cellmodeller_run(f, args.size) for f in args.cellmodeller]
    runs += [qpcontact_run(f, args.size) for f in args.qpcontact]
    text = (f"{datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {machine()} when the table was made (the runs' times "
            f"are their own, taken when they ran). Each statistic: the mean over the seeds (their "
            f"range), Δ its error against the same simulator's finest step; time: the median over the seeds "
            f"(range).\n\n{table(runs, args.size)}\n")
    print(text)
    if args.out is not None:
        args.out.write_text(text)
    if args.plot is not None:
        plot(runs, args.size, args.plot)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
