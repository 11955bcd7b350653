"""What a colony run writes so that it loses nothing: its output folder, its history, its
snapshots, and how it continues (its clean stop on Ctrl-C is :mod:`qpcontact.simulation.signals`).

- :class:`RunFolder`: the output folder of one run. :meth:`RunFolder.create` checks it before
  the run starts (created, writable, not holding another run unless ``overwrite``; with
  ``overwrite`` the earlier run's files are removed, none stays stale); :meth:`RunFolder.resume`
  continues the run of a folder from one of its snapshots. It appends one row per step to
  ``history.csv`` as the step completes, writes snapshots atomically
  (:func:`qpcontact.io.snapshots.save_colony`) carrying the settings, the step index and
  the random generator's state, optionally ParaView files (:mod:`qpcontact.io.paraview`),
  and ``config.toml``, and lists what it wrote.
- TOML: :func:`write_toml` / :func:`read_toml`, the settings' tables (``config.toml``).

Resuming: a run continued from a snapshot of step S (``qpcontact simulate --resume`` or
``--start OUT/snapshots/step_S.npz`` with ``--out OUT``) starts at step index S, with the
snapshot's time, random-generator state and settings, and so follows the same trajectory as
the run that was not interrupted, bit for bit
(``tests/io/test_runs.py::test_an_interrupted_and_resumed_run_equals_the_uninterrupted_one``).
Its history rows from step S on replace those of the earlier attempt (which may have gone
further than its last snapshot before being killed); snapshots after S are refused unless
``overwrite`` (they would be replaced).
"""

from __future__ import annotations

import csv
import json
import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .. import moved
from ..colony.growth import Colony
from ..errors import InvalidArgumentError, OutputFolderError
from ..timestep.mechanics import CellMechanics
from .outputs import atomic_write, earlier_outputs, prepare_folder, write_text
from .snapshots import Snapshot, save_colony


def __getattr__(name: str) -> Any:
    """The names that moved out of this module (deprecated; :mod:`qpcontact.moved`)."""
    return moved.attribute(__name__, name, moved.NAMES[__name__])

#: Columns of ``history.csv``, one row per step.
HISTORY_FIELDS = ("step", "time", "dt", "cells", "contacts", "max_overlap", "mean_overlap", "solve_seconds",
                  "step_seconds", "penetration", "complementarity", "rejected", "linearizations", "mean_pressure",
                  "max_pressure")
#: Columns a history written before they existed lacks: read as NaN (not measured).
LATER_FIELDS = ("mean_pressure", "max_pressure")
#: Columns that measure the machine, not the trajectory (they differ between two runs of the
#: same trajectory).
TIMING_FIELDS = ("solve_seconds", "step_seconds")
#: Every file a run writes in its folder (glob patterns, relative to it).
RUN_OUTPUTS = ("config.toml", "history.csv", "snapshots/step_*.npz", "colony.png", "history.png", "colony.gif",
               "colony.pvd", "vtk/step_*.vtu", "pressure.png")
#: Temporary files of writes that a killed process left (``qpcontact.io.outputs.replacing``).
LEFTOVERS = (".*.tmp", "snapshots/.*.tmp", "vtk/.*.tmp")
_STEP_FILE = re.compile(r"step_(\d+)\.(npz|vtu)")


def step_of(path: Path) -> int:
    """The step index in a file name ``step_NNNNNN.npz`` / ``.vtu`` (-1 if it has none)."""
    match = _STEP_FILE.fullmatch(path.name)
    return int(match.group(1)) if match else -1


