"""Contact forces, per-cell stress and pressure (qpcontact.timestep.mechanics): the forces of the
position-level step against statics worked out by hand (a column resting on a plane carries the
weight above each contact, a cell pushed against a wall presses with its drive, a growing rod
between two walls), action and reaction in a jammed cluster, the stress of a cell by hand, and
growth slowed by pressure."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import qpcontact as qc
from qpcontact.colony import Colony
from qpcontact.errors import InvalidArgumentError
from qpcontact.geometry import Contacts, Plane, capsule_footprint, capsule_volume, substrate
from qpcontact.timestep import CellMechanics, PositionSettings, position_step
from qpcontact.timestep.mechanics import fit_parabola, is_monolayer_scene, pressure_of, radial_profile

RADIUS = 0.5

#: The gap at which the position step leaves touching cells (its aim, for cells of radius RADIUS).
REST_GAP = PositionSettings().aim * 2 * RADIUS

def rods(centers, axes, lengths, growth_inertia=np.inf):
    """Capsules of radius 0.5 with mass = volume (as ``qpcontact simulate``)."""
    centers = np.asarray(centers, dtype=float)
    lengths = np.broadcast_to(np.asarray(lengths, dtype=float), (len(centers),))
    masses = capsule_volume(lengths, RADIUS)
    return qc.Cells(centers=centers, axes=np.asarray(axes, dtype=float), lengths=lengths, radii=RADIUS,
                    masses=masses, growth_inertia=growth_inertia * masses)


def settle(cells, drive, planes=(), steps=4, dt=0.05, **settings):
    """A few position steps under a constant drive; the last step's result."""
    for _ in range(steps):
        out = position_step(cells, dt, drive=drive, planes=planes, settings=PositionSettings(**settings))
        assert out.converged
        cells = out.cells
    return out


def test_a_column_resting_on_a_plane_carries_the_weight_of_the_cells_above_each_contact():
    """Five rods stacked on the substrate, each driven down by the same force f (its weight):
    the contacts between layers k and k+1 carry (4 − k)·f together, the plane 5f, and nothing
    moves. (Side-by-side rods keep three contacts each, which share a load as the solver picks:
    their sum is what statics determines.)"""
    n, f, gap = 5, 3.0, REST_GAP
    z = RADIUS + gap + np.arange(n) * (2 * RADIUS + gap)
    cells = rods(np.c_[np.zeros(n), np.zeros(n), z], [[1, 0, 0]] * n, 2.0)
    drive = np.zeros((n, 7))
    drive[:, 2] = -f
    out = settle(cells, drive, [substrate(0.0)])
    contacts, forces = out.contacts, out.contact_forces
    assert np.all(forces >= 0) and len(out.contact_forces) == len(contacts)
    on_plane = contacts.cell_b == -1
    assert set(contacts.cell_a[on_plane]) == {0}
    assert forces[on_plane].sum() == pytest.approx(n * f, rel=1e-4)
    for k in range(n - 1):
        between = (contacts.cell_a == k) & (contacts.cell_b == k + 1)
        assert between.sum() >= 2
        assert forces[between].sum() == pytest.approx((n - 1 - k) * f, rel=1e-4), k
    again = settle(out.cells, drive, [substrate(0.0)], steps=1)
    np.testing.assert_allclose(again.cells.centers, out.cells.centers, atol=1e-6)
    # The net contact force on each cell cancels its weight.
    force, torque = qc.cell_forces(out.cells, contacts, forces)
    np.testing.assert_allclose(force, -drive[:, :3], rtol=0, atol=1e-4 * f)
    np.testing.assert_allclose(torque, 0.0, atol=1e-4 * f)


