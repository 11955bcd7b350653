"""Contact detection: broad phase against brute force, and each degenerate geometry of model.md."""

import itertools

import numpy as np
import pytest

import qpcontact as qc
from qpcontact.errors import InvalidArgumentError
from qpcontact.geometry.contacts import candidate_pairs, colliding, narrow_phase
from qpcontact.studies import scenes
from tests.helpers import random_scene


def rods(centres, axes, lengths, radii=0.5, **kw):
    return qc.Cells(np.asarray(centres, float), np.asarray(axes, float), lengths, radii, normalize_axes=True, **kw)


def keyed(contacts):
    return {(int(a), int(b), round(float(d), 9)) for a, b, d in zip(contacts.cell_a, contacts.cell_b, contacts.separation, strict=True)}


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("margin", [0.0, 0.3])
def test_broad_phase_finds_every_touching_pair(seed, margin):
    cells = random_scene(seed, n_cells=60, box=6.0)
    # Mixed lengths: a few long rods must still be found against everything they touch.
    cells = cells.replace(lengths=np.where(np.arange(60) % 17 == 0, 8.0, cells.lengths))
    all_pairs = np.array(list(itertools.combinations(range(cells.n), 2)))
    brute = narrow_phase(cells, all_pairs, margin)
    fast = qc.find_contacts(cells, margin)
    assert len(brute) > 30
    assert keyed(fast) == keyed(brute)


@pytest.mark.parametrize("seed", range(4))
def test_broad_phase_with_slack_holds_every_pair_within_reach_after_the_cells_move(seed):
    """candidate_pairs(cells, margin, slack) is a superset of the pairs within margin wherever
    each cell's axis moves by at most its slack (turned, grown, shifted); a few cells move far
    (searched on their own)."""
    rng = np.random.default_rng(seed)
    cells = random_scene(seed, n_cells=80, box=7.0)
    far = rng.random(cells.n) < 0.05
    shift = rng.normal(size=(cells.n, 3)) * np.where(far, 2.0, 0.2)[:, None]
    axes = cells.axes + 0.2 * rng.normal(size=(cells.n, 3))
    moved = cells.replace(centers=cells.centers + shift, axes=axes / np.linalg.norm(axes, axis=1)[:, None],
                          lengths=cells.lengths * 1.1)
    half0, half1 = 0.5 * cells.lengths[:, None], 0.5 * moved.lengths[:, None]
    slack = np.maximum(np.linalg.norm(shift + half1 * moved.axes - half0 * cells.axes, axis=1),
                       np.linalg.norm(shift - half1 * moved.axes + half0 * cells.axes, axis=1))
    margin = 0.3
    all_pairs = np.array(list(itertools.combinations(range(cells.n), 2)))
    within = narrow_phase(moved, all_pairs, margin)
    found = {tuple(p) for p in candidate_pairs(cells, margin, slack).tolist()}
    needed = {(int(a), int(b)) for a, b in zip(within.cell_a, within.cell_b, strict=True)}
    assert len(needed) > 20 and needed <= found
    assert len(found) < len(all_pairs)  # still a search, not every pair


def test_contact_geometry_of_two_crossed_rods():
    # a above b, axes x and z: closest points on the y axis, overlap 0.1.
    cells = rods([[0, 0.9, 0], [0, 0, 0]], [[1, 0, 0], [0, 0, 1]], [2.0, 2.0])
    c = qc.find_contacts(cells)
    assert len(c) == 1
    assert np.allclose(c.normal[0], [0, 1, 0])
    assert c.separation[0] == pytest.approx(-0.1)
    assert np.allclose(c.offset_a[0], [0, -0.5, 0]) and np.allclose(c.offset_b[0], [0, 0.5, 0])


def test_parallel_rods_lying_along_each_other_get_two_contacts_at_the_overlap_ends():
    cells = rods([[0, 0.9, 0], [1.0, 0, 0]], [[1, 0, 0], [1, 0, 0]], [4.0, 4.0])
    c = qc.find_contacts(cells)
    assert len(c) == 2
    axial = np.sort(c.offset_a[:, 0])
    assert np.allclose(axial, [-1.0, 2.0])  # a spans [-2, 2], b spans [-1, 3]: overlap [-1, 2]
    assert np.allclose(c.normal, [0, 1, 0]) and np.allclose(c.separation, -0.1)


