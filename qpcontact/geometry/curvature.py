"""The curvature of a contact's separation: its Hessian in the two cells' configurations.

A contact's separation ``d = |p_a − p_b| − ρ_a − ρ_b`` is the distance between the closest
points of two axis segments, ``p_a = c_a + s·â`` and ``p_b = c_b + t·b̂``, each of which is
either an end (``s = ±l_a/2``, which moves with the cell's length) or free (inside the segment:
the closest point slides along the rod as the cells move). Its gradient is the contact's row of
the Jacobian (the closest points held fixed); its Hessian is not: where a point slides, the
minimum over ``s`` and ``t`` bends the separation down (concave), and a turn moves a point on an
arc, not on its tangent. A position step that linearizes the separations
(:mod:`qpcontact.timestep.position`) overstates how far apart such a pair ends up: a contact
point sliding along a rod while that rod turns is the error of its linearizations
(docs/model-notes.md, "A second-order step").

Coordinates of a cell (7): its centre (3), a turn ``φ`` applied to it (3; ``â ← exp(φ×)â``) and
its length (1). :func:`separation_hessians` returns, per contact, the (14, 14) Hessian over the
coordinates of cell ``a`` then ``b`` (a plane's side is zero), with the closest points' slide
eliminated::

    H = D_qq − D_qz D_zz⁻¹ D_zq,   D = |u|,  u = p_a − p_b,  z = the free parameters (s, t),

where ``D_qq = u_qᵀ P u_q / |u| + n·u_qq`` (``P = I − nnᵀ``: the normal turning, and the turns'
arcs), ``D_qz = u_qᵀ P u_z / |u| + n·u_qz`` (a slide along a turning rod) and
``D_zz = u_zᵀ P u_z / |u|``. Exact for the distance of the two axis points when both are where
the contact's kind puts them (:class:`~qpcontact.geometry.Contacts`); ``|u|`` is taken at least
:data:`SMALLEST_DISTANCE` of ``ρ_a + ρ_b`` (rods deep in each other have no meaningful normal
curvature).
"""

from __future__ import annotations

import numpy as np

from .cells import Cells
from .contacts import Contacts

__all__ = ["SMALLEST_DISTANCE", "separation_hessians"]

#: The smallest axis distance ``|u|`` the curvature uses, as a fraction of ``ρ_a + ρ_b``.
SMALLEST_DISTANCE = 0.25
#: A parameter closer than this fraction of the length to a segment's end is at that end.
END = 1e-9
#: A slide whose curvature is below this fraction of the other's is flat (not followed).
FLAT = 1e-8


def _cross_matrix(v: np.ndarray) -> np.ndarray:
    """(K, 3, 3) ``[v]×``: ``[v]× w = v × w``."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def _turn_arc(n: np.ndarray, axis: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(K, 3, 3) the Hessian in the turn ``φ`` of ``n·exp(φ×)(s·â)`` at ``φ = 0``:
    ``s (sym(n âᵀ) − (n·â) I)``."""
    outer = n[:, :, None] * axis[:, None, :]
    return s[:, None, None] * (0.5 * (outer + outer.transpose(0, 2, 1))
                               - np.einsum("ij,ij->i", n, axis)[:, None, None] * np.eye(3))


