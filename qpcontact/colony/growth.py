"""Growth and division of a colony, with lineage.

Growth: each cell elongates exponentially at its own rate ``r`` [1/time]. The drive is the
growth momentum ``g = G·l̇`` with ``l̇ = l (e^{r dt} − 1)/dt``, so that a free cell reaches
exactly ``l e^{r dt}`` after a step; contacts compress it through the growth degree of freedom
(the contact solve changes ``g`` like any other momentum). Mass and growth inertia grow in
proportion to the volume (constant density).

Division: a cell whose length reaches the division length splits into two daughters along its
axis, touching at the parent's centre, each with half the parent's mass, growth inertia and
momenta (so linear momentum is conserved, and angular momentum about any point too: the
daughters' centres are symmetric about the parent's). Volume: two capsules of the parent's
radius that fit exactly in the parent's outline have length ``l/2 − ρ`` each and hold
``2/3 π ρ³`` less than the parent (the new pair of caps). Daughters that were given their full
half volume at once (length ``l/2 − 2ρ/3``) would poke ``ρ/3`` out of the parent's poles, and
two neighbours dividing end to end in the same step would then overlap by a third of a
diameter — an overlap made by bookkeeping, not by the contact solve. So each daughter is born
with length ``l/2 − ρ`` and an owed length ``ρ/3`` (``Colony.owed``), which it grows on top of
its own growth (at most its own growth again per step, i.e. at up to twice its rate) through
the contact solve, which pushes the neighbours out of the way. Volume including what is owed
(``volumes(cells) + π ρ² owed``) is conserved exactly by division.

Noise: each daughter's axis is turned by a small random angle (``axis_noise``, radians) to
break the symmetry of a perfect chain, and may draw its own growth rate (``rate_noise``).

Cell types and a model's own per-cell state (``Colony.cell_types``, ``Colony.cell_data``, as
CellModeller's ``cell.cellType`` and ``cell.targetVol``): both daughters inherit their mother's
row, and with per-type growth rates (``type_rates``) a newborn's mean rate is her type's.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..checks import flag, instance, integer, integer_array, number, real_array
from ..errors import InvalidArgumentError
from ..geometry import Cells, Plane, capsule_volume
from ..geometry.motion import rotate
from ..timestep.position import CellMotion, ContactImpulses, PositionSettings, PositionStepResult, position_step
from ..timestep.step import StepResult, step


@dataclass(frozen=True, eq=False)
class Colony:
    """A growing colony: the cells plus what growth and lineage need, one entry per cell.

    Attributes:
        cells: the cells (:class:`qpcontact.Cells`).
        ids: (N,) unique cell ids (int).
        parent_ids: (N,) the id of each cell's mother, ``-1`` for a founder.
        rates: (N,) exponential elongation rate ``r`` [1/time].
        owed: (N,) length still owed to the cell from its division [length] (module docstring).
        time: the simulated time [time].
        next_id: the id the next newborn cell gets (default: one more than the largest id).
        cell_types: (N,) each cell's type, an integer >= 0 (default: all 0); daughters inherit
            their mother's (:func:`divide`).
        cell_data: a model's own per-cell arrays by name (default: none), e.g. a target volume
            or a signal: each an array of numbers (or booleans) whose first axis has one entry
            per cell; names are Python identifiers. Daughters inherit their mother's rows.
            Replace an array to change it (``colony.replace(cell_data={**colony.cell_data,
            "signal": s})``); the arrays are not copied.
    """

    cells: Cells
    ids: np.ndarray
    parent_ids: np.ndarray
    rates: np.ndarray
    owed: Any = 0.0
    time: float = 0.0
    next_id: int = -1
    cell_types: Any = None
    cell_data: Any = None

    def __post_init__(self) -> None:
        instance("Colony.cells", self.cells, Cells, "qpcontact.Cells")
        n = self.cells.n
        for name in ("ids", "parent_ids", "rates", "owed"):
            value = getattr(self, name)
            arr = (integer_array(f"Colony.{name}", value) if name.endswith("ids")
                   else real_array(f"Colony.{name}", value, InvalidArgumentError))
            if name == "owed" and arr.ndim == 0:
                arr = np.full(n, float(arr))
            if arr.shape != (n,):
                raise InvalidArgumentError(f"Colony.{name}: expected shape ({n},) (one per cell), got {arr.shape}")
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "time", number("Colony.time", self.time))
        object.__setattr__(self, "next_id", integer("Colony.next_id", self.next_id))
        for name in ("rates", "owed"):
            arr = getattr(self, name)
            if not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise InvalidArgumentError(f"Colony.{name}: must be finite and >= 0")
        growing = np.isfinite(self.cells.masses) & np.isfinite(self.cells.growth_inertia)
        stuck = growing & (self.cells.lengths == 0) & (self.rates > 0)
        if stuck.any():
            i = int(np.flatnonzero(stuck)[0])
            raise InvalidArgumentError(
                f"Colony: cell {i} has length 0 and growth rate {self.rates[i]:g} > 0, but exponential elongation "
                "l·e^(rt) of a zero length stays 0: give it a length > 0 (or rate 0)")
        if np.unique(self.ids).size != n:
            raise InvalidArgumentError("Colony.ids: must be unique")
        if self.next_id < 0:
            object.__setattr__(self, "next_id", int(self.ids.max(initial=-1)) + 1)
        elif n and self.next_id <= int(self.ids.max()):
            raise InvalidArgumentError(f"Colony.next_id: {self.next_id} is not above the largest id {int(self.ids.max())}")
        object.__setattr__(self, "cell_types", _cell_types(self.cell_types, n))
        object.__setattr__(self, "cell_data", _cell_data(self.cell_data, n))

    @classmethod
    def founder(cls, cells: Cells, rates: Any) -> Colony:
        """A colony of founder cells (ids 0..N-1, no parents) growing at ``rates`` [1/time]: one
        rate for all, or one per cell."""
        instance("cells", cells, Cells, "qpcontact.Cells")
        rates = real_array("rates", rates, InvalidArgumentError)
        if rates.shape not in ((), (cells.n,)):
            raise InvalidArgumentError(f"rates: expected one rate or {cells.n} (one per cell), got shape {rates.shape}")
        return cls(cells, np.arange(cells.n), np.full(cells.n, -1), np.broadcast_to(rates, (cells.n,)))

    def replace(self, **changes: Any) -> Colony:
        """A new, validated Colony with some fields replaced.

        A change of the number of cells that does not give ``cell_types`` and ``cell_data``
        gives the defaults (type 0, no data) if the colony has only those, and raises otherwise
        (use :meth:`subset`, which keeps them, or give them)."""
        if "cells" in changes and getattr(changes["cells"], "n", self.cells.n) != self.cells.n:
            if "cell_types" not in changes:
                changes["cell_types"] = None if not self.cell_types.any() else self.cell_types
            if "cell_data" not in changes:
                changes["cell_data"] = None if not self.cell_data else self.cell_data
        return dataclasses.replace(self, **changes)

    def subset(self, index: Any) -> Colony:
        """The colony of the cells ``index`` selects (a boolean mask or integer indices, in
        their order), every per-cell field kept aligned: cells, ids, lineage, rates, owed
        length, types and ``cell_data``; time and ``next_id`` unchanged (ids are not reused)."""
        index = np.asarray(index)
        if index.dtype.kind not in "biu":
            raise InvalidArgumentError(f"index: expected a boolean mask or integer indices, got {index.dtype} values")
        if index.dtype.kind == "b" and index.shape != (self.cells.n,):
            raise InvalidArgumentError(f"index: a mask needs one entry per cell ({self.cells.n}), got {index.shape}")
        return self.replace(cells=self.cells.subset(index), ids=self.ids[index], parent_ids=self.parent_ids[index],
                            rates=self.rates[index], owed=self.owed[index], cell_types=self.cell_types[index],
                            cell_data={name: value[index] for name, value in self.cell_data.items()})


def _cell_types(value: Any, n: int) -> np.ndarray:
    """``Colony.cell_types`` checked: (n,) integers >= 0 (None: all 0)."""
    if value is None:
        return np.zeros(n, dtype=np.int64)
    types = integer_array("Colony.cell_types", value)
    if types.ndim == 0:
        types = np.full(n, int(types), dtype=np.int64)
    if types.shape != (n,):
        raise InvalidArgumentError(f"Colony.cell_types: expected shape ({n},) (one per cell), got {types.shape}")
    if np.any(types < 0):
        raise InvalidArgumentError(f"Colony.cell_types: must be >= 0, got {int(types.min())}")
    return types


def _cell_data(value: Any, n: int) -> dict[str, np.ndarray]:
    """``Colony.cell_data`` checked: a mapping of identifiers to numeric arrays whose first axis
    is n (None: empty)."""
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise InvalidArgumentError(f"Colony.cell_data: expected a dict of names to per-cell arrays, got "
                                   f"{type(value).__name__}")
    out = {}
    for name, array in value.items():
        if not (isinstance(name, str) and name.isidentifier()):
            raise InvalidArgumentError(f"Colony.cell_data: names must be Python identifiers (letters, digits, _), got "
                                       f"{name!r}")
        try:
            array = np.asarray(array)
        except (TypeError, ValueError) as exc:  # ragged nesting
            raise InvalidArgumentError(f"Colony.cell_data[{name!r}]: cannot be read as an array ({exc})") from None
        if array.dtype.kind not in "biuf":
            raise InvalidArgumentError(f"Colony.cell_data[{name!r}]: expected numbers or booleans, got an array of "
                                       f"{array.dtype} values")
        if array.shape[:1] != (n,):
            raise InvalidArgumentError(f"Colony.cell_data[{name!r}]: expected one row per cell (first axis {n}), got "
                                       f"shape {array.shape}")
        out[name] = array
    return out


def volumes(cells: Cells) -> np.ndarray:
    """(N,) capsule volumes ``π ρ² l + 4/3 π ρ³`` [length³]
    (:func:`qpcontact.geometry.capsule_volume`)."""
    return capsule_volume(cells.lengths, cells.radii)


def growth_step(colony: Colony, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The length each cell is driven to grow over ``dt`` [length]: ``l (e^{r dt} − 1)`` plus
    the part of its owed length it pays now (at most as much again). Returns
    ``(length_increase, owed_paid)``."""
    own = colony.cells.lengths * np.expm1(colony.rates * dt)
    paid = np.minimum(colony.owed, own)
    return own + paid, paid


