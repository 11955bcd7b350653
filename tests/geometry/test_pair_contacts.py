"""One pair, one contact (issue 19, items 1 and 2): a skew pair of capsules is one contact at the
closest points of its axes, as for any two convex bodies (and as MuJoCo's capsule–capsule test
counts them), so the plain solve gives the textbook two-body impulse; only rods lying side by
side keep the two ends of their overlap. The normal at the closest points is exact to 1e-9 rad,
against closest points computed here in exact rational arithmetic."""

from fractions import Fraction
from functools import cache

import numpy as np
import pytest

import qpcontact as qc
from qpcontact.geometry import evaluate_contacts, select_contacts
from qpcontact.geometry.contacts import SIDE_BY_SIDE_SINE


# ------------------------------------------------------------------------------------------
# The reference: closest points of two segments in exact rational arithmetic
# ------------------------------------------------------------------------------------------
def _exact(values):
    return [Fraction(float(x)) for x in values]


def _dot(u, v):
    return sum(x * y for x, y in zip(u, v, strict=True))


def exact_closest(cells, i=0, j=1):
    """``(s, t, q_a − q_b)`` as Fractions: the closest points of the axis segments of cells i and
    j, with the cells' floats taken as exact numbers. The minimum of a convex quadratic over a
    box is at the interior stationary point if that lies in the box, else on an edge, where it is
    the clamped 1-D minimizer: every candidate is computed exactly and the nearest one wins."""
    ca, aa, cb, bb = (_exact(v) for v in (cells.centers[i], cells.axes[i], cells.centers[j], cells.axes[j]))
    ha, hb = Fraction(float(cells.lengths[i])) / 2, Fraction(float(cells.lengths[j])) / 2
    r = [x - y for x, y in zip(ca, cb, strict=True)]
    A, B, C, e, f = _dot(aa, aa), _dot(aa, bb), _dot(bb, bb), _dot(aa, r), _dot(bb, r)

    def clamp(x, h):
        return min(max(x, -h), h)

    def gap(s, t):
        return [x + s * y - t * z for x, y, z in zip(r, aa, bb, strict=True)]

    candidates = []
    det = A * C - B * B
    if det != 0:  # stationary point of |r + s a − t b|²
        s, t = (B * f - C * e) / det, (A * f - B * e) / det
        if abs(s) <= ha and abs(t) <= hb:
            candidates.append((s, t))
    candidates += [(s, clamp((f + B * s) / C, hb)) for s in (-ha, ha)]
    candidates += [(clamp((B * t - e) / A, ha), t) for t in (-hb, hb)]
    s, t = min(candidates, key=lambda st: _dot(gap(*st), gap(*st)))
    return s, t, gap(s, t)


def angle_to(normal, exact):
    """Angle [rad] between a float vector and an exact one (sine from the exact cross product)."""
    n = _exact(normal)
    cross = [n[1] * exact[2] - n[2] * exact[1], n[2] * exact[0] - n[0] * exact[2], n[0] * exact[1] - n[1] * exact[0]]
    sine = float(_dot(cross, cross) / (_dot(n, n) * _dot(exact, exact))) ** 0.5
    return sine if _dot(n, exact) > 0 else np.pi - sine