def test_a_cell_pushed_against_a_wall_by_a_constant_drive_presses_with_that_drive():
    """A rod lying against the wall y = 0, driven into it by f: its two end contacts carry f
    between them (f/2 each, by symmetry), it stays put, and its stress is −ρf/V in yy only
    (hand computation: offsets (∓l/2, −ρ), forces (0, f/2)). Masses: a drag that moves the free
    cell 0.1 of a diameter per step, enough for the step to solve (a weaker push creeps in
    within the overlap tolerance and reports no force: PositionStepResult.contact_forces)."""
    f, length = 5.0, 2.0
    cells = rods([[0.0, RADIUS + REST_GAP, 0.0]], [[1, 0, 0]], length)
    drive = np.zeros((1, 7))
    drive[0, 1] = -f
    out = settle(cells, drive, [Plane((0, 0, 0), (0, 1, 0))], steps=3)
    assert out.contacts.kind.tolist() == [5, 6] and np.all(out.contacts.cell_b == -1)
    assert out.contact_forces.sum() == pytest.approx(f, rel=1e-4)
    np.testing.assert_allclose(out.contact_forces, f / 2, rtol=1e-4)
    assert out.cells.centers[0, 1] == pytest.approx(cells.centers[0, 1], abs=1e-4)
    volume = capsule_volume(length, RADIUS)
    stress = qc.cell_stress(out.cells, out.contacts, out.contact_forces, planar=False)[0]
    expected = np.zeros((3, 3))
    expected[1, 1] = -RADIUS * f / volume
    np.testing.assert_allclose(stress, expected, atol=1e-4 * abs(expected[1, 1]))
    assert qc.cell_pressure(out.cells, out.contacts, out.contact_forces, planar=False)[0] == pytest.approx(
        RADIUS * f / (3 * volume), rel=1e-4)


def test_the_stress_of_a_rod_growing_between_two_walls_matches_the_hand_computation():
    """A rod of length L growing between walls at its two poles: growth is held by the walls,
    each pressing with the growth drive g (the growth momentum's contact term is −½ per unit
    force at each pole), so σ_xx = −2 g (L/2 + ρ)/V and every other component 0; the 3D pressure
    g (L + 2ρ)/(3V), the 2D one g (L + 2ρ)/(2A) over the footprint A = 2ρL + πρ². (No shrinking
    bound here: with it, the bound and the walls would share the stopped growth.)"""
    length, dt = 3.0, 0.05
    cells = rods([[0.0, 0.0, 0.0]], [[1, 0, 0]], length, growth_inertia=1000.0)
    pole = length / 2 + RADIUS + REST_GAP
    walls = [Plane((-pole, 0, 0), (1, 0, 0)), Plane((pole, 0, 0), (-1, 0, 0))]
    for _ in range(4):
        drive = np.zeros((1, 7))
        drive[0, 6] = cells.growth_inertia[0] * cells.lengths[0] * np.expm1(np.log(2) * dt) / dt
        out = position_step(cells, dt, drive=drive, planes=walls, settings=PositionSettings(allow_shrinking=True))
        cells = out.cells
    g = drive[0, 6]
    np.testing.assert_allclose(out.contact_forces, g, rtol=1e-5)
    reach = out.cells.lengths[0] / 2 + RADIUS
    np.testing.assert_allclose(np.abs(out.contacts.offset_a[:, 0]), reach, rtol=1e-12)
    volume, footprint = capsule_volume(out.cells.lengths[0], RADIUS), capsule_footprint(out.cells.lengths[0], RADIUS)
    stress = qc.cell_stress(out.cells, out.contacts, out.contact_forces, planar=False)[0]
    expected = np.zeros((3, 3))
    expected[0, 0] = -2 * g * reach / volume
    np.testing.assert_allclose(stress, expected, rtol=1e-5, atol=1e-9 * g)
    assert qc.cell_pressure(out.cells, out.contacts, out.contact_forces, planar=False)[0] == pytest.approx(
        2 * g * reach / (3 * volume), rel=1e-5)
    # The rod is a monolayer with walls in its plane: detected as 2D (over the footprint).
    assert is_monolayer_scene(out.cells, out.contacts)
    assert qc.cell_pressure(out.cells, out.contacts, out.contact_forces)[0] == pytest.approx(
        2 * g * reach / (2 * footprint), rel=1e-5)


