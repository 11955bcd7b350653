"""Bad arguments to the public API raise the named errors the README promises, naming the argument
and what was expected, never a raw TypeError, AttributeError, IndexError or ValueError, and never
a silent misreading (issue 13, item 9). Checks of the cell arrays themselves (ragged, strings,
complex, overflowing axes, underflowing radii) are in tests/geometry/test_cells.py."""

import numpy as np
import pytest

import qpcontact as qc
from qpcontact.colony import Colony, divide, grow
from qpcontact.errors import InvalidArgumentError, InvalidCellsError, UnknownSolverError


def pair(**kw):
    """Two crossed rods, a above b, approaching: one colliding contact."""
    return qc.Cells([[0, 0.9, 0], [0, 0, 0]], [[1, 0, 0], [0, 0, 1]], 2.0, 0.5, momenta=[[0, -1.0, 0], [0, 0, 0]], **kw)


@pytest.mark.parametrize("options, match", [
    (dict(tolerance="1e-6"), "tolerance: expected a finite real number in \\(0, 1\\)"),
    (dict(tolerance=None), "tolerance"),
    (dict(tolerance=np.array([1e-6])), "tolerance"),
    (dict(time_limit="1"), "time_limit: expected a finite real number"),
    (dict(time_limit=0), "time_limit"),
    (dict(position_correction=0.5, dt="0.1"), "dt: expected a finite real number"),
    (dict(position_correction=0.5), "dt: position correction needs the time step"),
    (dict(position_correction="half", dt=0.1), "position_correction"),
    (dict(margin="0.1"), "margin"),
    (dict(regularization=-1.0), "regularization"),
    (dict(solver_settings=[("max_iter", 10)]), "solver_settings: expected a dict"),
    (dict(contacts=[]), "contacts: expected qpcontact.Contacts"),
    (dict(scale="no"), "scale: expected True or False"),
    (dict(reduce="yes"), "reduce: expected True or False"),
    (dict(estimate_condition=1), "estimate_condition: expected True or False"),
    (dict(keep_separating="no"), "keep_separating: expected True or False"),
    (dict(planar="yes"), "planar: expected True, False or None"),
])
def test_resolve_names_the_bad_argument(options, match):
    with pytest.raises(InvalidArgumentError, match=match):
        qc.resolve(pair(), solver="clarabel", **options)


def test_solver_names_that_are_not_strings_are_unknown_solvers():
    for name in (None, ["osqp"], 3):
        with pytest.raises(UnknownSolverError):
            qc.resolve(pair(), solver=name)


def test_contacts_of_another_scene_are_refused():
    big = qc.Cells(np.arange(30).reshape(10, 3) * [1.0, 0, 0], [1, 0, 0], 2.0, 0.5)
    foreign = qc.find_contacts(big)
    assert foreign.cell_b.max() >= 2
    with pytest.raises(InvalidArgumentError, match="contacts of another scene"):
        qc.resolve(pair(), contacts=foreign)


def test_the_cells_must_be_cells():
    for call in (lambda: qc.resolve(None), lambda: qc.find_contacts(None), lambda: qc.step(None, 0.1)):
        with pytest.raises(InvalidCellsError, match="cells: expected qpcontact.Cells"):
            call()


@pytest.mark.parametrize("options, match", [
    (dict(dt="0.1"), "dt: expected a finite real number"),
    (dict(dt=None), "dt"),
    (dict(planes=qc.substrate()), "planes: expected a list of qpcontact.Plane.*wrap a single one in a list"),
    (dict(planes=None), "planes: expected a list"),
    (dict(planes=[(0, 0, 1)]), "planes: expected a list of qpcontact.Plane objects.*got an item of type tuple"),
    (dict(damping="1", dynamics="inertial"), "damping"),
    (dict(planar="no"), "planar: expected True, False or None"),
    (dict(keep_separating="yes"), "keep_separating"),
    (dict(drive=np.full((2, 7), 1j)), "drive: complex values are not accepted"),
])
def test_step_names_the_bad_argument(options, match):
    options = {"dt": 0.1, **options}
    with pytest.raises(InvalidArgumentError, match=match):
        qc.step(pair(), **options)


def test_a_huge_time_step_is_blamed_on_the_time_step():
    """It was blamed on growth_momenta (grow) or on axes/centers (the moved state)."""
    moving = qc.Cells([[0, 0, 0]], [1, 0, 0], 2.0, 0.5, momenta=[[1.0, 0, 0]], angular_momenta=[[0, 0, 1.0]])
    with pytest.raises(InvalidArgumentError, match="dt = 1e\\+308 is too large: cell 0"):
        qc.step(moving, 1e308, dynamics="inertial")
    colony = Colony.founder(qc.Cells([[0, 0, 0]], [1, 0, 0], 2.0, 0.5, growth_inertia=1.0), rates=np.log(2))
    with pytest.raises(InvalidArgumentError, match="dt = 1e\\+300 is too large: cell 0 would grow"):
        grow(colony, 1e300)