def separation_hessians(cells: Cells, contacts: Contacts, directions: np.ndarray | None = None) -> np.ndarray:
    """(K, 14, 14) the Hessian of each contact's separation in the coordinates of its two cells
    (module docstring), at the cells as they are (those the contacts were evaluated at).

    ``directions``: (K, 14, m) the moves of those coordinates along ``m`` directions per contact
    (a linearization's columns): the Hessian along them, ``Tᵀ H T`` (K, m, m), computed in them
    (a monolayer's 8 columns, not the 14 coordinates)."""
    k = len(contacts)
    if directions is None:
        directions = np.broadcast_to(np.eye(14), (k, 14, 14))
    a, b = contacts.cell_a, contacts.cell_b
    pair = b >= 0
    bb = np.where(pair, b, 0)
    n = contacts.normal
    ax, bx = cells.axes[a], cells.axes[bb]
    la, lb = cells.lengths[a], np.where(pair, cells.lengths[bb], 0.0)
    s, t = contacts.stretch_a * la, np.where(pair, contacts.stretch_b * lb, 0.0)
    kind = contacts.kind
    free_a = np.isin(kind, (0, 3, 4)) & pair & (la > 0) & (np.abs(contacts.stretch_a) < 0.5 - END)
    free_b = np.isin(kind, (0, 1, 2)) & pair & (lb > 0) & (np.abs(contacts.stretch_b) < 0.5 - END)
    # How an end rides with its cell's length (a free point does not: it slides instead).
    ride_a = np.where(free_a, 0.0, contacts.stretch_a)
    ride_b = np.where(free_b | ~pair, 0.0, contacts.stretch_b)
    move_a, turn_a, grow_a = directions[:, 0:3], directions[:, 3:6], directions[:, 6]
    move_b, turn_b, grow_b = directions[:, 7:10], directions[:, 10:13], directions[:, 13]
    # u_T (K, 3, m): how the axis difference moves along each direction (a turn φ moves s·â by
    # φ × s·â; an end rides along its axis with the length).
    cross = lambda v, w: np.cross(w, v[:, :, None], axisa=1, axisb=1, axisc=1)  # noqa: E731  (K,3,m) w × v
    u_t = (move_a + cross(s[:, None] * ax, turn_a) + ride_a[:, None, None] * ax[:, :, None] * grow_a[:, None, :]
           - pair[:, None, None] * (move_b + cross(t[:, None] * bx, turn_b)
                                    + ride_b[:, None, None] * bx[:, :, None] * grow_b[:, None, :]))
    # n·u_TT: the turns' arcs, and an end riding on a turning rod.
    tt = lambda m, x, y: x.transpose(0, 2, 1) @ (m @ y)  # noqa: E731
    second = tt(_turn_arc(n, ax, s), turn_a, turn_a) - tt(_turn_arc(n, bx, t), turn_b, turn_b)
    ride_turn = (np.einsum("ki,kim->km", ride_a[:, None] * np.cross(ax, n), turn_a)[:, :, None] * grow_a[:, None, :]
                 - np.einsum("ki,kim->km", ride_b[:, None] * np.cross(bx, n), turn_b)[:, :, None] * grow_b[:, None, :])
    second += ride_turn + ride_turn.transpose(0, 2, 1)
    # The free parameters z = (s, t): u_z (K, 3, 2) and n·u_Tz (K, m, 2).
    u_z = np.stack([free_a[:, None] * ax, -(free_b[:, None] * bx)], axis=2)
    slide_turn = np.stack([np.einsum("ki,kim->km", free_a[:, None] * np.cross(ax, n), turn_a),
                           -np.einsum("ki,kim->km", free_b[:, None] * np.cross(bx, n), turn_b)], axis=2)
    # The normal's turning, P/|u| (none for a plane: its normal is fixed).
    radii = cells.radii[a] + np.where(pair, cells.radii[bb], 0.0)
    weight = pair / np.maximum(contacts.separation + radii, SMALLEST_DISTANCE * radii)
    def projected(x: np.ndarray, y: np.ndarray) -> np.ndarray:  # xᵀ P y / |u|
        return (np.einsum("kim,kil->kml", x, y) - np.einsum("ki,kim->km", n, x)[:, :, None]
                * np.einsum("ki,kil->kl", n, y)[:, None, :]) * weight[:, None, None]
    d_tt = projected(u_t, u_t) + second
    d_tz = projected(u_t, u_z) + slide_turn
    d_zz = projected(u_z, u_z)
    # A parameter that is not free is decoupled (its row of D_zz is the identity's).
    d_zz[:, 0, 0] += ~free_a
    d_zz[:, 1, 1] += ~free_b
    # A pseudo-inverse: two free points of rods that cross (or lie parallel) can slide together
    # with no change of distance, a direction of D_zz with no curvature, which no slide follows
    # (D_zz is then of rank one, λvvᵀ with λ its trace, and its pseudo-inverse D_zz/λ²).
    p, q, r = d_zz[:, 0, 0], d_zz[:, 0, 1], d_zz[:, 1, 1]
    trace, det = p + r, p * r - q * q
    full = det > FLAT * trace**2
    inverse = np.empty_like(d_zz)
    inverse[:, 0, 0], inverse[:, 1, 1] = np.where(full, r, p), np.where(full, p, r)
    inverse[:, 0, 1] = inverse[:, 1, 0] = np.where(full, -q, q)
    inverse /= np.where(full, det, trace**2)[:, None, None]
    return d_tt - d_tz @ inverse @ d_tz.transpose(0, 2, 1)
