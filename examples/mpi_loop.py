"""Your own timestep loop over MPI processes: ``mpiexec -n 2 python examples/mpi_loop.py``.

Every process holds the same cells and calls :func:`qpcontact.position_step` with the same
arguments; the solver ``ipm-petsc`` splits each step's solve among the processes and gives every
one the whole answer, so the processes stay identical (docs/distributed.md). 400 rods in a
monolayer, drawn together towards the origin, stepped with the distributed solver; process 0
prints the largest overlap of each step. Needs the distributed stack (scripts/install-mpi VENV):
without it, one line says what to install and the exit status is 2.

    mpiexec -n 2 VENV/bin/python examples/mpi_loop.py [--steps 10]
"""

from __future__ import annotations

import argparse
import hashlib
import sys

import numpy as np

import qpcontact as qc
from qpcontact.solvers.petsc import world


def scene(side: int = 20, seed: int = 1) -> qc.Cells:
    """``side`` × ``side`` rods of length 2 and radius 0.5 on a loose grid, turned at random
    (the same in every process: the same seed)."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(3.2 * np.arange(side), 1.5 * np.arange(side))
    centers = np.column_stack([x.ravel(), y.ravel(), np.zeros(side * side)])
    angle = rng.uniform(-0.1, 0.1, side * side)
    axes = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(side * side)])
    return qc.Cells(centers=centers - centers.mean(axis=0), axes=axes, lengths=2.0, radii=0.5, masses=1.0,
                    growth_inertia=np.inf)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--steps", type=int, default=10, help="number of steps (default: 10)")
    parser.add_argument("--dt", type=float, default=0.05, help="time step (default: 0.05)")
    args = parser.parse_args(argv)

    try:
        comm = world()
    except qc.NotInstalledError as exc:  # one line naming what to install, no traceback
        print(f"mpi_loop: {exc}", file=sys.stderr)
        return 2
    cells = scene()
    settings = qc.PositionSettings(solver="ipm-petsc")
    if comm.Get_rank() == 0:
        print(f"{cells.n} cells on {comm.Get_size()} processes")
    for i in range(args.steps):
        drive = -4.0 * cells.masses[:, None] * np.column_stack([cells.centers, np.zeros((cells.n, 4))])
        drive[:, 2] = 0.0  # stay in the plane
        out = qc.position_step(cells, args.dt, drive=drive, settings=settings, comm=comm)
        cells = out.cells
        if comm.Get_rank() == 0:
            print(f"step {i}: {len(out.contacts)} contacts, largest overlap {out.max_overlap:.4f} of a diameter, "
                  f"{out.iterations} linearizations, {out.solver_iterations} interior-point iterations")
    # Every process got the whole answer of each step: they hold the same cells, to the last bit.
    digest = hashlib.sha256(cells.centers.tobytes() + cells.axes.tobytes() + cells.lengths.tobytes()).hexdigest()
    same = len(set(comm.allgather(digest))) == 1
    if comm.Get_rank() == 0:
        print(f"every process holds the same cells: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
