"""The timestep loop: kinematics of a step, the two dynamics, overlaps over time, failures."""

import numpy as np
import pytest

import qpcontact as q
from qpcontact.colony.growth import Colony, divide, grow
from qpcontact.errors import InvalidArgumentError, InvalidCellsError, SolverFailedError
from qpcontact.geometry.motion import move, rotate
from qpcontact.timestep.step import step


def rod_pair_end_to_end(gap=0.0):
    """Two rods on the x-axis, tip to tip with the given gap, both growing."""
    return q.Cells(centers=[[-1.5 - gap / 2, 0, 0], [1.5 + gap / 2, 0, 0]], axes=[1, 0, 0], lengths=2.0,
                   radii=0.5, masses=1.0, growth_inertia=1000.0)



def test_rotate_is_exact_and_keeps_unit_length():
    v = np.array([[1.0, 0, 0], [0, 1.0, 0], [0.6, 0.8, 0]])
    turned = rotate(v, np.array([[0, 0, np.pi / 2], [0, 0, 0], [np.pi, 0, 0]]))
    np.testing.assert_allclose(turned, [[0, 1, 0], [0, 1, 0], [0.6, -0.8, 0]], atol=1e-15)
    many = rotate(np.tile([[1.0, 0, 0]], (1000, 1)), np.random.default_rng(0).normal(0, 3, (1000, 3)))
    np.testing.assert_allclose(np.linalg.norm(many, axis=1), 1.0, atol=1e-15)



def test_move_moves_turns_and_stretches_with_the_cells_own_momenta():
    cells = q.Cells(centers=[[0, 0, 0]], axes=[[1, 0, 0]], lengths=2.0, radii=0.5, masses=2.0,
                    growth_inertia=4.0, momenta=[[2.0, 0, 0]], angular_momenta=[[0, 0, 0.3]], growth_momenta=[8.0])
    dt = 0.1
    moved = move(cells, dt)  # (the velocity step's move: the cells' own momenta)
    omega = cells.angular_velocities[0, 2]
    np.testing.assert_allclose(moved.centers[0], [0.1, 0, 0], atol=1e-15)  # v = p/m = 1
    np.testing.assert_allclose(moved.axes[0], [np.cos(omega * dt), np.sin(omega * dt), 0], atol=1e-15)
    assert moved.lengths[0] == pytest.approx(2.0 + 2.0 * dt)  # l̇ = g/G = 2
    with pytest.raises(InvalidArgumentError, match="too large"):
        move(cells.replace(growth_momenta=[-100.0]), dt)



def test_overdamped_resets_momenta_and_inertial_keeps_them():
    cells = q.Cells(centers=[[0, 0, 0]], axes=[[1, 0, 0]], lengths=2.0, radii=0.5, momenta=[[1.0, 0, 0]])
    assert np.all(step(cells, 0.1).cells.centers == 0)  # overdamped, no drive: does not move
    inertial = step(cells, 0.1, dynamics="inertial")
    np.testing.assert_allclose(inertial.cells.centers[0], [0.1, 0, 0])
    damped = step(cells, 0.1, dynamics="inertial", damping=2.0)
    np.testing.assert_allclose(damped.cells.momenta[0], [np.exp(-0.2), 0, 0])
    driven = step(cells, 0.1, drive=np.array([[0, 3.0, 0, 0, 0, 0, 0]]))
    np.testing.assert_allclose(driven.cells.centers[0], [0, 0.3, 0])
    with pytest.raises(InvalidArgumentError):
        step(cells, 0.1, damping=1.0)  # damping means nothing when momenta are reset
    with pytest.raises(InvalidArgumentError):
        step(cells, 0.0)
    with pytest.raises(InvalidArgumentError):
        step(cells, 0.1, dynamics="brownian")



def test_planar_mode_rejects_a_cell_out_of_the_plane():
    cells = q.Cells(centers=[[0, 0, 0], [3, 0, 0.1]], axes=[1, 0, 0], lengths=2.0, radii=0.5)
    with pytest.raises(InvalidCellsError, match="planar"):
        step(cells, 0.1, planar=True)



@pytest.mark.parametrize("solver", ["clarabel", "osqp"])
def test_two_cells_growing_end_to_end_do_not_interpenetrate(solver):
    colony = Colony.founder(rod_pair_end_to_end(), rates=np.log(2))
    worst = 0.0
    for _ in range(100):  # one doubling time; no division (threshold not reached)
        colony, out = grow(colony, 0.01, planar=True, solver=solver, tolerance=1e-6, position_correction=0.5,
                           margin=0.2)
        worst = max(worst, out.max_overlap)
    assert worst < 1e-3  # overlap bounded at 0.1 % of a diameter
    # They grew (incompressible growth, G = 1000 m) and pushed each other apart symmetrically.
    assert colony.cells.lengths == pytest.approx([4.0, 4.0], rel=1e-2)
    assert colony.cells.centers[0, 0] == pytest.approx(-colony.cells.centers[1, 0], abs=1e-6)
    tips_gap = np.diff(colony.cells.centers[:, 0])[0] - colony.cells.lengths.sum() / 2 - 1.0
    assert tips_gap > -1e-3



