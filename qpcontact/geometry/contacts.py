"""Contacts between capsules: broad phase, narrow phase, and the colliding set.

Broad phase: every rod is covered by a few bounding spheres (one per piece of length at most
``h``, the median cell length), and ``scipy.spatial.cKDTree.query_pairs`` finds the sphere
pairs that can touch. This stays O(N log N) for colonies of mixed lengths, where one bounding
sphere per cell would make a single long rod touch everything.

Narrow phase, vectorized over candidate pairs, in two parts: :func:`select_contacts` decides
which contacts a pair gets (its *kinds*: the closest points of the two axis segments, and the
ends of each segment with their closest points on the other; see :class:`Contacts`), and
:func:`evaluate_contacts` computes them at the cells' positions. A pair is one contact, at the
closest points of its axes, as for any two convex bodies; only rods lying side by side (nearly
parallel, with both ends of their overlap within reach) get the two ends of their overlap, since
one contact would let them turn through each other about it. Every contact is a true distance
between two axis points, so none reports a separation below the pair's true one. The closest
points and their normal are computed without the ``1 − (â·b̂)²`` cancellation of the textbook
formula (:func:`_closest_parameters`), exact to ~1e-16 rad in the normal also for nearly
parallel rods and very short capsules.

A pair is a contact when its separation is **at most** the margin: touching capsules (``d = 0``)
count, with ``margin = 0`` too (as in the broad phase, and as MuJoCo counts them).

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

from ..checks import flag, instance, number
from ..errors import InvalidArgumentError, InvalidCellsError, TooManyContactsError
from .cells import Cells, perpendicular_basis

#: Contact kinds (:attr:`Contacts.kind`). Between two cells: the closest points of the axis
#: segments (0); the −/+ end of a's segment and its closest point on b's (1/2); the −/+ end of
#: b's segment and its closest point on a's (3/4). With a plane: a's −end, or a sphere (5); a's
#: +end (6).
CLOSEST, A_MINUS_END, A_PLUS_END, B_MINUS_END, B_PLUS_END, PLANE_MINUS_END, PLANE_PLUS_END = range(7)
#: Number of kinds a pair of cells can have (0–4).
PAIR_KINDS = 5
#: The broad phase raises :class:`~qpcontact.errors.TooManyContactsError` when there are more
#: candidate pairs than this per cell on average, before allocating them. A dense 3D colony has
#: 11; N coincident cells have (N − 1)/2, so 130 or more of them alone are refused. Module
#: attribute, read at each call: set ``qpcontact.geometry.contacts.MAX_PAIRS_PER_CELL`` to allow
#: more.
MAX_PAIRS_PER_CELL = 64
#: Separations (and end projections) that differ by less than this times ``ρ_a + ρ_b`` count as
#: equal: rounding.
ROUNDING = 1e-9
#: An end contact whose ``s`` and ``t`` both lie within this times ``ρ_a + ρ_b`` of a contact of
#: the same pair kept before it is a near duplicate and is dropped. ¼, not ½: with ½ the two ends
#: of a short overlap (rods end to end but offset, a newborn beside its neighbour's pole) merged
#: into one contact, about which the pair spun (2D colonies to 600 cells, 5 seeds: largest
#: overlap 0.09–0.15 with ½, 0.055–0.063 with ¼; docs/model-notes.md). Smaller values bring no
#: further gain and more nearly dependent rows.
DUPLICATE_DISTANCE = 0.25
#: Rods whose axes make an angle θ with ``sin θ`` at most this are *nearly parallel*: with two
#: distinct ends of their overlap within reach they lie side by side and keep those ends
#: (:func:`select_contacts`). A single contact lets a pair turn about it through about θ before
#: the far end of their overlap meets; a step turns a colony cell through up to about this
#: much (its tips by 0.2–0.3 of a diameter: the position step's cap until issue 32, ``cfl`` of
#: ``simulate --step velocity``; for rods of 1.5–4 µm and radius 0.5 µm, 0.1–0.25 rad), so
#: closer to parallel than this a single contact could let them turn through each other within
#: one step; the position step, uncapped, finds a pair's contacts again at each linearization.
#: docs/model-notes.md, "Contacts of a pair".
SIDE_BY_SIDE_SINE = 0.2


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
        kind: (K,) int, which contact of its pair it is, so that the same contact can be
            evaluated again at other positions (:func:`evaluate_contacts`). Cell pairs: 0 the
            closest points of the two axis segments; 1 / 2 the − / + end of a's axis segment
            (``s = ∓l_a/2``) and its closest point on b's; 3 / 4 the − / + end of b's segment
            (``t = ∓l_b/2``) and its closest point on a's. Planes (``cell_b = -1``): 5 a's −end
            (or a sphere's centre), 6 a's +end.
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
    kind: np.ndarray

    def __len__(self) -> int:
        return int(self.cell_a.shape[0])

    def subset(self, index: np.ndarray) -> Contacts:
        """The contacts selected by a boolean mask or integer indices."""
        return Contacts(**{f.name: getattr(self, f.name)[index] for f in dataclasses.fields(self)})

    @classmethod
    def empty(cls) -> Contacts:
        z1, z3 = np.zeros(0), np.zeros((0, 3))
        zi = np.zeros(0, dtype=np.intp)
        return cls(zi, zi.copy(), z3, z3, z3, z1, z1, z1, z1, zi.copy())


def check_contacts(contacts: object, cells: Cells) -> Contacts:
    """``contacts`` if it is a :class:`Contacts` of these cells: one length for every field, and
    cell indices in range (``cell_b = -1`` for a static body); else
    :class:`~qpcontact.errors.InvalidArgumentError` (e.g. contacts of another scene)."""
    instance("contacts", contacts, Contacts, "qpcontact.Contacts (e.g. from find_contacts)")
    assert isinstance(contacts, Contacts)
    k = len(contacts)
    for f in dataclasses.fields(Contacts):
        value = getattr(contacts, f.name)
        if not isinstance(value, np.ndarray) or value.shape[:1] != (k,):
            raise InvalidArgumentError(f"contacts.{f.name}: expected an array of {k} rows, got "
                                       f"{getattr(value, 'shape', type(value).__name__)}")
    for name, values, low in (("cell_a", contacts.cell_a, 0), ("cell_b", contacts.cell_b, -1)):
        if k and (values.dtype.kind not in "iu" or values.min() < low or values.max() >= cells.n):
            raise InvalidArgumentError(f"contacts.{name}: indices {values.min()}..{values.max()} are not cells of "
                                       f"these {cells.n} cells (contacts of another scene?)")
    return contacts


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
def candidate_pairs(cells: Cells, margin: float = 0.0, slack: np.ndarray | None = None) -> np.ndarray:
    """(P, 2) cell pairs ``i < j`` whose capsules may be closer than ``margin``; a superset of
    the touching pairs. Pairs of two fixed cells are left out (neither can move).

    ``slack`` (N,) [length]: how far each cell's axis may move (its tips' largest displacement)
    before the pairs are used: the pairs are then a superset of those within ``margin`` at any
    such positions (one search for several configurations of the cells, e.g. the start of a step
    and where its motion takes them)."""
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
    if slack is not None:
        bound += np.asarray(slack, dtype=float)[owner]
    tree = cKDTree(points)
    # One radius for all pairs of pieces; with slack, the few pieces that may move far (a cell
    # pushed out of a jam) would widen it for everyone: they search around themselves instead.
    common = float(bound.max()) if slack is None else float(np.quantile(bound, 0.99))
    reach = 2.0 * common + margin
    _check_pair_count(tree, points, reach, cells.n, margin)
    pairs = tree.query_pairs(r=reach, output_type="ndarray").reshape(-1, 2)
    far = np.flatnonzero(bound > common)
    if far.size:
        around = tree.query_ball_point(points[far], r=bound[far] + float(bound.max()) + margin)
        counts = np.fromiter((len(found) for found in around), dtype=np.intp, count=far.size)
        if counts.sum():
            pairs = np.concatenate([pairs, np.column_stack([np.repeat(far, counts), np.concatenate(around)])])
    if pairs.size == 0:
        return np.zeros((0, 2), dtype=np.intp)
    one, other = pairs[:, 0], pairs[:, 1]
    gap = points[one] - points[other]
    within = bound[one] + bound[other] + margin
    keep = np.einsum("ij,ij->i", gap, gap) <= within * within
    one, other = owner[one[keep]], owner[other[keep]]
    low, high = np.minimum(one, other), np.maximum(one, other)
    # Rods of several pieces give repeated pairs. One int64 key per pair, sorted, duplicates
    # dropped: the same sorted (i, j) list as np.unique(axis=0), many times faster.
    key = low[low != high].astype(np.int64) * n + high[low != high]
    key.sort()
    first = np.ones(key.size, dtype=bool)
    first[1:] = key[1:] != key[:-1]
    key = key[first]
    cp = np.column_stack([key // n, key % n]).astype(np.intp)
    if cp.shape[0] > MAX_PAIRS_PER_CELL * n:
        _too_many(f"{cp.shape[0]:,} candidate pairs of {n:,} cells", "cell", margin)
    both_fixed = np.isinf(cells.masses[cp[:, 0]]) & np.isinf(cells.masses[cp[:, 1]])
    return cp[~both_fixed]


def _too_many(what: str, unit: str, margin: float) -> None:
    raise TooManyContactsError(
        f"{what}: more than MAX_PAIRS_PER_CELL = {MAX_PAIRS_PER_CELL} per {unit} (margin {margin:g}); coincident "
        "or deeply interpenetrating cells? (set qpcontact.geometry.contacts.MAX_PAIRS_PER_CELL to allow more)")


def _check_pair_count(tree: cKDTree, points: np.ndarray, reach: float, n: int, margin: float) -> None:
    """Raise before ``query_pairs`` allocates more sphere pairs than :data:`MAX_PAIRS_PER_CELL`
    per cell allows (a pair of cells of k spheres each can give k² sphere pairs: the limit is
    ``MAX_PAIRS_PER_CELL · n · (m/n)²`` for m spheres). A cheap upper bound first (points in the
    same or adjacent cells of a grid of spacing ``reach``: 0.1 s at 10⁵ cells); only where that
    exceeds the limit are the pairs counted exactly (``count_neighbors``, no allocation; fast
    exactly where the points are clustered)."""
    m = points.shape[0]
    limit = MAX_PAIRS_PER_CELL * m * m // max(n, 1)
    if m * (m - 1) // 2 <= limit:
        return
    index = np.floor((points - points.min(axis=0)) / max(reach, 1e-300)).astype(np.int64) + 1
    dims = index.max(axis=0) + 2
    key = (index[:, 0] * dims[1] + index[:, 1]) * dims[2] + index[:, 2]
    occupied, counts = np.unique(key, return_counts=True)
    around = np.zeros(occupied.size, dtype=np.int64)
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                other = occupied + (dx * dims[1] + dy) * dims[2] + dz
                at = np.minimum(np.searchsorted(occupied, other), occupied.size - 1)
                around += np.where(occupied[at] == other, counts[at], 0)
    if (int(counts @ around) - m) // 2 <= limit:
        return
    pairs = (int(tree.count_neighbors(tree, reach)) - m) // 2
    if pairs > limit:
        _too_many(f"{pairs:,} candidate pairs of {m:,} bounding spheres ({m / n:.3g} per cell) of {n:,} cells",
                  "cell", margin)


# ------------------------------------------------------------------------------------------
# Narrow phase
# ------------------------------------------------------------------------------------------
def _two_product(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``x·y = p + err`` exactly (Dekker's product with Veltkamp's split; |x|, |y| ≲ 1e150)."""
    p = x * y
    split = 134217729.0  # 2^27 + 1
    xc, yc = split * x, split * y
    xh, yh = xc - (xc - x), yc - (yc - y)
    xl, yl = x - xh, y - yh
    return p, ((xh * yh - p) + xh * yl + xl * yh) + xl * yl


