"""A run over MPI processes (docs/distributed.md): ``mpiexec -n P qpcontact simulate ...``.

Every process holds the whole colony (its state is small: about 200 bytes a cell) and takes the
same steps with the same random numbers; contact detection is shared by region
(:mod:`qpcontact.geometry.regions`) and the position step's solve, the part of a step that grows
fastest with the colony, is split among them by the distributed interior point (``ipm-petsc``,
:mod:`qpcontact.solvers.petsc`); every process receives the whole of each, so the processes stay
identical bit for bit. Process 0 alone writes the run's folder (snapshots,
history, ParaView files, pictures) and prints; a resumed run reads the same snapshot in every
process. A signal (Ctrl-C, SIGTERM) stops the run at the end of the step on every process at
once (:class:`CollectiveInterrupt`), never in the middle of a collective solve.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from typing import Any

from ..errors import InvalidArgumentError, NotInstalledError
from ..solvers.ipm import UNKNOWNS_ACCURACY
from .settings import Settings
from .signals import Interrupt

#: What MPI launchers put in each process's environment: the number of processes (Open MPI's
#: mpiexec; MPICH's and Intel MPI's, through PMI; Slurm's srun, for its job step).
SIZE_VARIABLES = ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "SLURM_STEP_NUM_TASKS")
#: The solver that splits a step among the processes.
DISTRIBUTED_SOLVER = "ipm-petsc"


def launched_size() -> int:
    """The number of processes the MPI launcher started (1 when not launched by one), from the
    environment: no MPI library is loaded to find out."""
    for name in SIZE_VARIABLES:
        value = os.environ.get(name, "")
        if value.isdigit():
            return int(value)
    return 1


def processes() -> Any | None:
    """The MPI communicator of this run when it was launched on more than one process (mpi4py's
    ``COMM_WORLD``), else None: a run in one process never loads MPI.

    Raises:
        NotInstalledError: launched on several processes without petsc4py and mpi4py.
    """
    if launched_size() <= 1:
        return None
    from ..solvers import petsc

    if not petsc.installed():
        raise NotInstalledError(
            f"launched on {launched_size()} MPI processes, but petsc4py and mpi4py cannot be imported: install the "
            "distributed stack with scripts/install-mpi VENV (docs/distributed.md), or run in one process")
    comm = petsc.world()
    return comm if comm.Get_size() > 1 else None


def distributed_settings(settings: Settings, comm: Any) -> tuple[Settings, str]:
    """The settings of a run over ``comm``'s processes and what was changed, said: the position
    step's solver ``ipm`` becomes its distributed form ``ipm-petsc`` (the same method).

    Raises:
        InvalidArgumentError: a velocity-level run, another solver (each process would solve
            the whole problem), a solver tolerance below what ``ipm-petsc`` reaches, or a
            second-order step.
    """
    size = comm.Get_size()
    if settings.run.step != "position":
        raise InvalidArgumentError(f"a run on {size} MPI processes takes the position step (--step position); got "
                                   f"--step {settings.run.step}")
    solver = settings.position.solver
    if settings.position.tolerance < UNKNOWNS_ACCURACY:
        raise InvalidArgumentError(f"a run on {size} MPI processes solves to --position-tolerance {UNKNOWNS_ACCURACY:g} "
                                   f"or looser ({DISTRIBUTED_SOLVER} works in the unknowns only); got "
                                   f"{settings.position.tolerance:g}")
    if settings.position.second_order:
        raise InvalidArgumentError(f"a run on {size} MPI processes takes first-order linearizations "
                                   f"({DISTRIBUTED_SOLVER} takes no curvature); got --position-second-order true")
    if solver == DISTRIBUTED_SOLVER:
        return settings, ""
    if solver != "ipm":
        raise InvalidArgumentError(f"a run on {size} MPI processes splits its solves with {DISTRIBUTED_SOLVER}; "
                                   f"--position-solver {solver} would solve the whole problem in every process")
    return (settings.updated({"position.solver": DISTRIBUTED_SOLVER}, "mpi"),
            f"running on {size} MPI processes: position solver ipm -> {DISTRIBUTED_SOLVER} (the same interior point, "
            "split among them)")


class CollectiveInterrupt(Interrupt):
    """:class:`~qpcontact.simulation.signals.Interrupt` for a run over MPI processes: a signal never
    abandons a step (the other processes would wait in the step's solve for ever); the run stops
    at the end of the step, on every process at once, as soon as any of them has had one."""

    def __init__(self, comm: Any) -> None:
        super().__init__()
        self.comm = comm

    @property
    def requested(self) -> bool:
        """Whether any process has had a signal (collective: every process asks once a step);
        then every process takes it as its own, so that all end the run alike."""
        number = max(self.comm.allgather(self.signal or 0))
        if number:
            self.signal = number
        return bool(number)

    @contextlib.contextmanager
    def armed(self) -> Iterator[None]:
        yield

    def _handle(self, number: int, frame: Any) -> None:
        self.signal = number