def test_position_correction_removes_an_overlap_that_velocity_constraints_keep():
    overlapping = q.Cells(centers=[[0, 0, 0], [0, 0.8, 0]], axes=[1, 0, 0], lengths=2.0, radii=0.5)
    without, with_ = overlapping, overlapping
    for _ in range(20):
        without = step(without, 0.05).cells
        out = step(with_, 0.05, position_correction=0.5)
        with_ = out.cells
    gap_without = np.diff(without.centers[:, 1])[0] - 1.0
    gap_with = np.diff(with_.centers[:, 1])[0] - 1.0
    assert gap_without == pytest.approx(-0.2)  # at rest and overlapping: nothing approaches, nothing moves
    assert -1e-4 < gap_with < 1e-3



def test_total_linear_momentum_stays_zero_in_inertial_colony():
    rng = np.random.default_rng(3)
    n = 12
    angles = rng.uniform(0, np.pi, n)
    cells = q.Cells(centers=np.c_[rng.uniform(0, 6, (n, 2)), np.zeros(n)], axes=np.c_[np.cos(angles), np.sin(angles), np.zeros(n)],
                    lengths=rng.uniform(1.0, 2.5, n), radii=0.5, masses=rng.uniform(0.5, 2.0, n), growth_inertia=5.0)
    colony = Colony.founder(cells, rates=0.7)
    scale = 0.0
    for _ in range(60):
        colony, out = grow(colony, 0.02, dynamics="inertial", planar=True, solver="osqp", tolerance=1e-8,
                           position_correction=0.2, margin=0.2)
        colony = divide(colony, 3.0, rng, planar=True)
        scale = max(scale, np.abs(colony.cells.momenta).sum())
        total = colony.cells.momenta.sum(axis=0)
        assert np.linalg.norm(total) <= 1e-6 * scale
    assert scale > 0.1  # the contacts did push cells about
    assert colony.cells.n > n  # and cells divided



def test_a_failed_solve_is_raised_and_not_applied():
    cells = q.Cells(centers=[[0, 0, 0], [0, 0.9, 0]], axes=[1, 0, 0], lengths=2.0, radii=0.5,
                    momenta=[[0, 1.0, 0], [0, -1.0, 0]])
    with pytest.raises(SolverFailedError) as info:
        step(cells, 0.1, dynamics="inertial", solver="clarabel", solver_settings={"max_iter": 1})
    assert not info.value.result.converged
    # The unconverged impulses were not applied (and step returned no new state at all).
    np.testing.assert_array_equal(info.value.result.cells.momenta, cells.momenta)



def test_contacts_that_do_not_collide_before_the_solve_must_still_be_in_the_system():
    """The original design notes put only colliding (approaching) contacts into the system. Over a step that is
    not enough: A hits B, and B, touching C at rest (not approaching), is pushed into C unless
    the B–C contact is in the system too (``keep_separating``)."""
    from qpcontact.geometry.contacts import relative_normal_velocity

    cells = q.Cells(centers=[[0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]], axes=[0, 1, 0], lengths=1.0, radii=0.5,
                    momenta=[[1.0, 0, 0], [0, 0, 0], [0, 0, 0]])
    contacts = q.find_contacts(cells, margin=0.01)
    assert len(contacts) == 4  # A–B and B–C, two contacts each (parallel rods)

    def post_velocities(keep):
        r = q.resolve(cells, solver="clarabel", contacts=contacts, keep_separating=keep, tolerance=1e-8)
        c = contacts
        return relative_normal_velocity(r.cells, c.cell_a, c.cell_b, c.normal, c.offset_a, c.offset_b,
                                        c.stretch_a, c.stretch_b)

    only_colliding = post_velocities(False)
    assert only_colliding[contacts.cell_a == 1].min() < -0.3  # B is driven into C
    all_near = post_velocities(True)
    assert all_near.min() > -1e-6  # nothing approaches any more
    with pytest.raises(InvalidArgumentError, match="keep_separating"):
        q.resolve(cells, solver="linear", contacts=contacts, keep_separating=True)


def test_a_runs_step_options_clear_an_overlap_that_steps_defaults_leave():
    """A new user's loop with step()'s defaults (no margin, no position correction) left an
    overlap of 0.067 of a diameter standing for 50 steps; the difference to qpcontact simulate is
    said in step's docstring, and the run's own settings object, VelocitySettings() (issue 35:
    beside the step, as PositionSettings is beside position_step), steps as simulate does, and
    so do Settings().step_options() (the keyword arguments of earlier versions)."""
    from qpcontact.geometry.overlap import largest_overlap
    from qpcontact.simulation import Settings

    cells = q.Cells(centers=[[0, 0, 0], [0, 1.0 - 0.067, 0]], axes=[1, 0, 0], lengths=2.0, radii=0.5)
    plain, run_like, by_options = cells, cells, cells
    for _ in range(50):
        plain = step(plain, 0.02).cells
        run_like = step(run_like, 0.02, settings=q.VelocitySettings(), planar=True).cells
        by_options = step(by_options, 0.02, **Settings().step_options()).cells
    assert largest_overlap(plain) == pytest.approx(0.067)
    assert largest_overlap(run_like) < 1e-9
    np.testing.assert_array_equal(run_like.centers, by_options.centers)  # the same step, bit for bit
    assert "settings=VelocitySettings()" in step.__doc__ and "no position correction" in step.__doc__
    assert Settings().velocity == q.VelocitySettings()


