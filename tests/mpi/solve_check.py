"""Run under ``mpiexec -n P``: the QPs of a grown colony's position steps (with their bounds),
solved by ipm in each process and by ipm-petsc over the processes; process 0 prints one line per
QP and partition (METIS's, or owners given: contiguous blocks of cells, each process's rows those
of its first cell), ``checked P HOW STATUS DIFFERENCE`` (the largest difference of the answers, relative to the
largest unknown). Used by test_distributed.py."""

from __future__ import annotations

import numpy as np

from qpcontact.simulation import Settings, run_colony
from qpcontact.solvers import Problem, solve
from qpcontact.solvers.ipm import interior_point
from qpcontact.solvers.petsc import distributed_interior_point, world
from qpcontact.timestep import position

comm = world()
problems: list[Problem] = []


def capture(problem: Problem, *args, **kwargs):
    problems.append(problem)
    return solve(problem, *args, **kwargs)


position.solve = capture  # the QPs of every linearization (the same in each process: same run)
run_colony(Settings().updated({"cells": 300}), progress=False)
size = comm.Get_size()
for problem in problems[-3:]:
    one = interior_point(problem.matrix, problem.rhs, problem.lower, problem.upper, tolerance=1e-4)
    columns = problem.matrix.shape[1]
    column_owner = np.arange(columns) * size // columns  # blocks of whole cells or not: any owner is valid
    row_owner = column_owner[problem.matrix.indices[problem.matrix.indptr[:-1]]]
    for how, owners in (("metis", None), ("owners", (column_owner, row_owner))):
        split = distributed_interior_point(problem.matrix, problem.rhs, problem.lower, problem.upper, tolerance=1e-4,
                                           owners=owners)
        difference = float(np.max(np.abs(one.y - split.y))) / max(1.0, float(np.max(np.abs(one.y))))
        if comm.Get_rank() == 0:
            print(f"checked {size} {how} {split.status} {difference:.3g}", flush=True)

# Where MUMPS with PT-Scotch is installed (scripts/install-mpi installs it), its analysis ran on
# every process (INFOG(32) = 2).
from qpcontact.solvers.petsc import COUNTERS, parallel_analysis  # noqa: E402

if comm.Get_rank() == 0:
    print(f"analysis loaded {int(parallel_analysis())} parallel {int(COUNTERS['parallel_analysis'])}", flush=True)