@pytest.mark.parametrize("angle", [0.0, 1e-12, 1e-8, 1e-5])
def test_nearly_parallel_rods_behave_like_parallel_ones(angle):
    axis_b = [np.cos(angle), np.sin(angle), 0.0]
    cells = rods([[0, 0.9, 0], [0, 0, 0]], [[1, 0, 0], axis_b], [4.0, 4.0])
    c = qc.find_contacts(cells)
    assert len(c) == 2
    assert np.allclose(np.sort(c.offset_a[:, 0]), [-2.0, 2.0], atol=1e-4)
    assert np.allclose(c.normal[:, :2], [[0, 1], [0, 1]], atol=1e-4)


def test_parallel_rods_end_to_end_get_one_contact_along_the_axis():
    cells = rods([[0, 0, 0], [2.9, 0, 0]], [[1, 0, 0], [1, 0, 0]], [2.0, 2.0])
    c = qc.find_contacts(cells)
    assert len(c) == 1
    assert np.allclose(c.normal[0], [-1, 0, 0])  # from b to a
    assert c.separation[0] == pytest.approx(-0.1)
    assert c.stretch_a[0] == pytest.approx(0.5) and c.stretch_b[0] == pytest.approx(-0.5)


def test_crossing_axes_fall_back_to_the_cross_product():
    cells = rods([[0, 0, 0], [0, 0, 0]], [[1, 0, 0], [0, 1, 0]], [2.0, 2.0])
    c = qc.find_contacts(cells)
    crossing = c.kind == 0
    assert np.count_nonzero(crossing) == 1
    assert np.allclose(np.abs(c.normal[crossing][0]), [0, 0, 1])
    assert c.separation[crossing][0] == pytest.approx(-1.0)
    assert np.all(np.isfinite(c.offset_a))
    # The four ends lie exactly one diameter from the other axis (touching), but the rods cross at
    # right angles: one contact, at the closest points (issue 19; until then five).
    assert len(c) == 1


def test_crossing_axes_in_a_planar_scene_keep_the_normal_in_the_plane():
    cells = rods([[0.1, 0.2, 0], [0, 0, 0]], [[1, 0, 0], [0, 1, 0]], [2.0, 2.0])
    c = qc.find_contacts(cells, planar=True)
    assert len(c) >= 1 and np.all(c.normal[:, 2] == 0)
    assert np.array_equal(qc.find_contacts(cells, planar=None).normal, c.normal)  # detected: a monolayer
    assert np.abs(qc.find_contacts(cells).normal[:, 2]).max() == 1.0  # not planar (default): â × b̂


@pytest.mark.parametrize("height", [0.0, 7.5])
def test_crossing_axes_in_a_monolayer_collide_without_planar_true(height):
    """Issue 13, item 2: resolve(planar=None) detected the planar reduction only after detection
    had given the crossing the out-of-plane normal â × b̂, along which nothing approaches: no
    contact at all. Detection now makes the same decision as the system."""
    cells = rods([[0.1, 0.2, height], [0, 0, height]], [[1, 0, 0], [0, 1, 0]], [2.0, 2.0],
                 momenta=[[-1.0, -1.0, 0], [0, 0, 0]])
    assert cells.is_monolayer() and not cells.replace(centers=[[0.1, 0.2, height], [0, 0, height + 1e-6]]).is_monolayer()
    assert not cells.replace(axes=[[1, 0, 1e-6], [0, 1, 0]], normalize_axes=True).is_monolayer()
    detected = qc.resolve(cells, planar=None, solver="clarabel")
    forced = qc.resolve(cells, planar=True, solver="clarabel")
    assert len(detected.contacts) == len(forced.contacts) == 1 and detected.planar
    np.testing.assert_array_equal(detected.contacts.normal, forced.contacts.normal)
    np.testing.assert_allclose(detected.impulses, forced.impulses, atol=1e-9)
    stepped = qc.step(cells, 0.01, dynamics="inertial", solver="clarabel")
    crossing = stepped.result.contacts.kind == 0
    assert np.count_nonzero(crossing) == 1 and stepped.result.planar
    np.testing.assert_array_equal(stepped.result.contacts.normal[crossing], forced.contacts.normal)
    # Moving out of the plane is not a monolayer: the crossing keeps â × b̂.
    lifting = cells.replace(momenta=[[0, 0, -1.0], [0, 0, 1.0]])
    assert not lifting.is_monolayer()
    np.testing.assert_allclose(np.abs(qc.resolve(lifting, solver="clarabel").contacts.normal[0]), [0, 0, 1])


