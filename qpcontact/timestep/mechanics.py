"""Mechanics from contact forces: the net force and torque on each cell, its virial stress and
pressure, radial profiles of a colony (growth that slows under pressure: :mod:`qpcontact.colony.pressure`).

**Forces.** A contact ``k`` between cells ``a`` and ``b`` (``b = -1``: a static plane or wall)
with unit normal ``n_k`` (from b to a) and normal force ``λ_k`` pushes a with ``λ_k n_k`` at
its contact point (``offset_a``, relative to a's centre) and b with ``−λ_k n_k`` at
``offset_b``. The forces are those of a step: :attr:`qpcontact.timestep.PositionStepResult.contact_forces`
(the units in which the drive is a force). A plane counts as a contact of its cell.

**Stress** (the Love–Weber virial of a particle): for cell ``i`` with contacts ``c``,

    σ_i = (1/V_i) Σ_c r_c ⊗ f_c,

``r_c`` the contact point minus the centre, ``f_c`` the force *on the cell* there, ``V_i`` its
volume (``π ρ² l + 4/3 π ρ³``). The sign is that of continuum mechanics: tension positive,
so a cell squeezed by its neighbours has a negative trace. ``σ_i`` is not symmetric in general:
its antisymmetric part is half the net contact torque over the volume
(``τ = Σ r × f``, ``σ − σᵀ = −[τ]×/V``), which the drive or the cell's turning balances.
Units: force/length² in 3D.

**Pressure**, compressive positive: ``p_i = −tr(σ_i)/3`` in 3D [force/length²]. In a
monolayer (all cells and forces in the xy-plane) the pressure is the 2D one: the stress is taken
over the cell's *footprint* ``A_i = 2ρ l + π ρ²`` instead of its volume, and
``p_i = −(σ_xx + σ_yy)/2`` [force/length], the in-plane mean normal stress.
A cell with no loaded contact has zero stress. A contact force that points away from the
cell's centre at its contact point (``r·f > 0``: possible at the end of a rod lying across
another at a slant) counts as tension and can make a cell's pressure negative (none of the 5,001
cells of the grown colony of docs/mechanics.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from .. import moved
from ..checks import flag, instance, real_array
from ..errors import InvalidArgumentError
from ..geometry import Cells, Contacts, capsule_footprint, capsule_volume
from ..geometry.cells import PLANAR_TOLERANCE
from ..geometry.contacts import check_contacts


def __getattr__(name: str) -> Any:
    """The names that moved out of this module (deprecated; :mod:`qpcontact.moved`)."""
    return moved.attribute(__name__, name, moved.NAMES[__name__])


class Lineage(Protocol):
    """What the mechanics read of a colony (:class:`qpcontact.colony.Colony` is one; the per-step
    calls import nothing from the colony model above them, docs/architecture.md): its cells, their
    ids and their mothers' ids, and their growth rates [1/time]."""

    @property
    def cells(self) -> Cells: ...
    @property
    def ids(self) -> np.ndarray: ...
    @property
    def parent_ids(self) -> np.ndarray: ...
    @property
    def rates(self) -> np.ndarray: ...


