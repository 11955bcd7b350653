"""Scene generators: reproducible, the right shapes, plausible packing, and always something to
solve."""

import numpy as np
import pytest

from qpcontact import colliding, find_contacts
from qpcontact.errors import InvalidArgumentError
from qpcontact.studies import scenes

SMALL = {"two_rods": None, "rod_chain": 8, "rod_across_many": 7, "jammed_packing": 19, "colony_2d": 300, "colony_3d": 300}
FIELDS = ("centers", "axes", "lengths", "radii", "masses", "growth_inertia", "momenta", "angular_momenta", "growth_momenta")


def test_registry_lists_every_generator():
    assert set(SMALL) == {name for name, s in scenes.SCENES.items() if s.family in ("hand-made", "colony")}
    with pytest.raises(InvalidArgumentError, match="unknown scene"):
        scenes.make_scene("no_such_scene")


@pytest.mark.parametrize("name", sorted(SMALL))
def test_same_seed_same_scene_other_seed_other_scene(name):
    a = scenes.make_scene(name, SMALL[name], seed=3)
    b = scenes.make_scene(name, SMALL[name], seed=3)
    c = scenes.make_scene(name, SMALL[name], seed=4)
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    assert any(getattr(a, f).shape != getattr(c, f).shape or not np.array_equal(getattr(a, f), getattr(c, f))
               for f in FIELDS)


@pytest.mark.parametrize("name", sorted(SMALL))
def test_every_scene_has_colliding_contacts(name):
    cells = scenes.make_scene(name, SMALL[name])
    contacts = find_contacts(cells)
    active, b = colliding(contacts)
    assert len(active) > 0 and np.all(b > 0)
    # Overlaps are small: at most MAX_OVERLAP of the diameter (hand-made cases included).
    assert -contacts.separation.min() <= scenes.MAX_OVERLAP * 2 * scenes.RADIUS + 1e-9


@pytest.mark.parametrize("n", [1, 57, 500])
@pytest.mark.parametrize("generator", [scenes.colony_2d, scenes.colony_3d])
def test_colonies_have_exactly_n_cells_with_growth(generator, n):
    cells = generator(n, seed=1)
    assert cells.n == n
    assert cells.centers.shape == (n, 3) and cells.axes.shape == (n, 3)
    assert np.all((cells.lengths >= scenes.LENGTH_RANGE[0]) & (cells.lengths <= scenes.LENGTH_RANGE[1]))
    assert np.all(np.isfinite(cells.growth_inertia)) and np.all(cells.growth_momenta > 0)
    # Masses proportional to volume.
    volume = np.pi * cells.radii**2 * (cells.lengths + 4 / 3 * cells.radii)
    np.testing.assert_allclose(cells.masses / volume, scenes.DENSITY)


def test_colony_2d_is_planar():
    cells = scenes.colony_2d(400)
    for arr in (cells.centers[:, 2], cells.axes[:, 2], cells.momenta[:, 2]):
        assert np.all(arr == 0.0)
    assert np.all(cells.angular_momenta[:, :2] == 0.0)


def test_colony_3d_is_a_dome_on_the_substrate():
    cells = scenes.colony_3d(2000)
    z = cells.centers[:, 2]
    assert z.min() == pytest.approx(scenes.RADIUS)
    assert z.max() > 4 * scenes.RADIUS  # several layers
    r = np.hypot(cells.centers[:, 0], cells.centers[:, 1])
    assert np.median(z[r < 0.3 * r.max()]) > np.median(z[r > 0.7 * r.max()])  # higher in the middle
    bottom = z <= scenes.RADIUS + 1e-9
    assert np.all(cells.momenta[bottom, 2] >= 0)  # nothing moves into the substrate


@pytest.mark.parametrize("generator", [scenes.colony_2d, scenes.colony_3d])
def test_colony_contact_counts_are_those_of_a_dense_packing(generator):
    cells = generator(3000, seed=2)
    contacts = find_contacts(cells)
    per_cell = len(contacts) / cells.n
    assert 1.5 <= per_cell <= 5.5, per_cell  # rods side by side count two contacts
    active, _ = colliding(contacts)
    assert 0.3 * len(contacts) <= len(active) <= 0.9 * len(contacts)
    # Every cell touches something (no isolated cells inside the colony's packing), nearly.
    touched = np.unique(np.concatenate([contacts.cell_a, contacts.cell_b]))
    assert touched.size >= 0.95 * cells.n
    overlap = -contacts.separation / (2 * scenes.RADIUS)
    assert 0.01 <= np.median(overlap) <= 0.1


def test_jammed_packing_has_more_contacts_than_unknowns():
    cells = scenes.jammed_packing(37)
    active, _ = colliding(find_contacts(cells))
    mobile = np.isfinite(cells.masses).sum()
    assert len(active) > 2 * mobile  # planar spheres: 2 unknowns each


def test_bad_counts_are_rejected():
    with pytest.raises(InvalidArgumentError, match="n_cells"):
        scenes.colony_2d(0)
    with pytest.raises(InvalidArgumentError, match="n_cells"):
        scenes.rod_chain(1)
