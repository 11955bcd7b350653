"""Colony snapshots and the NPZ cell arrays: what is written loads back equal."""

import numpy as np
import pytest

import qpcontact as q
from qpcontact.colony import Colony
from qpcontact.colony.snapshots import load_cells, load_colony, save_cells, save_colony
from qpcontact.errors import InvalidArgumentError


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


def test_cells_alone_load_back_equal_and_from_a_snapshot(tmp_path):
    cells = q.Cells(centers=[[0, 0, 0], [3, 0, 1]], axes=[[1, 0, 0], [0, 0.6, 0.8]], lengths=[1.0, 0.0],
                    radii=[0.5, 0.4], masses=[1.0, np.inf], growth_inertia=[10.0, np.inf], momenta=[[1, 2, 3], [0, 0, 0]])
    path = save_cells(tmp_path / "cache" / "cells.npz", cells)
    assert sorted(np.load(path).files) == sorted(f for f in ("centers", "axes", "lengths", "radii", "masses",
                                                          "growth_inertia", "momenta", "angular_momenta",
                                                          "growth_momenta"))
    for source in (path, save_colony(tmp_path / "snapshot.npz", Colony.founder(cells, 0.5))):
        loaded = load_cells(source)
        for name in ("centers", "axes", "lengths", "radii", "masses", "growth_inertia", "momenta", "angular_momenta",
                     "growth_momenta"):
            np.testing.assert_array_equal(getattr(loaded, name), getattr(cells, name))
    assert not list((tmp_path / "cache").glob("*.tmp.npz"))  # written through a temporary file
