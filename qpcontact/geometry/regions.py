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

from typing import Any

import numpy as np

from .cells import Cells
from .contacts import candidate_pairs


def halo_width(cells: Cells, margin: float, slack: np.ndarray | None = None) -> float:
    """How far [length] beyond its slab a process must see: the largest distance between the
    centres of two cells that can be candidates (module docstring)."""
    widest = float(np.max(slack)) if slack is not None and slack.size else 0.0
    return float(np.max(cells.lengths) + 2.0 * np.max(cells.radii)) + margin + 2.0 * widest


def region_pairs(cells: Cells, margin: float, slack: np.ndarray | None, rank: int, size: int) -> np.ndarray:
    """(P, 2) the candidate pairs ``i < j`` (global indices) whose first cell ``i`` lies in slab
    ``rank`` of ``size``, searched among that slab's cells and its halo."""
    centers = cells.centers
    axis = int(np.argmax(np.ptp(centers, axis=0)))
    x = centers[:, axis]
    edges = np.quantile(x, np.linspace(0.0, 1.0, size + 1))
    own = (x >= edges[rank]) & ((x < edges[rank + 1]) | (rank == size - 1))
    halo = halo_width(cells, margin, slack)
    near = np.flatnonzero((x >= edges[rank] - halo) & (x <= edges[rank + 1] + halo))
    if near.size < 2:
        return np.zeros((0, 2), dtype=np.intp)
    found = near[candidate_pairs(cells.subset(near), margin, None if slack is None else slack[near])]
    return found[own[found[:, 0]]]


class Split:
    """The processes of ``comm`` (an mpi4py communicator) sharing a step's detection; None: one
    process, which does it all."""

    def __init__(self, comm: Any = None) -> None:
        self.comm = comm
        self.size = 1 if comm is None else int(comm.Get_size())
        self.rank = 0 if comm is None else int(comm.Get_rank())

    def candidate_pairs(self, cells: Cells, margin: float = 0.0, slack: np.ndarray | None = None) -> np.ndarray:
        """:func:`~qpcontact.geometry.contacts.candidate_pairs`, searched region by region and put
        together in every process (sorted as one search sorts them)."""
        if self.size == 1 or cells.n < 2:
            return candidate_pairs(cells, margin, slack)
        pairs = np.concatenate(self.comm.allgather(region_pairs(cells, margin, slack, self.rank, self.size)))
        return pairs[np.argsort(pairs[:, 0].astype(np.int64) * cells.n + pairs[:, 1])]

    def share(self, count: int) -> slice:
        """This process's contiguous part of ``count`` items (parts in the order of the processes)."""
        bounds = np.linspace(0, count, self.size + 1).astype(np.intp)
        return slice(int(bounds[self.rank]), int(bounds[self.rank + 1]))

    def gather(self, part: Any) -> list[Any]:
        """Every process's ``part``, in the order of the processes, in every process."""
        return [part] if self.size == 1 else list(self.comm.allgather(part))


#: One process on its own.
ONE = Split()
