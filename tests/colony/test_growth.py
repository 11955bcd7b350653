"""Growth, division and lineage."""

import numpy as np
import pytest

import qpcontact as q
from qpcontact.colony.growth import Colony, divide, grow, volumes
from qpcontact.errors import InvalidArgumentError


def one_cell(length=2.0, **extra):
    return q.Cells(centers=[[1.0, 2.0, 0.0]], axes=[[0.6, 0.8, 0.0]], lengths=length, radii=0.5, masses=3.0,
                   growth_inertia=30.0, **extra)



@pytest.mark.parametrize("dynamics", ["overdamped", "inertial"])
def test_single_cell_grows_exponentially_at_its_rate(dynamics):
    rate, dt = 0.3, 0.05
    colony = Colony.founder(one_cell(), rates=rate)
    for _ in range(200):
        colony, out = grow(colony, dt, dynamics=dynamics)
        assert len(out.contacts) == 0
    assert colony.time == pytest.approx(10.0)
    assert colony.cells.lengths[0] == pytest.approx(2.0 * np.exp(rate * 10.0), rel=1e-12)
    np.testing.assert_allclose(colony.cells.centers[0], [1.0, 2.0, 0.0], atol=1e-12)  # grows about its centre
    # Constant density: the mass follows the volume.
    assert colony.cells.masses[0] / volumes(colony.cells)[0] == pytest.approx(3.0 / volumes(one_cell())[0])



def test_division_conserves_volume_mass_and_momentum_and_records_lineage():
    mother = one_cell(length=4.2, momenta=[[0.3, -0.2, 0.1]], angular_momenta=[[0.0, 0.1, 0.4]], growth_momenta=[1.5])
    colony = Colony.founder(q.Cells(
        centers=[[1.0, 2.0, 0.0], [-5.0, 0.0, 0.0]], axes=[[0.6, 0.8, 0.0], [1, 0, 0]], lengths=[4.2, 1.0],
        radii=0.5, masses=3.0, growth_inertia=30.0,
        momenta=[[0.3, -0.2, 0.1], [0, 0, 0]], angular_momenta=[[0.0, 0.1, 0.4], [0, 0, 0]], growth_momenta=[1.5, 0]),
        rates=0.5)
    before = colony.cells
    after = divide(colony, 4.0, np.random.default_rng(0), axis_noise=0.05)
    cells = after.cells
    assert cells.n == 3
    daughters = [0, 2]
    area = np.pi * 0.25
    assert (volumes(cells)[daughters] + area * after.owed[daughters]).sum() == pytest.approx(volumes(mother)[0], rel=1e-14)
    assert cells.masses[daughters].sum() == pytest.approx(3.0)
    np.testing.assert_allclose(cells.momenta[daughters].sum(axis=0), before.momenta[0], atol=1e-15)
    np.testing.assert_allclose(cells.growth_momenta[daughters].sum(), 1.5)

    def angular_about_origin(c, idx):
        return (np.cross(c.centers[idx], c.momenta[idx]) + c.angular_momenta[idx]).sum(axis=0)

    np.testing.assert_allclose(angular_about_origin(cells, daughters), angular_about_origin(before, [0]), atol=1e-14)
    # The daughters fill the mother's outline, touch at her centre, and barely overlap (axis noise only).
    assert np.mean(cells.centers[daughters], axis=0) == pytest.approx(before.centers[0])
    pair = q.find_contacts(cells.subset(daughters), 0.1)
    assert len(pair) >= 1 and pair.separation.min() > -0.05
    # Lineage: new ids for both daughters, mother's id as parent; the other cell is untouched.
    assert list(after.ids) == [2, 1, 3] and list(after.parent_ids) == [0, -1, 0]
    assert after.next_id == 4
    np.testing.assert_array_equal(cells.centers[1], before.centers[1])
    # Daughters grow what they are owed through the contact solve, then grow at their rate.
    grown = after
    for _ in range(40):
        grown, _ = grow(grown, 0.05)
    assert np.all(grown.owed == 0)
    with pytest.raises(InvalidArgumentError, match="division_length: must exceed 2 × radius"):
        divide(colony, 0.9, np.random.default_rng(0))


