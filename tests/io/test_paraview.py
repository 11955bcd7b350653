"""ParaView files of a run (qpcontact.io.paraview): read back with meshio, the library that
writes them, and by a reader of the VTK XML format (what ParaView reads) written here."""

from __future__ import annotations

import numpy as np
import pytest

from qpcontact.cli import main
from qpcontact.io.paraview import ARRAYS, MECHANICS_ARRAYS, read_series
from qpcontact.io.snapshots import load_snapshot
from qpcontact.simulation.simulate import EXIT_SHORT

meshio = pytest.importorskip("meshio", reason="ParaView files need the extra qpcontact[vtk]")


@pytest.fixture(scope="module")
def run_3d(tmp_path_factory):
    out = tmp_path_factory.mktemp("biofilm")
    # growth 0.05 a step (the 3D default is 0.00625): every snapshot then has cells in contact
    assert main(["simulate", "--dimensions", "3", "--cells", "12", "--vtk", "--snapshot-every", "20", "--max-dt", "0.1",
                 "--growth-per-step", "0.05", "--out", str(out), "--quiet"]) == 0
    return out


def expected(snapshot):
    colony, mechanics = snapshot.colony, snapshot.mechanics
    cells = colony.cells
    return {"axis": cells.axes, "length": cells.lengths, "radius": cells.radii, "id": colony.ids,
            "parent_id": colony.parent_ids, "growth_rate": colony.rates, "velocity": cells.velocities,
            "cell_type": colony.cell_types, "pressure": mechanics.pressure, "stress": mechanics.stress.reshape(cells.n, 9)}


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