def packed_cluster(rings=2):
    """Spheres of radius 0.5 in a hexagonal patch with small gaps, a monolayer."""
    points = [(0.0, 0.0)]
    spacing = 2 * RADIUS + 0.02
    for ring in range(1, rings + 1):
        for side in range(6):
            a, b = np.exp(1j * np.pi / 3 * side), np.exp(1j * np.pi / 3 * (side + 1))
            for step in range(ring):
                z = spacing * (ring * a + step * (b - a))
                points.append((z.real, z.imag))
    centers = np.c_[np.array(points), np.zeros(len(points))]
    return rods(centers, [[1, 0, 0]] * len(points), 0.0)


def test_a_free_cluster_squeezed_together_obeys_action_and_reaction_and_its_forces_balance():
    """A hexagonal cluster of 19 spheres, each driven towards the centroid (Σ drive = 0):
    once packed, nothing moves, and the contact forces balance every cell's drive (so they
    sum to zero over the free cluster), every contact's two forces are equal, opposite and on
    one line (the total torque about any point vanishes), and every force pushes."""
    cells = packed_cluster()
    drive = np.zeros((cells.n, 7))
    drive[:, :2] = -8.0 * cells.masses[:, None] * (cells.centers[:, :2] - cells.centers[:, :2].mean(axis=0))
    out = settle(cells, drive, steps=6)
    contacts, forces = out.contacts, out.contact_forces
    assert len(contacts) >= 30 and np.all(forces >= 0) and forces.max() > 0
    force, torque = qc.cell_forces(out.cells, contacts, forces)
    # To the solver's tolerance (PositionSettings.tolerance = 10⁻³ of the largest force).
    np.testing.assert_allclose(force, -drive[:, :3], atol=1e-3 * np.abs(drive).max())
    np.testing.assert_allclose(force.sum(axis=0), 0.0, atol=1e-12 * forces.sum())
    # Action and reaction: the two contact points lie on the normal through them (collinear forces).
    centers = out.cells.centers
    on_a = centers[contacts.cell_a] + contacts.offset_a
    on_b = centers[contacts.cell_b] + contacts.offset_b
    np.testing.assert_allclose(np.cross(on_a - on_b, contacts.normal), 0.0, atol=1e-12)
    total_torque = np.cross(centers, force).sum(axis=0) + torque.sum(axis=0)
    np.testing.assert_allclose(total_torque, 0.0, atol=1e-10 * forces.sum())
    # Every cell but the middle one is pressed inwards: positive pressure everywhere.
    assert np.all(qc.cell_pressure(out.cells, contacts, forces) > 0)


def test_a_grown_colony_step_balances_forces_and_torques_and_its_pressure_does_not_depend_on_when_in_the_step():
    """A step of a small grown colony (no planes): the contact forces sum to zero and so do their
    torques about the origin, whatever the geometry. The contacts are reported at the end of the
    step, the forces solved for at its linearization: the cells' pressures with the contacts
    taken at the start of the step instead differ by a few per cent (their net forces, small
    differences of large contact forces, do not balance the step's momenta that closely:
    docs/mechanics.md)."""
    from qpcontact.colony import grow_position
    from qpcontact.geometry import evaluate_contacts
    from qpcontact.simulation import Settings, run_colony

    colony = run_colony(Settings().updated({"cells": 60}), progress=False).colony
    _, out = grow_position(colony, 0.05, planar=True)
    contacts, forces = out.contacts, out.contact_forces
    force, torque = qc.cell_forces(out.cells, contacts, forces)
    scale = np.abs(forces).sum()
    np.testing.assert_allclose(force.sum(axis=0), 0.0, atol=1e-12 * scale)
    np.testing.assert_allclose((np.cross(out.cells.centers, force) + torque).sum(axis=0), 0.0, atol=1e-10 * scale)
    end = qc.cell_pressure(out.cells, contacts, forces, planar=True)
    at_start = evaluate_contacts(colony.cells, contacts.cell_a, contacts.cell_b, contacts.kind, planar=True)
    start = qc.cell_pressure(colony.cells, at_start, forces, planar=True)
    assert np.all(end > 0) and np.linalg.norm(start - end) < 0.1 * np.linalg.norm(end)