def frame(rng):
    """Three orthonormal vectors."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    side = np.cross(axis, rng.normal(size=3))
    side /= np.linalg.norm(side)
    return axis, side, np.cross(axis, side)


# ------------------------------------------------------------------------------------------
# Item 2: normals to 1e-9 rad
# ------------------------------------------------------------------------------------------
def hard_pair(rng, case):
    a, side, up = frame(rng)
    if case == "short_beside_a_rod":  # the issue's: a capsule of length 2.6e-4 beside a rod
        angle = 10.0 ** rng.uniform(-8, 0.2)
        lengths = [rng.uniform(1.0, 5.0), float(rng.choice([2.6e-4, 10.0 ** rng.uniform(-6, -2)]))]
    elif case == "near_parallel_skew":  # closest points inside both segments
        angle = 10.0 ** rng.uniform(-12, -2)
        lengths = list(rng.uniform(0.5, 6.0, 2))
    else:  # "near_parallel_ends": the nearest points at an end
        angle = 10.0 ** rng.uniform(-12, -2)
        lengths = list(rng.uniform(0.5, 6.0, 2))
    b = np.cos(angle) * a + np.sin(angle) * side
    height = 10.0 ** rng.uniform(-3, 0)  # distance of the axes: overlapping, from barely to deeply
    along = rng.uniform(-0.4, 0.4) * lengths[0]
    if case == "near_parallel_ends":
        along = rng.choice([-1, 1]) * rng.uniform(0.5, 0.95) * (lengths[0] + lengths[1]) / 2
    offset = along * a + height * up + rng.uniform(-0.3, 0.3) * height * side
    origin = rng.uniform(-50, 50, 3)
    return qc.Cells([origin, origin + offset], [a, b], lengths, 0.5, normalize_axes=True)


@pytest.mark.parametrize("case", ["short_beside_a_rod", "near_parallel_skew", "near_parallel_ends"])
def test_the_normal_at_the_closest_points_is_exact_to_1e_9_rad(case):
    """Until issue 19 the normal came from q_a − q_b with s = (fk − e)/(1 − k²): off by up to 6e-6
    rad for nearly parallel rods (1 − k² cancels) and 7e-5 for the issue's short capsules."""
    rng = np.random.default_rng(["short_beside_a_rod", "near_parallel_skew", "near_parallel_ends"].index(case))
    worst = 0.0
    for _ in range(150):
        cells = hard_pair(rng, case)
        contact = evaluate_contacts(cells, np.array([0]), np.array([1]), np.array([0]))
        s, t, gap = exact_closest(cells)
        worst = max(worst, angle_to(contact.normal[0], gap))
        # the separation and the points are the exact ones too (to rounding of the coordinates)
        assert contact.separation[0] + 1.0 == pytest.approx(float(_dot(gap, gap)) ** 0.5, rel=0, abs=1e-13)
    assert worst <= 1e-9


def test_the_exact_reference_agrees_with_a_dense_search():
    """The rational reference itself, against the minimum over a fine grid of both segments."""
    rng = np.random.default_rng(11)
    for _ in range(5):
        cells = hard_pair(rng, "near_parallel_ends")
        s = np.linspace(-cells.lengths[0] / 2, cells.lengths[0] / 2, 601)
        t = np.linspace(-cells.lengths[1] / 2, cells.lengths[1] / 2, 601)
        p = cells.centers[0] + s[:, None] * cells.axes[0]
        q = cells.centers[1] + t[:, None] * cells.axes[1]
        brute = np.sqrt(((p[:, None, :] - q[None, :, :]) ** 2).sum(axis=2)).min()
        exact = float(_dot(exact_closest(cells)[2], exact_closest(cells)[2])) ** 0.5
        assert exact <= brute + 1e-12 and brute - exact <= cells.lengths.max() / 600


