"""Growth, division, lineage, snapshots and the simulate command."""

import numpy as np
import pytest

import qpcontact as q
from qpcontact.colony.growth import Colony, divide, grow, volumes
from qpcontact.colony.snapshots import load_colony, save_colony
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
    with pytest.raises(InvalidArgumentError, match="too short"):
        divide(colony, 0.9, np.random.default_rng(0))


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


def test_snapshot_loads_back_equal(tmp_path):
    cells = q.Cells(centers=[[0, 0, 0], [3, 0, 1]], axes=[[1, 0, 0], [0, 0.6, 0.8]], lengths=[1.0, 2.5],
                    radii=[0.5, 0.4], masses=[1.0, np.inf], growth_inertia=[10.0, np.inf],
                    momenta=[[1, 2, 3], [0, 0, 0]], angular_momenta=[[0.1, 0, 0], [0, 0, 0]], growth_momenta=[0.5, 0])
    colony = Colony(cells, [7, 9], [3, -1], [0.7, 0.0], [0.1, 0.0], time=12.5, next_id=11)
    path = save_colony(tmp_path / "sub" / "step_000001.npz", colony, step=42)
    loaded, step = load_colony(path)
    assert step == 42 and loaded.time == 12.5 and loaded.next_id == 11
    for name in ("centers", "axes", "lengths", "radii", "masses", "growth_inertia", "momenta", "angular_momenta",
                 "growth_momenta"):
        np.testing.assert_array_equal(getattr(loaded.cells, name), getattr(cells, name))
    for name in ("ids", "parent_ids", "rates", "owed"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(colony, name))
    np.savez(tmp_path / "other.npz", centers=np.zeros((1, 3)))
    with pytest.raises(InvalidArgumentError, match="not a qpcontact-colony"):
        load_colony(tmp_path / "other.npz")


def test_simulate_command_writes_snapshots_history_and_pictures(tmp_path):
    from qpcontact.cli import main

    out = tmp_path / "run"
    code = main(["simulate", "--cells", "12", "--out", str(out), "--quiet", "--snapshot-every", "50", "--gif"])
    assert code == 0
    for name in ("history.csv", "colony.png", "history.png", "colony.gif"):
        assert (out / name).stat().st_size > 0
    snapshots = sorted((out / "snapshots").glob("step_*.npz"))
    assert len(snapshots) >= 2
    last, step = load_colony(snapshots[-1])
    assert last.cells.n >= 12 and step > 0
    assert np.all(last.cells.centers[:, 2] == 0)  # 2D monolayer stayed in the plane
    # Lineage: every non-founder's parent id is an id that existed before it.
    assert np.all(last.parent_ids < last.ids)
    rows = (out / "history.csv").read_text().splitlines()
    assert rows[0].startswith("step,time,dt,cells") and len(rows) == step + 1


@pytest.mark.parametrize("change, message", [
    ({"cfl": -1.0}, "cfl: must be finite and > 0"),
    ({"overlap_limit": float("nan")}, "overlap_limit: must be finite and >= 0"),
    ({"n_cells": 0}, "n_cells: must be an integer >= 1"),
    ({"dimensions": 4}, "dimensions: must be 2 or 3"),
    ({"position_correction": 1.5}, r"position_correction: must be in \[0, 1\]"),
])
def test_simulate_settings_are_checked(change, message):
    from qpcontact.colony.simulate import Settings

    with pytest.raises(InvalidArgumentError, match=message):
        Settings(**change)
