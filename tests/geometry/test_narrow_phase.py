"""The narrow phase against an independent segment distance written here, and the contact set of
nearly parallel rods (issue 13, item 1): conservative (no contact reports a separation below the
pair's true one, the true minimum is always represented) and stable (rods side by side get the
two ends of their overlap), in 2D and 3D, with no angle threshold."""

import numpy as np
import pytest

import qpcontact as qc
from qpcontact.errors import InvalidArgumentError
from qpcontact.geometry import evaluate_contacts, narrow_phase, select_contacts
from qpcontact.geometry.contacts import ROUNDING
from qpcontact.timestep.step import step


# ------------------------------------------------------------------------------------------
# The reference: a textbook closest-point routine, nothing from qpcontact
# ------------------------------------------------------------------------------------------
def point_to_segment(p, c, axis, half):
    """Distance from point p to the segment c + t·axis, |t| <= half (clamped projection)."""
    t = min(max(float(np.dot(p - c, axis)), -half), half)
    return float(np.linalg.norm(p - (c + t * axis)))


def segment_distance(c_a, a_axis, half_a, c_b, b_axis, half_b):
    """min over s of the distance from c_a + s·â to b's segment: convex in s, so a ternary search
    (100 rounds of 2/3, then the best of the ends) finds it to rounding; also returns the minimizing s."""
    def g(s):
        return point_to_segment(c_a + s * a_axis, c_b, b_axis, half_b)

    lo, hi = -half_a, half_a
    for _ in range(100):
        m1, m2 = lo + (hi - lo) / 3, hi - (hi - lo) / 3
        if g(m1) <= g(m2):
            hi = m2
        else:
            lo = m1
    best = min((g(s), s) for s in (lo, hi, 0.5 * (lo + hi), -half_a, half_a))
    return best


def two_cells(c_b, b_axis, *, length_a=4.0, length_b=4.0, radius_a=0.5, radius_b=0.5, a_axis=(1.0, 0.0, 0.0),
              c_a=(0.0, 0.0, 0.0), **kw):
    return qc.Cells([c_a, c_b], [a_axis, b_axis], [length_a, length_b], [radius_a, radius_b], normalize_axes=True, **kw)


def true_separation(cells):
    d, _ = segment_distance(cells.centers[0], cells.axes[0], cells.lengths[0] / 2,
                            cells.centers[1], cells.axes[1], cells.lengths[1] / 2)
    return d - cells.radii[0] - cells.radii[1]


def axis_points(cells, contacts):
    """The axis points q_a, q_b behind each contact (contact point ± ρ n)."""
    q_a = cells.centers[contacts.cell_a] + contacts.offset_a + cells.radii[contacts.cell_a, None] * contacts.normal
    q_b = cells.centers[contacts.cell_b] + contacts.offset_b - cells.radii[contacts.cell_b, None] * contacts.normal
    return q_a, q_b


