"""Colony snapshots as NPZ files (one per saved step), loadable back into a :class:`Colony`; and
the one mapping between :class:`~qpcontact.Cells` and NPZ arrays (:func:`cell_arrays`,
:func:`cells_from_arrays`), which the benchmark's scene cache uses too (:func:`save_cells`,
:func:`load_cells`: the cell arrays alone, same names).

Format (``numpy.savez_compressed``; every array is plain NumPy, no pickles):

===================  ===========  ==========================================================
key                  shape        meaning
===================  ===========  ==========================================================
``format``           ()           the string ``"qpcontact-colony"``
``version``          ()           format version (int, currently 1)
``time``             ()           simulated time [time]
``step``             ()           step index (int; -1 if unknown)
``next_id``          ()           the id the next newborn cell gets
``centers``          (N, 3)       :class:`qpcontact.Cells` fields, same names and units
``axes``             (N, 3)
``lengths``          (N,)
``radii``            (N,)
``masses``           (N,)         ``inf`` = fixed cell
``growth_inertia``   (N,)         ``inf`` = non-growing cell
``momenta``          (N, 3)
``angular_momenta``  (N, 3)
``growth_momenta``   (N,)
``ids``              (N,)         cell ids (int64)
``parent_ids``       (N,)         mother's id, -1 for a founder
``rates``            (N,)         growth rate [1/time]
``owed``             (N,)         length still owed from division [length]
===================  ===========  ==========================================================

Read one with plain NumPy (``np.load(path)["centers"]``) or with :func:`load_colony`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InvalidArgumentError
from ..geometry import Cells
from .growth import Colony

FORMAT = "qpcontact-colony"
VERSION = 1
CELL_FIELDS = tuple(f.name for f in dataclasses.fields(Cells))
COLONY_FIELDS = ("ids", "parent_ids", "rates", "owed")


def cell_arrays(cells: Cells) -> dict[str, Any]:
    """The arrays of :class:`~qpcontact.Cells`, by field name (:data:`CELL_FIELDS`)."""
    return {name: getattr(cells, name) for name in CELL_FIELDS}


def cells_from_arrays(data: Mapping[str, Any]) -> Cells:
    """:class:`~qpcontact.Cells` from arrays named as its fields (e.g. an opened NPZ file)."""
    return Cells(**{name: data[name] for name in CELL_FIELDS})


def save_cells(path: str | Path, cells: Cells) -> Path:
    """Write the cell arrays alone to ``path`` (``.npz``, uncompressed; parent folders are
    created). Written to a temporary file first, so a reader never sees half a file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, **cell_arrays(cells))
    tmp.replace(path)
    return path


def load_cells(path: str | Path) -> Cells:
    """Read cells written by :func:`save_cells` (or the cell arrays of a colony snapshot)."""
    with np.load(Path(path), allow_pickle=False) as data:
        return cells_from_arrays(data)


def save_colony(path: str | Path, colony: Colony, step: int = -1) -> Path:
    """Write ``colony`` to ``path`` (an ``.npz`` file; parent folders are created)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = cell_arrays(colony.cells)
    arrays.update({name: getattr(colony, name) for name in COLONY_FIELDS})
    np.savez_compressed(path, format=np.array(FORMAT), version=np.array(VERSION), time=np.array(colony.time),
                        step=np.array(step), next_id=np.array(colony.next_id), **arrays)
    return path


def load_colony(path: str | Path) -> tuple[Colony, int]:
    """Read a snapshot written by :func:`save_colony`. Returns ``(colony, step)``.

    Raises:
        InvalidArgumentError: the file is not a qpcontact colony snapshot, or of a newer version,
            or misses a field.
    """
    with np.load(Path(path), allow_pickle=False) as data:
        if "format" not in data or str(data["format"]) != FORMAT:
            raise InvalidArgumentError(f"{path}: not a {FORMAT} snapshot")
        if int(data["version"]) > VERSION:
            raise InvalidArgumentError(f"{path}: snapshot version {int(data['version'])} is newer than this qpcontact ({VERSION})")
        missing = [k for k in (*CELL_FIELDS, *COLONY_FIELDS, "time", "step", "next_id") if k not in data]
        if missing:
            raise InvalidArgumentError(f"{path}: snapshot misses {missing}")
        cells = cells_from_arrays(data)
        colony = Colony(cells, data["ids"], data["parent_ids"], data["rates"], data["owed"],
                        time=float(data["time"]), next_id=int(data["next_id"]))
        return colony, int(data["step"])