# ------------------------------------------------------------------------------------------
# Item 1: one contact per skew pair
# ------------------------------------------------------------------------------------------
def crossing_pair(rng, *, lengths=None, radii=None, overlap=None, angle=None):
    """Two capsules whose axes pass each other inside both segments (closest points interior),
    crossing at ``angle`` (default: 15°–165°, a skew pair), their axes ``(ρ_a + ρ_b)(1 − overlap)``
    apart; random masses, growth inertias and approaching momenta."""
    lengths = rng.uniform(0.5, 4.0, 2) if lengths is None else np.asarray(lengths, dtype=float)
    radii = rng.uniform(0.2, 0.6, 2) if radii is None else np.asarray(radii, dtype=float)
    overlap = rng.uniform(0.01, 0.2) if overlap is None else overlap
    angle = np.radians(rng.uniform(15.0, 165.0)) if angle is None else angle
    a, side, up = frame(rng)
    b = np.cos(angle) * a + np.sin(angle) * side
    s, t = rng.uniform(-0.45, 0.45) * lengths[0], rng.uniform(-0.45, 0.45) * lengths[1]
    height = radii.sum() * (1.0 - overlap)
    c_a = rng.uniform(-5, 5, 3)
    c_b = c_a + s * a + height * up - t * b  # q_b = c_b + t b̂ lies `height` below q_a = c_a + s â
    masses = rng.uniform(0.5, 2.0, 2)
    momenta = rng.normal(size=(2, 3))
    cells = qc.Cells([c_a, c_b], [a, b], lengths, radii, masses=masses, growth_inertia=masses * rng.uniform(1, 100, 2),
                     momenta=momenta, angular_momenta=rng.normal(size=(2, 3)), growth_momenta=rng.normal(size=2))
    return cells


def textbook_impulse(cells):
    """The two-rigid-body contact impulse, from model.md and nothing of qpcontact: the contact
    at the closest points (exact), the generalized inverse mass ``W = diag(1/m, I⁻¹, 1/G)`` with
    the inertia of a solid cylinder, the rows ``J = [n, r × n, s(â·n)/l]``, ``u = J_a W p_a −
    J_b W p_b``, ``λ = −u / (J_a W_a J_aᵀ + J_b W_b J_bᵀ)``. Returns ``(λ, (2, 7) impulses)``."""
    s, t, gap = exact_closest(cells)
    gap = np.array([float(g) for g in gap])
    n = gap / np.linalg.norm(gap)
    q = [cells.centers[0] + float(s) * cells.axes[0], cells.centers[1] + float(t) * cells.axes[1]]
    points = [q[0] - cells.radii[0] * n, q[1] + cells.radii[1] * n]
    rows, weights, velocities = [], [], []
    for i, axial in ((0, float(s)), (1, float(t))):
        m, rho, length, axis = cells.masses[i], cells.radii[i], cells.lengths[i], cells.axes[i]
        lever = points[i] - cells.centers[i]
        rows.append(np.concatenate([n, np.cross(lever, n), [axial * (axis @ n) / length]]))
        along, across = m * rho**2 / 2, m * (3 * rho**2 + length**2) / 12
        inverse_inertia = np.outer(axis, axis) / along + (np.eye(3) - np.outer(axis, axis)) / across
        w = np.zeros((7, 7))
        w[:3, :3], w[3:6, 3:6], w[6, 6] = np.eye(3) / m, inverse_inertia, 1.0 / cells.growth_inertia[i]
        weights.append(w)
        p = np.concatenate([cells.momenta[i], cells.angular_momenta[i], [cells.growth_momenta[i]]])
        velocities.append(w @ p)
    u = rows[0] @ velocities[0] - rows[1] @ velocities[1]
    lam = -u / (rows[0] @ weights[0] @ rows[0] + rows[1] @ weights[1] @ rows[1])
    return lam, np.array([lam * rows[0], -lam * rows[1]]), u


def approaching(cells):
    """The cells, with their momenta reversed if they separate (u is linear in the momenta)."""
    if textbook_impulse(cells)[2] < 0:
        return cells
    return cells.replace(momenta=-cells.momenta, angular_momenta=-cells.angular_momenta,
                         growth_momenta=-cells.growth_momenta)


@cache
def crossing_pairs():
    """The issue's 40 random crossing pairs, plus short and fat rods with deep overlaps."""
    rng = np.random.default_rng(19)
    pairs = [crossing_pair(rng) for _ in range(40)]
    for angle in (np.pi / 2, np.radians(20.0), np.radians(45.0), np.radians(135.0)):
        pairs.append(crossing_pair(rng, lengths=[0.5, 0.5], radii=[0.6, 0.6], overlap=0.2, angle=angle))
        pairs.append(crossing_pair(rng, lengths=[0.5, 4.0], radii=[0.6, 0.2], overlap=0.2, angle=angle))
    return [approaching(cells) for cells in pairs]