def _loads(cells: Cells, contacts: Contacts, forces: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every contact seen from each cell it touches: ``(cell, offset, force on the cell)``,
    a's side of every contact, then b's side of the cell–cell contacts (M ≤ 2K rows)."""
    instance("cells", cells, Cells, "qpcontact.Cells")
    contacts = check_contacts(contacts, cells)
    forces = real_array("forces", forces, InvalidArgumentError)
    if forces.shape != (len(contacts),) or not np.all(np.isfinite(forces)):
        raise InvalidArgumentError(f"forces: expected {len(contacts)} finite numbers (one per contact), got "
                                   f"shape {forces.shape}")
    on_a = forces[:, None] * contacts.normal
    cell = contacts.cell_b >= 0
    return (np.concatenate([contacts.cell_a, contacts.cell_b[cell]]),
            np.concatenate([contacts.offset_a, contacts.offset_b[cell]]),
            np.concatenate([on_a, -on_a[cell]]))


def _per_cell(n: int, cell: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Sum rows of ``values`` (M, ...) by ``cell`` into (N, ...) (``np.bincount`` per column)."""
    flat = values.reshape(len(values), int(np.prod(values.shape[1:])))
    summed = np.stack([np.bincount(cell, weights=column, minlength=n) for column in flat.T], axis=1)
    return summed.reshape((n, *values.shape[1:]))


def cell_forces(cells: Cells, contacts: Contacts, forces: Any) -> tuple[np.ndarray, np.ndarray]:
    """The net contact force and torque on each cell.

    Args:
        cells: the cells the contacts are of.
        contacts: the contacts (cell–cell and cell–plane, :class:`qpcontact.Contacts`).
        forces: (K,) normal force of each contact (e.g. ``PositionStepResult.contact_forces``).

    Returns:
        ``(force, torque)``: (N, 3) the sum of the contact forces on each cell [force], and (N, 3)
        their torque about the cell's centre [force·length]. For a position step whose cells
        do not move (a resting load) these are the linear and angular parts of its
        ``impulses``, to the solver's tolerance; where cells move, the contacts (reported at the
        end of the step) have turned since the forces were solved for, and the small net
        forces do not reproduce the impulses (docs/mechanics.md).

    Raises:
        InvalidArgumentError: contacts not of these cells, or forces of the wrong shape or not
            finite.
    """
    cell, offset, force = _loads(cells, contacts, forces)
    return _per_cell(cells.n, cell, force), _per_cell(cells.n, cell, np.cross(offset, force))


def is_monolayer_scene(cells: Cells, contacts: Contacts) -> bool:
    """The cells are a monolayer in the xy-plane (:meth:`~qpcontact.Cells.is_monolayer`) and
    every contact normal lies in it (no substrate under them): the scene whose pressure is
    the 2D one."""
    return cells.is_monolayer() and bool(np.all(np.abs(contacts.normal[:, 2]) <= PLANAR_TOLERANCE))


def cell_sizes(cells: Cells, planar: bool) -> np.ndarray:
    """(N,) what a cell's stress is taken over: its volume [length³], or in a monolayer its
    footprint ``2ρl + πρ²`` [length²]."""
    return capsule_footprint(cells.lengths, cells.radii) if planar else capsule_volume(cells.lengths, cells.radii)


def cell_stress(cells: Cells, contacts: Contacts, forces: Any, *, planar: bool | None = None) -> np.ndarray:
    """(N, 3, 3) virial stress of each cell, ``σ_i = (1/V_i) Σ_c r_c ⊗ f_c`` (module docstring):
    tension positive, so a compressed cell has a negative trace.

    Args:
        cells: the cells the contacts are of (their lengths and radii give the volumes).
        contacts: the contacts; planes and walls (``cell_b = -1``) count as contacts of the cell.
        forces: (K,) normal force of each contact [force; e.g. ``PositionStepResult.contact_forces``,
            in the units in which the drive is a force].
        planar: True: a monolayer, the stress is taken over each cell's footprint
            ``2ρl + πρ²`` (2D stress [force/length]); False: over its volume (3D stress
            [force/length²]); None: :func:`is_monolayer_scene`. Pass it explicitly in a run, so that the
            units do not change when a 3D colony happens to be flat.

    Returns:
        ``stress[i, j, k] = (1/V_i) Σ_c r_c[j] f_c[k]``.

    Raises:
        InvalidArgumentError: contacts not of these cells, forces of the wrong shape or not finite.
    """
    return _stress(cells, contacts, forces, planar)[0]


def _stress(cells: Cells, contacts: Contacts, forces: Any, planar: bool | None) -> tuple[np.ndarray, bool]:
    """:func:`cell_stress`, and whether it is the 2D one (``planar``, detected if None)."""
    cell, offset, force = _loads(cells, contacts, forces)  # checks the arguments first
    planar = flag("planar", planar, allow_none=True)
    planar = is_monolayer_scene(cells, contacts) if planar is None else planar
    virial = _per_cell(cells.n, cell, offset[:, :, None] * force[:, None, :])
    return virial / cell_sizes(cells, planar)[:, None, None], planar


def pressure_of(stress: np.ndarray, planar: bool) -> np.ndarray:
    """(N,) pressure from (N, 3, 3) stresses, compressive positive: ``−tr σ/3``, or in a
    monolayer ``−(σ_xx + σ_yy)/2`` (the 2D pressure)."""
    if planar:
        return -(stress[:, 0, 0] + stress[:, 1, 1]) / 2.0
    return -np.trace(stress, axis1=1, axis2=2) / 3.0


def cell_pressure(cells: Cells, contacts: Contacts, forces: Any, *, planar: bool | None = None) -> np.ndarray:
    """(N,) pressure of each cell, compressive positive.

    3D: ``p_i = −tr(σ_i)/3`` with the virial stress of :func:`cell_stress` [force/length²]. In a
    monolayer (``planar``): the 2D pressure ``p_i = −(σ_xx + σ_yy)/2`` with the stress taken over
    the cell's footprint ``2ρl + πρ²`` [force/length], i.e. ``−Σ_c (r_c·f_c)/(2 A_i)``.

    Args:
        cells, contacts, forces, planar: as :func:`cell_stress` (None: :func:`is_monolayer_scene`).

    Raises:
        InvalidArgumentError: see :func:`cell_stress`.
    """
    return pressure_of(*_stress(cells, contacts, forces, planar))


@dataclass(frozen=True)
class CellMechanics:
    """The mechanics of each cell of a colony over the step that led to it (what a run saves in
    its snapshots and hands to a model hook that asks for it: :mod:`qpcontact.colony.hooks`).

    Attributes:
        pressure: (N,) pressure, compressive positive (:func:`cell_pressure`).
        stress: (N, 3, 3) virial stress (:func:`cell_stress`).
        planar: a monolayer: 2D stress and pressure (over the footprint, [force/length]); else
            3D (over the volume, [force/length²]).
    """

    pressure: np.ndarray
    stress: np.ndarray
    planar: bool

    @classmethod
    def zero(cls, n: int, planar: bool) -> CellMechanics:
        """No load on any of ``n`` cells (before the first step of a run)."""
        return cls(np.zeros(n), np.zeros((n, 3, 3)), planar)

    @classmethod
    def of(cls, cells: Cells, contacts: Contacts, forces: Any, *, planar: bool) -> CellMechanics:
        """Stress and pressure of the cells under these contact forces."""
        stress = cell_stress(cells, contacts, forces, planar=planar)
        return cls(pressure_of(stress, planar), stress, planar)

    @classmethod
    def stored(cls, pressure: Any, stress: Any, n: int, planar: bool) -> CellMechanics:
        """From arrays a snapshot holds (None: :meth:`zero`, e.g. a snapshot written before
        snapshots carried them)."""
        if pressure is None or stress is None:
            return cls.zero(n, planar)
        return cls(np.asarray(pressure, dtype=float), np.asarray(stress, dtype=float), planar)

    def carried_over(self, before: Lineage, after: Lineage) -> CellMechanics:
        """These values (of ``before``'s cells) for the cells of ``after``: a cell keeps its own
        (matched by id), a newborn takes its mother's (a mother's stress is the mean over her
        volume; splitting her contacts between the daughters would leave out the force between
        the two, which no step has measured yet), a cell with neither gets 0."""
        if before.cells.n == 0:
            return CellMechanics.zero(after.cells.n, self.planar)
        order = np.argsort(before.ids)
        ids = before.ids[order]

        def index(keys: np.ndarray) -> np.ndarray:
            """The index in ``before`` of each id (-1 where there is none)."""
            where = np.minimum(np.searchsorted(ids, keys), ids.size - 1)
            return np.where(ids[where] == keys, order[where], -1)

        source = index(after.ids)
        source = np.where(source >= 0, source, index(after.parent_ids))
        known, pick = source >= 0, np.maximum(source, 0)
        return CellMechanics(np.where(known, self.pressure[pick], 0.0),
                             np.where(known[:, None, None], self.stress[pick], 0.0), self.planar)


@dataclass(frozen=True)
class RadialProfile:
    """Values of a colony's cells binned by distance from the colony's centre
    (:func:`radial_profile`).

    Attributes:
        edges: (B + 1,) bin edges [length].
        radius: (B,) mean distance of the cells in each bin [length].
        mean, std: (B,) mean and standard deviation of the values in each bin (NaN when empty).
        counts: (B,) cells in each bin.
        center: (2,) the centre the distances are measured from (x, y) [length].
    """

    edges: np.ndarray
    radius: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    counts: np.ndarray
    center: np.ndarray


def radial_distances(cells: Cells, center: Sequence[float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(N,) distance of each cell's centre from ``center`` in the xy-plane (default: the mean
    of the centres) [length], and that centre (2,)."""
    middle = cells.centers[:, :2].mean(axis=0) if center is None else np.asarray(center, dtype=float)[:2]
    return np.linalg.norm(cells.centers[:, :2] - middle, axis=1), middle


def radial_profile(cells: Cells, values: Any, *, bins: int = 20, center: Sequence[float] | None = None) -> RadialProfile:
    """``values`` (one per cell, e.g. the pressure) binned by the distance of the cells' centres
    from the colony's centre in the xy-plane, ``bins`` equal bins from 0 to the farthest cell.

    Raises:
        InvalidArgumentError: values not one finite number per cell, or ``bins`` not an integer
            >= 1.
    """
    values = real_array("values", values, InvalidArgumentError)
    if values.shape != (cells.n,) or not np.all(np.isfinite(values)):
        raise InvalidArgumentError(f"values: expected {cells.n} finite numbers, got shape {values.shape}")
    if isinstance(bins, bool) or not isinstance(bins, (int, np.integer)) or bins < 1:
        raise InvalidArgumentError(f"bins: expected an integer >= 1, got {bins!r}")
    r, middle = radial_distances(cells, center)
    edges = np.linspace(0.0, float(r.max(initial=0.0)) or 1.0, bins + 1)
    which = np.clip(np.searchsorted(edges, r, side="right") - 1, 0, bins - 1)
    count = np.bincount(which, minlength=bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.bincount(which, weights=values, minlength=bins) / count
        spread = np.bincount(which, weights=(values - mean[which]) ** 2, minlength=bins) / count
        radius = np.bincount(which, weights=r, minlength=bins) / count
    return RadialProfile(edges, radius, mean, np.sqrt(spread), count, middle)


@dataclass(frozen=True)
class ParabolaFit:
    """``p(r) = a (R² − r²)`` fitted by least squares (:func:`fit_parabola`).

    Attributes:
        amplitude: ``a`` [value unit/length²]; ``a R²`` is the value at the centre.
        radius: ``R`` where the parabola reaches 0 [length] (NaN if ``a R² ≤ 0``).
        rms: root mean square of the residuals [value unit].
    """

    amplitude: float
    radius: float
    rms: float


def fit_parabola(r: Any, values: Any) -> ParabolaFit:
    """Least-squares fit of ``values ≈ c − a r²`` (linear in ``c`` and ``a``), reported as
    ``a (R² − r²)`` with ``R² = c/a``.

    Raises:
        InvalidArgumentError: fewer than two points, or arrays that differ in shape or are not
            finite.
    """
    r = real_array("r", r, InvalidArgumentError)
    values = real_array("values", values, InvalidArgumentError)
    if r.ndim != 1 or r.shape != values.shape or r.size < 2 or not np.all(np.isfinite(r) & np.isfinite(values)):
        raise InvalidArgumentError(f"r and values: expected two equal 1-D arrays of at least 2 finite numbers, got "
                                   f"shapes {r.shape} and {values.shape}")
    design = np.stack([np.ones_like(r), -r**2], axis=1)
    (c, a), *_ = np.linalg.lstsq(design, values, rcond=None)
    rms = float(np.sqrt(np.mean((design @ np.array([c, a]) - values) ** 2)))
    radius = float(np.sqrt(c / a)) if a != 0 and c / a > 0 else float("nan")
    return ParabolaFit(float(a), radius, rms)