def test_step_takes_its_settings_or_the_keywords_of_earlier_versions_not_both():
    """The single solve is step's default, with resolve's own solver, formulation, form and
    tolerance (step no longer reads resolve's defaults at run time: SINGLE_SOLVE says them, and
    this test holds them equal); settings and a keyword that names one of its fields together are
    refused, naming the keyword."""
    import inspect

    from qpcontact.timestep.step import SINGLE_SOLVE, VelocitySettings

    defaults = {k: p.default for k, p in inspect.signature(q.resolve).parameters.items()}
    assert {k: SINGLE_SOLVE[k] for k in ("solver", "formulation", "form", "tolerance", "margin",
                                        "position_correction")} == {k: defaults[k] for k in (
        "solver", "formulation", "form", "tolerance", "margin", "position_correction")}
    cells = q.Cells(centers=[[0, 0, 0], [0, 0.95, 0]], axes=[1, 0, 0], lengths=2.0, radii=0.5)
    by_settings = step(cells, 0.02, settings=VelocitySettings.single_solve(margin=0.2, position_correction=0.5))
    by_keywords = step(cells, 0.02, margin=0.2, position_correction=0.5)
    np.testing.assert_array_equal(by_settings.cells.centers, by_keywords.cells.centers)
    with pytest.raises(InvalidArgumentError, match="margin: given together with settings"):
        step(cells, 0.02, settings=VelocitySettings(), margin=0.2)
    with pytest.raises(InvalidArgumentError, match="settings: expected qpcontact.timestep.VelocitySettings"):
        step(cells, 0.02, settings={"margin": 0.2})
    with pytest.raises(InvalidArgumentError, match="dynamics: expected one of"):
        step(cells, 0.02, dynamics="ballistic")


@pytest.mark.parametrize("dt, closes", [(0.05, True), (0.2, False)])
def test_a_gap_within_the_margin_may_close_within_the_step_and_no_more(dt, closes):
    """docs/model.md, "The velocity-level step": a contact at a gap ``d > 0`` within the margin
    gets ``b = −u − d/dt``, not ``b = −u``. A sphere approaching a fixed one at speed 1 across a
    gap of 0.1: with dt = 0.05 the gap cannot close within the step, so nothing stops it (``b =
    −u`` would stop it 0.1 short); with dt = 0.2 it is slowed to ``d/dt`` = 0.5 and ends the step
    touching."""
    cells = q.Cells(centers=[[0.0, 0, 0], [1.1, 0, 0]], axes=[1, 0, 0], lengths=0.0, radii=0.5,
                    masses=[1.0, np.inf])
    drive = np.zeros((2, 7))
    drive[0, 0] = 1.0
    out = step(cells, dt, drive=drive, margin=0.3, solver="clarabel", tolerance=1e-9)
    speed = out.cells.velocities[0, 0]
    if closes:
        assert speed == pytest.approx(1.0)
        assert out.cells.centers[0, 0] == pytest.approx(0.05)
    else:
        assert speed == pytest.approx(0.1 / dt, rel=1e-6)
        assert out.cells.centers[1, 0] - out.cells.centers[0, 0] == pytest.approx(1.0, abs=1e-7)  # touching


def test_a_3d_loop_takes_the_3d_step_options():
    """Settings().step_options() is the 2D run's (planar=True, refusing cells out of the plane);
    a 3D loop takes step_options(dimensions=3), or the options of 3D settings: the substrate,
    no planar reduction (issue 27: a 3D loop built from the README's line raised)."""
    from qpcontact.errors import InvalidCellsError
    from qpcontact.simulation import Settings

    cells = q.Cells(centers=[[0, 0, 0.5], [0.2, 0.3, 1.3]], axes=[[1, 0, 0], [0, 0.6, 0.8]], lengths=2.0, radii=0.5,
                    momenta=[[0, 0, 0.5], [0, 0, -0.5]])
    with pytest.raises(InvalidCellsError, match="planar=True"):
        step(cells, 0.02, **Settings().step_options())
    for options in (Settings().step_options(dimensions=3), Settings().updated({"dimensions": 3}).step_options()):
        assert options["planar"] is None and len(options["planes"]) == 1
        assert step(cells, 0.02, **options).cells.n == 2
    assert Settings().updated({"dimensions": 3}).step_options(dimensions=2)["planar"] is True
    with pytest.raises(InvalidArgumentError, match="dimensions"):
        Settings().step_options(dimensions=4)