@pytest.mark.parametrize("index", range(48))
def test_the_plain_solve_of_a_crossing_pair_is_the_textbook_two_body_impulse(index):
    """Until issue 19 a crossing pair had up to five contacts, and the plain solve, which stops
    every one of them, differed from this by up to 17× with impulses of opposite signs."""
    cells = crossing_pairs()[index]
    lam, impulses, u = textbook_impulse(cells)
    assert u < 0 and lam > 0
    result = qc.resolve(cells, solver="linear")
    assert len(result.contacts) == 1 and result.contacts.kind[0] == 0
    assert result.contact_impulses[0] == pytest.approx(lam, rel=1e-6)
    scale = np.abs(impulses).max()
    np.testing.assert_allclose(result.impulses, impulses, rtol=0, atol=1e-6 * scale)
    # the QP of the same pair (one active contact) is the same impulse
    qp = qc.resolve(cells, solver="clarabel", tolerance=1e-9)
    np.testing.assert_allclose(qp.impulses, impulses, rtol=0, atol=1e-6 * scale)


def mujoco_count(cells, margin):
    """How many contacts MuJoCo's capsule–capsule test (mjc_CapsuleCapsule) reports, from its
    documented behaviour: for axes that are not parallel (the determinant ``|â|²|b̂|² − (â·b̂)²``
    of the half-length-scaled axes at least 1e-15) one, at the closest points of the axes, if
    they are within the margin; parallel axes are handled apart (up to two). Only skew pairs are
    asked here."""
    scaled = cells.axes * (cells.lengths / 2)[:, None]
    det = (scaled[0] @ scaled[0]) * (scaled[1] @ scaled[1]) - (scaled[0] @ scaled[1]) ** 2
    assert det >= 1e-15, "not a skew pair"
    s, t, gap = exact_closest(cells)
    return int(float(_dot(gap, gap)) ** 0.5 - cells.radii.sum() <= margin)


def skew_pairs():
    rng = np.random.default_rng(7)
    pairs = [crossing_pair(rng) for _ in range(30)]
    for _ in range(30):  # general skew pairs near each other: closest points anywhere (ends too)
        a, side, up = frame(rng)
        angle = np.radians(rng.uniform(15.0, 165.0))
        lengths, radii = rng.uniform(0.5, 4.0, 2), rng.uniform(0.2, 0.6, 2)
        offset = rng.uniform(-0.5, 0.5) * lengths.sum() * a + rng.uniform(-1, 1, 3) * radii.sum()
        pairs.append(qc.Cells([[0, 0, 0], offset], [a, np.cos(angle) * a + np.sin(angle) * side], lengths, radii))
    # the issue's: crossing at right angles with the axes intersecting (5 contacts), coincident
    # centres at 45° (3)
    pairs.append(qc.Cells([[0, 0, 0], [0, 0, 0.0]], [[1, 0, 0], [0, 1, 0]], 2.0, 0.5))
    pairs.append(qc.Cells([[0, 0, 0], [0, 0, 0.0]], [[1, 0, 0], [1, 1, 0]], 2.0, 0.5, normalize_axes=True))
    pairs.append(qc.Cells([[0, 0, 0], [0.3, 0.2, 0.9]], [[1, 0, 0], [0, 1, 0]], 0.5, 0.6))
    return pairs


@pytest.mark.parametrize("margin", [0.0, 0.3])
def test_skew_pairs_get_as_many_contacts_as_mujoco_gives_them(margin):
    counted = 0
    for cells in skew_pairs():
        found = qc.find_contacts(cells, margin)
        expected = mujoco_count(cells, margin)
        assert len(found) == expected
        if expected:
            counted += 1
            assert found.kind[0] == 0
            s, t, gap = exact_closest(cells)
            assert found.separation[0] == pytest.approx(float(_dot(gap, gap)) ** 0.5 - cells.radii.sum(), abs=1e-12)
    assert counted >= 33


