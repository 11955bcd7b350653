"""ParaView files of a run (qpcontact.colony.paraview): read back with meshio, the library that
writes them, and with VTK's own XML reader (what ParaView uses)."""

from __future__ import annotations

import numpy as np
import pytest

from qpcontact.cli import main
from qpcontact.colony.paraview import ARRAYS, MECHANICS_ARRAYS, read_series
from qpcontact.colony.snapshots import load_snapshot

meshio = pytest.importorskip("meshio", reason="ParaView files need the extra qpcontact[vtk]")


@pytest.fixture(scope="module")
def run_3d(tmp_path_factory):
    out = tmp_path_factory.mktemp("biofilm")
    assert main(["simulate", "--dimensions", "3", "--cells", "12", "--vtk", "--snapshot-every", "20", "--max-dt", "0.1",
                 "--out", str(out), "--quiet"]) == 0
    return out


def expected(snapshot):
    colony, mechanics = snapshot.colony, snapshot.mechanics
    cells = colony.cells
    return {"axis": cells.axes, "length": cells.lengths, "radius": cells.radii, "id": colony.ids,
            "parent_id": colony.parent_ids, "growth_rate": colony.rates, "velocity": cells.velocities,
            "pressure": mechanics.pressure, "stress": mechanics.stress.reshape(cells.n, 9)}


def test_a_3d_run_writes_a_vtu_per_snapshot_and_a_time_series(run_3d):
    snapshots = sorted((run_3d / "snapshots").glob("step_*.npz"))
    series = read_series(run_3d / "colony.pvd")
    assert [f.name for _, f in series] == [s.name.replace(".npz", ".vtu") for s in snapshots]
    assert len(series) >= 2
    for (time, vtu), npz in zip(series, snapshots, strict=True):
        snapshot = load_snapshot(npz)
        colony = snapshot.colony
        assert time == colony.time
        mesh = meshio.read(vtu)
        n = colony.cells.n
        np.testing.assert_allclose(mesh.points[:n], colony.cells.centers)
        half = 0.5 * colony.cells.lengths[:, None] * colony.cells.axes
        np.testing.assert_allclose(mesh.points[n:].reshape(n, 2, 3), np.stack([colony.cells.centers - half,
                                                                                colony.cells.centers + half], axis=1))
        assert [(block.type, len(block.data)) for block in mesh.cells] == [("vertex", n), ("line", n)]
        assert sorted(mesh.point_data) == sorted(ARRAYS + MECHANICS_ARRAYS)
        assert not snapshot.mechanics.planar and snapshot.mechanics.pressure.max() > 0  # 3D: per volume
        for name, values in expected(snapshot).items():
            np.testing.assert_allclose(mesh.point_data[name][:n], values, err_msg=name)
            np.testing.assert_allclose(mesh.point_data[name][n:], np.repeat(values, 2, axis=0), err_msg=name)
            np.testing.assert_allclose(mesh.cell_data[name][1], values, err_msg=name)
    assert np.any(mesh.points[:, 2] > 0.5)  # a 3D colony: cells off the substrate's first layer too


def test_vtks_own_reader_reads_the_files(run_3d):
    vtk = pytest.importorskip("vtkmodules.vtkIOXML", reason="VTK is not installed (pip install vtk)")
    for _, vtu in read_series(run_3d / "colony.pvd"):
        reader = vtk.vtkXMLUnstructuredGridReader()
        reader.SetFileName(str(vtu))
        reader.Update()
        grid = reader.GetOutput()
        n = meshio.read(vtu).cells[0].data.shape[0]
        assert (grid.GetNumberOfPoints(), grid.GetNumberOfCells()) == (3 * n, 2 * n)
        data = grid.GetPointData()
        assert sorted(data.GetArrayName(i) for i in range(data.GetNumberOfArrays())) == sorted(ARRAYS + MECHANICS_ARRAYS)
        assert data.GetArray("axis").GetNumberOfComponents() == 3
        assert data.GetArray("stress").GetNumberOfComponents() == 9  # a tensor, to ParaView


def test_a_resumed_run_keeps_the_earlier_entries_of_the_series(tmp_path):
    out = tmp_path / "run"
    assert main(["simulate", "--cells", "3", "--vtk", "--snapshot-every", "5", "--max-dt", "0.1", "--max-steps", "12",
                 "--out", str(out), "--quiet"]) == 0
    assert main(["simulate", "--resume", "--max-steps", "17", "--vtk", "--out", str(out), "--quiet"]) == 0
    steps = [int(f.stem.split("_")[1]) for _, f in read_series(out / "colony.pvd")]
    assert steps == [5, 10, 12, 15, 17]


def test_vtk_without_meshio_is_a_one_line_error(tmp_path, monkeypatch, capsys):
    import sys

    monkeypatch.setitem(sys.modules, "meshio", None)
    assert main(["simulate", "--vtk", "--out", str(tmp_path / "run"), "--quiet"]) == 2
    assert "pip install 'qpcontact[vtk]'" in capsys.readouterr().err
