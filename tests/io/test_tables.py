"""Tables and pictures of a run (issue 27): ``qpcontact table`` (CSV without pandas, Parquet with
the extra), ``qc.colony_frame`` / ``qc.run_frame`` (pandas), ``qpcontact plot``."""

from __future__ import annotations

import csv
import io
import sys

import numpy as np
import pytest

import qpcontact as qc
from qpcontact.cli import main
from qpcontact.io.runs import HISTORY_FIELDS
from qpcontact.io.snapshots import load_snapshot, save_colony
from qpcontact.io.tables import CELL_COLUMNS, MECHANICS_COLUMNS, colony_columns

HOOK = """import numpy as np

def hook(colony, step):
    age = colony.cell_data.get("age", np.zeros(colony.cells.n)) + 1.0
    signals = np.stack([age, -age], axis=1)
    return colony.replace(cell_types=colony.ids % 3 if step == 30 else colony.cell_types,
                          cell_data={"age": age, "signals": signals})
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A 20-cell run whose model gives the cells types and two per-cell arrays."""
    folder = tmp_path_factory.mktemp("tables")
    (folder / "model.py").write_text(HOOK)
    out = folder / "run"
    assert main(["simulate", "--cells", "20", "--hook", str(folder / "model.py"), "--snapshot-every", "40", "--out",
                 str(out), "--quiet"]) == 0
    return out


def last(run):
    return sorted((run / "snapshots").glob("step_*.npz"))[-1]


def read_csv(text: str) -> tuple[list[str], list[list[str]]]:
    rows = list(csv.reader(io.StringIO(text)))
    return rows[0], rows[1:]


def test_a_snapshots_columns_are_its_cells(run):
    snapshot = load_snapshot(last(run))
    colony, mechanics = snapshot.colony, snapshot.mechanics
    columns = colony_columns(colony, mechanics)
    assert list(columns) == [*CELL_COLUMNS, *MECHANICS_COLUMNS, "age", "signals_0", "signals_1"]
    np.testing.assert_array_equal(columns["id"], colony.ids)
    np.testing.assert_array_equal(columns["cell_type"], colony.cell_types)
    assert len(set(colony.cell_types)) >= 2  # types set at step 30, inherited since
    np.testing.assert_array_equal(np.stack([columns[k] for k in ("x", "y", "z")], axis=1), colony.cells.centers)
    np.testing.assert_array_equal(np.stack([columns[k] for k in ("axis_x", "axis_y", "axis_z")], axis=1),
                                  colony.cells.axes)
    np.testing.assert_array_equal(columns["stress_xy"], mechanics.stress[:, 0, 1])
    np.testing.assert_array_equal(columns["stress_yx"], mechanics.stress[:, 1, 0])
    np.testing.assert_array_equal(columns["signals_1"], -colony.cell_data["age"])
    taken = colony.replace(cell_data={"length": np.ones(colony.cells.n)})  # a name of a built-in column
    np.testing.assert_array_equal(colony_columns(taken)["data_length"], 1.0)
    assert "pressure" not in colony_columns(colony)  # no mechanics given


def test_table_prints_a_snapshots_cells_as_exact_csv(run, capsys):
    assert main(["table", str(last(run))]) == 0
    header, rows = read_csv(capsys.readouterr().out)
    columns = colony_columns(load_snapshot(last(run)).colony, load_snapshot(last(run)).mechanics)
    assert header == list(columns) and len(rows) == 20
    for i, name in enumerate(header):  # every float read back is the same number
        kind = int if columns[name].dtype.kind in "iu" else float
        np.testing.assert_array_equal([kind(row[i]) for row in rows], columns[name], err_msg=name)
    assert main(["table", str(run)]) == 0  # a run's folder: its latest snapshot
    assert read_csv(capsys.readouterr().out) == (header, rows)
    assert main(["table", str(run), "--snapshot", "40"]) == 0
    assert len(read_csv(capsys.readouterr().out)[1]) == load_snapshot(run / "snapshots" / "step_000040.npz").colony.cells.n
    assert main(["table", str(run), "--snapshot", "step_000040"]) == 0


def test_table_of_a_runs_history_is_its_history_csv(run, capsys):
    assert main(["table", str(run), "--history"]) == 0
    assert capsys.readouterr().out == (run / "history.csv").read_text()


