"""A handful of cells in your own timestep loop, with the position-level step.

Six rods in a monolayer, two of them overlapping and pushed into the others, stepped with
``qpcontact.position_step`` (what ``qpcontact simulate`` runs): overdamped cells move by
``dt·W·(drive + contact forces)``, and no contact overlaps at the end of a step by more than the
overlap tolerance (``PositionSettings().overlap_tolerance``, 0.01 of a diameter). An overlap the
cells start with is cleared over a step or two (at most ``relaxation`` + ``aim`` of a diameter
per step, so that no cell is thrown). Each step's ``motion`` is handed to the next, whose first
linearization then sees the contacts the cells are moving into. Prints the largest overlap every
few steps.

    python examples/own_loop.py [--steps 60]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

import qpcontact as qc
from qpcontact.geometry import largest_overlap

#: Units of this example: µm, doubling times, mass = volume (as in qpcontact simulate).
RADIUS = 0.5


def scene() -> qc.Cells:
    """Six rods in the xy-plane; the first two overlap by 5 % of a diameter."""
    centers = np.array([[0.0, y, 0.0] for y in (0.0, 0.95, 2.0, 3.0)] + [[3.0, 0.5, 0.0], [3.0, 2.3, 0.0]])
    axes = np.array([[1.0, 0.0, 0.0]] * 4 + [[0.8, 0.6, 0.0], [1.0, 0.0, 0.0]])
    return qc.Cells(centers=centers, axes=axes, lengths=2.0, radii=RADIUS, masses=1.0, growth_inertia=np.inf)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--steps", type=int, default=60, help="number of steps (default: 60)")
    parser.add_argument("--dt", type=float, default=0.02, help="time step [doubling times] (default: 0.02)")
    args = parser.parse_args(argv)

    cells = scene()
    settings = qc.PositionSettings()  # the [position] settings of qpcontact simulate
    drive = np.zeros((cells.n, 7))
    drive[:2, 1] = 2.0 * cells.masses[:2]  # push the first two rods along +y at 2 µm per doubling time
    print(f"position step: {settings.solver} at tolerance {settings.tolerance:g}, overlap ≤ "
          f"{settings.overlap_tolerance:g} of a diameter")
    print("step | largest overlap [fraction of the diameter] | contacts | linearizations")
    motion = None
    for i in range(args.steps + 1):
        if i % 10 == 0:
            print(f"{i:4d} | {largest_overlap(cells):.2e} |", end=" ")
        out = qc.position_step(cells, args.dt, drive=drive, planar=True, settings=settings, motion=motion)
        cells, motion = out.cells, out.motion
        if i % 10 == 0:
            print(f"{len(out.contacts)} | {out.iterations}")
    print(f"final largest overlap {largest_overlap(cells):.2e} of a diameter")
    return 0 if largest_overlap(cells) <= settings.overlap_tolerance else 1


if __name__ == "__main__":
    sys.exit(main())
