"""ParaView (VTK) files of a colony: one ``.vtu`` per snapshot and a ``.pvd`` time series.

Each ``.vtu`` (VTK XML unstructured grid, written with `meshio <https://github.com/nschloe/meshio>`_,
the optional extra ``qpcontact[vtk]``) holds, for N cells:

- points: the N centres, then the two ends of each cell's axis segment (``c ∓ (l/2)·â``),
  3N points in all;
- cells: a ``vertex`` at each centre (N), and a ``line`` from end to end of each axis (N);
- data on every point and every cell (an end point carries its cell's values): ``axis`` (3,
  unit vector), ``length`` (cylinder length), ``radius``, ``id``, ``parent_id`` (-1 for a
  founder), ``growth_rate`` [1/time], ``velocity`` (3), ``cell_type`` (integer), and each of
  the model's own per-cell arrays (``Colony.cell_data``) under its name (``data_<name>`` if that
  name is one of these; booleans as 0/1; an array of several numbers per cell flattened to
  that many components) — in the colony's units (µm and doubling
  times in ``qpcontact simulate``); with the cells' mechanics (a run's snapshots) also
  ``pressure`` (compressive positive) and ``stress`` (9 components, the 3 × 3 virial stress row
  by row, tension positive; ParaView reads 9 components as a tensor): per footprint area in a
  monolayer [force/µm], per volume in 3D [force/µm²] (:mod:`qpcontact.timestep.mechanics`).

The ``.pvd`` collection lists the files with their simulated time, so that ParaView plays the
run as a time series. To see capsules: open ``colony.pvd``, apply *Tube* to the lines with *Vary
Radius: By Absolute Scalar* on ``radius`` (and *Capping* on), or *Glyph* the centres with a
cylinder oriented by ``axis`` and scaled by ``length``; colour by any of the arrays (e.g.
``pressure``).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..colony.growth import Colony
from ..errors import InvalidArgumentError, NotInstalledError, install_hint
from ..timestep.mechanics import CellMechanics
from .outputs import atomic_write, replacing

#: The arrays on every point and cell, in order.
ARRAYS = ("axis", "length", "radius", "id", "parent_id", "growth_rate", "velocity", "cell_type")
#: The arrays added when the cells' mechanics are given.
MECHANICS_ARRAYS = ("pressure", "stress")


def _meshio() -> Any:
    try:
        import meshio
    except ImportError:
        raise NotInstalledError(f"ParaView files need meshio: {install_hint('vtk')}") from None
    return meshio


def check_installed() -> None:
    """Refuse, before any work, to write ParaView files where meshio is missing.

    Raises:
        NotInstalledError: one line naming the extra to install.
    """
    _meshio()


def available() -> bool:
    """Whether the ParaView files can be written here (meshio is installed)."""
    try:
        _meshio()
    except NotInstalledError:
        return False
    return True


def cell_data(colony: Colony, mechanics: CellMechanics | None = None) -> dict[str, np.ndarray]:
    """The per-cell arrays of :data:`ARRAYS` (and :data:`MECHANICS_ARRAYS` with ``mechanics``),
    then the colony's ``cell_data`` (module docstring)."""
    cells = colony.cells
    data = {"axis": cells.axes, "length": cells.lengths, "radius": cells.radii, "id": colony.ids,
            "parent_id": colony.parent_ids, "growth_rate": colony.rates, "velocity": cells.velocities,
            "cell_type": colony.cell_types}
    if mechanics is not None:
        data.update(pressure=mechanics.pressure, stress=mechanics.stress.reshape(cells.n, 9))
    for name, values in colony.cell_data.items():
        values = values.astype(np.int8) if values.dtype.kind == "b" else values
        key = f"data_{name}" if name in ARRAYS or name in MECHANICS_ARRAYS else name
        data[key] = values.reshape(cells.n, -1) if values.ndim > 2 else values
    return data


def colony_mesh(colony: Colony, mechanics: CellMechanics | None = None) -> Any:
    """The colony as a ``meshio.Mesh`` (module docstring)."""
    meshio = _meshio()
    cells = colony.cells
    n = cells.n
    half = 0.5 * cells.lengths[:, None] * cells.axes
    ends = np.stack([cells.centers - half, cells.centers + half], axis=1).reshape(2 * n, 3)
    per_cell = cell_data(colony, mechanics)
    point_data = {name: np.concatenate([values, np.repeat(values, 2, axis=0)]) for name, values in per_cell.items()}
    blocks = [("vertex", np.arange(n)[:, None]), ("line", n + np.arange(2 * n).reshape(n, 2))]
    return meshio.Mesh(np.concatenate([cells.centers, ends]), blocks, point_data=point_data,
                       cell_data={name: [values, values] for name, values in per_cell.items()})


def write_vtu(path: str | Path, colony: Colony, step: int = -1, *, mechanics: CellMechanics | None = None) -> Path:
    """Write the colony as a ``.vtu`` file (atomically), with the cells' pressure and stress
    when ``mechanics`` is given. ``step`` is for the caller's records. Returns the path."""
    mesh = colony_mesh(colony, mechanics)
    with replacing(path) as temporary:
        _meshio().write(temporary, mesh, file_format="vtu")
    return Path(path)


def write_series(path: str | Path, entries: Sequence[tuple[float, Path]]) -> Path:
    """Write a ParaView collection (``.pvd``) of ``(time, file)`` entries, files relative to it."""
    path = Path(path)
    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    collection = ET.SubElement(root, "Collection")
    for time, file in sorted(entries, key=lambda entry: entry[0]):
        ET.SubElement(collection, "DataSet", timestep=repr(float(time)), group="", part="0",
                      file=Path(os.path.relpath(file, path.parent)).as_posix())
    ET.indent(root)
    return atomic_write(path, lambda fh: ET.ElementTree(root).write(fh, encoding="utf-8", xml_declaration=True))


def read_series(path: str | Path) -> list[tuple[float, Path]]:
    """The ``(time, file)`` entries of a ``.pvd`` file (files as paths next to it).

    Raises:
        InvalidArgumentError: not a ParaView collection.
    """
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
        entries = [(float(item.attrib["timestep"]), path.parent / item.attrib["file"])
                   for item in root.iter("DataSet")]
    except (ET.ParseError, KeyError, ValueError, OSError) as exc:
        raise InvalidArgumentError(f"{path}: not a ParaView collection ({exc})") from None
    if root.tag != "VTKFile" or root.attrib.get("type") != "Collection":
        raise InvalidArgumentError(f"{path}: not a ParaView collection")
    return entries


def write_time_series(folder: str | Path, colonies: Sequence[tuple[int, Colony]], name: str = "colony") -> list[Path]:
    """Write ``folder/vtk/step_NNNNNN.vtu`` for each ``(step, colony)`` and ``folder/<name>.pvd``
    listing them (e.g. from snapshots: ``[(step, colony) for colony, step in map(load_colony, files)]``).
    Returns the files written."""
    folder = Path(folder)
    files = [write_vtu(folder / "vtk" / f"step_{step:06d}.vtu", colony, step) for step, colony in colonies]
    series = write_series(folder / f"{name}.pvd", [(colony.time, f) for (_, colony), f in zip(colonies, files, strict=True)])
    return [*files, series]
