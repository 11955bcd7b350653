"""A cell as a CellModeller model sees it: :class:`CellState`, with CellModeller's attribute names.

The objects a model's ``init(cell)``, ``update(cells)`` and ``divide(parent, d1, d2)`` are given,
and what the pickles in CellModeller's layout hold (:mod:`qpcontact.cellmodeller.pickles`): an
analysis script written for CellModeller's pickles loads them with qpcontact installed, without
CellModeller.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any


class CellState:
    """One cell, as CellModeller's ``CellModeller.CellState.CellState``.

    Set by qpcontact from the physics (CellModeller's ``CLBacterium`` sets the same): ``id``,
    ``pos`` (3 floats, µm), ``dir`` (unit 3-vector), ``length`` (the cylinder between the cap
    centres, µm), ``radius`` (µm), ``volume`` (equal to ``length``, as CellModeller sets it),
    ``ends`` (``pos ∓ dir·length/2``), ``strainRate`` (relative length change over the last step),
    ``effGrowth`` (the mean length change per step over the cell's life), ``cellAge`` (steps since
    birth), ``oldLen``, ``startVol``, ``neighbours`` (ids of the cells it touches, with
    ``CLBacterium(compNeighbours=True)``), ``cts`` (their number), ``time`` (the model's time at
    the start of the step). Set by the model: ``growthRate`` [1/time unit], ``cellType``,
    ``divideFlag``, ``color`` (RGB in [0, 1]), ``targetVol`` and any attribute of its own, which
    both daughters inherit (copied) before ``divide(parent, d1, d2)`` runs.
    """

    # CellModeller's GUI hides these (kept for scripts that read it).
    excludeAttr = ["id", "divideFlag", "ends", "cellAdh"]  # noqa: RUF012 (CellModeller's class attribute)

    def __init__(self, cid: int) -> None:
        self.id = cid
        self.growthRate = 1.0
        self.color: Any = [0.5, 0.5, 0.5]
        self.divideFlag = False
        self.cellAge = 0
        self.neighbours: list[int] = []
        self.effGrowth = 0.0

    if TYPE_CHECKING:  # any attribute, as CellModeller's (typing only: no behaviour added)
        def __getattr__(self, name: str) -> Any: ...

        def __setattr__(self, name: str, value: Any) -> None: ...

    def __repr__(self) -> str:
        return f"CellState(id={getattr(self, 'id', '?')})"
