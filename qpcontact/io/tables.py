"""Tables of a colony run: one row per cell of a snapshot, one row per step of a run.

- :func:`colony_columns`: the cells of a colony or snapshot as named columns (NumPy arrays), in
  this order: ``id``, ``parent_id`` (-1 for a founder), ``cell_type``, ``x``, ``y``, ``z`` (the
  centre), ``axis_x``, ``axis_y``, ``axis_z`` (the unit axis), ``length`` (of the cylinder),
  ``radius``, ``rate`` (elongation rate [1/time]), ``owed`` (length still owed from division);
  with the cells' mechanics (a run's snapshots) ``pressure`` and the nine components of the
  stress, ``stress_xx``, ``stress_xy``, ... ``stress_zz`` (row by row; units:
  :mod:`qpcontact.timestep.mechanics`); then each of the model's own per-cell arrays
  (``Colony.cell_data``) under its name (``name_0``, ``name_1``, ... for several numbers per
  cell; ``data_<name>`` if the name is taken above). Lengths in µm and time in doubling times
  for a run of ``qpcontact simulate``.
- :func:`colony_frame`, :func:`run_frame`: the same as pandas DataFrames, and a run's time series
  (``history.csv``; columns :data:`~qpcontact.io.runs.HISTORY_FIELDS`). pandas is the
  optional extra ``qpcontact[table]`` (with pyarrow, for Parquet files); it is imported only
  by these.
- :func:`statistics_columns`: the statistics of a snapshot's colony
  (:func:`qpcontact.colony.colony_statistics`) as a table: one row per statistic, columns
  :data:`STATISTICS_COLUMNS` (``statistic``, ``value``, ``unit``, ``definition``).
- ``qpcontact table RUN_OR_SNAPSHOT``: a snapshot's cells (or, for a run folder, those of its
  latest snapshot, ``--snapshot N``, or its time series, ``--history``), or its statistics
  (``--statistics``), as CSV on stdout or in ``--out FILE.csv`` (no pandas needed), or as
  Parquet (``--out FILE.parquet``, needs the extra), written atomically and never over an
  existing file without ``--overwrite``.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

from ..colony.growth import Colony
from ..colony.statistics import colony_statistics
from ..errors import InvalidArgumentError, NotInstalledError, OutputFolderError, install_hint
from ..timestep.mechanics import CellMechanics
from .outputs import atomic_write
from .runs import HISTORY_FIELDS, RunFolder, latest_snapshot
from .snapshots import Snapshot, load_snapshot

#: The extra that :func:`colony_frame`, :func:`run_frame` and Parquet files need.
EXTRA = install_hint("table")
#: The columns of every cell table, in order (the mechanics and ``cell_data`` columns follow).
CELL_COLUMNS = ("id", "parent_id", "cell_type", "x", "y", "z", "axis_x", "axis_y", "axis_z", "length", "radius", "rate",
                "owed")
#: The columns of the cells' mechanics, when the snapshot has them.
MECHANICS_COLUMNS = ("pressure", *(f"stress_{a}{b}" for a in "xyz" for b in "xyz"))
#: The files ``qpcontact table --out`` writes, by suffix.
SUFFIXES = (".csv", ".parquet")
#: The columns of a table of statistics (``qpcontact table --statistics``), one row per statistic.
STATISTICS_COLUMNS = ("statistic", "value", "unit", "definition")
#: History columns that count (integers in a table).
_COUNTS = ("step", "cells", "contacts", "rejected", "linearizations")


def colony_columns(colony: Colony, mechanics: CellMechanics | None = None) -> dict[str, np.ndarray]:
    """The colony's cells as named columns, one entry per cell (module docstring), with the
    pressure and stress columns when ``mechanics`` is given."""
    cells = colony.cells
    columns: dict[str, np.ndarray] = {"id": colony.ids, "parent_id": colony.parent_ids, "cell_type": colony.cell_types}
    columns.update(zip(("x", "y", "z"), cells.centers.T, strict=True))
    columns.update(zip(("axis_x", "axis_y", "axis_z"), cells.axes.T, strict=True))
    columns.update(length=cells.lengths, radius=cells.radii, rate=colony.rates, owed=colony.owed)
    if mechanics is not None:
        columns["pressure"] = mechanics.pressure
        columns.update(zip(MECHANICS_COLUMNS[1:], mechanics.stress.reshape(cells.n, 9).T, strict=True))
    for name, values in colony.cell_data.items():
        key = f"data_{name}" if name in columns or name in MECHANICS_COLUMNS else name
        if values.ndim == 1:
            columns[key] = values
        else:
            columns.update((f"{key}_{i}", column) for i, column in enumerate(values.reshape(cells.n, -1).T))
    return columns


def statistics_columns(snapshot: Snapshot | Colony) -> dict[str, np.ndarray]:
    """The statistics of a snapshot's (or a colony's) state as columns :data:`STATISTICS_COLUMNS`:
    one row per statistic, each bin of a profile a row (:meth:`ColonyStatistics.rows
    <qpcontact.colony.ColonyStatistics.rows>`); values NaN where a statistic does not apply."""
    rows = colony_statistics(snapshot).rows()
    return {"statistic": np.array([r[0] for r in rows]), "value": np.array([r[1] for r in rows], dtype=float),
            "unit": np.array([r[2] for r in rows]), "definition": np.array([r[3] for r in rows])}


def _pandas() -> Any:
    try:
        import pandas
    except ImportError:
        raise NotInstalledError(f"DataFrames need pandas: {EXTRA}") from None
    return pandas


def colony_frame(source: Colony | Snapshot | str | Path, mechanics: CellMechanics | None = None) -> Any:
    """One row per cell (:func:`colony_columns`) as a ``pandas.DataFrame``.

    Args:
        source: a :class:`~qpcontact.Colony`, a :class:`~qpcontact.io.Snapshot`, a snapshot
            file (``.npz``), or a run's folder (its latest snapshot).
        mechanics: the cells' pressure and stress, for a Colony (a snapshot's own are used).

    Returns:
        The DataFrame; ``attrs`` holds ``time`` [doubling times in a run], ``step`` (-1 unknown)
        and, for a file, ``path``.

    Raises:
        NotInstalledError: pandas is not installed (the extra ``qpcontact[table]``); InvalidArgumentError: a file
            or folder that is no snapshot or run (:class:`~qpcontact.errors.InvalidSnapshotError`,
            :class:`~qpcontact.errors.OutputFolderError`).
    """
    pandas = _pandas()
    step, path = -1, None
    if isinstance(source, (str, Path)):
        source = load_snapshot(snapshot_file(source))
    if isinstance(source, Snapshot):
        colony, mechanics, step, path = source.colony, source.mechanics, source.step, source.path
    elif isinstance(source, Colony):
        colony = source
    else:
        raise InvalidArgumentError(f"source: expected a Colony, a Snapshot, or the path of a snapshot or a run's "
                                   f"folder, got {type(source).__name__}")
    frame = pandas.DataFrame(colony_columns(colony, mechanics))
    frame.attrs.update(time=colony.time, step=step)
    if path is not None:
        frame.attrs["path"] = str(path)
    return frame


def run_frame(folder: str | Path) -> Any:
    """A run's time series (its ``history.csv``: one row per step, columns
    :data:`~qpcontact.io.runs.HISTORY_FIELDS`, counts as integers) as a ``pandas.DataFrame``.

    Raises:
        NotInstalledError: pandas is not installed; InvalidArgumentError: the folder has no history or not a run's.
    """
    pandas = _pandas()
    return pandas.DataFrame(history_columns(folder))


def history_columns(folder: str | Path) -> dict[str, np.ndarray]:
    """A run's ``history.csv`` as named columns (counts as integers, the rest floats).

    Raises:
        OutputFolderError: no run folder, no history, or a file that is not a run's history.
    """
    run = RunFolder(Path(folder))
    if not run.history_path.is_file():
        raise OutputFolderError(f"{folder}: holds no history.csv (not a qpcontact run's folder)")
    return {name: np.array(values, dtype=np.int64 if name in _COUNTS else float)
            for name, values in run.read_history().items()}


def snapshot_file(source: str | Path, snapshot: str | None = None) -> Path:
    """The snapshot ``source`` names: a snapshot file, or a run folder's latest snapshot (or
    its ``snapshot``: a step number, or a file name in its ``snapshots/``).

    Raises:
        InvalidArgumentError: nothing at ``source``; ``snapshot`` given with a file; no such
            snapshot in the folder.
        OutputFolderError: a folder without snapshots.
    """
    path = Path(source)
    if path.is_dir():
        if snapshot is None:
            return latest_snapshot(path)
        name = f"step_{int(snapshot):06d}.npz" if snapshot.isdigit() else snapshot
        found = path / "snapshots" / (name if name.endswith(".npz") else f"{name}.npz")
        if not found.is_file():
            raise InvalidArgumentError(f"{path}: has no snapshot {snapshot!r} ({found} does not exist)")
        return found
    if not path.exists():
        raise InvalidArgumentError(f"{path}: no such file or folder")
    if snapshot is not None:
        raise InvalidArgumentError(f"--snapshot {snapshot}: names a snapshot of a run's folder, but {path} is a file")
    return path


# ------------------------------------------------------------------------------------------
# qpcontact table
# ------------------------------------------------------------------------------------------
def write_csv_columns(fh: IO[str], columns: Mapping[str, np.ndarray]) -> None:
    """The columns as CSV: a header, then one line per row; floats written exactly (the
    shortest text that reads back the same number), booleans as True/False."""
    writer = csv.writer(fh, lineterminator="\n")
    writer.writerow(columns)
    writer.writerows(zip(*(np.asarray(values).tolist() for values in columns.values()), strict=True))


def _rows_as_text(fh: IO[str], header: Sequence[str], rows: Iterable[Mapping[str, str]]) -> None:
    writer = csv.writer(fh, lineterminator="\n")
    writer.writerow(header)
    writer.writerows([row[name] for name in header] for row in rows)


def write_parquet(path: Path, columns: Mapping[str, np.ndarray]) -> Path:
    """The columns as a Parquet file (pandas with pyarrow), atomically.

    Raises:
        NotInstalledError: pandas or pyarrow is missing (naming the extra).
    """
    try:
        import pandas
        import pyarrow  # noqa: F401  (pandas' Parquet engine; imported here for a clear error)
    except ImportError as exc:
        raise NotInstalledError(f"Parquet files need pandas and pyarrow ({exc.name} is missing): {EXTRA}") from None
    frame = pandas.DataFrame(dict(columns))
    return atomic_write(path, lambda fh: frame.to_parquet(fh, engine="pyarrow", index=False))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "A table of a colony run: one row per cell of a snapshot (id, parent_id, cell_type, centre, axis, length, "
        "radius, rate, owed, pressure and stress where the snapshot has them, and the model's own per-cell arrays), "
        "one row per statistic of a snapshot's colony (--statistics), or one row per step of a run (--history). CSV on "
        f"stdout, or --out FILE.csv / FILE.parquet (Parquet needs {EXTRA}).")
    parser.add_argument("source", type=Path, metavar="RUN_OR_SNAPSHOT",
                        help="a snapshot (.npz), or a run's folder (its latest snapshot, --snapshot, or --history)")
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--snapshot", metavar="N|NAME",
                       help="of a run's folder: the snapshot of step N, or the file NAME in its snapshots/")
    which.add_argument("--history", action="store_true", help="of a run's folder: its time series (history.csv)")
    parser.add_argument("--statistics", action="store_true",
                        help="the snapshot's colony statistics instead of its cells: one row per statistic (statistic, "
                             "value, unit, definition): packing, contacts per cell, nematic correlation length, local "
                             "order, edge alignment, lengths, aspect ratio, 3D layers (docs/statistics.md)")
    parser.add_argument("--out", type=Path, metavar="FILE", help="write FILE.csv or FILE.parquet (default: CSV on stdout)")
    parser.add_argument("--overwrite", action="store_true", help="replace --out if it exists (default: refuse)")


def run_command(args: argparse.Namespace) -> int:
    out: Path | None = args.out
    if out is not None:
        if out.suffix.lower() not in SUFFIXES:
            raise InvalidArgumentError(f"--out {out}: unknown suffix {out.suffix!r}; a table is written as "
                                       f"{' or '.join(SUFFIXES)}")
        if out.exists() and not args.overwrite:
            raise OutputFolderError(f"--out {out}: exists; pass --overwrite to replace it")
        if out.is_dir():
            raise OutputFolderError(f"--out {out}: is a folder, not a file")
    if args.history and args.statistics:
        raise InvalidArgumentError("--statistics: measures a snapshot; --history is a run's time series: give one")
    if args.history:
        if not args.source.is_dir():
            raise InvalidArgumentError(f"--history: names a run's folder, but {args.source} is "
                                       f"{'a file' if args.source.exists() else 'not there'}")
        columns = history_columns(args.source)  # checked, whatever is written
        if out is None or out.suffix.lower() == ".csv":  # the rows as the run wrote them: exact
            rows = RunFolder(args.source).read_history_rows()
            return _emit(out, lambda fh: _rows_as_text(fh, HISTORY_FIELDS, rows))
    else:
        snapshot = load_snapshot(snapshot_file(args.source, args.snapshot))
        columns = statistics_columns(snapshot) if args.statistics else colony_columns(snapshot.colony, snapshot.mechanics)
    if out is not None and out.suffix.lower() == ".parquet":
        print(f"wrote {write_parquet(out, columns)}", file=sys.stderr)
        return 0
    return _emit(out, lambda fh: write_csv_columns(fh, columns))


def _emit(out: Path | None, write: Any) -> int:
    """Write the CSV to ``out`` atomically, or to stdout."""
    if out is not None:
        print(f"wrote {atomic_write(out, write, text=True)}", file=sys.stderr)
        return 0
    try:
        write(sys.stdout)
        sys.stdout.flush()
    except BrokenPipeError:  # `qpcontact table ... | head`: the reader has what it wanted
        # Python flushes stdout again at exit: point it at /dev/null so that no error follows.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0


def main(argv: list[str] | None = None) -> int:
    from ..cli import run_standalone

    return run_standalone("qpcontact table", add_arguments, run_command, argv)
