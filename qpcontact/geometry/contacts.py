"""Contacts between capsules: broad phase, narrow phase, and the colliding set.

Broad phase: every rod is covered by a few bounding spheres (one per piece of length at most
``h``, the median cell length), and ``scipy.spatial.cKDTree.query_pairs`` finds the sphere
pairs that can touch. This stays O(N log N) for colonies of mixed lengths, where one bounding
sphere per cell would make a single long rod touch everything.

Narrow phase, vectorized over candidate pairs: the closest points of the two axis segments.
Nearly parallel rods that lie along each other get two contacts, at the two ends of the
overlapping interval; otherwise a rod can turn through its neighbour about the single contact.

Conventions (model.md): the normal ``n`` points from cell b to cell a, the separation is
``d = |q_a − q_b| − ρ_a − ρ_b`` (negative = overlap), the relative normal velocity is
``u = nᵀ(v_{r_a} − v_{r_b})`` (negative = approaching). ``cell_b = -1`` marks a static body
(a plane or wall: zero velocity, infinite mass); see :func:`concatenate`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..errors import InvalidArgumentError
from .cells import Cells, perpendicular_basis

#: Pairs whose axes make an angle with sine below this get two contacts (ends of the overlap).
PARALLEL_SINE = 1e-3


@dataclass(frozen=True, eq=False)
class Contacts:
    """K contacts as arrays. ``cell_b == -1`` is a static body (no velocity, no unknowns).

    Attributes:
        cell_a, cell_b: (K,) cell indices; the normal points from b to a.
        normal: (K, 3) unit normal, from b to a.
        offset_a, offset_b: (K, 3) contact point minus the cell's centre [length]
            (``q_a − ρ_a n − c_a`` and ``q_b + ρ_b n − c_b``); zero for a static body.
        stretch_a, stretch_b: (K,) ``s/l`` in ``[-½, ½]``, the fraction of the length rate with
            which the contact point rides along the axis (``s`` = axial coordinate of the closest
            axis point; for a sphere, ``±½`` towards the contact, see docs/model-notes.md).
        separation: (K,) ``d`` [length]; negative when the capsules overlap.
        normal_velocity: (K,) ``u`` [length/time]; negative when approaching.
    """

    cell_a: np.ndarray
    cell_b: np.ndarray
    normal: np.ndarray
    offset_a: np.ndarray
    offset_b: np.ndarray
    stretch_a: np.ndarray
    stretch_b: np.ndarray
    separation: np.ndarray
    normal_velocity: np.ndarray

    def __len__(self) -> int:
        return int(self.cell_a.shape[0])

    def subset(self, index: np.ndarray) -> Contacts:
        """The contacts selected by a boolean mask or integer indices."""
        return Contacts(**{f.name: getattr(self, f.name)[index] for f in dataclasses.fields(self)})

    @classmethod
    def empty(cls) -> Contacts:
        z1, z3 = np.zeros(0), np.zeros((0, 3))
        zi = np.zeros(0, dtype=np.intp)
        return cls(zi, zi.copy(), z3, z3, z3, z1, z1, z1, z1)


def concatenate(parts: list[Contacts]) -> Contacts:
    """One Contacts holding all of ``parts`` in order (e.g. cell–cell and cell–plane)."""
    if not parts:
        return Contacts.empty()
    return Contacts(**{
        f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in dataclasses.fields(Contacts)
    })


def relative_normal_velocity(
    cells: Cells, cell_a: np.ndarray, cell_b: np.ndarray, normal: np.ndarray,
    offset_a: np.ndarray, offset_b: np.ndarray, stretch_a: np.ndarray, stretch_b: np.ndarray,
) -> np.ndarray:
    """``u = nᵀ(v_{r_a} − v_{r_b})`` [length/time]; a static body (``cell_b == -1``) is at rest."""
    v_a = cells.point_velocities(cell_a, offset_a, stretch_a)
    moving_b = cell_b >= 0
    v_b = np.zeros_like(v_a)
    if moving_b.any():
        v_b[moving_b] = cells.point_velocities(cell_b[moving_b], offset_b[moving_b], stretch_b[moving_b])
    return np.einsum("ij,ij->i", normal, v_a - v_b)


def stretch_of(s: np.ndarray, lengths: np.ndarray, axes: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """``s/l`` for points with axial coordinate ``s``; a sphere (``l = 0``) rides with the tip
    that faces the contact: ``½ sign(â·r)`` (the limit of a very short rod)."""
    safe = np.where(lengths > 0, lengths, 1.0)
    sphere = 0.5 * np.sign(np.einsum("ij,ij->i", axes, offsets))
    return np.where(lengths > 0, np.clip(s / safe, -0.5, 0.5), sphere)


# ------------------------------------------------------------------------------------------
# Broad phase
# ------------------------------------------------------------------------------------------
def candidate_pairs(cells: Cells, margin: float = 0.0) -> np.ndarray:
    """(P, 2) cell pairs ``i < j`` whose capsules may be closer than ``margin``; a superset of
    the touching pairs. Pairs of two fixed cells are left out (neither can move)."""
    n = cells.n
    if n < 2:
        return np.zeros((0, 2), dtype=np.intp)
    lengths, radii = cells.lengths, cells.radii
    # Cover each rod by k_i pieces of length <= h; a piece's bounding radius is half its
    # length plus the cell radius. h = half the median length: tighter spheres than one per
    # median rod, so fewer candidate pairs reach the narrow phase (3D colony of 10⁵ cells:
    # 1.8M → 1.1M candidates, detection 2.2× faster; 2D unchanged; docs/performance.md).
    h = max(0.5 * float(np.median(lengths)), float(np.median(2.0 * radii)))
    pieces = np.maximum(1, np.ceil(lengths / h)).astype(np.intp)
    owner = np.repeat(np.arange(n), pieces)
    first = np.cumsum(pieces) - pieces
    j = np.arange(owner.size) - first[owner]
    piece_len = lengths[owner] / pieces[owner]
    s = -0.5 * lengths[owner] + (j + 0.5) * piece_len
    points = cells.centers[owner] + s[:, None] * cells.axes[owner]
    bound = 0.5 * piece_len + radii[owner]
    tree = cKDTree(points)
    pairs = tree.query_pairs(r=2.0 * float(bound.max()) + margin, output_type="ndarray")
    if pairs.size == 0:
        return np.zeros((0, 2), dtype=np.intp)
    gap = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1)
    pairs = pairs[gap <= bound[pairs[:, 0]] + bound[pairs[:, 1]] + margin]
    cp = np.sort(owner[pairs], axis=1)
    cp = cp[cp[:, 0] != cp[:, 1]]
    # Rods of several pieces give repeated pairs. One int64 key per pair, sorted, duplicates
    # dropped: the same sorted (i, j) list as np.unique(axis=0), many times faster.
    key = np.sort(cp[:, 0].astype(np.int64) * n + cp[:, 1])
    first = np.ones(key.size, dtype=bool)
    first[1:] = key[1:] != key[:-1]
    key = key[first]
    cp = np.column_stack([key // n, key % n]).astype(np.intp)
    both_fixed = np.isinf(cells.masses[cp[:, 0]]) & np.isinf(cells.masses[cp[:, 1]])
    return cp[~both_fixed]


# ------------------------------------------------------------------------------------------
# Narrow phase
# ------------------------------------------------------------------------------------------
def _closest_parameters(e, f, k, ha, hb):
    """Axial coordinates ``(s, t)`` of the closest points of segments ``c_a + s â``,
    ``s ∈ [−ha, ha]`` and ``c_b + t b̂``, ``t ∈ [−hb, hb]``, with ``e = â·(c_a − c_b)``,
    ``f = b̂·(c_a − c_b)``, ``k = â·b̂``. Exact clamped minimization (clamp s, then t, then s)."""
    denom = 1.0 - k * k
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-300, (f * k - e) / denom, 0.0)
    s = np.clip(s, -ha, ha)
    t = f + s * k
    tc = np.clip(t, -hb, hb)
    s = np.where(t != tc, np.clip(tc * k - e, -ha, ha), s)
    return s, tc


def _fallback_normals(cells: Cells, a: np.ndarray, b: np.ndarray, planar: bool) -> np.ndarray:
    """Normals for pairs whose axis closest points coincide (crossing or coincident axes):
    ``â × b̂``, else the centre difference, else a fixed axis normal to ``â`` (``e₁`` of
    :func:`qpcontact.geometry.perpendicular_basis`, which lies in the plane for planar scenes).
    In a planar scene ``â × b̂`` leaves the plane and is skipped. Oriented so that
    ``n·(c_a − c_b) >= 0``."""
    diff = cells.centers[a] - cells.centers[b]
    if planar:
        diff = diff.copy()
        diff[:, 2] = 0.0
        cross = np.zeros_like(diff)
    else:
        cross = np.cross(cells.axes[a], cells.axes[b])
    scale = np.maximum(cells.lengths[a] + cells.radii[a] + cells.lengths[b] + cells.radii[b], 1e-300)
    out = perpendicular_basis(cells.axes[a])[0]
    # Assigned in reverse priority, so â × b̂ wins over the centre difference, which wins over e₁.
    for candidate, tiny in ((diff, 1e-12 * scale), (cross, 1e-12)):
        norm = np.linalg.norm(candidate, axis=1)
        ok = norm > tiny
        out[ok] = candidate[ok] / norm[ok, None]
    flip = np.einsum("ij,ij->i", out, diff) < 0
    out[flip] *= -1.0
    return out


def narrow_phase(
    cells: Cells, pairs: np.ndarray, margin: float = 0.0, *, planar: bool = False,
    parallel_sine: float = PARALLEL_SINE,
) -> Contacts:
    """Contacts of the candidate ``pairs`` whose separation is below ``margin``."""
    if pairs.size == 0:
        return Contacts.empty()
    a, b = pairs[:, 0], pairs[:, 1]
    ax, bx = cells.axes[a], cells.axes[b]
    ha, hb = 0.5 * cells.lengths[a], 0.5 * cells.lengths[b]
    r = cells.centers[a] - cells.centers[b]
    e = np.einsum("ij,ij->i", ax, r)
    f = np.einsum("ij,ij->i", bx, r)
    k = np.einsum("ij,ij->i", ax, bx)
    s, t = _closest_parameters(e, f, k, ha, hb)

    # Nearly parallel rods lying along each other: two contacts, at the ends of the interval of
    # a's axis that b's axis projects onto.
    sine2 = np.maximum(0.0, 1.0 - k * k)
    ends = np.stack([-e - hb * k, -e + hb * k], axis=1)
    lo = np.maximum(ends.min(axis=1), -ha)
    hi = np.minimum(ends.max(axis=1), ha)
    two = (sine2 < parallel_sine**2) & (ha > 0) & (hb > 0) & (hi - lo > 1e-9 * (ha + hb))
    # Each pair's contacts stay together (the second right after the first, s increasing), so
    # pairs given in sorted order, as candidate_pairs gives them, need no sort at the end.
    idx = np.repeat(np.arange(a.size), 1 + two)
    second = np.zeros(idx.size, dtype=bool)
    second[np.cumsum(1 + two)[two] - 1] = True
    s_all = np.where(second, hi[idx], np.where(two, lo, s)[idx])
    t_all = np.where(second, np.clip(f + hi * k, -hb, hb)[idx], np.where(two, np.clip(f + lo * k, -hb, hb), t)[idx])
    a, b = a[idx], b[idx]
    ax, bx = ax[idx], bx[idx]
    q_a = cells.centers[a] + s_all[:, None] * ax
    q_b = cells.centers[b] + t_all[:, None] * bx
    diff = q_a - q_b
    dist = np.linalg.norm(diff, axis=1)
    rho_a, rho_b = cells.radii[a], cells.radii[b]
    separation = dist - rho_a - rho_b
    keep = separation < margin
    a, b, ax, bx, s_all, t_all = a[keep], b[keep], ax[keep], bx[keep], s_all[keep], t_all[keep]
    diff, dist, separation = diff[keep], dist[keep], separation[keep]
    rho_a, rho_b = rho_a[keep], rho_b[keep]

    degenerate = dist <= 1e-12 * (rho_a + rho_b)
    with np.errstate(invalid="ignore", divide="ignore"):
        normal = diff / dist[:, None]
    if degenerate.any():
        normal[degenerate] = _fallback_normals(cells, a[degenerate], b[degenerate], planar)
    offset_a = s_all[:, None] * ax - rho_a[:, None] * normal
    offset_b = t_all[:, None] * bx + rho_b[:, None] * normal
    stretch_a = stretch_of(s_all, cells.lengths[a], ax, offset_a)
    stretch_b = stretch_of(t_all, cells.lengths[b], bx, offset_b)
    u = relative_normal_velocity(cells, a, b, normal, offset_a, offset_b, stretch_a, stretch_b)
    found = Contacts(a, b, normal, offset_a, offset_b, stretch_a, stretch_b, separation, u)
    # Deterministic order: by pair, then along a. Sorted input pairs already give it.
    key = a.astype(np.int64) * cells.n + b
    same = key[1:] == key[:-1]
    if np.all(key[1:] >= key[:-1]) and np.all(s_all[1:][same] > s_all[:-1][same]):
        return found
    return found.subset(np.lexsort((s_all, b, a)))


def find_contacts(
    cells: Cells, margin: float = 0.0, *, planar: bool = False, parallel_sine: float = PARALLEL_SINE
) -> Contacts:
    """All cell–cell contacts with separation ``d < margin`` [length].

    Args:
        cells: the cells.
        margin: contacts closer than this count (0: overlapping only) [length].
        planar: the scene is a monolayer in the xy-plane: fallback normals stay in the plane.
        parallel_sine: sine of the angle below which two rods lying along each other get two
            contacts.
    """
    margin = float(margin)
    if not np.isfinite(margin) or margin < 0:
        raise InvalidArgumentError(f"margin: must be finite and >= 0, got {margin!r}")
    if not 0 <= parallel_sine < 1:
        raise InvalidArgumentError(f"parallel_sine: must be in [0, 1), got {parallel_sine!r}")
    return narrow_phase(cells, candidate_pairs(cells, margin), margin, planar=planar, parallel_sine=parallel_sine)


def required_velocity_change(
    contacts: Contacts, *, position_correction: float = 0.0, dt: float | None = None
) -> np.ndarray:
    """(K,) ``b = −u + β·max(0, −d)/Δt`` [length/time]: the increase of normal velocity that
    stops approach (β = 0) or also clears a fraction β of the overlap within the step."""
    b = -contacts.normal_velocity
    if position_correction:
        if dt is None or not dt > 0 or not np.isfinite(dt):
            raise InvalidArgumentError(f"dt: position correction needs a finite time step > 0, got {dt!r}")
        if not 0 < position_correction <= 1:
            raise InvalidArgumentError(f"position_correction: must be in (0, 1], got {position_correction!r}")
        b = b + position_correction * np.maximum(0.0, -contacts.separation) / dt
    return b


def colliding(
    contacts: Contacts, *, position_correction: float = 0.0, dt: float | None = None,
    keep_separating: bool = False,
) -> tuple[Contacts, np.ndarray]:
    """The colliding contacts and their right-hand sides ``b > 0``.

    A contact collides when it is within the margin it was found with and approaches
    (``b = −u > 0``); with position correction, also when it overlaps and does not separate fast
    enough to clear the overlap within the step.

    ``keep_separating=True`` keeps every contact (``b <= 0`` too) as soon as one collides: the
    impulses at colliding contacts can drive a separating neighbour into approach, which only
    its own constraint ``(Mx)_k >= b_k`` prevents (for the complementarity formulation).
    """
    b = required_velocity_change(contacts, position_correction=position_correction, dt=dt)
    mask = b > 0
    if keep_separating and mask.any():
        mask[:] = True
    return contacts.subset(mask), b[mask]