@pytest.mark.parametrize("length", [0.4, 1.0, [5.0, 0.8]])
def test_divide_refuses_the_division_lengths_simulate_refuses(length):
    """issue 28: divide accepted a division length of at most 2ρ as long as the dividing cells
    were long enough (a cell of 2.5 at a threshold of 0.4: daughters of 0.75, then daughters of
    those at 0.4 − ...), where qpcontact simulate refuses it. One check for both, same words."""
    from qpcontact.colony.growth import check_division_length
    from qpcontact.simulation import ModelSettings

    colony = Colony.founder(q.Cells([[0, 0, 0], [0, 3, 0]], [1, 0, 0], [2.5, 2.5], 0.5), rates=1.0)
    with pytest.raises(InvalidArgumentError, match=r"division_length: must exceed 2 × radius = 1 µm \(daughters are born"):
        divide(colony, np.asarray(length) if isinstance(length, list) else length, np.random.default_rng(0))
    if np.ndim(length) == 0:
        with pytest.raises(InvalidArgumentError, match=r"division_length: must exceed 2 × radius = 1 µm \(daughters"):
            ModelSettings(division_length=length)
    check_division_length(1.01, 0.5)  # just above 2ρ: born at 0.005
    assert divide(colony, 1.01, np.random.default_rng(0)).cells.n == 4



def test_planar_division_keeps_axes_in_the_plane():
    colony = Colony.founder(one_cell(length=5.0), rates=1.0)
    after = divide(colony, 4.0, np.random.default_rng(1), axis_noise=0.3, planar=True)
    assert np.all(after.cells.axes[:, 2] == 0) and np.all(after.cells.centers[:, 2] == 0)



def test_colony_rejects_bad_lineage():
    cells = q.Cells(centers=[[0, 0, 0], [3, 0, 0]], axes=[1, 0, 0], lengths=1.0, radii=0.5)
    with pytest.raises(InvalidArgumentError, match="unique"):
        Colony(cells, [1, 1], [-1, -1], [1.0, 1.0])
    with pytest.raises(InvalidArgumentError, match="rates"):
        Colony(cells, [0, 1], [-1, -1], [1.0, -1.0])
    with pytest.raises(InvalidArgumentError, match="shape"):
        Colony(cells, [0, 1, 2], [-1, -1], [1.0, 1.0])


# ------------------------------------------------------------------------------------------
# Issue 27: cell types and a model's own per-cell arrays
# ------------------------------------------------------------------------------------------
def three_cells(**colony_fields):
    cells = q.Cells(centers=[[0, 0, 0], [10, 0, 0], [20, 0, 0]], axes=[[1, 0, 0]] * 3, lengths=[4.2, 1.0, 4.5],
                    radii=0.5, masses=3.0, growth_inertia=30.0)
    return Colony.founder(cells, rates=0.5).replace(**colony_fields)


def test_daughters_inherit_their_mothers_type_and_cell_data():
    colony = three_cells(cell_types=[3, 1, 2], cell_data={"targetVol": [4.0, 5.0, 6.0],
                                                          "signals": np.arange(6.0).reshape(3, 2),
                                                          "infected": np.array([True, False, False])})
    after = divide(colony, 4.0, np.random.default_rng(0))
    # Mothers 0 and 2 divide: daughter 1 in her place, daughter 2 appended in order.
    assert list(after.ids) == [3, 1, 4, 5, 6] and list(after.parent_ids) == [0, -1, 2, 0, 2]
    assert list(after.cell_types) == [3, 1, 2, 3, 2]
    np.testing.assert_array_equal(after.cell_data["targetVol"], [4.0, 5.0, 6.0, 4.0, 6.0])
    np.testing.assert_array_equal(after.cell_data["signals"], [[0, 1], [2, 3], [4, 5], [0, 1], [4, 5]])
    np.testing.assert_array_equal(after.cell_data["infected"], [True, False, False, True, False])
    assert after.cell_data["infected"].dtype == bool
    assert divide(after, 100.0, np.random.default_rng(0)) is after  # nobody divides: nothing changes


def test_types_default_to_zero_and_cell_data_to_empty():
    colony = three_cells()
    assert colony.cell_types.dtype == np.int64 and list(colony.cell_types) == [0, 0, 0]
    assert colony.cell_data == {}
    assert list(colony.replace(cell_types=2).cell_types) == [2, 2, 2]  # one type for all