def test_step_gives_a_skew_pair_one_contact():
    """``step`` (with the margin and position correction of ``simulate --step velocity``) too."""
    from qpcontact.simulation import Settings

    rng = np.random.default_rng(3)
    for _ in range(10):
        cells = approaching(crossing_pair(rng, lengths=[0.5, 0.5], radii=[0.6, 0.6], overlap=0.2))
        options = {**Settings().step_options(), "planes": [], "planar": None}
        out = qc.step(cells, 0.01, **options)
        assert len(out.contacts) == 1 and out.contacts.kind[0] == 0


# ------------------------------------------------------------------------------------------
# Side by side: the two ends of the overlap
# ------------------------------------------------------------------------------------------
def side_by_side(angle, *, height=0.95, lengths=(4.0, 3.0), dimensions=3):
    """Rod b beside rod a, turned by ``angle`` about the normal of the plane of the axes, its
    centre ``height`` above a's axis (in the plane in 2D)."""
    up = np.array([0.0, 0.0, 1.0]) if dimensions == 3 else np.array([0.0, 1.0, 0.0])
    turn = np.array([0.0, 1.0, 0.0]) if dimensions == 3 else np.array([0.0, 0.0, 1.0])
    b = np.cos(angle) * np.array([1.0, 0.0, 0.0]) + np.sin(angle) * np.cross(turn, [1.0, 0.0, 0.0])
    return qc.Cells([[0.0, 0.0, 0.0], 0.3 * np.array([1.0, 0, 0]) + height * up], [[1.0, 0, 0], b], lengths, 0.5)


@pytest.mark.parametrize("dimensions", [2, 3])
@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-3, 0.02])
def test_rods_side_by_side_keep_both_ends_of_their_overlap(angle, dimensions):
    cells = side_by_side(angle, dimensions=dimensions)
    found = qc.find_contacts(cells, 0.3, planar=dimensions == 2)
    assert len(found) >= 2 and set(found.kind) & {1, 2, 3, 4}
    along = found.offset_a[:, 0]
    assert along.min() <= -1.0 + 0.3 + 1e-9 and along.max() >= 1.5 - 1e-9  # both ends of the overlap [-1.2, 2]
    a, b, kind = select_contacts(cells, np.array([[0, 1]]), 0.3)
    assert np.array_equal(kind, found.kind)


def test_beyond_the_side_by_side_angle_a_pair_is_one_contact():
    """Both ends within reach but the axes further from parallel than SIDE_BY_SIDE_SINE: a skew
    pair. (Short fat rods, so that both ends of the overlap stay within reach at that angle.)"""
    below, above = np.arcsin(0.9 * SIDE_BY_SIDE_SINE), np.arcsin(1.1 * SIDE_BY_SIDE_SINE)
    for angle, expected in ((below, 2), (above, 1)):
        cells = side_by_side(angle, height=0.9, lengths=(1.0, 1.0))
        ends = select_contacts(cells, np.array([[0, 1]]), 0.3, always_closest=True)[2]
        assert len({1, 2, 3, 4} & set(ends)) >= 2  # both ends of the overlap within reach, in both cases
        assert len(qc.find_contacts(cells, 0.3)) == expected


def test_the_position_step_keeps_its_linearization_points():
    """``always_closest=True`` (the position step) keeps its meaning: kind 0 for every pair
    within the margin, and every end within reach, deduplicated among the ends only."""
    cells = qc.Cells([[0, 0, 0], [0, 0, 0.0]], [[1, 0, 0], [0, 1, 0]], 2.0, 0.5)
    a, b, kind = select_contacts(cells, np.array([[0, 1]]), 0.0, always_closest=True)
    assert sorted(kind) == [0, 1, 2, 3, 4]
    assert list(select_contacts(cells, np.array([[0, 1]]), 0.0)[2]) == [0]