def growth_drive(cells: Cells, length_increase: np.ndarray, dt: float) -> np.ndarray:
    """(N,) growth momentum ``g = G·Δl/dt`` [mass·length/time] that grows a free cell by
    ``length_increase`` over the step (0 for a non-growing cell, ``G = inf``)."""
    growing = np.isfinite(cells.growth_inertia)
    return np.where(growing, np.where(growing, cells.growth_inertia, 0.0) * length_increase / dt, 0.0)


def check_division_length(division_length: float | np.ndarray, radii: float | np.ndarray) -> None:
    """Refuse a division length at which a daughter would be born with a cylinder length of 0 or
    less: a mother of length ``L`` leaves daughters of ``L/2 − ρ``, so ``L`` must exceed ``2ρ``.
    The one check of :func:`divide`, ``qpcontact simulate`` (:class:`ModelSettings`) and a model
    hook's ``division_length``.

    Args:
        division_length: one length, or one per cell [length].
        radii: the cells' radii, one or one per cell [length].

    Raises:
        InvalidArgumentError: naming the length, ``2 × radius`` and the daughters' length.
    """
    length, radius = np.broadcast_arrays(np.asarray(division_length, dtype=float), np.asarray(radii, dtype=float))
    short = ~(length > 2.0 * radius)
    if np.any(short):
        i = int(np.flatnonzero(short.ravel())[0])
        at = "" if length.ndim == 0 else f" (cell {i})"
        big, rho = float(length.ravel()[i]), float(radius.ravel()[i])
        raise InvalidArgumentError(
            f"division_length: must exceed 2 × radius = {2 * rho:g} µm (daughters are born at division_length/2 − "
            f"radius = {big / 2 - rho:g} µm), got {big:g}{at}")