#: Below this ``|â × b̂| = sin θ`` the cross product of two axes is computed compensated
#: (:func:`axis_cross`): above it the plain product's relative error, ~1e-16/θ, is below 1e-13.
COMPENSATED_SINE = 1e-3


def axis_cross(ax: np.ndarray, bx: np.ndarray) -> np.ndarray:
    """``â × b̂`` to full relative precision, also for nearly parallel axes, where the plain
    product loses it (each component is a difference of nearly equal products: relative error
    ~1e-16/θ for an angle θ; the common normal of rods at θ = 1e-8 would be off by 1e-8 rad).
    Compensated (Dekker's exact products) where ``sin θ <`` :data:`COMPENSATED_SINE`, the plain
    product elsewhere (4× cheaper, and as exact there to 1e-13)."""
    out = np.cross(ax, bx)
    near = np.flatnonzero(np.einsum("ij,ij->i", out, out) < COMPENSATED_SINE**2)
    if near.size:
        a, b = ax[near], bx[near]
        for i, (j, k) in enumerate(((1, 2), (2, 0), (0, 1))):
            p1, e1 = _two_product(a[:, j], b[:, k])
            p2, e2 = _two_product(a[:, k], b[:, j])
            out[near, i] = (p1 - p2) + (e1 - e2)  # p1 − p2 is exact where it cancels (Sterbenz)
    return out