def test_table_writes_a_csv_file_atomically_and_refuses_to_overwrite(run, tmp_path, capsys):
    out = tmp_path / "sub" / "cells.csv"
    assert main(["table", str(run), "--out", str(out)]) == 0
    assert capsys.readouterr().err.strip() == f"wrote {out}"
    header, rows = read_csv(out.read_text())
    assert header[:3] == ["id", "parent_id", "cell_type"] and len(rows) == 20
    assert [p.name for p in out.parent.iterdir()] == ["cells.csv"]  # no temporary file left
    out.write_text("mine")
    assert main(["table", str(run), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "exists; pass --overwrite to replace it" in err and len(err.strip().splitlines()) == 1
    assert out.read_text() == "mine"
    assert main(["table", str(run), "--history", "--out", str(out), "--overwrite"]) == 0
    assert out.read_text() == (run / "history.csv").read_text()


@pytest.mark.parametrize("argv, message", [
    (["{tmp}/nosuch.npz"], "nosuch.npz: no such file or folder"),
    (["{tmp}/notes.txt"], "notes.txt: cannot be read, truncated or corrupted (not an NPZ file)"),
    (["{tmp}/other.npz"], "other.npz: not a qpcontact-colony snapshot"),
    (["{run}", "--out", "{tmp}/cells.xlsx"], "unknown suffix '.xlsx'; a table is written as .csv or .parquet"),
    (["{run}", "--snapshot", "7"], "has no snapshot '7'"),
    (["{tmp}", "--history"], "holds no history.csv"),
    (["{tmp}"], "holds no snapshot"),
    (["{tmp}/other.npz", "--history"], "--history: names a run's folder, but"),
    (["{tmp}/other.npz", "--snapshot", "3"], "--snapshot 3: names a snapshot of a run's folder, but"),
    (["{run}", "--history", "--snapshot", "3"], "not allowed with argument"),
])
def test_a_bad_table_source_is_one_line_and_exit_2(run, tmp_path, capsys, argv, message):
    (tmp_path / "notes.txt").write_text("not a snapshot")
    np.savez(tmp_path / "other.npz", centers=np.zeros((1, 3)))
    argv = [a.format(tmp=tmp_path, run=run) for a in argv]
    assert main(["table", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err


def test_without_pandas_the_dataframes_and_parquet_name_the_extra(run, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas raises ImportError
    with pytest.raises(qc.NotInstalledError, match=r"DataFrames need pandas: pip install 'qpcontact\[table\]'"):
        qc.colony_frame(run)
    with pytest.raises(qc.NotInstalledError, match="DataFrames need pandas"):
        qc.run_frame(run)
    assert main(["table", str(run), "--out", str(tmp_path / "cells.parquet")]) == 2
    assert "Parquet files need pandas and pyarrow (pandas is missing): pip install 'qpcontact[table]'" in \
        capsys.readouterr().err
    assert main(["table", str(run), "--out", str(tmp_path / "cells.csv")]) == 0  # CSV needs no pandas


def test_colony_frame_and_run_frame_are_dataframes_of_the_run(run, tmp_path):
    pandas = pytest.importorskip("pandas", reason="DataFrames need the extra qpcontact[table]")
    snapshot = load_snapshot(last(run))
    frame = qc.colony_frame(last(run))
    assert frame.attrs == {"time": snapshot.colony.time, "step": snapshot.step, "path": str(last(run))}
    expected = pandas.DataFrame(colony_columns(snapshot.colony, snapshot.mechanics))
    pandas.testing.assert_frame_equal(frame, expected)
    assert frame["id"].dtype == np.int64 and frame["cell_type"].dtype == np.int64
    for source in (run, snapshot):
        pandas.testing.assert_frame_equal(qc.colony_frame(source), expected)
    plain = qc.colony_frame(snapshot.colony)  # a Colony: no mechanics unless given
    assert "pressure" not in plain and plain.attrs == {"time": snapshot.colony.time, "step": -1}
    history = qc.run_frame(run)
    assert list(history) == list(HISTORY_FIELDS) and history["step"].tolist() == list(range(len(history)))
    assert history["cells"].dtype == np.int64 and history["cells"].iloc[-1] == snapshot.colony.cells.n
    pandas.testing.assert_frame_equal(history, pandas.read_csv(run / "history.csv"), check_dtype=False)
    with pytest.raises(qc.InvalidArgumentError, match="expected a Colony, a Snapshot"):
        qc.colony_frame(42)


def test_table_writes_parquet_with_the_extra(run, tmp_path, capsys):
    pandas = pytest.importorskip("pandas", reason="Parquet files need the extra qpcontact[table]")
    pytest.importorskip("pyarrow", reason="Parquet files need the extra qpcontact[table]")
    out = tmp_path / "cells.parquet"
    assert main(["table", str(run), "--out", str(out)]) == 0
    pandas.testing.assert_frame_equal(pandas.read_parquet(out), qc.colony_frame(run))
    assert main(["table", str(run), "--history", "--out", str(out), "--overwrite"]) == 0
    pandas.testing.assert_frame_equal(pandas.read_parquet(out), qc.run_frame(run))


# ------------------------------------------------------------------------------------------
# qpcontact plot
# ------------------------------------------------------------------------------------------
def test_plot_draws_the_last_snapshot_exactly_as_the_run_drew_it(run, tmp_path, capsys):
    out = tmp_path / "again.png"
    assert main(["plot", str(last(run)), "--out", str(out)]) == 0
    assert out.read_bytes() == (run / "colony.png").read_bytes()  # the same picture, byte for byte
    assert main(["plot", str(last(run)), "--out", str(out)]) == 2
    assert "exists; pass --overwrite" in capsys.readouterr().err
    for color in ("cell_type", "pressure", "age"):
        assert main(["plot", str(run), "--color", color, "--out", str(tmp_path / f"{color}.svg")]) == 0
        assert (tmp_path / f"{color}.svg").read_text().startswith("<?xml")


def test_plot_of_a_3d_snapshot_has_the_side_view(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    out = tmp_path / "run3d"
    assert main(["simulate", "--cells", "4", "--dimensions", "3", "--max-dt", "0.1", "--out", str(out),
                 "--quiet"]) == 0
    saved = []
    monkeypatch.setattr(Figure, "savefig", lambda self, path, **kw: saved.append(self))
    assert main(["plot", str(out), "--out", str(tmp_path / "p.png")]) == 0
    assert saved[0].axes[1].get_title() == "side view (from −y)"


def test_plot_default_output_is_the_snapshots_name_in_the_current_folder(run, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["plot", str(run), "--snapshot", "40"]) == 0
    assert (tmp_path / "step_000040.png").stat().st_size > 1000


@pytest.mark.parametrize("argv, message", [
    (["{run}", "--color", "nonsense"], "color: 'nonsense' is none of orientation, pressure, cell_type, age"),
    (["{run}", "--color", "signals"], "color: cell_data 'signals' has (2,) numbers per cell; a colour needs one"),
    (["{run}", "--out", "{tmp}/p.docx"], "unknown picture suffix '.docx'"),
    (["{tmp}/nosuch.npz"], "no such file or folder"),
    (["{tmp}/plain.npz", "--color", "pressure"], "holds no pressure"),
])
def test_a_bad_plot_is_one_line_and_exit_2(run, tmp_path, capsys, argv, message):
    save_colony(tmp_path / "plain.npz", load_snapshot(last(run)).colony)  # without mechanics
    argv = [a.format(tmp=tmp_path, run=run) for a in argv]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "p.png")]
    assert main(["plot", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "p.png").exists()


def test_table_of_statistics_is_one_row_per_statistic_with_its_unit(run, tmp_path, capsys):
    assert main(["table", str(run), "--statistics"]) == 0
    header, rows = read_csv(capsys.readouterr().out)
    assert header == ["statistic", "value", "unit", "definition"]
    by_name = {row[0]: row for row in rows}
    expected = qc.colony_statistics(load_snapshot(last(run)))
    assert float(by_name["packing"][1]) == expected.packing and by_name["nematic_length"][2] == "µm"
    assert 0.5 < expected.packing <= 1.0 and "vertical_fraction" not in by_name  # a 2D run: no 3D rows
    out = tmp_path / "statistics.csv"
    assert main(["table", str(run), "--snapshot", "40", "--statistics", "--out", str(out)]) == 0
    earlier = {row[0]: float(row[1]) for row in read_csv(out.read_text())[1]}
    assert earlier["cells"] == load_snapshot(run / "snapshots" / "step_000040.npz").colony.cells.n
    capsys.readouterr()
    assert main(["table", str(run), "--statistics", "--history"]) == 2
    assert "--statistics: measures a snapshot" in capsys.readouterr().err


def test_plot_writes_the_statistics_under_the_title(run, tmp_path, monkeypatch):
    from qpcontact.io import plots

    titles = []
    real = plots.save_colony_picture
    monkeypatch.setattr(plots, "save_colony_picture", lambda path, cells, title, **kw: titles.append(title) or
                        real(path, cells, title, **kw))
    assert main(["plot", str(run), "--statistics", "--out", str(tmp_path / "s.png")]) == 0
    expected = qc.colony_statistics(load_snapshot(last(run)))
    assert f"packing {expected.packing:.3f}" in titles[0] and "contacts/cell" in titles[0]