@pytest.mark.parametrize("changes, message", [
    (dict(cell_types=[0, 1]), r"cell_types: expected shape \(3,\)"),
    (dict(cell_types=[0, -1, 0]), "cell_types: must be >= 0"),
    (dict(cell_types=[0.0, 1.0, 0.0]), "cell_types: expected integers"),
    (dict(cell_types=["a", "b", "c"]), "cell_types: expected integers"),
    (dict(cell_data=[1, 2, 3]), "cell_data: expected a dict"),
    (dict(cell_data={"target vol": [1, 2, 3]}), "names must be Python identifiers"),
    (dict(cell_data={1: [1, 2, 3]}), "names must be Python identifiers"),
    (dict(cell_data={"x": [1, 2]}), r"cell_data\['x'\]: expected one row per cell \(first axis 3\)"),
    (dict(cell_data={"x": 1.0}), r"cell_data\['x'\]: expected one row per cell"),
    (dict(cell_data={"x": ["a", "b", "c"]}), r"cell_data\['x'\]: expected numbers or booleans"),
    (dict(cell_data={"x": [1j, 2, 3]}), r"cell_data\['x'\]: expected numbers or booleans"),
])
def test_bad_cell_types_or_cell_data_are_named_errors(changes, message):
    with pytest.raises(InvalidArgumentError, match=message):
        three_cells(**changes)


def test_subset_keeps_every_per_cell_field_aligned():
    colony = three_cells(cell_types=[3, 1, 2], cell_data={"v": [4.0, 5.0, 6.0]}, owed=[0.1, 0.2, 0.3])
    for index in ([2, 0], np.array([2, 0], dtype=np.uint8)):
        kept = colony.subset(index)
        assert list(kept.ids) == [2, 0] and list(kept.cell_types) == [2, 3]
        np.testing.assert_array_equal(kept.cell_data["v"], [6.0, 4.0])
        np.testing.assert_array_equal(kept.owed, [0.3, 0.1])
        np.testing.assert_array_equal(kept.cells.lengths, [4.5, 4.2])
    masked = colony.subset(np.array([False, True, True]))
    assert list(masked.ids) == [1, 2] and masked.next_id == colony.next_id
    with pytest.raises(InvalidArgumentError, match="a mask needs one entry per cell"):
        colony.subset(np.array([True, False]))


def test_per_type_rates_set_a_newborns_mean_rate():
    colony = three_cells(cell_types=[1, 0, 0])
    after = divide(colony, 4.0, np.random.default_rng(0), base_rate=0.9, type_rates=[0.2, 0.7])
    # Mothers 0 (type 1) and 2 (type 0) divide; no noise: each daughter gets her type's rate.
    np.testing.assert_array_equal(after.rates, [0.7, 0.5, 0.2, 0.7, 0.2])
    noisy = divide(colony, 4.0, np.random.default_rng(0), rate_noise=0.1, type_rates=[0.2, 0.7])
    assert noisy.rates[0] != 0.7 and noisy.rates[0] == pytest.approx(0.7, rel=0.5)
    with pytest.raises(InvalidArgumentError, match="type_rates: gives 2 types .0 to 1., but a dividing cell has type 2"):
        divide(colony.replace(cell_types=[2, 0, 0]), 4.0, np.random.default_rng(0), type_rates=[0.2, 0.7])
    for bad in ([], [0.2, 0.0], [0.2, np.inf], [[0.2]]):
        with pytest.raises(InvalidArgumentError, match="type_rates"):
            divide(colony, 4.0, np.random.default_rng(0), type_rates=bad)


def test_replacing_the_cells_by_fewer_keeps_defaults_and_refuses_to_drop_types():
    colony = three_cells()
    fewer = colony.replace(cells=colony.cells.subset([0]), ids=[0], parent_ids=[-1], rates=[0.5], owed=[0.0])
    assert list(fewer.cell_types) == [0] and fewer.cell_data == {}
    typed = three_cells(cell_types=[0, 1, 0])
    with pytest.raises(InvalidArgumentError, match=r"cell_types: expected shape \(1,\)"):
        typed.replace(cells=colony.cells.subset([0]), ids=[0], parent_ids=[-1], rates=[0.5], owed=[0.0])
    with pytest.raises(InvalidArgumentError, match=r"cell_data\['v'\]: expected one row per cell"):
        three_cells(cell_data={"v": [1, 2, 3]}).replace(cells=colony.cells.subset([0]), ids=[0], parent_ids=[-1],
                                                        rates=[0.5], owed=[0.0])