def divide(colony: Colony, division_length: float | np.ndarray, rng: np.random.Generator, *,
           axis_noise: float = 0.02, rate_noise: float = 0.0, base_rate: float | None = None,
           planar: bool = False, type_rates: Any = None, dividing: Any = None) -> Colony:
    """Split every cell with ``l >= division_length`` (or every cell ``dividing`` marks) into
    two daughters (module docstring).

    Args:
        colony: the colony.
        division_length: the length threshold [length], one for all or an (N,) array, one per
            cell; must exceed each cell's ``2ρ`` so that daughters get a positive length
            (:func:`check_division_length`, the check ``qpcontact simulate`` makes too).
        rng: random numbers for the noise.
        axis_noise: standard deviation of each daughter's axis turn [rad].
        rate_noise: relative standard deviation of a daughter's growth rate around ``base_rate``
            (0 = daughters inherit the mother's rate).
        base_rate: mean growth rate for newborn cells (default: the mother's rate).
        planar: 2D monolayer: turn the axes about z only, so they stay in the xy-plane.
        type_rates: mean growth rate of newborn cells of each type [1/time], indexed by
            ``Colony.cell_types`` (a sequence, each > 0); replaces ``base_rate`` when given.
        dividing: an (N,) boolean mask of the cells that divide, whatever their length (a
            model's own rule, as CellModeller's ``divideFlag``); ``division_length`` is then not
            used. Each marked cell must be longer than ``2ρ`` (daughters of a positive length).

    Returns:
        The new colony: each mother replaced by daughter 1 (in her place), daughter 2 appended;
        new ids, parent ids set; both daughters with their mother's type and ``cell_data``
        rows. The colony itself when no cell divides.

    Raises:
        InvalidArgumentError: bad arguments; a dividing cell whose type has no rate in
            ``type_rates``.
    """
    division_length = _division_lengths(colony, division_length, check=dividing is None)
    axis_noise = number("axis_noise", axis_noise, minimum=0.0)
    rate_noise = number("rate_noise", rate_noise, minimum=0.0)
    base_rate = number("base_rate", base_rate, minimum=0.0, allow_none=True)
    planar = flag("planar", planar)
    if type_rates is not None:
        type_rates = check_type_rates("type_rates", type_rates)
    cells = colony.cells
    if dividing is None:
        dividing = np.flatnonzero(cells.lengths >= division_length)
    else:
        dividing = np.flatnonzero(_division_mask(dividing, cells))
    if dividing.size == 0:
        return colony
    mother_types = colony.cell_types[dividing]
    if type_rates is not None and mother_types.max() >= type_rates.size:
        raise InvalidArgumentError(f"type_rates: gives {type_rates.size} types (0 to {type_rates.size - 1}), but a "
                                   f"dividing cell has type {int(mother_types.max())}")
    m = dividing.size
    owed = colony.owed[dividing] / 2 + cells.radii[dividing] / 3.0

    def split(mother_values: np.ndarray, first: np.ndarray, second: np.ndarray) -> np.ndarray:
        """Daughter 1 takes the mother's place, daughter 2 is appended."""
        out = mother_values.copy()
        out[dividing] = first
        return np.concatenate([out, second])

    daughters = _daughter_cells(cells, dividing, split, _daughter_axes(cells.axes[dividing], rng, axis_noise, planar))
    if type_rates is not None:
        mean_rate = type_rates[mother_types]
    else:
        mean_rate = colony.rates[dividing] if base_rate is None else np.full(m, float(base_rate))
    noise = rng.standard_normal((2, m)) if rate_noise else np.zeros((2, m))
    daughter_rates = np.maximum(mean_rate * (1.0 + rate_noise * noise), 0.0)
    new_ids = colony.next_id + np.arange(2 * m)
    mother_ids = colony.ids[dividing]
    return colony.replace(
        cells=daughters,
        ids=split(colony.ids, new_ids[:m], new_ids[m:]),
        parent_ids=split(colony.parent_ids, mother_ids, mother_ids),
        rates=split(colony.rates, daughter_rates[0], daughter_rates[1]),
        owed=split(colony.owed, owed, owed),
        next_id=colony.next_id + 2 * m,
        cell_types=split(colony.cell_types, mother_types, mother_types),
        cell_data={name: split(value, value[dividing], value[dividing]) for name, value in colony.cell_data.items()},
    )