def read_vtu(path) -> dict:
    """A .vtu file read from the VTK XML format itself (what ParaView reads; independent of meshio,
    which wrote it): an UnstructuredGrid piece whose DataArrays are base64 binary blocks, each
    zlib-compressed when the file names vtkZLibDataCompressor, after a UInt32 header (number of
    blocks, block size, last block size, compressed sizes)."""
    import base64
    import xml.etree.ElementTree as ET
    import zlib

    root = ET.parse(path).getroot()
    assert root.get("type") == "UnstructuredGrid" and root.get("byte_order") == "LittleEndian"
    assert root.get("header_type", "UInt32") == "UInt32"
    compressed = root.get("compressor") == "vtkZLibDataCompressor"
    dtypes = {"Float64": "<f8", "Float32": "<f4", "Int64": "<i8", "Int32": "<i4", "UInt8": "u1", "Int8": "i1"}

    def values(array) -> np.ndarray:
        assert array.get("format") == "binary", array.get("format")
        text = "".join(array.text.split())
        if compressed:
            blocks = int(np.frombuffer(base64.b64decode(text[:8])[:4], "<u4")[0])
            header_chars = 4 * ((4 * (3 + blocks) + 2) // 3)
            header = np.frombuffer(base64.b64decode(text[:header_chars]), "<u4")
            data, raw = base64.b64decode(text[header_chars:]), b""
            start = 0
            for size in header[3:3 + blocks]:
                raw += zlib.decompress(data[start:start + int(size)])
                start += int(size)
        else:
            raw = base64.b64decode(text)[4:]
        out = np.frombuffer(raw, dtypes[array.get("type")])
        components = int(array.get("NumberOfComponents", "1"))
        return out.reshape(-1, components) if components > 1 else out

    piece = root.find("UnstructuredGrid/Piece")
    assert piece is not None
    grid = {"points": int(piece.get("NumberOfPoints")), "cells": int(piece.get("NumberOfCells"))}
    for section in ("Points", "Cells", "PointData", "CellData"):
        for array in piece.findall(f"{section}/DataArray"):
            grid[f"{section}/{array.get('Name')}"] = values(array)
    return grid


def test_the_files_follow_the_vtk_xml_format_paraview_reads(run_3d):
    """(Read by a reader of the format written here, not VTK's own: VTK alone was 566 MB of the
    test tools.)"""
    for _, vtu in read_series(run_3d / "colony.pvd"):
        grid = read_vtu(vtu)
        n = grid["cells"] // 2
        assert grid["points"] == 3 * n and grid["Points/Points"].shape == (3 * n, 3)
        np.testing.assert_array_equal(grid["Cells/types"], [1] * n + [3] * n)  # VTK_VERTEX, VTK_LINE
        np.testing.assert_array_equal(grid["Cells/connectivity"],
                                      np.concatenate([np.arange(n), np.arange(n, 3 * n)]))
        np.testing.assert_array_equal(grid["Cells/offsets"], np.concatenate([np.arange(1, n + 1),
                                                                             n + 2 * np.arange(1, n + 1)]))
        snapshot = load_snapshot(run_3d / "snapshots" / vtu.with_suffix(".npz").name)
        np.testing.assert_allclose(grid["Points/Points"][:n], snapshot.colony.cells.centers)
        for section in ("PointData", "CellData"):
            names = sorted(k.split("/")[1] for k in grid if k.startswith(f"{section}/"))
            assert names == sorted(ARRAYS + MECHANICS_ARRAYS), section
        for name, expected_values in expected(snapshot).items():
            np.testing.assert_allclose(grid[f"PointData/{name}"][:n], expected_values, err_msg=name)
            # cell data: the vertices, then the lines, each cell's value once per block
            np.testing.assert_allclose(grid[f"CellData/{name}"][n:], expected_values, err_msg=name)
        assert grid["PointData/axis"].shape == (3 * n, 3)
        assert grid["CellData/stress"].shape == (2 * n, 9)  # a tensor, to ParaView
        assert grid["CellData/pressure"].shape == (2 * n,) and grid["CellData/pressure"].max() > 0


def test_a_resumed_run_keeps_the_earlier_entries_of_the_series(tmp_path):
    out = tmp_path / "run"
    assert main(["simulate", "--cells", "3", "--vtk", "--snapshot-every", "5", "--max-dt", "0.1", "--max-steps", "12",
                 "--out", str(out), "--quiet"]) == EXIT_SHORT  # short of --cells at --max-steps
    assert main(["simulate", "--resume", "--max-steps", "17", "--vtk", "--out", str(out), "--quiet"]) == EXIT_SHORT  # short of --cells at --max-steps
    steps = [int(f.stem.split("_")[1]) for _, f in read_series(out / "colony.pvd")]
    assert steps == [5, 10, 12, 15, 17]


def test_vtk_without_meshio_is_a_one_line_error(tmp_path, monkeypatch, capsys):
    import sys

    monkeypatch.setitem(sys.modules, "meshio", None)
    assert main(["simulate", "--vtk", "--out", str(tmp_path / "run"), "--quiet"]) == 2
    assert "pip install 'qpcontact[vtk]'" in capsys.readouterr().err


def test_cell_types_and_a_models_per_cell_arrays_are_cell_data_of_the_files(tmp_path):
    """Issue 27: the types and each cell_data array (booleans as 0/1, several numbers per cell
    as components, a name of a built-in array prefixed) reach ParaView."""
    from qpcontact.io.paraview import write_vtu

    run = _small_run(tmp_path)
    snapshot = load_snapshot(sorted(run.glob("snapshots/step_*.npz"))[-1])
    colony = snapshot.colony
    n = colony.cells.n
    data = {"targetVol": np.linspace(3.0, 5.0, n), "signals": np.arange(2.0 * n).reshape(n, 2),
            "infected": np.arange(n) % 2 == 0, "length": np.ones(n)}
    colony = colony.replace(cell_types=np.arange(n) % 3, cell_data=data)
    grid = read_vtu(write_vtu(run / "typed.vtu", colony, mechanics=snapshot.mechanics))
    for section, rows in (("PointData", slice(0, n)), ("CellData", slice(n, 2 * n))):
        np.testing.assert_array_equal(grid[f"{section}/cell_type"][rows], np.arange(n) % 3)
        np.testing.assert_array_equal(grid[f"{section}/targetVol"][rows], data["targetVol"])
        np.testing.assert_array_equal(grid[f"{section}/signals"][rows], data["signals"])
        np.testing.assert_array_equal(grid[f"{section}/infected"][rows], data["infected"].astype(int))
        np.testing.assert_array_equal(grid[f"{section}/data_length"][rows], data["length"])
        np.testing.assert_array_equal(grid[f"{section}/length"][rows], colony.cells.lengths)


def _small_run(tmp_path):
    out = tmp_path / "small"
    assert main(["simulate", "--cells", "5", "--max-dt", "0.1", "--out", str(out), "--quiet"]) == 0
    return out
