"""The parts of a run over MPI processes that need no MPI: how a launch is recognized, the
settings of a distributed run, the partition of a problem, the collective stop (with a stand-in
for the communicator). The runs themselves are in test_distributed.py."""

from __future__ import annotations

import signal

import numpy as np
import pytest
import scipy.sparse as sp

from qpcontact import InvalidArgumentError, NotInstalledError
from qpcontact.simulation import ranks
from qpcontact.simulation.settings import Settings
from qpcontact.solvers.petsc import Partition


class FakeComm:
    """The few calls the code makes of an mpi4py communicator, for ``size`` processes of which
    this is ``rank``; ``others`` is what the other processes contribute to a reduction."""

    def __init__(self, size: int = 2, rank: int = 0, others: int = 0) -> None:
        self.size, self.rank, self.others = size, rank, others

    def Get_size(self) -> int:
        return self.size

    def Get_rank(self) -> int:
        return self.rank

    def bcast(self, value, root=0):
        return value

    def allgather(self, value):
        return [value, self.others]


@pytest.mark.parametrize(("environment", "size"), [
    ({}, 1), ({"OMPI_COMM_WORLD_SIZE": "4"}, 4), ({"PMI_SIZE": "2"}, 2), ({"SLURM_STEP_NUM_TASKS": "8"}, 8),
    ({"OMPI_COMM_WORLD_SIZE": "x"}, 1)])
def test_a_launch_is_recognized_from_the_environment(monkeypatch, environment, size):
    for name in ranks.SIZE_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    for name, value in environment.items():
        monkeypatch.setenv(name, value)
    assert ranks.launched_size() == size


def test_one_process_never_loads_mpi(monkeypatch):
    for name in ranks.SIZE_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    assert ranks.processes() is None


def test_a_launch_without_the_stack_is_a_named_error(monkeypatch):
    from qpcontact.solvers import petsc

    monkeypatch.setenv("OMPI_COMM_WORLD_SIZE", "2")
    monkeypatch.setattr(petsc, "installed", lambda: False)
    with pytest.raises(NotInstalledError, match="scripts/install-mpi"):
        ranks.processes()
    monkeypatch.delenv("OMPI_COMM_WORLD_SIZE")
    with pytest.raises(NotInstalledError, match=r"^the distributed stack needs petsc4py and mpi4py: scripts/install-mpi"):
        petsc.world()  # (issue 35: a ModuleNotFoundError's traceback before)


@pytest.mark.parametrize(("values", "match"), [({"position.solver": "clarabel"}, "every process"),
                                               ({"step": "velocity"}, "--step position"),
                                               ({"position.tolerance": 1e-6}, "0.0001 or looser")])
def test_what_a_distributed_run_cannot_do_is_refused(values, match):
    with pytest.raises(InvalidArgumentError, match=match):
        ranks.distributed_settings(Settings().updated(values), FakeComm(2))


def test_a_signal_on_any_process_stops_every_process_at_the_end_of_the_step():
    quiet = ranks.CollectiveInterrupt(FakeComm(2, others=0))
    assert not quiet.requested
    told = ranks.CollectiveInterrupt(FakeComm(2, others=int(signal.SIGTERM)))
    assert told.requested and told.signal == signal.SIGTERM
    with told.armed():
        told._handle(signal.SIGINT, None)  # no KeyboardInterrupt in the middle of a step
    assert told.signal == signal.SIGINT


def _cells_matrix(cells: int, seed: int = 0) -> sp.csr_matrix:
    """A contact matrix of a chain of cells with 3 unknowns each (rows: neighbours)."""
    rng = np.random.default_rng(seed)
    rows, cols, vals = [], [], []
    for k in range(cells - 1):
        for cell, sign in ((k, 1.0), (k + 1, -1.0)):
            for slot in range(3):
                rows.append(k)
                cols.append(3 * cell + slot)
                vals.append(sign * rng.uniform(0.5, 1.0))
    return sp.csr_matrix((vals, (rows, cols)), shape=(cells - 1, 3 * cells))


