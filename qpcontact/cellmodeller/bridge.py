"""A CellModeller model as a qpcontact model hook: :class:`ModelHook`.

Each step of :func:`qpcontact.simulation.run_colony`, the hook does what CellModeller's
``Simulator.step`` does around its physics:

1. the cells' :class:`~qpcontact.cellmodeller.state.CellState` objects get what the last step
   made (``CLBacterium.updateCellState``): ``pos``, ``dir``, ``length``, ``volume``, ``strainRate``,
   ``effGrowth``, ``cellAge``, ``neighbours``; and every ``pickleSteps`` steps a pickle in
   CellModeller's layout is written;
2. the model's ``update(cells)`` runs; its ``growthRate``, ``cellType``, ``color`` and every number
   of its own go into the colony (``rates``, ``cell_types``, ``cell_data``: snapshots keep them, so
   ``--resume`` has them back), and the cells it flagged (``divideFlag``) divide at the start of the
   step (``StepControl.dividing``), at the model's step ``dt``;
3. each division gives the daughters copies of their mother's state, new ids, ``cellAge = 0``,
   then the model's ``divide(parent, d1, d2)`` (:meth:`ModelHook.divided`, the hook's divide
   callback).

Units and what maps onto what: docs/cellmodeller.md.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

import numpy as np

from ..colony.growth import Colony
from ..colony.hooks import StepControl
from ..geometry import Cells
from ..geometry.contacts import find_contacts
from .model import Model, place, seed_model_random
from .state import CellState

#: CellState attributes the physics sets (or that are set again each step): not the model's numbers.
PHYSICS = frozenset({"id", "idx", "pos", "dir", "length", "radius", "volume", "ends", "neighbours", "cts", "vel",
                     "time", "startVol", "strainRate", "cellType", "divideFlag"})
#: CellState attributes of CellModeller's that snapshots keep (with the model's own numbers).
KEPT = ("growthRate", "cellAge", "effGrowth", "oldLen")


def rates_of(growth_rates: np.ndarray, dt: float) -> np.ndarray:
    """qpcontact's exponential rates [1/time unit] for CellModeller's ``growthRate``: a free cell
    of CellModeller grows ``length·growthRate·dt`` in a step of ``dt``; at ``ln(1 + r·dt)/dt``
    qpcontact's grows the same in the same step."""
    return np.log1p(growth_rates * dt) / dt