def test_coincident_rods_get_a_normal_perpendicular_to_the_axis():
    cells = rods([[1, 1, 1], [1, 1, 1]], [[0, 0, 1], [0, 0, 1]], [2.0, 2.0])
    c = qc.find_contacts(cells)
    assert len(c) == 2  # parallel: both ends of the overlap
    assert np.allclose(c.normal @ [0, 0, 1], 0.0)
    assert np.allclose(np.linalg.norm(c.normal, axis=1), 1.0)
    again = qc.find_contacts(cells)
    assert np.array_equal(again.normal, c.normal)  # deterministic


def test_coincident_spheres_and_sphere_rod_contacts():
    spheres = rods([[0, 0, 0], [0, 0, 0], [0.8, 0, 0]], [[1, 0, 0]] * 3, [0.0, 0.0, 0.0])
    c = qc.find_contacts(spheres)
    assert len(c) == 3 and np.all(np.isfinite(c.normal))
    pair = (c.cell_a == 0) & (c.cell_b == 2)
    assert np.allclose(c.normal[pair], [-1, 0, 0]) and c.separation[pair] == pytest.approx(-0.2)
    mixed = rods([[0, 0.9, 0], [0, 0, 0]], [[1, 0, 0], [1, 0, 0]], [0.0, 3.0])
    m = qc.find_contacts(mixed)
    assert len(m) == 1 and np.allclose(m.normal[0], [0, 1, 0])


def test_sphere_growth_lever_points_towards_the_contact():
    # A growing sphere of zero length touched at its +axis side rides with the +tip (½ l̇).
    cells = rods([[0, 0, 0], [0.9, 0, 0]], [[1, 0, 0], [1, 0, 0]], [0.0, 0.0])
    c = qc.find_contacts(cells)
    assert c.stretch_a[0] == pytest.approx(0.5) and c.stretch_b[0] == pytest.approx(-0.5)


def test_margin_admits_near_contacts_and_pairs_of_fixed_cells_are_skipped():
    cells = rods([[0, 1.05, 0], [0, 0, 0]], [[1, 0, 0], [0, 0, 1]], [2.0, 2.0])
    assert len(qc.find_contacts(cells)) == 0
    assert len(qc.find_contacts(cells, margin=0.1)) == 1
    fixed = cells.replace(centers=[[0, 0.9, 0], [0, 0, 0]], masses=np.inf)
    assert len(candidate_pairs(fixed)) == 0
    with pytest.raises(InvalidArgumentError, match="margin"):
        qc.find_contacts(cells, margin=-1.0)


def test_colliding_keeps_approaching_pairs_and_position_correction():
    cells = rods([[0, 0.9, 0], [0, 0, 0], [5, 0.9, 0], [5, 0, 0]], [[1, 0, 0], [0, 0, 1]] * 2, 2.0,
                 momenta=[[0, -1, 0], [0, 0, 0], [0, 0.01, 0], [0, 0, 0]])
    contacts = qc.find_contacts(cells)
    assert len(contacts) == 2
    active, b = colliding(contacts)
    assert len(active) == 1 and active.cell_a[0] == 0 and b[0] == pytest.approx(1.0)
    # The separating pair (0.01 per unit time) does not clear an overlap of 0.1 in dt = 1 with β = 1.
    active, b = colliding(contacts, position_correction=1.0, dt=1.0)
    assert len(active) == 2 and np.allclose(np.sort(b), [0.09, 1.1])
    with pytest.raises(InvalidArgumentError, match="dt"):
        colliding(contacts, position_correction=0.5)


# ------------------------------------------------------------------------------------------
# The vectorized broad and narrow phases give the same answers as the plain definitions
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", range(4))
def test_broad_phase_keeps_the_sorted_unique_pairs(seed):
    """Rods of many pieces (lengths up to 6× the median) produce repeated piece pairs; the result
    is the sorted unique list, the same as np.unique(axis=0) over all touching pairs."""
    rng = np.random.default_rng(seed)
    n = 60
    cells = qc.Cells(rng.uniform(0, 6, (n, 3)), rng.normal(size=(n, 3)), rng.choice([0.0, 1.0, 6.0], n), 0.4,
                     normalize_axes=True)
    pairs = candidate_pairs(cells)
    assert np.array_equal(pairs, np.unique(pairs, axis=0))
    everything = np.array([(i, j) for i in range(n) for j in range(i + 1, n)])
    touching = narrow_phase(cells, everything)
    found = narrow_phase(cells, pairs)
    assert np.array_equal(found.cell_a, touching.cell_a) and np.array_equal(found.cell_b, touching.cell_b)
    assert np.allclose(found.normal, touching.normal, rtol=0, atol=1e-12)