def _division_lengths(colony: Colony, division_length: Any, check: bool = True) -> float | np.ndarray:
    """The division length checked: a number > 0, or one finite number > 0 per cell, each above
    its cell's ``2ρ`` (:func:`check_division_length`; not when ``check`` is False: cells marked
    to divide do not use it)."""
    if np.ndim(division_length) == 0:
        division_length = number("division_length", division_length, minimum=0.0, open_minimum=True)
    else:
        division_length = real_array("division_length", division_length, InvalidArgumentError)
        if division_length.shape != (colony.cells.n,) or not np.all(np.isfinite(division_length) & (division_length > 0)):
            raise InvalidArgumentError(f"division_length: expected a number > 0 or {colony.cells.n} finite numbers > 0 "
                                       f"(one per cell), got shape {division_length.shape}")
    if check:
        check_division_length(division_length, colony.cells.radii)
    return division_length


def _daughter_axes(axes: np.ndarray, rng: np.random.Generator, axis_noise: float, planar: bool) -> np.ndarray:
    """(2M, 3) the axes of the daughters of mothers with ``axes`` (M, 3): the mother's, each
    turned by the noise (about z only in a monolayer; never a spin about the axis)."""
    m = axes.shape[0]
    both_axes = np.concatenate([axes, axes])
    if planar:
        turns = np.zeros((2 * m, 3))
        turns[:, 2] = rng.normal(0.0, axis_noise, 2 * m)
    else:
        turns = rng.normal(0.0, axis_noise, (2 * m, 3))
        turns -= np.einsum("ij,ij->i", turns, both_axes)[:, None] * both_axes  # a spin about â turns nothing
    return rotate(both_axes, turns)