class RunFolder:
    """The output folder of a run (module docstring). Use :meth:`create` or :meth:`resume`.

    Attributes:
        path: the folder.
        vtk: also write a ParaView file (``vtk/step_NNNNNN.vtu``, listed in ``colony.pvd``) with
            each snapshot.
        written: every file written so far, in order.
    """

    def __init__(self, path: Path, *, vtk: bool = False, first_step: int = 0):
        self.path = Path(path)
        self.vtk = vtk
        self.written: list[Path] = []
        self.first_step = first_step
        self._series: list[tuple[float, Path]] = []

    # -- opening ----------------------------------------------------------------------------
    @classmethod
    def create(cls, path: str | Path, *, overwrite: bool = False, vtk: bool = False, first_step: int = 0) -> RunFolder:
        """A folder for a new run (starting at step index ``first_step``).

        Raises:
            OutputFolderError: it cannot be written, or holds another run and ``overwrite`` is
                False (with ``overwrite`` that run's files are removed now).
        """
        folder = cls(prepare_folder(path, RUN_OUTPUTS + LEFTOVERS, overwrite=overwrite), vtk=vtk, first_step=first_step)
        folder._start_history([])
        return folder

    @classmethod
    def resume(cls, path: str | Path, snapshot: Snapshot, *, overwrite: bool = False, vtk: bool = False) -> RunFolder:
        """The folder of an interrupted run, continued from one of its snapshots.

        The history keeps the rows before the snapshot's step (they must end at the step
        before it); ParaView files after it, and temporary files a killed process left, are
        removed.

        Raises:
            OutputFolderError: the folder cannot be written; it has snapshots after this one
                (pass ``overwrite`` to continue from this one anyway: they are removed); or its
                history does not belong to this snapshot.
        """
        folder = cls(prepare_folder(path), vtk=vtk, first_step=max(snapshot.step, 0))
        start = folder.first_step
        later = sorted((p for p in (folder.path / "snapshots").glob("step_*.npz") if step_of(p) > start), key=step_of)
        if later and not overwrite:
            raise OutputFolderError(
                f"{folder.path}: the run has snapshots after step {start} (the latest is {later[-1].name}); continue "
                f"from the latest (--resume), or pass --overwrite to continue from step {start} and drop them")
        for stale in [*later, *(p for p in (folder.path / "vtk").glob("step_*.vtu") if step_of(p) > start),
                      *earlier_outputs(folder.path, LEFTOVERS)]:
            stale.unlink()
        rows = folder.read_history_rows()
        kept = [row for row in rows if int(row["step"]) < start]
        if kept and int(kept[-1]["step"]) != start - 1:
            raise OutputFolderError(f"{folder.history_path}: ends at step {kept[-1]['step']}, but the snapshot is of "
                                    f"step {start}: they are not of the same run")
        folder._start_history(kept)
        folder._series = [(t, p) for t, p in folder._read_series() if step_of(p) <= start]
        return folder

    # -- history ----------------------------------------------------------------------------
    @property
    def history_path(self) -> Path:
        return self.path / "history.csv"

    def read_history_rows(self) -> list[dict[str, str]]:
        """The rows of ``history.csv`` as text (none if it does not exist).

        A history written before the columns of :data:`LATER_FIELDS` existed is read with them
        as ``nan`` (so an earlier run can be resumed).

        Raises:
            OutputFolderError: it has other columns than :data:`HISTORY_FIELDS`.
        """
        if not self.history_path.exists():
            return []
        earlier = tuple(name for name in HISTORY_FIELDS if name not in LATER_FIELDS)
        with self.history_path.open(newline="") as fh:
            reader = csv.DictReader(fh)
            if tuple(reader.fieldnames or ()) not in (HISTORY_FIELDS, earlier):
                raise OutputFolderError(f"{self.history_path}: not the history of a qpcontact run (columns "
                                        f"{reader.fieldnames})")
            rows = list(reader)
        if any(None in row or None in row.values() for row in rows):
            raise OutputFolderError(f"{self.history_path}: has rows of the wrong length (a truncated file?)")
        return [{**dict.fromkeys(LATER_FIELDS, "nan"), **row} for row in rows]

    def read_history(self) -> dict[str, list[float]]:
        """``history.csv`` by column, as numbers (the whole run, earlier attempts included)."""
        rows = self.read_history_rows()
        return {name: [float(row[name]) for row in rows] for name in HISTORY_FIELDS}

    def _start_history(self, rows: Sequence[Mapping[str, Any]]) -> None:
        def write(fh: Any) -> None:
            writer = csv.DictWriter(fh, fieldnames=HISTORY_FIELDS)
            writer.writeheader()
            writer.writerows(rows)

        self._note(atomic_write(self.history_path, write, text=True))

    def append_history(self, row: Mapping[str, Any]) -> None:
        """Append one step's row (columns :data:`HISTORY_FIELDS`; floats are written exactly)."""
        with self.history_path.open("a", newline="") as fh:
            csv.DictWriter(fh, fieldnames=HISTORY_FIELDS).writerow({name: row[name] for name in HISTORY_FIELDS})

    # -- snapshots and ParaView files -------------------------------------------------------
    def snapshot_path(self, step: int) -> Path:
        return self.path / "snapshots" / f"step_{step:06d}.npz"

    def save_snapshot(self, colony: Colony, step: int, *, settings: Mapping[str, Any] | None = None,
                      rng: np.random.Generator | None = None, extra: Mapping[str, Any] | None = None,
                      mechanics: CellMechanics | None = None) -> Path:
        """Save the state of step ``step`` (atomically; and its ParaView file with ``vtk``), with
        the cells' pressure and stress if ``mechanics`` is given."""
        path = self._note(save_colony(self.snapshot_path(step), colony, step, settings=settings, rng=rng, extra=extra,
                                      mechanics=mechanics))
        if self.vtk:
            from .paraview import write_series, write_vtu  # meshio: only when asked for

            vtu = self._note(write_vtu(self.path / "vtk" / f"step_{step:06d}.vtu", colony, step=step,
                                       mechanics=mechanics))
            self._series = [(t, p) for t, p in self._series if p != vtu] + [(colony.time, vtu)]
            self._note(write_series(self.path / "colony.pvd", self._series))
        return path

    def latest_snapshot(self) -> Path | None:
        """The snapshot of the largest step in the folder (None if there is none)."""
        found = sorted((self.path / "snapshots").glob("step_*.npz"), key=step_of)
        return found[-1] if found else None

    def _read_series(self) -> list[tuple[float, Path]]:
        if not (self.path / "colony.pvd").exists():
            return []
        from .paraview import read_series

        return read_series(self.path / "colony.pvd")

    # -- configuration ----------------------------------------------------------------------
    def write_config(self, values: Mapping[str, Any], comment: str = "") -> Path:
        """``config.toml``: the run's settings (:func:`write_toml`)."""
        return self._note(write_text(self.path / "config.toml", write_toml(values, comment)))

    def note(self, path: Path) -> Path:
        """Record a file written into the folder by someone else (pictures)."""
        return self._note(path)

    def _note(self, path: Path) -> Path:
        if path not in self.written:
            self.written.append(path)
        return path