def test_stress_by_hand_on_hand_made_contacts_sign_and_units():
    """A sphere of radius ρ squeezed along y by two walls with force F each: σ_yy = −2ρF/V
    (compression: negative stress, positive pressure ρF·2/(3V)); pulled (negative forces):
    the opposite. A cell–cell contact loads both cells, with the force on b opposite."""
    cells = rods([[0, 0, 0], [5, 0, 0]], [[1, 0, 0]] * 2, 0.0)
    volume = capsule_volume(0.0, RADIUS)
    contacts = Contacts(
        cell_a=np.array([0, 0, 0]), cell_b=np.array([-1, -1, 1]),
        normal=np.array([[0, 1.0, 0], [0, -1.0, 0], [-1.0, 0, 0]]),
        offset_a=np.array([[0, -RADIUS, 0], [0, RADIUS, 0], [RADIUS, 0, 0]]),
        offset_b=np.array([[0, 0, 0], [0, 0, 0], [-RADIUS, 0, 0]]),
        stretch_a=np.zeros(3), stretch_b=np.zeros(3), separation=np.zeros(3), normal_velocity=np.zeros(3),
        kind=np.zeros(3, dtype=int))
    stress = qc.cell_stress(cells, contacts, [2.0, 2.0, 0.0], planar=False)
    assert stress[0, 1, 1] == pytest.approx(-2 * RADIUS * 2.0 / volume)
    assert np.count_nonzero(stress[0]) == 1 and not stress[1].any()
    assert qc.cell_pressure(cells, contacts, [2.0, 2.0, 0.0], planar=False)[0] == pytest.approx(4 * RADIUS / (3 * volume))
    assert qc.cell_pressure(cells, contacts, [-2.0, -2.0, 0.0], planar=False)[0] < 0
    # The cell-cell contact (3rd) presses both cells along x.
    stress = qc.cell_stress(cells, contacts, [0.0, 0.0, 1.5], planar=False)
    assert stress[0, 0, 0] == stress[1, 0, 0] == pytest.approx(-RADIUS * 1.5 / volume)
    force, _ = qc.cell_forces(cells, contacts, [0.0, 0.0, 1.5])
    np.testing.assert_allclose(force, [[-1.5, 0, 0], [1.5, 0, 0]])
    # 2D: over the footprint, half the in-plane trace.
    footprint = capsule_footprint(0.0, RADIUS)
    assert qc.cell_pressure(cells, contacts, [0.0, 0.0, 1.5], planar=True)[1] == pytest.approx(
        RADIUS * 1.5 / (2 * footprint))
    assert pressure_of(np.diag([-1.0, -2.0, -6.0])[None], planar=False)[0] == pytest.approx(3.0)
    assert pressure_of(np.diag([-1.0, -2.0, -6.0])[None], planar=True)[0] == pytest.approx(1.5)


def test_bad_forces_and_contacts_are_named_errors():
    cells = rods([[0, 0, 0]], [[1, 0, 0]], 1.0)
    contacts = qc.plane_contacts(cells, [Plane((0, -0.5, 0), (0, 1, 0))])
    for forces, message in (([1.0], "forces: expected 2 finite"), ([1.0, np.nan], "forces: expected 2 finite"),
                            (["a", "b"], "forces: expected numbers")):
        with pytest.raises(InvalidArgumentError, match=message):
            qc.cell_stress(cells, contacts, forces)
    with pytest.raises(InvalidArgumentError, match="contacts"):
        qc.cell_pressure(cells, "contacts", [1.0])
    with pytest.raises(InvalidArgumentError, match="planar: expected True, False or None"):
        qc.cell_pressure(cells, contacts, [1.0, 1.0], planar="yes")
    with pytest.raises(InvalidArgumentError, match="contacts.cell_a"):  # contacts of another scene
        qc.cell_forces(cells, dataclasses.replace(contacts, cell_a=np.array([0, 1])), [1.0, 1.0])


def test_no_contacts_no_stress():
    cells = rods([[0, 0, 0], [5, 0, 0]], [[1, 0, 0]] * 2, 1.0)
    assert not qc.cell_stress(cells, Contacts.empty(), []).any()
    assert qc.cell_pressure(cells, Contacts.empty(), []).shape == (2,)