def _closest_parameters(r, ax, bx, ha, hb, w=None):
    """Axial coordinates ``(s, t)`` of the closest points of the segments ``c_a + s â``,
    ``s ∈ [−ha, ha]``, and ``c_b + t b̂``, ``t ∈ [−hb, hb]`` (``r = c_a − c_b``), and a mask of the
    pairs whose closest points lie inside both segments.

    Clamped minimization (clamp s, then t, then s), started from the closest points of the two
    lines written with ``w = â × b̂`` (:func:`axis_cross`): ``s = w·(b̂ × r)/|w|²``,
    ``t = w·(â × r)/|w|²``. The textbook form ``(f k − e)/(1 − k²)`` (``k = â·b̂``) loses all
    precision in ``1 − k²`` for nearly parallel rods (relative error 1e-16/θ², against 1e-16/θ
    here). Then one refinement from the residual ``q_a − q_b`` (the same formulas with ``r``
    replaced by it, or the foot of the free point for a clamped one): the error of ``s``, ``t``
    is then that of the residual, not of the centre difference."""
    w = axis_cross(ax, bx) if w is None else w
    ww = np.einsum("ij,ij->i", w, w)
    lines = ww > 0.0
    safe = np.where(lines, ww, 1.0)
    k = np.einsum("ij,ij->i", ax, bx)
    e, f = np.einsum("ij,ij->i", ax, r), np.einsum("ij,ij->i", bx, r)
    s = np.where(lines, np.einsum("ij,ij->i", w, np.cross(bx, r)) / safe, 0.0)
    s = np.clip(s, -ha, ha)
    t = f + s * k
    tc = np.clip(t, -hb, hb)
    s = np.where(t != tc, np.clip(tc * k - e, -ha, ha), s)
    free_s, free_t = np.abs(s) < ha, np.abs(tc) < hb
    inside = free_s & free_t & lines
    diff = r + s[:, None] * ax - tc[:, None] * bx
    # Refinement on the active set: both free, a Newton step of the 2 × 2 system; one free, its
    # foot. (s, t stay within their segments: the correction is of the order of the rounding.)
    ds = np.where(inside, np.einsum("ij,ij->i", w, np.cross(bx, diff)) / safe,
                  np.where(free_s & ~free_t, -np.einsum("ij,ij->i", ax, diff), 0.0))
    dt = np.where(inside, np.einsum("ij,ij->i", w, np.cross(ax, diff)) / safe,
                  np.where(free_t & ~free_s, np.einsum("ij,ij->i", bx, diff), 0.0))
    return np.clip(s + ds, -ha, ha), np.clip(tc + dt, -hb, hb), inside


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