def latest_snapshot(folder: str | Path) -> Path:
    """The latest snapshot of the run in ``folder``.

    Raises:
        OutputFolderError: the folder has no snapshot.
    """
    found = RunFolder(Path(folder)).latest_snapshot()
    if found is None:
        raise OutputFolderError(f"{folder}: holds no snapshot (snapshots/step_*.npz) to resume from")
    return found


def is_inside(snapshot: Path, folder: Path) -> bool:
    """Whether ``snapshot`` is one of the snapshots of the run in ``folder``."""
    return snapshot.resolve().parent == (folder / "snapshots").resolve()


# -- TOML ---------------------------------------------------------------------------------
def _toml_value(value: Any) -> str:
    if value is None:
        return '"none"'  # TOML has no null; the settings read "none" as None
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a TOML basic string: JSON's escapes are TOML's
    if isinstance(value, (list, tuple)) and not any(isinstance(item, (list, tuple, Mapping)) for item in value):
        return "[" + ", ".join(map(_toml_value, value)) + "]"
    raise InvalidArgumentError(f"TOML: cannot write {value!r} (only numbers, booleans, strings and lists of them, in "
                               "tables)")


def write_toml(values: Mapping[str, Any], comment: str = "") -> str:
    """TOML of numbers, booleans, strings and lists of them (None as ``"none"``), at the top and in one level
    of tables (``{"run": {"cells": 500}}`` is ``[run]`` / ``cells = 500``), with a comment on
    top; read back equal by :func:`read_toml` (floats exactly)."""
    head = "".join(f"# {line}\n" for line in comment.splitlines())
    text = head + "".join(f"{key} = {_toml_value(value)}\n" for key, value in values.items()
                          if not isinstance(value, Mapping))
    for name, values_of_table in values.items():
        if isinstance(values_of_table, Mapping):
            text += f"\n[{name}]\n" + "".join(f"{key} = {_toml_value(value)}\n" for key, value in values_of_table.items())
    return text


def read_toml(path: str | Path) -> dict[str, Any]:
    """A TOML file as a mapping (what its tables and keys mean is the reader's:
    :func:`qpcontact.simulation.settings.file_layer`).

    Raises:
        InvalidArgumentError: the file is missing or not TOML.
    """
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise InvalidArgumentError(f"{path}: no such file") from None
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InvalidArgumentError(f"{path}: not a TOML file ({exc})") from None
