"""A handful of cells in your own timestep loop.

Six rods in a monolayer, two of them pushed into the others, stepped with ``qpcontact.step``.
The step options are those ``qpcontact simulate`` uses (``Settings().step_options()``: a
speculative margin of 0.3 µm, position correction 0.5, Clarabel at 1e-6): ``step``'s own
defaults are those of a single contact solve (no margin, no position correction), which leave
an overlap standing once there is one. Prints the largest overlap every few steps.

    python examples/own_loop.py [--steps 60]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

import qpcontact as qc
from qpcontact.geometry import largest_overlap
from qpcontact.simulation import Settings

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
    options = Settings().step_options()  # what qpcontact simulate passes to step (2D: planar, no planes)
    drive = np.zeros((cells.n, 7))
    drive[:2, 1] = 2.0 * cells.masses[:2]  # push the first two rods along +y at 2 µm per doubling time
    print(f"step options: {', '.join(f'{k}={v!r}' for k, v in options.items() if k != 'planes')}")
    print("step | largest overlap [fraction of the diameter] | contacts | solve [ms]")
    for i in range(args.steps + 1):
        if i % 10 == 0:
            print(f"{i:4d} | {largest_overlap(cells):.2e} |", end=" ")
        out = qc.step(cells, args.dt, drive=drive, **options)
        cells = out.cells
        if i % 10 == 0:
            print(f"{len(out.result.contacts)} | {1e3 * out.result.times['solve']:.1f}")
    print(f"final largest overlap {largest_overlap(cells):.2e} of a diameter")
    return 0 if largest_overlap(cells) < 0.05 else 1


if __name__ == "__main__":
    sys.exit(main())