def _end_parameters(kind, e, f, k, ha, hb):
    """``(s, t, projection)`` of the end kinds 1–4 (see :class:`Contacts`): the end's axial
    coordinate on its own segment, the clamped projection on the other one, and the unclamped
    projection (interior when it lies within the other segment)."""
    sign = np.where(np.asarray(kind) % 2 == 1, -1.0, 1.0)  # kinds 1 and 3 are the − ends
    on_a = np.asarray(kind) <= 2
    # An end of a at s = ±ha projects onto b at t = f + s k; an end of b at t = ±hb onto a at
    # s = −e + t k (the coordinates of the closest point of the other axis line).
    own = sign * np.where(on_a, ha, hb)
    projection = np.where(on_a, f, -e) + own * k
    clamped = np.clip(projection, -np.where(on_a, hb, ha), np.where(on_a, hb, ha))
    return np.where(on_a, own, clamped), np.where(on_a, clamped, own), projection


def _pair_projections(cells: Cells, a, b):
    """``r = c_a − c_b``, ``â``, ``b̂``, ``e = â·r``, ``f = b̂·r``, ``k = â·b̂`` and the half lengths."""
    r = cells.centers[a] - cells.centers[b]
    ax, bx = cells.axes[a], cells.axes[b]
    return (r, ax, bx, np.einsum("ij,ij->i", ax, r), np.einsum("ij,ij->i", bx, r), np.einsum("ij,ij->i", ax, bx),
            0.5 * cells.lengths[a], 0.5 * cells.lengths[b])


