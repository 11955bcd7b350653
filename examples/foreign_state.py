"""Clear the overlaps of a state from another simulator with the position-level step.

A state written by another simulator (CellModeller, say) has overlaps that qpcontact's own runs
never reach: 0.1–0.15 of a diameter. The position-level step removes overlap present at the start
at a bounded speed (0.05 of a diameter per step, ``PositionSettings.relaxation``), so no cell
is thrown or spun: a step's push is the least that clears that much. This script takes such a state, steps it
without growth, and prints per step the largest overlap and how far the cells moved and turned
(tip travel from turning and centre travel, fractions of the diameter).

    python examples/foreign_state.py                          # a packed layer made to overlap
    python examples/foreign_state.py --state tests/data/cellmodeller/ex1_simpleGrowth_seed1 --steps 3

``--state`` is a CellModeller state — one of its ``step-NNNNN.pickle`` files or a run folder of
them (its last step), read with :func:`qpcontact.read_cellmodeller`; the 10⁴-cell states of
``benchmarks/cellmodeller/grow_cellmodeller.py`` are such pickles — or a qpcontact snapshot
(``.npz``, e.g. one that ``qpcontact import-cellmodeller`` wrote). Exit status 1 if the largest
overlap ever grew or a cell's tips turned by more than :data:`SPUN` of a diameter in a step.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import qpcontact as qc
from qpcontact.geometry import largest_overlap
from qpcontact.timestep import PositionSettings, position_step


def packed_layer(rows: int, overlap: float, seed: int = 1) -> qc.Cells:
    """Rows of rods (length 2, radius 0.5) with neighbouring rows ``overlap`` diameters into each
    other and small random tilts: the kind of state a looser simulator leaves."""
    rng = np.random.default_rng(seed)
    y, x = np.meshgrid(np.arange(rows) * (1.0 - overlap), np.arange(rows) * 3.05, indexing="ij")
    n = x.size
    angle = rng.uniform(-0.02, 0.02, n)
    centers = np.column_stack([x.ravel(), y.ravel(), np.zeros(n)])
    axes = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(n)])
    return qc.Cells(centers=centers, axes=axes, lengths=2.0, radii=0.5, masses=1.0, growth_inertia=np.inf)


def load_state(path: Path) -> qc.Cells:
    """The cells of a CellModeller state or a qpcontact snapshot (masses: volume in µm³), not
    growing."""
    colony = qc.load_colony(path)[0] if path.suffix == ".npz" else qc.read_cellmodeller(path).colony
    return colony.cells.replace(growth_inertia=np.inf)


#: Tips that turn this far [diameters] in a step that clears 0.05 of a diameter of overlap: spun.
SPUN = 0.5


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--state", type=Path, help="a CellModeller pickle or run folder, or a qpcontact snapshot (.npz); default: a packed layer")
    parser.add_argument("--rows", type=int, default=20, help="rows (and columns) of the packed layer (default: 20)")
    parser.add_argument("--overlap", type=float, default=0.15,
                        help="overlap of the packed layer's rows [fraction of the diameter] (default: 0.15)")
    parser.add_argument("--steps", type=int, default=8, help="steps (default: 8)")
    parser.add_argument("--dt", type=float, default=0.05, help="time step [doubling times] (default: 0.05)")
    args = parser.parse_args(argv)

    cells = load_state(args.state) if args.state else packed_layer(args.rows, args.overlap)
    planar = bool(np.all(cells.centers[:, 2] == cells.centers[0, 2]) and np.all(cells.axes[:, 2] == 0.0))
    settings = PositionSettings()
    diameter = 2.0 * cells.radii
    print(f"{cells.n} cells, {'2D' if planar else '3D'}, largest overlap {largest_overlap(cells):.3f} of a diameter")
    print("step | largest overlap | largest turn (tip travel) | largest move (centre) | linearizations | seconds")
    ok, before = True, largest_overlap(cells)
    for i in range(1, args.steps + 1):
        t0 = time.perf_counter()
        out = position_step(cells, args.dt, planar=planar, settings=settings)
        seconds = time.perf_counter() - t0
        turn = np.linalg.norm(out.cells.axes - cells.axes, axis=1) * cells.lengths / 2 / diameter
        move = np.linalg.norm(out.cells.centers - cells.centers, axis=1) / diameter
        cells, after = out.cells, largest_overlap(out.cells)
        print(f"{i:4d} | {after:.4f} | {turn.max():.4f} | {move.max():.4f} | {out.iterations} | {seconds:.2f}")
        ok &= after <= before + 1e-9 and turn.max() <= SPUN
        before = after
    print(f"largest overlap never grew, no cell's tips turned {SPUN} of a diameter in a step" if ok
          else "FAILED: overlap grew or a cell spun")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