def test_the_partition_keeps_cells_whole_and_rows_with_their_first_cell():
    matrix = _cells_matrix(400)
    part = Partition(matrix, FakeComm(2))
    assert part.column_counts.sum() == matrix.shape[1] and part.row_counts.sum() == matrix.shape[0]
    assert np.all(part.column_counts > 0.3 * matrix.shape[1])  # balanced
    owner = np.empty(matrix.shape[1], dtype=int)
    for rank in range(2):
        owner[part.columns(rank)] = rank
    assert np.all(owner.reshape(-1, 3) == owner.reshape(-1, 3)[:, :1])  # a cell's unknowns together
    for rank in range(2):
        rows = part.rows(rank)
        assert np.all(owner[matrix.indices[matrix.indptr[rows]]] == rank)
    assert sorted(np.concatenate([part.rows(0), part.rows(1)])) == list(range(matrix.shape[0]))


def test_owners_given_are_taken_and_bad_ones_refused_by_name():
    matrix = _cells_matrix(40)
    columns = np.arange(matrix.shape[1]) * 2 // matrix.shape[1]
    rows = columns[matrix.indices[matrix.indptr[:-1]]]
    part = Partition(matrix, FakeComm(2), columns, rows)
    assert np.array_equal(part.columns(1), np.flatnonzero(columns == 1))
    assert np.array_equal(part.rows(0), np.flatnonzero(rows == 0))
    with pytest.raises(InvalidArgumentError, match="owners: expected"):
        Partition(matrix, FakeComm(2), columns + 1, rows)
    with pytest.raises(InvalidArgumentError, match="owners: expected"):
        Partition(matrix, FakeComm(2), columns[:-1], rows)


@pytest.mark.parametrize("size", [1, 2, 4, 8])
def test_the_slabs_own_every_cell_once_in_equal_parts(size):
    """The slabs that own the cells of a distributed step: every cell in one, equal numbers of
    cells (to one), in order along the colony's longest extent, and those of region_pairs."""
    from qpcontact.geometry import regions

    rng = np.random.default_rng(1)
    n = 1001
    centers = np.column_stack([rng.uniform(0, 100, n), rng.uniform(0, 20, n), np.zeros(n)])
    cells = qc_cells(centers)
    owner = regions.slab_owners(cells, size)
    counts = np.bincount(owner, minlength=size)
    assert counts.sum() == n and counts.max() - counts.min() <= 1
    order = np.argsort(centers[:, 0])
    assert np.all(np.diff(owner[order]) >= 0)  # slabs along x, the longest extent
    for rank in range(size):
        pairs = regions.region_pairs(cells, 0.5, None, rank, size)
        assert np.all(owner[pairs[:, 0]] == rank)


def qc_cells(centers: np.ndarray):
    import qpcontact as qc

    n = len(centers)
    return qc.Cells(centers=centers, axes=np.tile([1.0, 0.0, 0.0], (n, 1)), lengths=2.0, radii=0.5, masses=1.0,
                    growth_inertia=np.inf)


def test_one_process_owns_everything_in_its_order():
    matrix = _cells_matrix(50)
    part = Partition(matrix, FakeComm(1))
    assert np.array_equal(part.columns(0), np.arange(matrix.shape[1]))
    assert np.array_equal(part.rows(0), np.arange(matrix.shape[0]))


def test_a_communicator_is_for_the_distributed_solver_only():
    import qpcontact as qc

    cells = qc.Cells(centers=[[0.0, 0.0, 0.0], [0.0, 0.9, 0.0]], axes=[[1.0, 0.0, 0.0]] * 2, lengths=2.0, radii=0.5,
                     masses=1.0, growth_inertia=np.inf)
    with pytest.raises(InvalidArgumentError, match="only the solver ipm-petsc"):
        qc.position_step(cells, 0.1, comm=FakeComm(2))