def _axis_distances(r, ax, bx, s, t) -> np.ndarray:
    """``|c_a + s â − c_b − t b̂|`` (with ``r = c_a − c_b``) [length]."""
    return np.linalg.norm(r + s[:, None] * ax - t[:, None] * bx, axis=1)


def select_contacts(cells: Cells, pairs: np.ndarray, margin: float = 0.0, *,
                    always_closest: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which contacts each candidate pair gets: ``(a, b, kind)``, one entry per contact.

    A pair is one contact, at the closest points of its axes (kind 0), unless its rods lie *side
    by side*: then it gets the two ends of their overlap (kinds 1–4), and the closest points too
    where they are nearer. Side by side means

    - nearly parallel: ``sin θ <= SIDE_BY_SIDE_SINE`` (0.2) for the angle θ between the axes, and
    - both ends of the overlap within reach: two end kinds, each an end of one segment that
      projects into the other (unclamped, to rounding ``ROUNDING·(ρ_a + ρ_b)``), with separation
      at most ``margin``, and not near duplicates of each other (their ``s`` or ``t`` differ by
      more than ``DUPLICATE_DISTANCE·(ρ_a + ρ_b)``).

    Why: for a skew pair the distance grows away from the closest points on every side, the
    closest points move continuously as the cells move, and one contact is the physics of two
    convex bodies (one normal, one impulse; the plain solve then gives the two-body impulse; as
    MuJoCo counts capsule pairs). Extra contacts at the ends of a skew pair's overlap over-
    constrain it: the plain solve then pulled at some of them (issue 19). For rods lying side by
    side the distance is nearly the same along the whole overlap and the closest point jumps from
    one end to the other as they turn: a single contact lets them turn about it through about θ,
    and a step turns a colony cell through up to about 0.2 rad (see :data:`SIDE_BY_SIDE_SINE`),
    so they need both ends. Each contact is a true distance between a point of a's axis and a
    point of b's, so none reports a separation below the pair's true one. Among the contacts of
    a side-by-side pair: kind 0 is dropped when a kept end has the same (to rounding) or a
    smaller separation (exactly parallel rods thus keep two contacts, not three), and an end is
    dropped when both its ``s`` and ``t`` lie within ``DUPLICATE_DISTANCE·(ρ_a + ρ_b)`` (¼) of a
    contact of the same pair kept before it (the one with the smallest separation first):
    near-duplicate rows make the Delassus operator singular.

    With ``always_closest`` (the position-level step, which linearizes the distance of every pair
    at several points) the side-by-side test is not made: kind 0 is kept for every pair within the
    margin, every end within reach is kept, and ends are compared as duplicates only with each
    other: across the linearizations of a step the closest point moves along the pair, and only
    kind 0 follows it (an end that stood in for it may no longer be the nearest point, and a new
    overlap elsewhere on the pair would go unseen); the redundant rows this keeps cost an
    interior-point solver nothing.

    Args:
        cells: the cells.
        pairs: (P, 2) candidate pairs (e.g. :func:`candidate_pairs`).
        margin: largest separation that counts [length].
        always_closest: keep kind 0 for every pair within the margin (above).

    Returns:
        ``(a, b, kind)``, int arrays, ordered by pair ``(a, b)`` and then by the axial coordinate
        ``s`` on a (ties by kind): the order of the contacts :func:`evaluate_contacts` returns.
    """
    pairs = np.asarray(pairs, dtype=np.intp).reshape(-1, 2)
    if pairs.shape[0] == 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty.copy(), empty.copy()
    a, b = pairs[:, 0], pairs[:, 1]
    r, ax, bx, e, f, k, ha, hb = _pair_projections(cells, a, b)
    rho = cells.radii[a] + cells.radii[b]
    s0, t0, _ = _closest_parameters(r, ax, bx, ha, hb)
    separation0 = _axis_distances(r, ax, bx, s0, t0) - rho
    # No contact of a pair is nearer than kind 0: pairs beyond the margin are done.
    within = np.flatnonzero(separation0 <= margin)
    a, b, r, ax, bx, e, f, k, ha, hb, rho = (x[within] for x in (a, b, r, ax, bx, e, f, k, ha, hb, rho))
    rounding = ROUNDING * rho
    rods = (ha > 0) & (hb > 0)
    s = np.empty((a.size, PAIR_KINDS))
    t = np.empty_like(s)
    separation = np.full_like(s, np.inf)
    s[:, 0], t[:, 0], separation[:, 0] = s0[within], t0[within], separation0[within]
    for kind in range(1, PAIR_KINDS):
        s[:, kind], t[:, kind], projection = _end_parameters(kind, e, f, k, ha, hb)
        other = hb if kind <= 2 else ha
        rows = np.flatnonzero(rods & (np.abs(projection) <= other + rounding))
        separation[rows, kind] = _axis_distances(r[rows], ax[rows], bx[rows], s[rows, kind], t[rows, kind]) - rho[rows]
    keep = separation <= margin
    near = DUPLICATE_DISTANCE * rho
    if not always_closest:
        # Only rods lying side by side keep ends (docstring); every other pair is one contact, at
        # its closest points, as for any two convex bodies.
        keep[~_side_by_side(keep, s, t, near, ax, bx), 1:] = False
    _drop_duplicates(keep, s, t, separation, rounding, near, always_closest)
    keep[:, 0] |= (separation[:, 0] <= margin) & ~keep.any(axis=1)
    return _in_pair_order(cells.n, a, b, keep, s)


def _side_by_side(keep: np.ndarray, s: np.ndarray, t: np.ndarray, near: np.ndarray, ax: np.ndarray,
                  bx: np.ndarray) -> np.ndarray:
    """(P,) the pairs whose rods lie side by side (:func:`select_contacts`): nearly parallel, with
    two distinct ends of their overlap within reach."""
    distinct = np.zeros(keep.shape[0], dtype=bool)
    for j in range(2, PAIR_KINDS):
        for i in range(1, j):
            apart = (np.abs(s[:, j] - s[:, i]) > near) | (np.abs(t[:, j] - t[:, i]) > near)
            distinct |= keep[:, i] & keep[:, j] & apart
    sine = np.linalg.norm(axis_cross(ax, bx), axis=1)
    return distinct & (sine <= SIDE_BY_SIDE_SINE)


def _drop_duplicates(keep: np.ndarray, s: np.ndarray, t: np.ndarray, separation: np.ndarray, rounding: np.ndarray,
                     near: np.ndarray, always_closest: bool) -> None:
    """Drop (in ``keep``) kind 0 where the nearest kept end is as close (to rounding), and the
    near duplicates, in the order: the contact of least separation (kind 0 or the end that
    represents it) first, then the other ends by kind (:func:`select_contacts`)."""
    ends = np.where(keep[:, 1:], separation[:, 1:], np.inf)
    nearest_end = 1 + np.argmin(ends, axis=1)
    represented = (ends.min(axis=1) <= separation[:, 0] + rounding) & (not always_closest)
    keep[:, 0] &= ~represented
    order = np.tile(np.arange(PAIR_KINDS), (keep.shape[0], 1))
    swap = np.flatnonzero(represented)
    order[swap, 0], order[swap, nearest_end[swap]] = nearest_end[swap], 0
    rows = np.arange(keep.shape[0])[:, None]
    s_o, t_o, keep_o = s[rows, order], t[rows, order], keep[rows, order]
    for j in range(1, PAIR_KINDS):
        for i in range(1 if always_closest else 0, j):
            duplicate = keep_o[:, i] & (np.abs(s_o[:, j] - s_o[:, i]) <= near) & (np.abs(t_o[:, j] - t_o[:, i]) <= near)
            keep_o[:, j] &= ~duplicate
    keep[rows, order] = keep_o


def _in_pair_order(n: int, a: np.ndarray, b: np.ndarray, keep: np.ndarray,
                   s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The kept contacts ``(a, b, kind)`` ordered by pair, then along a (ties by kind: a stable
    sort of kinds 0..4)."""
    rows = np.arange(a.size)[:, None]
    along = np.argsort(np.where(keep, s, np.inf), axis=1, kind="stable")
    kinds = along[keep[rows, along]]
    row = np.repeat(np.arange(a.size), keep.sum(axis=1))
    a_out, b_out = a[row], b[row]
    key = a_out.astype(np.int64) * max(n, 1) + b_out
    if np.any(key[1:] < key[:-1]):
        order_all = np.lexsort((kinds, s[row, kinds], b_out, a_out))
        a_out, b_out, kinds = a_out[order_all], b_out[order_all], kinds[order_all]
    return a_out, b_out, kinds.astype(np.intp)


def evaluate_contacts(cells: Cells, a: np.ndarray, b: np.ndarray, kind: np.ndarray, *, planar: bool = False,
                      velocities: bool = True) -> Contacts:
    """The contacts ``(a, b, kind)`` (e.g. from :func:`select_contacts`) at the cells' current
    positions, in the order given, whatever their separation.

    Kind 0 is the closest points of the two axis segments; an end kind (1–4, see
    :class:`Contacts`) is that end and its closest point on the other segment (clamped, even if
    the end no longer projects inside it). Normals point from b to a; where the two axis points
    coincide (crossing or coincident axes) the fallback of :func:`_fallback_normals` is used.

    Args:
        cells: the cells (positions, momenta).
        a, b: (K,) cell indices (``a != b``).
        kind: (K,) contact kinds, 0–4.
        planar: the scene is a monolayer in the xy-plane: fallback normals stay in the plane.
        velocities: compute the relative normal velocities from the cells' momenta (False: 0,
            for a caller that needs only the geometry, e.g. the position step's linearizations:
            2/5 of an evaluation at 10⁴ cells).
    """
    a, b, kind = (np.asarray(x) for x in (a, b, kind))
    if not (a.shape == b.shape == kind.shape and a.ndim == 1):
        raise InvalidArgumentError(f"a, b, kind: expected three 1-D arrays of one length, got shapes "
                                   f"{a.shape}, {b.shape}, {kind.shape}")
    for name, values, high in (("a", a, cells.n), ("b", b, cells.n), ("kind", kind, PAIR_KINDS)):
        if values.size and (values.dtype.kind not in "iu" or values.min() < 0 or values.max() >= high):
            raise InvalidArgumentError(f"{name}: expected integers in [0, {high}), got {values.dtype} in "
                                       f"[{values.min()}, {values.max()}]")
    if np.any(a == b):
        raise InvalidArgumentError(f"a, b: a cell cannot touch itself (cell {int(a[a == b][0])})")
    a, b, kind = a.astype(np.intp), b.astype(np.intp), kind.astype(np.intp)
    if a.size == 0:
        return Contacts.empty()
    r, ax, bx, e, f, k, ha, hb = _pair_projections(cells, a, b)
    s, t = _end_parameters(np.maximum(kind, 1), e, f, k, ha, hb)[:2]
    # An end's foot on the other segment, refined once from the residual (its error is then that
    # of the residual, not of the centre difference).
    on_a, on_b = (kind >= 1) & (kind <= 2), kind >= 3
    rough = r + s[:, None] * ax - t[:, None] * bx
    t = np.where(on_a & (np.abs(t) < hb), np.clip(t + np.einsum("ij,ij->i", bx, rough), -hb, hb), t)
    s = np.where(on_b & (np.abs(s) < ha), np.clip(s - np.einsum("ij,ij->i", ax, rough), -ha, ha), s)
    closest = np.flatnonzero(kind == 0)
    w = axis_cross(ax[closest], bx[closest])
    s[closest], t[closest], inside = _closest_parameters(r[closest], ax[closest], bx[closest], ha[closest],
                                                         hb[closest], w)
    diff = r + s[:, None] * ax - t[:, None] * bx
    dist = np.linalg.norm(diff, axis=1)
    rho_a, rho_b = cells.radii[a], cells.radii[b]
    separation = dist - rho_a - rho_b
    degenerate = dist <= 1e-12 * (rho_a + rho_b)
    with np.errstate(invalid="ignore", divide="ignore"):
        normal = diff / dist[:, None]
    if not planar:
        # Closest points inside both segments: the normal is the common perpendicular â × b̂
        # exactly; from it, not from q_a − q_b, whose direction for nearly parallel rods carries
        # the error of s along the rods times the angle (issue 19: 6e-6 rad at θ = 4e-9).
        # (Planar scenes: two rods of a monolayer meet inside both segments only where their
        # axes cross, a degenerate contact.)
        common = closest[inside & ~degenerate[closest]]
        wc = w[inside & ~degenerate[closest]]
        side = np.sign(np.einsum("ij,ij->i", wc, diff[common]))
        normal[common] = (side / np.linalg.norm(wc, axis=1))[:, None] * wc
    if degenerate.any():
        normal[degenerate] = _fallback_normals(cells, a[degenerate], b[degenerate], planar)
    offset_a = s[:, None] * ax - rho_a[:, None] * normal
    offset_b = t[:, None] * bx + rho_b[:, None] * normal
    stretch_a = stretch_of(s, cells.lengths[a], ax, offset_a)
    stretch_b = stretch_of(t, cells.lengths[b], bx, offset_b)
    u = (relative_normal_velocity(cells, a, b, normal, offset_a, offset_b, stretch_a, stretch_b) if velocities
         else np.zeros(a.size))
    return Contacts(a, b, normal, offset_a, offset_b, stretch_a, stretch_b, separation, u, kind)


def narrow_phase(cells: Cells, pairs: np.ndarray, margin: float = 0.0, *, planar: bool = False) -> Contacts:
    """Contacts of the candidate ``pairs`` with separation at most ``margin``:
    :func:`evaluate_contacts` of :func:`select_contacts`."""
    return evaluate_contacts(cells, *select_contacts(cells, pairs, margin), planar=planar)


def find_contacts(cells: Cells, margin: float = 0.0, *, planar: bool | None = False) -> Contacts:
    """All cell–cell contacts with separation ``d <= margin`` [length] (touching counts):
    :func:`narrow_phase` of :func:`candidate_pairs`.

    Args:
        cells: the cells.
        margin: contacts this close count (0: overlapping and touching only) [length].
        planar: the scene is a monolayer in the xy-plane: fallback normals stay in the plane.
            None: detected from the cells (:meth:`Cells.is_monolayer`), as
            :func:`qpcontact.resolve` and :func:`qpcontact.step` do with ``planar=None``.
    """
    instance("cells", cells, Cells, "qpcontact.Cells", InvalidCellsError)
    margin = number("margin", margin, minimum=0.0)
    planar = flag("planar", planar, allow_none=True)
    planar = cells.is_monolayer() if planar is None else planar
    return narrow_phase(cells, candidate_pairs(cells, margin), margin, planar=planar)


def required_velocity_change(
    contacts: Contacts, *, position_correction: float = 0.0, dt: float | None = None
) -> np.ndarray:
    """(K,) ``b = −u + β·max(0, −d)/Δt`` [length/time]: the increase of normal velocity that
    stops approach (β = 0) or also clears a fraction β of the overlap within the step."""
    instance("contacts", contacts, Contacts, "qpcontact.Contacts")
    b = -contacts.normal_velocity
    position_correction = number("position_correction", position_correction, minimum=0.0, maximum=1.0)
    if position_correction:
        if dt is None:
            raise InvalidArgumentError("dt: position correction needs the time step")
        dt = number("dt", dt, minimum=0.0, open_minimum=True)
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
    keep_separating = flag("keep_separating", keep_separating)
    b = required_velocity_change(contacts, position_correction=position_correction, dt=dt)
    mask = b > 0
    if keep_separating and mask.any():
        mask[:] = True
    return contacts.subset(mask), b[mask]


#: A contact kind fits in this many bits of a key (:func:`contact_keys`).
KIND_BITS = 3
#: Cell indices (or ids) of keyed contacts must be below this (:func:`contact_keys`).
KEY_SPAN_LIMIT = 2**27


def contact_keys(a: np.ndarray, b: np.ndarray, kind: np.ndarray, span: int) -> np.ndarray:
    """(K,) one int64 per contact ``(a, b, kind)``: equal for the same contact, different for
    different ones, so contacts can be matched across linearizations and steps by sorting.
    ``key >> KIND_BITS`` identifies the pair (a cell and a plane, for ``b < 0``).

    Args:
        a: (K,) cells (indices or ids) in ``[0, span)``.
        b: (K,) cells in ``[0, span)``, or static bodies as negative numbers in ``[−span, 0)``
            (``−1 − j`` for plane ``j``).
        kind: (K,) contact kinds (:class:`Contacts`), 0–6.
        span: one more than the largest cell number (and than the number of static bodies).

    Raises:
        InvalidArgumentError: ``span`` of :data:`KEY_SPAN_LIMIT` or more (the keys would overflow).
    """
    if span >= KEY_SPAN_LIMIT:
        raise InvalidArgumentError(f"contact keys need cell numbers below {KEY_SPAN_LIMIT}, got up to {span - 1}")
    pair = np.asarray(a, dtype=np.int64) * (2 * span) + (np.asarray(b, dtype=np.int64) + span)
    return (pair << KIND_BITS) + np.asarray(kind, dtype=np.int64)
