"""Static planes and fixed cells as one-sided contacts in the same system."""

import numpy as np
import pytest

import qpcontact as q
from qpcontact.colony.growth import Colony, grow
from qpcontact.errors import InvalidArgumentError
from qpcontact.geometry.surfaces import Plane, channel, plane_contacts, substrate
from qpcontact.timestep.step import step


def test_plane_contact_geometry():
    cells = q.Cells(centers=[[0, 0, 0.45], [5, 0, 1.0], [9, 0, 0.3]],
                    axes=[[1, 0, 0], [np.cos(0.5), 0, np.sin(0.5)], [1, 0, 0]], lengths=[2.0, 2.0, 0.0], radii=0.5)
    contacts = plane_contacts(cells, [substrate()], margin=0.1)
    # Flat rod: both ends, overlap 0.05. Tilted rod: its lower end only. Sphere: one contact.
    assert list(contacts.cell_a) == [0, 1, 2, 0] and np.all(contacts.cell_b == -1)
    low_end = 1.0 - np.sin(0.5) - 0.5
    np.testing.assert_allclose(contacts.separation, [-0.05, low_end, -0.2, -0.05])
    np.testing.assert_allclose(contacts.normal, np.tile([0, 0, 1.0], (4, 1)))
    np.testing.assert_allclose(contacts.stretch_a, [-0.5, -0.5, -0.5, 0.5])
    points = cells.centers[contacts.cell_a] + contacts.offset_a
    np.testing.assert_allclose(points[:, 2], contacts.separation, atol=1e-15)  # the point nearest the plane
    with pytest.raises(InvalidArgumentError):
        Plane((0, 0, 0), (0, 0, 0))
    with pytest.raises(InvalidArgumentError):
        plane_contacts(cells, [(0, 0, 1)])


@pytest.mark.parametrize("dynamics", ["overdamped", "inertial"])
def test_substrate_stops_a_falling_cell(dynamics):
    # A tilted rod driven (overdamped) or thrown (inertial) down onto the substrate z = 0.
    cells = q.Cells(centers=[[0, 0, 2.0]], axes=[[np.cos(0.3), 0, np.sin(0.3)]], lengths=2.0, radii=0.5,
                    momenta=[[0, 0, -1.0]])
    drive = np.array([[0, 0, -1.0, 0, 0, 0, 0]])
    lowest = np.inf
    for _ in range(200):
        out = step(cells, 0.02, dynamics=dynamics, drive=drive if dynamics == "overdamped" else None,
                   planes=[substrate()], position_correction=0.5, margin=0.2, solver="clarabel")
        cells = out.cells
        ends = cells.centers[0, 2] + np.array([-1, 1]) * cells.axes[0, 2] * cells.lengths[0] / 2 - cells.radii[0]
        lowest = min(lowest, ends.min())
        if out.result.status != "no_contact":
            assert out.result.errors["momentum_change"] < 1e-6  # the plane takes the reaction
    assert lowest > -0.02  # never sinks through by more than 2 % of a diameter
    assert cells.centers[0, 2] == pytest.approx(0.5, abs=0.02)  # ended lying flat on the substrate
    assert abs(cells.axes[0, 2]) < 0.02


def test_channel_walls_hold_a_growing_colony():
    walls = channel(width=1.2)
    cells = q.Cells(centers=[[0, 0, 0]], axes=[[np.cos(0.4), np.sin(0.4), 0]], lengths=1.0, radii=0.5,
                    masses=1.0, growth_inertia=1000.0)
    colony = Colony.founder(cells, rates=np.log(2))
    for _ in range(150):
        colony, out = grow(colony, 0.01, planes=walls, planar=True, position_correction=0.5, margin=0.2)
    c = colony.cells
    reach_y = np.abs(c.centers[:, 1]) + np.abs(c.axes[:, 1]) * c.lengths / 2 + c.radii
    assert reach_y.max() < 0.6 + 0.02  # inside the walls (to 2 % of a diameter)
    assert abs(c.axes[0, 1]) < 0.2  # the walls turned it along the channel


def test_fixed_cell_does_not_move_and_stops_its_neighbour():
    cells = q.Cells(centers=[[0, 0, 0], [0, 1.1, 0]], axes=[1, 0, 0], lengths=2.0, radii=0.5,
                    masses=[np.inf, 1.0], growth_inertia=np.inf)
    drive = np.array([[0, 0, 0, 0, 0, 0, 0], [0, -1.0, 0, 0, 0, 0, 0]])
    for _ in range(50):
        out = step(cells, 0.02, drive=drive, position_correction=0.5, margin=0.2)
        cells = out.cells
    np.testing.assert_array_equal(cells.centers[0], [0, 0, 0])
    assert cells.centers[1, 1] == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("height, correction", [(0.5, 0.0), (0.3, 0.5)])
def test_a_fixed_cell_on_a_plane_does_not_stop_the_step(height, correction):
    """Issue 13, item 3: a fixed cell touching (or, with position correction, overlapping) the
    substrate made every step with a collision elsewhere raise "has no movable degree of
    freedom": its plane contact was kept though nothing can move there."""
    cells = q.Cells(centers=[[0, 0, height], [5, 0, 0.5], [5, 0, 1.45]], axes=[1, 0, 0], lengths=2.0, radii=0.5,
                    masses=[np.inf, 1.0, 1.0])
    assert 0 not in plane_contacts(cells, [substrate()]).cell_a
    drive = np.zeros((3, 7))
    drive[2, 2] = -1.0  # cell 2 pushed down onto cell 1, which rests on the substrate
    out = step(cells, 0.01, drive=drive, planes=[substrate()], margin=0.2, position_correction=correction,
               solver="clarabel")
    assert out.result.converged and len(out.result.contacts) >= 1
    np.testing.assert_array_equal(out.cells.centers[0], cells.centers[0])