def _daughter_cells(cells: Cells, dividing: np.ndarray, split: Callable[..., np.ndarray],
                    new_axes: np.ndarray) -> Cells:
    """The cells after the ``dividing`` cells split: each daughter half her mother's length less
    a radius, centred half that length plus a radius off the mother's centre along the axis, with
    half her mass, inertia and momenta (``split`` puts daughter 1 in the mother's place and
    appends daughter 2)."""
    m = dividing.size
    radii, lengths, axes = cells.radii[dividing], cells.lengths[dividing], cells.axes[dividing]
    daughter_length = lengths / 2 - radii  # > 0: lengths ≥ division_length > 2ρ (checked)
    shift = (daughter_length / 2 + radii)[:, None] * axes
    halved: dict[str, Any] = {}  # masses, growth inertias and momenta: each daughter takes half
    for name in ("masses", "growth_inertia", "momenta", "angular_momenta", "growth_momenta"):
        half = getattr(cells, name)[dividing] / 2
        halved[name] = split(getattr(cells, name), half, half)
    return Cells(
        centers=split(cells.centers, cells.centers[dividing] - shift, cells.centers[dividing] + shift),
        axes=split(cells.axes, new_axes[:m], new_axes[m:]),
        lengths=split(cells.lengths, daughter_length, daughter_length),
        radii=split(cells.radii, radii, radii),
        **halved,
    )


def _division_mask(dividing: Any, cells: Cells) -> np.ndarray:
    """``divide``'s ``dividing`` checked: an (N,) boolean mask whose cells are long enough to
    divide (daughters born at ``l/2 − ρ > 0``)."""
    mask = np.asarray(dividing)
    if mask.dtype.kind != "b" or mask.shape != (cells.n,):
        raise InvalidArgumentError(f"dividing: expected an ({cells.n},) boolean mask (one per cell), got "
                                   f"{mask.dtype} values of shape {mask.shape}")
    short = mask & ~(cells.lengths > 2.0 * cells.radii)
    if short.any():
        i = int(np.flatnonzero(short)[0])
        raise InvalidArgumentError(
            f"dividing: cell {i} is marked to divide at length {cells.lengths[i]:g} µm, but daughters are born at "
            f"length/2 − radius = {cells.lengths[i] / 2 - cells.radii[i]:g} µm: a cell must be longer than 2 × radius "
            f"= {2 * cells.radii[i]:g} µm to divide")
    return mask


