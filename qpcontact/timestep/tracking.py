"""The contacts a position step tracks (:func:`qpcontact.timestep.position_step`): found by a
broad phase at the moved positions of each linearization (one search for the start of the step
and its first linearization), kept for the rest of the step, evaluated with the true capsule
distances, and the targets of the pairs that start the step overlapping.

Plain functions over :class:`~qpcontact.geometry.Cells` and :class:`Tracked` (the contacts kept
so far, by key); the search and the narrow phase are shared among MPI processes by
:class:`~qpcontact.geometry.regions.Split`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..geometry.cells import Cells
from ..geometry.contacts import KIND_BITS, Contacts, concatenate, contact_keys, evaluate_contacts, select_contacts
from ..geometry.regions import ONE, Split
from ..geometry.surfaces import Plane, evaluate_plane_contacts, plane_contacts


@dataclass(frozen=True)
class Tracked:
    """Contacts kept during a step: cells ``a``, ``b`` (``-1 - j`` for plane ``j``) and contact
    kind (:class:`qpcontact.geometry.Contacts`), with their keys (:func:`contact_keys`)."""

    a: np.ndarray
    b: np.ndarray
    kind: np.ndarray
    keys: np.ndarray

    @classmethod
    def empty(cls) -> Tracked:
        none = np.zeros(0, dtype=np.intp)
        return cls(none, none, none, none.astype(np.int64))

    @classmethod
    def of(cls, a: np.ndarray, b: np.ndarray, kind: np.ndarray, span: int) -> Tracked:
        """The contacts ``(a, b, kind)``, each once (in the order of their keys)."""
        keys, first = np.unique(contact_keys(a, b, kind, span), return_index=True)
        return cls(a[first], b[first], kind[first], keys)

    def keyed(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(a, b)`` with cells as their ids (planes stay ``-1 - j``): the contacts as
        :class:`ContactImpulses` keys them."""
        return ids[self.a], np.where(self.b >= 0, ids[np.maximum(self.b, 0)], self.b)

    def union(self, other: Tracked, span: int) -> Tracked:
        return Tracked.of(np.concatenate([self.a, other.a]), np.concatenate([self.b, other.b]),
                           np.concatenate([self.kind, other.kind]), span)


def detect(cells: Cells, planes: Sequence[Plane], reach: float, span: int, pairs: np.ndarray | None = None,
            split: Split = ONE) -> Tracked:
    """Every contact within ``reach`` [length] of the cells as they are (the closest points of
    every pair, whatever its ends: across the linearizations the closest point moves along the
    pair, and only kind 0 follows it; docs/model-notes.md), among the candidate ``pairs`` when
    given (a superset of the pairs within reach, :func:`first_pairs`); the search and the narrow
    phase shared among the processes of ``split``."""
    if pairs is None:
        pairs = split.candidate_pairs(cells, reach)
    else:  # a superset for several configurations: the pairs whose enclosing spheres are within reach here
        i, j = pairs[:, 0], pairs[:, 1]
        apart = cells.centers[i] - cells.centers[j]
        within = 0.5 * (cells.lengths[i] + cells.lengths[j]) + cells.radii[i] + cells.radii[j] + reach
        pairs = pairs[np.einsum("ij,ij->i", apart, apart) <= within * within]
    parts = split.gather(select_contacts(cells, pairs[split.share(len(pairs))], reach, always_closest=True))
    for index, plane in enumerate(planes):
        found = plane_contacts(cells, [plane], reach)
        parts.append((found.cell_a, np.full(len(found), -1 - index), found.kind))
    a, b, kind = (np.concatenate(x) for x in zip(*parts, strict=True))
    return Tracked.of(a, b, kind, span)


def evaluate(cells: Cells, found: Tracked, planes: Sequence[Plane], planar: bool, split: Split = ONE) -> Contacts:
    """The contacts of ``found`` at the cells' present positions, in the order of ``found``
    (their geometry: the normal velocities are left 0, :func:`_result` gives the last ones theirs),
    the pairs shared among the processes of ``split`` (each evaluates a contiguous part)."""
    pairwise = np.flatnonzero(found.b >= 0)
    mine = pairwise[split.share(pairwise.size)]
    parts = split.gather(evaluate_contacts(cells, found.a[mine], found.b[mine], found.kind[mine], planar=planar,
                                           velocities=False))
    order = [pairwise]
    for j, plane in enumerate(planes):
        on = np.flatnonzero(found.b == -1 - j)
        parts.append(evaluate_plane_contacts(cells, plane, found.a[on], found.kind[on]))
        order.append(on)
    return concatenate(parts).subset(np.argsort(np.concatenate(order), kind="stable"))


