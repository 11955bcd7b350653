"""One CellModeller model grown by CellModeller and by ``qpcontact cellmodeller``, side by side:
the simulated time (the model's own unit) and the wall time to each size, and the colony at a
size both reached (2D): type fractions, sectors at the rim, and the statistics of issue 32
(packing, contacts per cell, nematic correlation length, local order S, edge alignment).

Inputs, per seed: CellModeller's folder from ``grow_cellmodeller.py --model MODEL --targets
...,N`` (its ``steps.json`` and ``cellmodeller_<N>.npz``), and qpcontact's run folder from
``qpcontact cellmodeller MODEL --cells N --seed S --out FOLDER`` (its ``history.csv`` and last
snapshot). README.md beside this file has the commands.

    python benchmarks/cellmodeller/compare_models.py --size 5000 \\
        --cellmodeller cm-s1 cm-s2 cm-s3 --qpcontact qp-s1 qp-s2 qp-s3

The statistics of issue 32 are the package's (``qpcontact.colony.statistics``, definitions in
docs/statistics.md); this script adds the type-1 fraction and the sectors: runs of one type (of at
least 3 cells) along the cells at the rim (within the edge width of the footprint's edge, as the
edge alignment takes them), ordered by polar angle about the centres' mean.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np

from qpcontact.colony.statistics import colony_statistics, rim
from qpcontact.geometry import Cells
from qpcontact.io.snapshots import load_snapshot


def statistics(cells: Cells, types: np.ndarray) -> dict[str, float]:
    """The package's colony statistics of a 2D colony (``colony_statistics``), with the type-1
    fraction and the sectors at the rim (the module docstring)."""
    found = colony_statistics(cells, dimensions=2)
    at_rim, polar_angle, _ = rim(cells)
    rim_types = types[at_rim][np.argsort(polar_angle[at_rim])]
    changes = np.flatnonzero(rim_types != np.roll(rim_types, 1))
    runs = np.diff(np.concatenate([changes, [changes[0] + rim_types.size]])) if changes.size else np.array([])
    return {"cells": float(cells.n), "type1_fraction": float(np.mean(types == 1)), "packing": found.packing,
            "contacts_per_cell": found.contacts_per_cell, "nematic_length": found.nematic_length,
            "local_S": found.local_order, "edge_alignment": found.edge_alignment, "sectors": float(np.sum(runs >= 3))}


def cellmodeller_side(folder: Path, size: int, dt: float) -> tuple[dict[str, float], dict[int, tuple[float, float]]]:
    """CellModeller's state at ``size`` (its statistics) and its (time, wall) to each size."""
    log = json.loads((folder / "steps.json").read_text())["log"]
    wall = np.cumsum([row["t_sim"] for row in log])
    reached = {n: next((row["step"] * dt, float(w)) for row, w in zip(log, wall, strict=True) if row["n"] >= n)
               for n in (1000, 2000, size)}
    data = np.load(folder / f"cellmodeller_{size}.npz")
    cells = Cells(centers=data["centers"], axes=data["axes"], lengths=data["lengths"], radii=data["radii"],
                  normalize_axes=True)
    return statistics(cells, data["cell_types"]), reached


def qpcontact_side(folder: Path, size: int) -> tuple[dict[str, float], dict[int, tuple[float, float]]]:
    """qpcontact's state at ``size`` (the first snapshot at least that large) and its (time, wall)."""
    with open(folder / "history.csv") as fh:
        rows = list(csv.DictReader(fh))
    wall = np.cumsum([float(r["step_seconds"]) for r in rows])
    reached = {n: next((float(r["time"]), float(w)) for r, w in zip(rows, wall, strict=True) if int(r["cells"]) >= n)
               for n in (1000, 2000, size)}
    snapshots = sorted((folder / "snapshots").glob("step_*.npz"))
    colony = next(s.colony for s in map(load_snapshot, snapshots) if s.colony.cells.n >= size)
    return statistics(colony.cells, colony.cell_types), reached


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--size", type=int, default=5000, help="the colony size compared (default 5000)")
    parser.add_argument("--dt", type=float, default=0.025, help="the model's time step (default 0.025)")
    parser.add_argument("--cellmodeller", type=Path, nargs="+", required=True, help="CellModeller's folders, one per seed")
    parser.add_argument("--qpcontact", type=Path, nargs="+", required=True, help="qpcontact's run folders, one per seed")
    args = parser.parse_args(argv)
    sides = {"CellModeller": [cellmodeller_side(f, args.size, args.dt) for f in args.cellmodeller],
             "qpcontact": [qpcontact_side(f, args.size) for f in args.qpcontact]}
    for name, runs in sides.items():
        print(f"{name} ({len(runs)} seeds)")
        for n in (1000, 2000, args.size):
            times = [r[1][n][0] for r in runs]
            walls = [r[1][n][1] for r in runs]
            print(f"  {n:>6} cells at t = {np.mean(times):.3f} ({min(times):.3f}–{max(times):.3f}), wall "
                  f"{np.mean(walls):.1f} s ({min(walls):.1f}–{max(walls):.1f})")
        for key in runs[0][0]:
            values = [r[0][key] for r in runs]
            print(f"  {key:>18}: {np.mean(values):.3f} ({min(values):.3f}–{max(values):.3f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