def random_frame(rng):
    """A random unit vector and a random unit vector perpendicular to it."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    perpendicular = np.cross(axis, rng.normal(size=3))
    return axis, perpendicular / np.linalg.norm(perpendicular)


def random_pair(rng, case):
    """Two capsules in one of the hard configurations."""
    length_a, length_b = rng.choice([0.0, 0.3, 2.0, 5.0, 40.0], 2)
    radius_a, radius_b = rng.uniform(0.05, 0.8, 2)
    a_axis, helper = random_frame(rng)
    angle = {"near_parallel": 10.0 ** rng.uniform(-12, -2), "skew": rng.uniform(0.01, 0.5),
             "random": rng.uniform(0, np.pi), "parallel": 0.0, "crossing": rng.uniform(0.05, np.pi / 2)}[case]
    b_axis = np.cos(angle) * a_axis + np.sin(angle) * helper
    along = rng.uniform(-0.6, 0.6) * (length_a + length_b)
    height = rng.uniform(0, 1.2) * (radius_a + radius_b)
    normal = np.cross(a_axis, helper)
    c_b = along * a_axis + height * normal
    if case == "crossing":
        c_b = rng.uniform(-0.5, 0.5) * length_a * a_axis  # the axes intersect
    cells = two_cells(c_b + 3.0, b_axis, c_a=np.full(3, 3.0), a_axis=a_axis, length_a=length_a, length_b=length_b,
                      radius_a=radius_a, radius_b=radius_b)
    return cells


CASES = ("near_parallel", "skew", "random", "parallel", "crossing")


@pytest.mark.parametrize("case", CASES)
def test_the_nearest_contact_is_the_true_segment_distance_and_none_is_nearer(case):
    rng = np.random.default_rng(CASES.index(case))
    checked = 0
    for _ in range(100):
        cells = random_pair(rng, case)
        expected = true_separation(cells)
        scale = cells.radii.sum() + cells.lengths.sum()
        contacts = narrow_phase(cells, np.array([[0, 1]]), margin=1e3)
        assert len(contacts) >= 1
        # (a) the minimum is represented (by kind 0, or by an end within rounding of it: ROUNDING
        # of the radii), (b) no contact is nearer than the true separation
        tie = ROUNDING * cells.radii.sum()
        assert contacts.separation.min() == pytest.approx(expected, rel=1e-9, abs=tie + 1e-12 * scale)
        assert np.all(contacts.separation >= expected - 1e-12 * scale)
        # every contact is a true distance between a point of a's axis and a point of b's
        q_a, q_b = axis_points(cells, contacts)
        np.testing.assert_allclose(np.linalg.norm(q_a - q_b, axis=1) - cells.radii.sum(), contacts.separation,
                                   rtol=0, atol=1e-12 * scale)
        for q, i in ((q_a, 0), (q_b, 1)):
            axial = (q - cells.centers[i]) @ cells.axes[i]
            assert np.all(np.abs(axial) <= cells.lengths[i] / 2 * (1 + 1e-12) + 1e-15)
            np.testing.assert_allclose(q, cells.centers[i] + axial[:, None] * cells.axes[i], atol=1e-12 * scale)
        checked += 1
    assert checked == 100


@pytest.mark.parametrize("case", CASES)
def test_within_the_margin_the_set_is_what_the_margin_admits(case):
    """find_contacts gives contacts exactly for the pairs whose true separation is within the
    margin (touching included), and only contacts within it."""
    rng = np.random.default_rng(100 + CASES.index(case))
    for _ in range(100):
        cells = random_pair(rng, case)
        margin = float(rng.choice([0.0, 0.1]))
        expected = true_separation(cells)
        found = qc.find_contacts(cells, margin)
        if expected <= margin - 1e-9:
            assert len(found) >= 1 and found.separation.min() == pytest.approx(expected, rel=1e-9, abs=1e-12)
        elif expected > margin + 1e-9:
            assert len(found) == 0
        assert np.all(found.separation <= margin)


def test_brute_force_samples_agree_with_the_reference():
    """The reference itself, against a dense grid over both segments (a few skew pairs)."""
    rng = np.random.default_rng(7)
    for _ in range(5):
        cells = random_pair(rng, "skew")
        ha, hb = cells.lengths / 2
        s = np.linspace(-ha, ha, 801)
        t = np.linspace(-hb, hb, 801)
        p = cells.centers[0] + s[:, None] * cells.axes[0]
        q = cells.centers[1] + t[:, None] * cells.axes[1]
        brute = np.sqrt(((p[:, None, :] - q[None, :, :]) ** 2).sum(axis=2)).min()
        reference, _ = segment_distance(cells.centers[0], cells.axes[0], ha, cells.centers[1], cells.axes[1], hb)
        spacing = max(ha, hb) * 2 / 800
        assert reference <= brute + 1e-12 and brute - reference <= spacing


# ------------------------------------------------------------------------------------------
# The reproductions
# ------------------------------------------------------------------------------------------
TILT = (np.cos(9e-4), np.sin(9e-4), 0.0)


def test_long_thin_rods_crossing_at_a_tiny_angle_are_in_contact():
    # true overlap 0.01; the ends of the overlap interval reported +0.026 and no contact
    cells = two_cells((0.0, 0.0, 0.01), TILT, length_a=100.0, length_b=100.0, radius_a=0.01, radius_b=0.01)
    assert true_separation(cells) == pytest.approx(-0.01, abs=1e-12)
    contacts = qc.find_contacts(cells)
    assert len(contacts) >= 1
    assert contacts.separation.min() == pytest.approx(-0.01, abs=1e-12)


def test_filament_depth_and_normal_are_the_true_ones():
    # depth −0.446 instead of −0.45 with normals tilted 0.38 rad
    cells = two_cells((3.0, 0.0, 0.05), TILT, length_a=50.0, length_b=50.0, radius_a=0.25, radius_b=0.25)
    expected = true_separation(cells)
    assert expected == pytest.approx(-0.45, abs=1e-12)
    contacts = qc.find_contacts(cells)
    nearest = int(np.argmin(contacts.separation))
    assert contacts.separation[nearest] == pytest.approx(expected, abs=1e-12)
    np.testing.assert_allclose(contacts.normal[nearest], [0, 0, -1], atol=1e-9)  # from b (above) to a
    assert np.all(contacts.separation >= expected - 1e-12)


@pytest.mark.parametrize("height, overlap", [(0.99, 0.01), (0.9, 0.1)])
def test_cells_crossing_at_ten_degrees_in_a_step(height, overlap):
    """Two ordinary cells, one above the other, crossing at 10°: step reported +0.047 (no
    overlap) and normals 20° off; the step must see the overlap and push along z."""
    angle = np.radians(10.0)
    cells = two_cells((0.0, 0.0, height), (np.cos(angle), np.sin(angle), 0.0), masses=1.0,
                      momenta=[[0, 0, 0.5], [0, 0, -0.5]])
    out = step(cells, 0.01, dynamics="inertial", margin=0.3, solver="clarabel")
    crossing = out.contacts.kind == 0
    assert np.count_nonzero(crossing) == 1
    assert out.contacts.separation[crossing][0] == pytest.approx(-overlap, abs=1e-12)
    assert out.contacts.separation.min() == pytest.approx(-overlap, abs=1e-12)
    np.testing.assert_allclose(out.contacts.normal[crossing][0], [0, 0, -1], atol=1e-12)
    assert out.max_overlap == pytest.approx(overlap / 1.0)
    # the crossing stopped the approach: the cells separate (or rest) along z after the step
    assert out.cells.velocities[0, 2] <= out.cells.velocities[1, 2] + 1e-9


def test_a_skew_pair_in_3d_gets_the_crossing_point():
    angle = np.radians(25.0)
    cells = two_cells((0.3, -0.2, 0.95), (np.cos(angle), np.sin(angle), 0.0))
    contacts = qc.find_contacts(cells, margin=0.3)
    s, t = contacts.offset_a @ cells.axes[0], contacts.offset_b @ cells.axes[1]
    q_a = cells.centers[0] + s[:, None] * cells.axes[0]
    q_b = cells.centers[1] + t[:, None] * cells.axes[1]
    _, s_true = segment_distance(cells.centers[0], cells.axes[0], 2.0, cells.centers[1], cells.axes[1], 2.0)
    closest = contacts.kind == 0
    assert np.count_nonzero(closest) == 1
    assert s[closest][0] == pytest.approx(s_true, abs=1e-6)  # a flat minimum: s only to sqrt(rounding)
    np.testing.assert_allclose(q_a[closest][0][:2], q_b[closest][0][:2], atol=1e-12)  # one above the other
    assert contacts.separation[closest][0] == pytest.approx(-0.05, abs=1e-12)


# ------------------------------------------------------------------------------------------
# Side by side: two contacts, at the ends of the overlap
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", range(6))
def test_parallel_rods_side_by_side_get_exactly_the_two_ends_of_their_overlap(seed):
    rng = np.random.default_rng(seed)
    axis, side = random_frame(rng)
    length_a, length_b = rng.uniform(1.0, 6.0, 2)
    shift = rng.uniform(-0.4, 0.4) * (length_a + length_b)
    origin = rng.uniform(-100, 100, 3)
    cells = qc.Cells([origin, origin + shift * axis + 0.95 * side], [axis, axis], [length_a, length_b], 0.5)
    lo, hi = max(-length_a / 2, shift - length_b / 2), min(length_a / 2, shift + length_b / 2)
    assert hi - lo > 0.5  # they overlap
    contacts = qc.find_contacts(cells)
    assert len(contacts) == 2
    s = contacts.offset_a @ axis
    np.testing.assert_allclose(s, [lo, hi], atol=1e-9)  # ordered along a
    np.testing.assert_allclose(contacts.separation, -0.05, atol=1e-9)
    np.testing.assert_allclose(contacts.normal, np.tile(-side, (2, 1)), atol=1e-9)
    assert set(contacts.kind) <= {1, 2, 3, 4}


@pytest.mark.parametrize("degrees", [0.5, 2.0, 8.0])
def test_nearly_parallel_neighbours_within_the_margin_get_both_ends(degrees):
    """No angle threshold: side-by-side rods at a small angle, one end touching and the other
    within the margin, get both (so they cannot turn through each other about one point)."""
    angle = np.radians(degrees)
    cells = two_cells((0.0, 0.97, 0.0), (np.cos(angle), np.sin(angle), 0.0))
    contacts = qc.find_contacts(cells, margin=0.3, planar=True)
    assert len(contacts) >= 2  # at 8° both rods' + ends are within the margin, 0.15 apart along b
    assert np.all(contacts.normal[:, 2] == 0)
    assert contacts.separation.min() == pytest.approx(true_separation(cells), abs=1e-12)
    assert np.ptp(contacts.offset_a[:, 0]) > 3.0  # one near each end


# ------------------------------------------------------------------------------------------
# The two halves: select once, evaluate anywhere
# ------------------------------------------------------------------------------------------
def test_select_then_evaluate_is_the_narrow_phase_and_evaluates_moved_cells():
    cells = qc.Cells(np.random.default_rng(3).uniform(0, 5, (40, 3)), np.random.default_rng(4).normal(size=(40, 3)),
                     2.5, 0.5, normalize_axes=True)
    pairs = qc.geometry.candidate_pairs(cells, 0.2)
    a, b, kind = select_contacts(cells, pairs, 0.2)
    assert a.dtype.kind == b.dtype.kind == kind.dtype.kind == "i"
    found = narrow_phase(cells, pairs, 0.2)
    assert np.array_equal(found.kind, kind) and np.array_equal(found.cell_a, a)
    assert np.array_equal(found.normal, evaluate_contacts(cells, a, b, kind).normal)
    # ordered by pair, then along a
    key = a.astype(np.int64) * cells.n + b
    assert np.all(np.diff(key) >= 0)
    s = np.einsum("ij,ij->i", found.offset_a + cells.radii[a, None] * found.normal, cells.axes[a])
    same = key[1:] == key[:-1]
    assert np.all(s[1:][same] >= s[:-1][same])
    # At moved positions the same triples, in the same order, with the end kinds still at the ends.
    moved = cells.replace(centers=cells.centers + 0.3)
    again = evaluate_contacts(moved, a[::-1], b[::-1], kind[::-1])
    assert np.array_equal(again.kind, kind[::-1]) and np.array_equal(again.cell_a, a[::-1])
    np.testing.assert_allclose(again.separation, found.separation[::-1], atol=1e-12)  # a rigid shift


def test_an_end_contact_is_evaluated_clamped_when_its_end_has_left_the_neighbour():
    cells = two_cells((0.0, 0.95, 0.0), (1.0, 0.0, 0.0))
    a, b, kind = select_contacts(cells, np.array([[0, 1]]), 0.0)
    assert len(kind) == 2
    slid = cells.replace(centers=[[0, 0, 0], [6.0, 0.95, 0]])  # b slid along, beyond a's +end
    later = evaluate_contacts(slid, a, b, kind)
    q_a, q_b = axis_points(slid, later)
    assert np.all(np.abs(q_a[:, 0]) <= 2.0 + 1e-12) and np.all(np.abs(q_b[:, 0] - 6.0) <= 2.0 + 1e-12)
    assert np.all(later.separation >= true_separation(slid) - 1e-12)


def test_evaluate_contacts_rejects_bad_triples():
    cells = two_cells((0.0, 0.95, 0.0), (1.0, 0.0, 0.0))
    for bad in (dict(a=[0], b=[0], kind=[0]), dict(a=[0], b=[1], kind=[5]), dict(a=[0], b=[2], kind=[0]),
                dict(a=[0, 0], b=[1], kind=[0]), dict(a=[0.0], b=[1.0], kind=[0])):
        with pytest.raises(InvalidArgumentError):
            evaluate_contacts(cells, *(np.array(bad[k]) for k in ("a", "b", "kind")))


# ------------------------------------------------------------------------------------------
# Touching (issue 13, item 5): separation exactly zero counts, with margin 0 too
# ------------------------------------------------------------------------------------------
def test_touching_capsules_and_planes_count_as_contacts():
    spheres = qc.Cells([[0, 0, 0], [1.0, 0, 0]], [1, 0, 0], 0.0, 0.5)
    touching = qc.find_contacts(spheres)
    assert len(touching) == 1 and touching.separation[0] == 0.0
    apart = qc.find_contacts(spheres.replace(centers=[[0, 0, 0], [1.0 + 1e-12, 0, 0]]))
    assert len(apart) == 0
    resting = qc.Cells([[0, 0, 0.5]], [1, 0, 0], 2.0, 0.5)
    assert len(qc.plane_contacts(resting, [qc.substrate()])) == 2
    # a touching pair that approaches is stopped (it would penetrate within any step)
    moving = spheres.replace(momenta=[[1.0, 0, 0], [0, 0, 0]])
    result = qc.resolve(moving, solver="clarabel")
    assert len(result.contacts) == 1
    assert result.cells.velocities[0, 0] == pytest.approx(result.cells.velocities[1, 0], abs=1e-6)