def test_division_and_growth_settings_that_would_do_nothing_silently_are_refused():
    cells = qc.Cells([[0, 0, 0]], [1, 0, 0], 5.0, 0.5, growth_inertia=1.0)
    colony = Colony.founder(cells, rates=np.log(2))
    rng = np.random.default_rng(0)
    for length in (np.nan, 0.0, "4"):
        with pytest.raises(InvalidArgumentError, match="division_length"):
            divide(colony, length, rng)
    assert divide(colony, 4.0, rng).cells.n == 2
    with pytest.raises(InvalidArgumentError, match="planar"):
        divide(colony, 4.0, rng, planar="no")
    # A founder of zero length never grew (l·e^(rt) = 0), silently.
    sphere = cells.replace(lengths=[0.0])
    with pytest.raises(InvalidArgumentError, match="length 0 and growth rate"):
        Colony.founder(sphere, rates=np.log(2))
    Colony.founder(sphere, rates=0.0)  # a sphere that does not grow is fine
    Colony.founder(sphere.replace(masses=np.inf), rates=np.log(2))  # so is a fixed one


# ------------------------------------------------------------------------------------------
# Issue 19, item 5: inputs that still escaped (one case each)
# ------------------------------------------------------------------------------------------
def one_cell():
    return qc.Cells([[0.0, 0.0, 0.0]], [1, 0, 0], 2.0, 0.5)


def empty_cells():
    return qc.Cells(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0))


@pytest.mark.parametrize("build, match", [
    (lambda: Colony(one_cell(), np.array([0.5]), [-1], [0.7]), "Colony.ids: expected integers"),
    (lambda: Colony(one_cell(), np.array([1.0]), [-1], [0.7]), "Colony.ids: expected integers"),
    (lambda: Colony(one_cell(), np.array([np.nan]), [-1], [0.7]), "Colony.ids: expected integers"),
    (lambda: Colony(one_cell(), [0], np.array([np.nan]), [0.7]), "Colony.parent_ids: expected integers"),
    (lambda: Colony(one_cell(), [0], [-1], [0.7], time=float("nan")), "Colony.time: expected a finite real number"),
    (lambda: Colony(one_cell(), [0], [-1], [0.7], time="0"), "Colony.time"),
    (lambda: Colony(one_cell(), [0], [-1], [0.7], next_id=float("nan")), "Colony.next_id: expected an integer"),
    (lambda: Colony(one_cell(), [0], [-1], [0.7], next_id=3.0), "Colony.next_id: expected an integer"),
    (lambda: Colony(one_cell(), [0], [-1], [[0.7, 0.2]]), "Colony.rates: expected shape \\(1,\\)"),
    (lambda: Colony(one_cell(), [0], [-1], ["fast"]), "Colony.rates: expected numbers"),
    (lambda: Colony.founder(one_cell(), [0.7, 0.2]), "rates: expected one rate or 1"),
    (lambda: Colony("cells", [0], [-1], [0.7]), "Colony.cells: expected qpcontact.Cells"),
    (lambda: qc.Plane("a", (0, 0, 1)), "Plane.point: expected numbers"),
    (lambda: qc.Plane((0, 0, 0), "up"), "Plane.normal: expected numbers"),
    (lambda: qc.channel("4"), "channel width: expected a finite real number"),
    (lambda: qc.channel(4.0, center_y="0"), "center_y: expected a finite real number"),
    (lambda: qc.substrate("0"), "height: expected a finite real number"),
    (lambda: qc.expansion_time_step(Colony.founder(one_cell(), 0.7), max_dt="0.02"), "max_dt"),
])
def test_bad_colony_and_plane_arguments_are_named(build, match):
    with pytest.raises(InvalidArgumentError, match=match):
        build()


def test_a_colony_of_integer_ids_still_builds():
    colony = Colony(one_cell(), np.array([7], dtype=np.int32), [-1], [0.7], time=1, next_id=np.int64(8))
    assert colony.ids.dtype == np.int64 and colony.time == 1.0 and colony.next_id == 8


def test_the_time_step_of_an_empty_colony_is_the_largest_one():
    empty = Colony(empty_cells(), np.zeros(0, dtype=int), np.zeros(0, dtype=int), np.zeros(0))
    assert qc.expansion_time_step(empty, max_dt=0.02) == 0.02
    from qpcontact.colony import growth_time_step

    assert growth_time_step(empty, still=0.03) == 0.03


@pytest.mark.parametrize("planar", [True, False, None])
def test_a_step_of_no_cells_is_no_step(planar):
    out = qc.step(empty_cells(), 0.1, planar=planar)
    assert out.cells.n == 0 and len(out.contacts) == 0 and out.max_overlap == 0.0