def births(before: Colony, after: Colony) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Who was born when ``after = divide(before, ...)``: ``(mothers, first, second)``, the rows
    of the dividing cells in ``before`` and of their first and second daughters in ``after``
    (:func:`divide` puts daughter 1 in her mother's row and appends daughter 2, in order).

    Raises:
        InvalidArgumentError: ``after`` is not a division of ``before``.
    """
    n = before.cells.n
    mothers = np.flatnonzero(after.ids[:n] != before.ids) if after.cells.n >= n else np.zeros(0, dtype=np.intp)
    if after.cells.n != n + mothers.size:
        raise InvalidArgumentError(f"after: {after.cells.n} cells are not a division of {n} ({mothers.size} mothers)")
    return mothers, mothers.copy(), n + np.arange(mothers.size)


def check_type_rates(name: str, value: Any) -> np.ndarray:
    """Per-type growth rates [1/time] as a float array: a non-empty sequence of finite numbers
    > 0, one per cell type (type ``k``'s rate is entry ``k``).

    Raises:
        InvalidArgumentError: naming ``name``.
    """
    rates = real_array(name, value, InvalidArgumentError)
    if rates.ndim != 1 or rates.size == 0:
        raise InvalidArgumentError(f"{name}: expected a list of rates, one per cell type, got shape {rates.shape}")
    if not np.all(np.isfinite(rates) & (rates > 0)):
        raise InvalidArgumentError(f"{name}: every rate must be finite and > 0, got {rates.tolist()}")
    return rates


def daughters_share(values: np.ndarray, before: Colony, after: Colony) -> np.ndarray:
    """Per-cell rows of ``before`` (e.g. a model hook's drive, (N, ...)) for the cells of
    ``after = divide(before, ...)``: a mother's row is halved between her two daughters (as
    :func:`divide` halves her momenta: a drive ``m·v`` then still moves each daughter at ``v``);
    other cells keep theirs.

    Raises:
        InvalidArgumentError: ``values`` has no row per cell of ``before``, or ``after`` is not a
            division of ``before``.
    """
    values = np.asarray(values, dtype=float)
    n = before.cells.n
    if values.shape[:1] != (n,):
        raise InvalidArgumentError(f"values: expected one row per cell ({n}), got shape {values.shape}")
    if after is before:
        return values
    dividing = births(before, after)[0]
    half = values[dividing] / 2
    out = values.copy()
    out[dividing] = half
    return np.concatenate([out, half])


def _grown(colony: Colony, before: Cells, after: Cells, paid: np.ndarray, dt: float) -> Colony:
    """The colony after a growth step that took ``before`` to ``after``: masses and growth
    inertias grown with the volume including what is owed (constant density), the owed length
    reduced by what was paid, the time advanced."""
    owed = colony.owed - paid
    area = np.pi * before.radii**2
    swell = (volumes(after) + area * owed) / (volumes(before) + area * colony.owed)
    after = after.replace(masses=after.masses * swell, growth_inertia=after.growth_inertia * swell)
    return colony.replace(cells=after, owed=owed, time=colony.time + dt)


def grow(colony: Colony, dt: float, *, dynamics: str = "overdamped", drive: np.ndarray | None = None,
         **step_options: Any) -> tuple[Colony, StepResult]:
    """One growth step with the velocity-level :func:`qpcontact.timestep.step` (no division: call
    :func:`divide` before it, so that the step's contact solve sees the daughters).

    The growth drive (:func:`growth_drive` of :func:`growth_step`) enters as the growth momentum
    — overdamped, as the growth column of ``drive``; inertial, by setting ``g`` (growth is a
    biological motor, not inertia) — then :func:`qpcontact.timestep.step` with ``step_options``.
    ``drive`` adds user-given momenta (its growth column is ignored). Afterwards masses and
    growth inertias grow with the volume including what is owed (constant density), and the
    owed length drops by what was paid. Returns the colony at ``t + dt`` and the step's result
    (whose ``cells`` are the colony's).
    """
    cells = colony.cells
    dt = number("dt", dt, minimum=0.0, open_minimum=True)
    with np.errstate(over="ignore", invalid="ignore"):
        increase, paid = growth_step(colony, dt)
        g = growth_drive(cells, increase, dt)
    if not np.all(np.isfinite(g)):
        i = int(np.flatnonzero(~np.isfinite(g))[0])
        raise InvalidArgumentError(f"dt = {dt!r} is too large: cell {i} would grow beyond the range of numbers "
                                   f"(rate {colony.rates[i]:g}); take a smaller time step")
    if dynamics == "overdamped":
        full = np.zeros((cells.n, 7)) if drive is None else np.array(drive, dtype=float, copy=True)
        full[:, 6] = g
        drive = full
    else:
        cells = cells.replace(growth_momenta=g)
        if drive is not None:
            drive = np.array(drive, dtype=float, copy=True)
            drive[:, 6] = 0.0
    out = step(cells, dt, dynamics=dynamics, drive=drive, **step_options)
    grown = _grown(colony, cells, out.cells, paid, dt)
    out.cells = grown.cells
    return grown, out


def grow_position(colony: Colony, dt: float, *, drive: np.ndarray | None = None, planes: Sequence[Plane] = (),
                  planar: bool | None = None, settings: PositionSettings | None = None,
                  warm: ContactImpulses | None = None, motion: CellMotion | None = None,
                  on_failure: str = "raise", comm: Any = None) -> tuple[Colony, PositionStepResult]:
    """One growth step with the position-level :func:`qpcontact.timestep.position_step`
    (overdamped; no division: call :func:`divide` before it, so that the step clears the
    overlap the daughters' axis noise makes and the state it returns keeps its tolerance).

    The growth drive of :func:`growth_step` is the growth column of ``drive`` (user-given
    momenta in the other columns); after the step, masses and growth inertias grow with the
    volume as in :func:`grow`. ``warm`` and ``motion`` are the previous step's ``result.warm``
    and ``result.motion`` (contact impulses and cell motion keyed by the colony's cell ids;
    daughters born since move with their mother in the prediction). A step that does not converge is not applied: it raises
    :class:`~qpcontact.errors.StepFailedError` (``on_failure="raise"``) or returns the colony
    unchanged with the unconverged result (``on_failure="return"``). ``comm``: the MPI processes
    the step's solves are split over (:func:`position_step`'s).
    """
    cells = colony.cells
    increase, paid = growth_step(colony, dt)
    full = np.zeros((cells.n, 7)) if drive is None else np.array(drive, dtype=float, copy=True)
    if full.shape != (cells.n, 7):
        raise InvalidArgumentError(f"drive: expected shape ({cells.n}, 7) (p, L, g per cell), got {full.shape}")
    full[:, 6] = growth_drive(cells, increase, dt)
    out = position_step(cells, dt, drive=full, planes=planes, planar=planar, settings=settings, ids=colony.ids,
                        warm=warm, motion=motion, parents=colony.parent_ids, on_failure=on_failure, comm=comm)
    if not out.converged:
        return colony, out
    grown = _grown(colony, cells, out.cells, paid, dt)
    out.cells = grown.cells
    return grown, out


def growth_time_step(colony: Colony, *, growth_per_step: float = 0.05, max_dt: float = np.inf,
                     still: float = 0.02) -> float:
    """A time step in which the fastest-growing cell lengthens by ``growth_per_step`` of its
    length (``dt = ln(1 + g)/max rate``), at most ``max_dt``: the step is set by growth, not by
    the size of the colony (newborn cells paying the length owed at division grow up to twice as
    fast). ``still`` is the step when no cell grows.

    Raises:
        InvalidArgumentError: a growth per step, ``max_dt`` or ``still`` that is not a number > 0
            (``max_dt`` may be infinite).
    """
    growth_per_step = number("growth_per_step", growth_per_step, minimum=0.0, open_minimum=True)
    still = number("still", still, minimum=0.0, open_minimum=True)
    if max_dt != np.inf:  # no cap is the default
        max_dt = number("max_dt", max_dt, minimum=0.0, open_minimum=True)
    rate = float(colony.rates.max(initial=0.0))
    step = float(np.log1p(growth_per_step)) / rate if rate > 0 else float(still)
    return min(float(max_dt), step)


def expansion_time_step(colony: Colony, *, max_dt: float, cfl: float = 0.2, dimensions: int = 2) -> float:
    """A time step at which the colony's edge moves at most ``cfl`` cell diameters per step.

    A colony of radius R growing at rate r with every cell pushing outwards expands at its edge
    with speed about ``r R / dimensions`` (the area, or volume, grows at rate r). Velocity-level
    contact handling is first order in the step, so the step must shrink as the colony grows;
    the speed is estimated from the geometry, not from the last step's velocities (those include
    the position-correction speeds ``β·overlap/dt``, which would feed back into ``dt``).
    """
    instance("colony", colony, Colony, "qpcontact.Colony")
    max_dt = number("max_dt", max_dt, minimum=0.0, open_minimum=True)
    cfl = number("cfl", cfl, minimum=0.0, open_minimum=True)
    if dimensions not in (2, 3):
        raise InvalidArgumentError(f"dimensions: expected 2 or 3, got {dimensions!r}")
    cells = colony.cells
    if cells.n == 0:  # nothing grows or moves
        return max_dt
    reach = np.linalg.norm(cells.centers - cells.centers.mean(axis=0), axis=1) + cells.lengths / 2 + cells.radii
    speed = float(colony.rates.max(initial=0.0)) * float(reach.max()) / dimensions
    diameter = 2.0 * float(np.median(cells.radii))
    return max_dt if speed <= 0 else min(max_dt, cfl * diameter / speed)