def test_broad_phase_of_cells_whose_only_close_pieces_are_their_own():
    """One long rod alone: its pieces are within reach of each other but no pair remains."""
    cells = qc.Cells([[0.0, 0.0, 0.0], [50.0, 0.0, 0.0], [0.0, 50.0, 0.0]], [1.0, 0.0, 0.0], [9.0, 1.0, 1.0], 0.5)
    assert candidate_pairs(cells).shape == (0, 2)


def test_narrow_phase_order_does_not_depend_on_the_pair_order():
    cells = scenes.colony_2d(300, seed=1)
    pairs = candidate_pairs(cells)
    shuffled = pairs[np.random.default_rng(0).permutation(len(pairs))]
    a, b = narrow_phase(cells, pairs, planar=True), narrow_phase(cells, shuffled, planar=True)
    for name in ("cell_a", "cell_b", "normal", "offset_a", "separation", "normal_velocity"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    # by pair, then along a (two contacts of parallel neighbours in increasing s)
    key = a.cell_a.astype(np.int64) * cells.n + a.cell_b
    assert np.all(np.diff(key) >= 0)


# ------------------------------------------------------------------------------------------
# Coincident cells (issue 13, item 7): a named error before anything large is allocated
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [300, 100_000])
def test_coincident_cells_are_refused_before_their_pairs_are_allocated(n):
    """N cells at one point have N²/2 pairs: 300 made Clarabel allocate 7.2 GB and abort, 10⁵ a
    raw MemoryError in the broad phase."""
    cells = qc.Cells(np.zeros((n, 3)), [1.0, 0.0, 0.0], 2.0, 0.5, momenta=[1.0, 0.0, 0.0])
    with pytest.raises(qc.TooManyContactsError, match=f"{n:,} cells.*MAX_PAIRS_PER_CELL = 64") as error:
        qc.resolve(cells)
    assert isinstance(error.value, qc.InvalidCellsError)
    with pytest.raises(qc.TooManyContactsError):
        qc.step(cells, 0.01)


def test_the_pair_limit_can_be_raised_and_dense_colonies_stay_below_it(monkeypatch):
    from qpcontact.geometry import contacts

    cells = qc.Cells(np.zeros((150, 3)), [1.0, 0.0, 0.0], 2.0, 0.5)
    with pytest.raises(qc.TooManyContactsError):
        candidate_pairs(cells)
    monkeypatch.setattr(contacts, "MAX_PAIRS_PER_CELL", 100)
    assert len(candidate_pairs(cells)) == 150 * 149 // 2
    monkeypatch.undo()
    dense = scenes.colony_3d(3000, seed=1)
    assert len(candidate_pairs(dense, margin=0.3)) < 20 * dense.n


@pytest.mark.parametrize("v_a, v_b, approaching", [
    ([2.0, 0.0, 0.0], [1.0, 0.0, 0.0], True),    # both move +x, a catches up: v_a·v_b > 0
    ([-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], False),  # they move apart: v_a·v_b < 0
])
def test_approaching_is_the_relative_normal_velocity_not_the_sign_of_a_dot_product(v_a, v_b, approaching):
    """Correction 4 of docs/model.md: a pair approaches when ``u = nᵀ(v_a − v_b) < 0``. The
    original derivation's test, a negative dot product of the two contact points' velocities,
    is wrong both ways: it misses a cell catching up with another and takes two cells moving
    apart for a collision."""
    cells = rods([[0, 0, 0], [0.9, 0, 0]], [[1, 0, 0]] * 2, 0.0, momenta=[v_a, v_b])
    contacts = qc.find_contacts(cells)
    assert len(contacts) == 1 and contacts.separation[0] < 0
    c = contacts
    point_a = cells.point_velocities(c.cell_a, c.offset_a, c.stretch_a)[0]
    point_b = cells.point_velocities(c.cell_b, c.offset_b, c.stretch_b)[0]
    assert (point_a @ point_b < 0) != approaching  # the original test gets it wrong
    assert (c.normal_velocity[0] < 0) == approaching
    active, _ = colliding(contacts)
    assert (len(active) == 1) == approaching
    result = qc.resolve(cells, solver="linear")
    if approaching:  # equal masses: both leave at the mean velocity
        assert np.allclose(result.cells.velocities[:, 0], 1.5)
    else:
        assert result.status == "no_contact"
