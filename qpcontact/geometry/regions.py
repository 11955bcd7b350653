"""Contact detection shared among MPI processes (docs/distributed.md): each process searches the
cells of its own region of space with a halo of the cells that can touch them.

The regions are slabs of equal numbers of cells along the colony's longest extent (recomputed at
every search, so they follow the colony as it grows and moves). Two cells can be a candidate pair
only if their centres are closer than the longest cell plus two radii, the margin and twice the
largest slack (:func:`~qpcontact.geometry.contacts.candidate_pairs`), so a slab widened by that much
on each side (its halo) holds every partner of its own cells: each process searches its widened
slab, keeps the pairs whose first cell is its own (so each pair is kept once, by one process), and
the pairs of all processes are put together in every process, in the order a search in one process
gives. The narrow phase and the evaluation of the contacts are shared by contiguous parts
(:meth:`Split.share`, :meth:`Split.gather`). :data:`ONE` is a process on its own.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from ..errors import InvalidArgumentError
from .cells import Cells
from .contacts import candidate_pairs
from .motion import move


def halo_width(cells: Cells, margin: float, slack: np.ndarray | None = None) -> float:
    """How far [length] beyond its slab a process must see: the largest distance between the
    centres of two cells that can be candidates (module docstring)."""
    widest = float(np.max(slack)) if slack is not None and slack.size else 0.0
    return float(np.max(cells.lengths) + 2.0 * np.max(cells.radii)) + margin + 2.0 * widest


def slabs(cells: Cells, size: int) -> tuple[np.ndarray, np.ndarray]:
    """``(x, edges)``: each cell's coordinate along the colony's longest extent and the ``size + 1``
    edges of the slabs of equal numbers of cells along it (quantiles: a selection, O(N), that every
    process makes alike from the replicated state, so no process partitions for the others)."""
    centers = cells.centers
    axis = int(np.argmax(np.ptp(centers, axis=0))) if cells.n else 0
    x = centers[:, axis]
    return x, np.quantile(x, np.linspace(0.0, 1.0, size + 1)) if cells.n else np.zeros(size + 1)


def slab_owners(cells: Cells, size: int) -> np.ndarray:
    """(N,) the slab (process) of each cell: the regions of :func:`region_pairs`, which own the
    cells for the rest of a distributed step (the rows of the QP, the solver's unknowns)."""
    if size == 1 or cells.n == 0:
        return np.zeros(cells.n, dtype=np.intp)
    x, edges = slabs(cells, size)
    return np.clip(np.searchsorted(edges, x, side="right") - 1, 0, size - 1).astype(np.intp)


def region_pairs(cells: Cells, margin: float, slack: np.ndarray | None, rank: int, size: int) -> np.ndarray:
    """(P, 2) the candidate pairs ``i < j`` (global indices) whose first cell ``i`` lies in slab
    ``rank`` of ``size``, searched among that slab's cells and its halo."""
    x, edges = slabs(cells, size)
    own = slab_owners(cells, size) == rank
    halo = halo_width(cells, margin, slack)
    near = np.flatnonzero((x >= edges[rank] - halo) & (x <= edges[rank + 1] + halo))
    if near.size < 2:
        return np.zeros((0, 2), dtype=np.intp)
    found = near[candidate_pairs(cells.subset(near), margin, None if slack is None else slack[near])]
    return found[own[found[:, 0]]]


#: What :class:`Split`'s collectives cost this process since the counters were last set to 0:
#: the bytes it sent (each part counted once, as it leaves; what MPI forwards inside a collective
#: is not), how many it took part in, and the CPU seconds inside them (``time.process_time``,
#: waiting for the other processes included: what is not this process's own work).
SENT: dict[str, float] = {"bytes": 0, "collectives": 0, "collective_cpu": 0.0}


@contextmanager
def counted(table: dict[str, float], key: str) -> Iterator[None]:
    """Count the ``with`` block in ``table``: one more ``key + "s"`` and its CPU seconds
    (``time.process_time``) added to ``key + "_cpu"`` (:data:`SENT`'s collectives, and the
    distributed solver's counters, :data:`qpcontact.solvers.petsc.COUNTERS`)."""
    cpu = time.process_time()
    try:
        yield
    finally:
        table[key + "s"] += 1
        table[key + "_cpu"] += time.process_time() - cpu


def _nbytes(part: Any) -> int:
    """The bytes of the arrays in ``part`` (an array, or a tuple or list of them, or an object
    whose fields are arrays): what a collective sends of it."""
    if isinstance(part, np.ndarray):
        return int(part.nbytes)
    if isinstance(part, tuple | list):
        return sum(_nbytes(p) for p in part)
    fields = getattr(part, "__dict__", None) or {}
    return sum(_nbytes(v) for v in fields.values() if isinstance(v, np.ndarray))


class Split:
    """The processes of ``comm`` (an mpi4py communicator) sharing a step's detection; None: one
    process, which does it all. ``owner``: (N,) the process that owns each cell in the step
    (:func:`slab_owners` of the cells at its start), set by :meth:`own`."""

    def __init__(self, comm: Any = None) -> None:
        self.comm = comm
        self.size = 1 if comm is None else int(comm.Get_size())
        self.rank = 0 if comm is None else int(comm.Get_rank())
        self.owner: np.ndarray | None = None

    def own(self, cells: Cells) -> np.ndarray:
        """Set and return :attr:`owner` from the cells at the start of a step."""
        self.owner = slab_owners(cells, self.size)
        return self.owner

    def _reduced(self, value: float, op: str) -> float:
        """``value`` reduced over the processes, to process 0 then broadcast (an all-reduce may
        give processes results that differ in the last bit, and their branches would part)."""
        if self.size == 1:
            return float(value)
        from mpi4py import MPI

        ops = {"total": MPI.SUM, "most": MPI.MAX}
        SENT["bytes"] += 16
        with counted(SENT, "collective"):
            return float(self.comm.bcast(self.comm.reduce(float(value), op=ops[op], root=0), root=0))

    def total(self, value: float) -> float:
        """The sum of ``value`` over the processes, the same bits in each."""
        return self._reduced(value, "total")

    def most(self, value: float) -> float:
        """The largest ``value`` of the processes."""
        return self._reduced(value, "most")

    def summed(self, vector: np.ndarray) -> np.ndarray:
        """The element-wise sum of every process's ``vector`` (the same length in each), the same
        bits in each process (summed on process 0 in the order of the processes, then broadcast)."""
        if self.size == 1:
            return vector
        from mpi4py import MPI

        vector = np.ascontiguousarray(vector, dtype=float)
        out = np.empty_like(vector)
        with counted(SENT, "collective"):
            self.comm.Reduce(vector, out, op=MPI.SUM, root=0)
            self.comm.Bcast(out, root=0)
        SENT["bytes"] += vector.nbytes * (2 if self.rank == 0 else 1)
        return out

    def candidate_pairs(self, cells: Cells, margin: float = 0.0, slack: np.ndarray | None = None) -> np.ndarray:
        """:func:`~qpcontact.geometry.contacts.candidate_pairs`, searched region by region and put
        together in every process (sorted as one search sorts them)."""
        if self.size == 1 or cells.n < 2:
            return candidate_pairs(cells, margin, slack)
        pairs = np.concatenate(self.gather(region_pairs(cells, margin, slack, self.rank, self.size)))
        return pairs[np.argsort(pairs[:, 0].astype(np.int64) * cells.n + pairs[:, 1])]

    def share(self, count: int) -> slice:
        """This process's contiguous part of ``count`` items (parts in the order of the processes)."""
        bounds = np.linspace(0, count, self.size + 1).astype(np.intp)
        return slice(int(bounds[self.rank]), int(bounds[self.rank + 1]))

    def moved(self, cells: Cells, dt: float, momenta: np.ndarray) -> Cells:
        """:func:`~qpcontact.geometry.motion.move` of the cells, each process moving those it owns
        (:attr:`owner`) and the moved positions, axes and lengths put together in every process
        (7 numbers a cell, in one ``Allgatherv``).

        Raises:
            InvalidArgumentError: as :func:`~qpcontact.geometry.motion.move`, in every process.
        """
        if self.size == 1 or self.owner is None:
            return move(cells, dt, momenta)
        mine = np.flatnonzero(self.owner == self.rank)
        failed: InvalidArgumentError | None = None
        try:
            part = move(cells.subset(mine), dt, momenta[mine])
            local = np.column_stack([part.centers, part.axes, part.lengths])
        except InvalidArgumentError as exc:  # told to every process, or the others would wait for ever
            failed, local = exc, np.zeros((mine.size, 7))
        if self.most(float(failed is not None)):
            raise failed or InvalidArgumentError(f"dt = {dt!r}: a cell of another process would move, turn or "
                                                 "shrink beyond what a step allows (its message is that process's)")
        counts = np.bincount(self.owner, minlength=self.size) * 7
        whole = np.empty(cells.n * 7)
        with counted(SENT, "collective"):
            self.comm.Allgatherv(np.ascontiguousarray(local).ravel(), [whole, counts])
        SENT["bytes"] += local.nbytes
        out = np.empty((cells.n, 7))
        out[np.argsort(self.owner, kind="stable")] = whole.reshape(-1, 7)
        return cells.replace(momenta=momenta[:, 0:3], angular_momenta=momenta[:, 3:6], growth_momenta=momenta[:, 6],
                             centers=out[:, :3], axes=out[:, 3:6], lengths=out[:, 6])

    def gather(self, part: Any) -> list[Any]:
        """Every process's ``part``, in the order of the processes, in every process."""
        if self.size == 1:
            return [part]
        SENT["bytes"] += _nbytes(part)
        with counted(SENT, "collective"):
            return list(self.comm.allgather(part))


#: One process on its own.
ONE = Split()
