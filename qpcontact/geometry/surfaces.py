"""Static planes (a substrate, the walls of a channel) as one-sided contacts.

A plane is a point on it and a unit normal pointing to the side where the cells live. A capsule
touches a plane at the ends of its axis segment (the closest points of a segment to a plane are
an end, or the whole segment when it lies parallel; the two ends then carry the contact, so a
rod lying flat cannot tip through the plane). The contacts have ``cell_b = -1`` (a static body:
zero velocity, infinite mass) and go into the same system as cell–cell contacts
(:func:`qpcontact.concatenate`). Fixed cells are ordinary cells with ``masses = inf``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..checks import number, real_array, sequence_of
from ..errors import InvalidArgumentError
from .cells import Cells
from .contacts import PLANE_MINUS_END, PLANE_PLUS_END, Contacts, concatenate, relative_normal_velocity


@dataclass(frozen=True)
class Plane:
    """A static plane.

    Attributes:
        point: (3,) any point on the plane [length].
        normal: (3,) normal pointing into the half-space where the cells are (normalized on
            construction).
    """

    point: tuple[float, float, float]
    normal: tuple[float, float, float]

    def __post_init__(self) -> None:
        point = real_array("Plane.point", self.point, InvalidArgumentError)
        normal = real_array("Plane.normal", self.normal, InvalidArgumentError)
        if point.shape != (3,) or not np.all(np.isfinite(point)):
            raise InvalidArgumentError(f"Plane.point: expected 3 finite numbers, got {self.point!r}")
        norm = float(np.linalg.norm(normal)) if normal.shape == (3,) else 0.0
        if not (np.isfinite(norm) and norm > 0):
            raise InvalidArgumentError(f"Plane.normal: expected a finite non-zero 3-vector, got {self.normal!r}")
        object.__setattr__(self, "point", tuple(point.tolist()))
        object.__setattr__(self, "normal", tuple((normal / norm).tolist()))


def substrate(height: float = 0.0) -> Plane:
    """The plane ``z = height`` with cells above it (a surface under a 3D biofilm) [length]."""
    return Plane((0.0, 0.0, number("height", height)), (0.0, 0.0, 1.0))


def channel(width: float, center_y: float = 0.0) -> list[Plane]:
    """Two walls ``y = center_y ± width/2`` facing each other (a channel along x) [length]."""
    width = number("channel width", width, minimum=0.0, open_minimum=True)
    center_y = number("center_y", center_y)
    return [Plane((0.0, center_y - width / 2, 0.0), (0.0, 1.0, 0.0)),
            Plane((0.0, center_y + width / 2, 0.0), (0.0, -1.0, 0.0))]


def plane_contacts(cells: Cells, planes: Sequence[Plane], margin: float = 0.0) -> Contacts:
    """Contacts of the cells' axis ends with each plane whose separation is at most ``margin``
    (touching counts, as between cells).

    Separation of an end ``q``: ``d = n·(q − p₀) − ρ`` (negative = overlap, or the cell is on
    the wrong side). A sphere (``l = 0``) has one end. Normal ``n`` (from the plane, body b, to
    the cell, body a); contact point ``q − ρn``; stretch ``±½`` (the ends ride with the tips);
    kind 5 for the −end (and a sphere), 6 for the +end (:class:`Contacts`). Fixed cells
    (``masses = inf``) get none: nothing could move at such a contact (as
    :func:`~qpcontact.geometry.contacts.candidate_pairs` leaves out pairs of fixed cells).
    """
    planes = sequence_of("planes", planes, Plane, "qpcontact.Plane objects (e.g. [qpcontact.substrate()])")
    margin = number("margin", margin, minimum=0.0)
    parts = []
    movable = np.isfinite(cells.masses)
    for plane in planes:
        normal, point = np.asarray(plane.normal), np.asarray(plane.point)
        for side, kind in ((-0.5, PLANE_MINUS_END), (0.5, PLANE_PLUS_END)):
            separation = (cells.centers + side * cells.lengths[:, None] * cells.axes - point) @ normal - cells.radii
            keep = (separation <= margin) & movable
            if side > 0:
                keep &= cells.lengths > 0  # a sphere has one end, counted once
            cell = np.flatnonzero(keep)
            parts.append(evaluate_plane_contacts(cells, plane, cell, np.full(cell.size, kind, dtype=np.intp)))
    return concatenate(parts)


def evaluate_plane_contacts(cells: Cells, plane: Plane, cell: np.ndarray, kind: np.ndarray) -> Contacts:
    """The contacts of the given cell ends (``kind`` 5: the −end or a sphere, 6: the +end) with
    one plane, at the cells' present positions, in the order given (as
    :func:`~qpcontact.geometry.contacts.evaluate_contacts` does between cells)."""
    normal, point = np.asarray(plane.normal), np.asarray(plane.point)
    side = np.where(kind == PLANE_PLUS_END, 0.5, -0.5)
    offset_axis = side[:, None] * cells.lengths[cell, None] * cells.axes[cell]
    separation = (cells.centers[cell] + offset_axis - point) @ normal - cells.radii[cell]
    k = cell.size
    normals = np.broadcast_to(normal, (k, 3)).copy()
    offset_a = offset_axis - cells.radii[cell, None] * normals
    static = np.full(k, -1, dtype=np.intp)
    zeros3, zeros1 = np.zeros((k, 3)), np.zeros(k)
    u = relative_normal_velocity(cells, cell, static, normals, offset_a, zeros3, side, zeros1)
    return Contacts(cell, static, normals, offset_a, zeros3, side, zeros1, separation, u, np.asarray(kind, dtype=np.intp))