def diameters(cells: Cells, contacts: Contacts) -> np.ndarray:
    """(K,) ``ρ_a + ρ_b`` (``2ρ_a`` against a plane)."""
    rho_a = cells.radii[contacts.cell_a]
    return rho_a + np.where(contacts.cell_b >= 0, cells.radii[np.maximum(contacts.cell_b, 0)], rho_a)


@dataclass(frozen=True)
class Floors:
    """Overlap present at the start of the step sets the floor of its own pair's target:
    ``min(0, d_start + relaxation·(ρ_a + ρ_b))``, per pair key (:data:`KIND_BITS` dropped)."""

    pairs: np.ndarray
    values: np.ndarray

    def targets(self, found: Tracked) -> np.ndarray:
        """(K,) the target separation of each contact of ``found`` [length]."""
        if self.pairs.size == 0:
            return np.zeros(found.keys.size)
        pair = found.keys >> KIND_BITS
        where = np.minimum(np.searchsorted(self.pairs, pair), self.pairs.size - 1)
        return np.where(self.pairs[where] == pair, np.minimum(0.0, self.values[where]), 0.0)


def start_floors(cells: Cells, planes: Sequence[Plane], planar: bool, span: int,
           relaxation: float, pairs: np.ndarray, split: Split = ONE) -> tuple[Floors, float]:
    """The floors of the targets and the largest overlap at the start of the step (among the
    candidate ``pairs``, a superset of the touching ones)."""
    found = detect(cells, planes, 0.0, span, pairs, split)
    start = evaluate(cells, found, planes, planar, split)
    diameter = diameters(cells, start)
    overlapping = start.separation < 0
    pairs = found.keys[overlapping] >> KIND_BITS
    values = start.separation[overlapping] + relaxation * diameter[overlapping]
    order = np.argsort(pairs)
    return Floors(pairs[order], values[order]), float(np.max(-start.separation / diameter, initial=0.0))


def track(found: Tracked, now: Cells, predicted: Cells | None, planes: Sequence[Plane], reach: float,
           span: int, pairs: np.ndarray | None = None, split: Split = ONE) -> Tracked:
    """The contacts kept so far and those within ``reach`` of the cells where they are now (and,
    at the first linearization, where the last step's motion would take them, ``predicted``),
    among the candidate ``pairs`` when given (the first linearization's, :func:`first_pairs`).

    Every linearization searches the whole margin: a cell pushed out of a jam can move a diameter
    against a neighbour within one linearization (measured on a grown colony of 10⁴ cells, with
    half the margin after the first: 0.14 of a diameter of overlap at the seventh linearization,
    with a pair found only then)."""
    found = found.union(detect(now, planes, reach, span, pairs, split), span)
    return found if predicted is None else found.union(detect(predicted, planes, reach, span, pairs, split), span)


def tip_displacement(start: Cells, end: Cells) -> np.ndarray:
    """(N,) the largest displacement of a point of each cell's axis between two configurations
    [length]: that of one of its tips (a point of the axis moves by an affine mix of the two)."""
    half_start, half_end = 0.5 * start.lengths[:, None], 0.5 * end.lengths[:, None]
    moved = end.centers - start.centers
    plus = moved + half_end * end.axes - half_start * start.axes
    minus = moved - half_end * end.axes + half_start * start.axes
    return np.sqrt(np.maximum(np.einsum("ij,ij->i", plus, plus), np.einsum("ij,ij->i", minus, minus)))


def first_pairs(cells: Cells, now: Cells, predicted: Cells | None, reach: float, split: Split = ONE) -> np.ndarray:
    """One broad phase for the start of the step and its first linearization: the candidate
    pairs of the cells at the start, each cell's reach widened by how far its axis moves to the
    first linearization's positions ``now`` (the free motion) and to ``predicted``. The start's
    overlaps and the first linearization's contacts are then found among them (a broad phase is
    2/3 of a detection; three were made at 10⁴ cells, 2026-12-04).

    Where the step moves many cells further than the search's reach (a large step of a fast
    colony: the edge of a 2D colony of 5,000 cells moves microns in a step of 0.2 growth), the
    widened reach would take in every neighbour of a moving region (2.4·10⁶ candidate pairs,
    ``TooManyContactsError``, 2026-12-04): each configuration is then searched on its own and the
    pairs put together, which bounds them by those of a packing."""
    slack = tip_displacement(cells, now)
    if predicted is not None:
        slack = np.maximum(slack, tip_displacement(cells, predicted))
    if slack.size == 0 or float(np.quantile(slack, 0.99)) <= reach:
        return split.candidate_pairs(cells, reach, slack)
    pairs = [split.candidate_pairs(c, reach) for c in (cells, now, predicted) if c is not None]
    n = np.int64(max(cells.n, 1))
    key = np.unique(np.concatenate([p[:, 0].astype(np.int64) * n + p[:, 1] for p in pairs]))
    return np.column_stack([key // n, key % n]).astype(np.intp)