def test_pressure_growth_rate_linear_and_exponential():
    pressure = np.array([-3.0, 0.0, 5.0, 10.0, 20.0])
    linear = qc.pressure_growth_rate(0.7, pressure, stall_pressure=10.0)
    np.testing.assert_allclose(linear, [0.7, 0.7, 0.35, 0.0, 0.0])
    exponential = qc.pressure_growth_rate(np.full(5, 0.7), pressure, law="exponential", stall_pressure=10.0)
    np.testing.assert_allclose(exponential, 0.7 * np.exp(-np.maximum(pressure, 0) / 10.0))
    assert qc.pressure_growth_rate(0.7, np.zeros(3), stall_pressure=1.0).tolist() == [0.7] * 3  # exact: bit for bit
    for kwargs, message in (({"law": "cubic", "stall_pressure": 1.0}, "law: expected one of linear, exponential"),
                            ({"stall_pressure": 0.0}, "stall_pressure"), ({"stall_pressure": np.inf}, "stall_pressure"),
                            ({"stall_pressure": "1"}, "stall_pressure")):
        with pytest.raises(InvalidArgumentError, match=message):
            qc.pressure_growth_rate(0.7, pressure, **kwargs)
    with pytest.raises(InvalidArgumentError, match="shapes"):
        qc.pressure_growth_rate(np.ones(4), pressure, stall_pressure=1.0)
    with pytest.raises(InvalidArgumentError, match="finite"):
        qc.pressure_growth_rate(-1.0, pressure, stall_pressure=1.0)
    with pytest.raises(InvalidArgumentError, match="law"):
        qc.colony.PressureGrowth("cubic", 1.0)


def test_mechanics_carried_over_division_go_to_both_daughters():
    cells = rods([[0, 0, 0], [5, 0, 0]], [[1, 0, 0]] * 2, [3.9, 1.0], growth_inertia=10.0)
    colony = Colony.founder(cells, 1.0)
    stress = np.zeros((2, 3, 3))
    stress[:, 0, 0] = [-3.0, -6.0]
    mechanics = CellMechanics(pressure_of(stress, True), stress, True)
    divided = qc.divide(colony, 3.5, np.random.default_rng(0), planar=True)
    assert divided.cells.n == 3
    carried = mechanics.carried_over(colony, divided)
    np.testing.assert_array_equal(carried.pressure, [1.5, 3.0, 1.5])  # daughters of cell 0 at 0 and 2
    np.testing.assert_array_equal(carried.stress[2], stress[0])
    removed = colony.replace(cells=cells.subset([1]), ids=[1], parent_ids=[-1], rates=[1.0], owed=[0.0])
    assert mechanics.carried_over(colony, removed).pressure.tolist() == [3.0]
    stranger = colony.replace(ids=[5, 6], next_id=7)
    assert mechanics.carried_over(colony, stranger).pressure.tolist() == [0.0, 0.0]


def test_radial_profile_and_parabola_fit_recover_a_parabola():
    rng = np.random.default_rng(3)
    xy = rng.uniform(-10, 10, (2000, 2))
    cells = rods(np.c_[xy, np.zeros(2000)], [[1, 0, 0]] * 2000, 1.0)
    r = np.linalg.norm(xy - xy.mean(axis=0), axis=1)
    values = 0.5 * (12.0**2 - r**2)
    fit = fit_parabola(r, values)
    assert fit.amplitude == pytest.approx(0.5) and fit.radius == pytest.approx(12.0) and fit.rms < 1e-9
    profile = radial_profile(cells, values, bins=10)
    assert profile.counts.sum() == 2000 and profile.edges[-1] == pytest.approx(r.max())
    kept = profile.counts > 0
    np.testing.assert_allclose(profile.mean[kept], 0.5 * (144 - profile.radius[kept] ** 2), rtol=0.05)
    with pytest.raises(InvalidArgumentError, match="values"):
        radial_profile(cells, values[:5])
    with pytest.raises(InvalidArgumentError, match="bins"):
        radial_profile(cells, values, bins=0)
    with pytest.raises(InvalidArgumentError, match="at least 2"):
        fit_parabola([1.0], [2.0])