class ModelHook:
    """The hook of a CellModeller model (module docstring).

    Args:
        model: the loaded model (:func:`qpcontact.cellmodeller.model.load_model`).
        seed: the run's seed: the model's random numbers are seeded for each step from it
            (:func:`~qpcontact.cellmodeller.model.seed_model_random`).
        pickles: ``write(step_num, states, lineage)`` for CellModeller-layout pickles, or None.
        lineage: daughter id → mother id of the run so far (a resumed run's, from its pickles).
    """

    def __init__(self, model: Model, *, seed: int = 1, pickles: Callable[..., Any] | None = None,
                 lineage: dict[int, int] | None = None) -> None:
        self.model = model
        self.seed = seed
        self.pickles = pickles
        self.lineage: dict[int, int] = dict(lineage or {})
        self.states: dict[int, CellState] = {}
        self.left_out: dict[str, str] = {}
        self.synced = -1
        self.muA = float(model.physics.options["muA"])
        self.gamma = float(model.physics.options["gamma"])
        self.neighbours = bool(model.physics.options["compNeighbours"])
        self.divide_function = getattr(model.module, "divide", None)

    # -- the colony a run starts from -------------------------------------------------------
    def founders(self) -> Colony:
        """The cells the model's ``setup`` added, as a colony (ids as CellModeller's)."""
        states = self.model.founders
        self.states = {s.id: s for s in states}
        cells = Cells(centers=[s.pos for s in states], axes=[s.dir for s in states],
                      lengths=[s.length for s in states], radii=[s.radius for s in states], normalize_axes=True)
        colony = Colony(cells, np.array([s.id for s in states]), np.full(len(states), -1), np.zeros(len(states)))
        return self.numbers(colony, states)

    # -- each step --------------------------------------------------------------------------
    def __call__(self, colony: Colony, step: int) -> StepControl:
        states = self.adopt(colony)
        if step > 0:
            self.after_physics(colony, states, step)
        seed_model_random(self.seed, step)
        self.model.module.update({s.id: s for s in states})
        for state in states:
            state.time = colony.time
        flags = np.fromiter((bool(getattr(s, "divideFlag", False)) for s in states), bool, len(states))
        return StepControl(self.numbers(colony, states), dividing=flags, dt=self.model.dt)

    def divided(self, before: Colony, after: Colony, born: tuple[np.ndarray, np.ndarray, np.ndarray]) -> Colony:
        """The divide callback: CellModeller's ``Simulator.divide`` for each mother (module
        docstring), then the colony with the daughters' numbers (no owed length: CellModeller's
        daughters are born at ``length/2 − radius`` and grow from there)."""
        mothers, first, second = born
        centers, axes, lengths, radii = after.cells.centers, after.cells.axes, after.cells.lengths, after.cells.radii
        for m, a, b in zip(mothers.tolist(), first.tolist(), second.tolist(), strict=True):
            parent = self.states.pop(int(before.ids[m]))
            parent.divideFlag = False
            daughters = copy.deepcopy(parent), copy.deepcopy(parent)
            for daughter, row in zip(daughters, (a, b), strict=True):
                daughter.id, daughter.cellAge = int(after.ids[row]), 0
                place(daughter, centers[row], axes[row], float(lengths[row]), float(radii[row]))
                self.lineage[daughter.id] = parent.id
                self.states[daughter.id] = daughter
            if callable(self.divide_function):
                self.divide_function(parent, *daughters)
        return self.numbers(after, [self.states[int(i)] for i in after.ids])

    # -- between the objects and the colony -------------------------------------------------
    def adopt(self, colony: Colony) -> list[CellState]:
        """The state objects of the colony's cells, in its order; a cell without one (a run
        resumed from a snapshot) gets one from the colony's arrays."""
        missing = [row for row, i in enumerate(colony.ids.tolist()) if i not in self.states]
        for row in missing:
            self.states[int(colony.ids[row])] = self._restored(colony, row)
        if len(self.states) != colony.cells.n:
            alive = set(colony.ids.tolist())
            self.states = {i: s for i, s in self.states.items() if i in alive}
        states = [self.states[i] for i in colony.ids.tolist()]
        for row, state in enumerate(states):
            state.idx = row
        return states

    def _restored(self, colony: Colony, row: int) -> CellState:
        state = CellState(int(colony.ids[row]))
        cells = colony.cells
        place(state, cells.centers[row], cells.axes[row], float(cells.lengths[row]), float(cells.radii[row]))
        state.cellType = int(colony.cell_types[row])
        for name, values in colony.cell_data.items():
            value = values[row]
            setattr(state, name, value.tolist() if np.ndim(value) else value.item())
        state.time = colony.time
        return state

    def after_physics(self, colony: Colony, states: list[CellState], step: int) -> None:
        """CellModeller's ``updateCellState`` after the step that led to ``colony``; then the
        pickle of that step (CellModeller's ``stepNum`` is ``step − 1``) every ``pickleSteps``."""
        if self.synced == step:
            return
        self.synced = step
        cells = colony.cells
        lengths = cells.lengths
        old = np.array([s.oldLen for s in states], dtype=float)
        age = np.array([s.cellAge for s in states], dtype=float)
        effective = np.array([s.effGrowth for s in states], dtype=float)
        strain = (lengths - old) / np.where(old > 0.0, old, 1.0)
        effective = (effective * age + strain * old) / (age + 1)
        ends = cells.axes * (lengths / 2)[:, None]
        neighbours = self._neighbours(colony) if self.neighbours else None
        for row, (state, pos, axis, length) in enumerate(zip(states, cells.centers.tolist(), cells.axes.tolist(),
                                                             lengths.tolist(), strict=True)):
            state.pos, state.dir, state.length, state.volume, state.oldLen = pos, axis, length, length, length
            state.radius = float(cells.radii[row])
            state.strainRate, state.effGrowth = float(strain[row]), float(effective[row])
            state.cellAge = int(age[row]) + 1
            state.ends = (cells.centers[row] - ends[row], cells.centers[row] + ends[row])
            state.neighbours = [] if neighbours is None else neighbours[row]
            state.cts = len(state.neighbours)
        every = max(int(self.model.sim.pickleSteps or 1), 1)
        if self.pickles is not None and (step - 1) % every == 0:
            self.pickles(step - 1, states, self.lineage)

    def _neighbours(self, colony: Colony) -> list[list[int]]:
        """Each cell's touching cells (ids), as ``CLBacterium(compNeighbours=True)`` lists them:
        pairs closer than 0.05 of a diameter (qpcontact's step leaves touching cells at a small
        gap, up to 0.03 of one)."""
        cells = colony.cells
        contacts = find_contacts(cells, 0.05 * 2 * float(np.median(cells.radii)), planar=self.model.planar)
        a, b = contacts.cell_a, contacts.cell_b
        keep = b >= 0
        a, b = np.concatenate([a[keep], b[keep]]), np.concatenate([b[keep], a[keep]])
        order = np.lexsort((b, a))
        a, b = a[order], b[order]
        starts = np.searchsorted(a, np.arange(cells.n + 1))
        ids = colony.ids[b].tolist()
        return [sorted(set(ids[starts[i]:starts[i + 1]])) for i in range(cells.n)]

    def numbers(self, colony: Colony, states: list[CellState]) -> Colony:
        """``colony`` with the model's numbers from ``states`` (in its order): rates from
        ``growthRate``, types from ``cellType``, ``cell_data`` from the model's own numbers,
        and CellModeller's drag: mass ``muA·(length + 2·radius)``, growth inertia ``gamma``
        (docs/cellmodeller.md, "gamma"); no owed length."""
        n = len(states)
        growth = np.array([s.growthRate for s in states], dtype=float)
        if not np.all(np.isfinite(growth) & (growth >= 0)):
            i = int(np.flatnonzero(~(np.isfinite(growth) & (growth >= 0)))[0])
            raise ValueError(f"cell {states[i].id} has growthRate {growth[i]!r}: qpcontact's cells grow at a rate >= 0")
        types = np.array([s.cellType for s in states])
        if types.dtype.kind not in "iub" or np.any(types < 0):
            raise ValueError(f"cellType must be an integer >= 0 per cell, got {types[:5].tolist()}...")
        data = {name: growth if name == "growthRate" else self._column(states, name) for name in self._names(states)}
        cells = colony.cells
        cells = cells.replace(masses=self.muA * (cells.lengths + 2 * cells.radii), growth_inertia=np.full(n, self.gamma))
        return colony.replace(cells=cells, rates=rates_of(growth, self.model.dt), cell_types=types.astype(np.int64),
                              owed=0.0, cell_data={k: v for k, v in data.items() if v is not None})

    def _names(self, states: list[CellState]) -> list[str]:
        names: set[str] = set()
        for state in states:
            names.update(vars(state))
        return sorted(name for name in names - PHYSICS if name.isidentifier())

    def _column(self, states: list[CellState], name: str) -> np.ndarray | None:
        """One number (or a fixed-length vector) per cell, or None (said in ``left_out``)."""
        marker = object()
        values = [getattr(s, name, marker) for s in states]
        if any(v is marker for v in values):
            self.left_out[name] = "only some cells have it"
            return None
        try:
            array = np.asarray(values)
        except (TypeError, ValueError):
            array = np.zeros(0, dtype=object)
        if array.dtype.kind not in "biuf" or array.shape[:1] != (len(states),):
            self.left_out[name] = "not a number (or a list of numbers) per cell"
            return None
        return array

    def finish(self, colony: Colony, step: int) -> None:
        """The state the run ended in, as the next step would have seen it: the objects updated
        and its pickle written (CellModeller's ``stepNum`` ``step − 1``), if not done yet."""
        states = self.adopt(colony)
        if step > 0 and self.synced != step:
            every = self.model.sim.pickleSteps
            self.model.sim.pickleSteps = 1  # the last state is always written
            try:
                self.after_physics(colony, states, step)
            finally:
                self.model.sim.pickleSteps = every
