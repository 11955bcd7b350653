"""Colony snapshots as NPZ files (one per saved step), loadable back into a :class:`Colony` and,
with the run's settings, step index and random-generator state, enough to continue a run
exactly (:mod:`qpcontact.io.runs`); and the one mapping between :class:`~qpcontact.Cells`
and NPZ arrays (:func:`cell_arrays`, :func:`cells_from_arrays`), which the benchmark's scene
cache uses too (:func:`save_cells`, :func:`load_cells`: the cell arrays alone, same names).

Format (``numpy.savez_compressed``; every array is plain NumPy, no pickles), version 3:

=====================  ===========  =========================================================
key                    shape        meaning
=====================  ===========  =========================================================
``format``             ()           the string ``"qpcontact-colony"``
``version``            ()           format version (integer: 3; versions 1 and 2 still load)
``time``               ()           simulated time [time], finite
``step``               ()           step index (integer >= -1; -1 if unknown): the number of
                                    steps taken to reach this state
``next_id``            ()           the id the next newborn cell gets (integer)
``centers``            (N, 3)       :class:`qpcontact.Cells` fields, same names and units
``axes``               (N, 3)
``lengths``            (N,)
``radii``              (N,)
``masses``             (N,)         ``inf`` = fixed cell
``growth_inertia``     (N,)         ``inf`` = non-growing cell
``momenta``            (N, 3)
``angular_momenta``    (N, 3)
``growth_momenta``     (N,)
``ids``                (N,)         cell ids (integer dtype, >= 0, unique)
``parent_ids``         (N,)         mother's id (integer dtype), -1 for a founder
``rates``              (N,)         growth rate [1/time], finite, >= 0
``owed``               (N,)         length still owed from division [length], finite, >= 0
``cell_types``         (N,)         each cell's type (integer dtype, >= 0); version 3 (files
                                    of versions 1 and 2 load with every type 0)
*optional (version 2)*
``settings``           ()           JSON object (a string): the run's settings
                                    (:class:`qpcontact.simulation.Settings` fields)
``rng_state``          ()           JSON object (a string): the random generator's state,
                                    ``numpy.random.Generator.bit_generator.state``
``extra.<name>``       any          extra per-run state, arrays keyed by name (letters,
                                    digits, ``_ . -``), e.g. a solver's warm-start data;
                                    numeric or boolean, no objects
``data.<name>``        (N, ...)     a model's own per-cell arrays (``Colony.cell_data``),
                                    keyed by a Python identifier; numeric or boolean; version 3
``qpcontact_version``  ()           the qpcontact version that wrote the file (information)
``pressure``           (N,)         each cell's pressure over the step that led to this state,
                                    compressive positive (:func:`qpcontact.cell_pressure`),
                                    finite
``stress``             (N, 3, 3)    each cell's virial stress, tension positive
                                    (:func:`qpcontact.cell_stress`), finite
``stress_dimensions``  ()           2: stress and pressure per footprint area (a monolayer;
                                    [force/length]); 3: per volume ([force/length²]).
                                    The three come together or not at all
``checksum``           ()           SHA-256 (hex string) of every other array: its name, dtype,
                                    shape and bytes, in the order of the names
                                    (:func:`array_checksum`); written since issue 19
                                    (covers the mechanics keys too)
=====================  ===========  =========================================================

Version 1 is the same without the optional keys and without ``cell_types``; version 2 without
``cell_types`` and ``data.*``. Cell types and a model's per-cell arrays raised the version to 3
so that an older qpcontact refuses such a file instead of continuing a run without them. Files
with the mechanics keys are still version 2: readers that do not know them ignore them, and
files without them load with ``mechanics`` None. A run can start from either
(``qpcontact simulate --start FILE``): from version 1, or a file without ``rng_state``, the
random generator starts from the run's seed. Other tools may write either version.

Snapshots are written through a temporary file and a rename (:func:`qpcontact.io.outputs.atomic_write`),
so a killed process never leaves a truncated one. :func:`load_snapshot` checks everything above
and raises :class:`~qpcontact.errors.InvalidSnapshotError` naming the file and the problem for a
missing, truncated, corrupted or inconsistent file. The checksum catches what the ZIP container's
own CRC cannot: arrays damaged and written again (a flipped byte in a value, a file rewritten by
another tool), which would otherwise load as a valid state. A file without a checksum (written
before it existed, or by another tool) loads as before.

Read one with plain NumPy (``np.load(path)["centers"]``), with :func:`load_colony` (the colony
and its step) or with :func:`load_snapshot` (everything).
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.metadata
import json
import re
import zipfile
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..checks import instance
from ..colony.growth import Colony
from ..errors import InvalidArgumentError, InvalidSnapshotError, QPContactError
from ..geometry import Cells
from ..timestep.mechanics import CellMechanics
from .outputs import atomic_write

FORMAT = "qpcontact-colony"
VERSION = 3
#: Versions :func:`load_snapshot` reads.
SUPPORTED_VERSIONS = (1, 2, 3)
CELL_FIELDS = tuple(f.name for f in dataclasses.fields(Cells))
COLONY_FIELDS = ("ids", "parent_ids", "rates", "owed")
SCALAR_FIELDS = ("time", "step", "next_id")
#: The keys of the cells' mechanics (optional, all three or none).
MECHANICS_FIELDS = ("pressure", "stress", "stress_dimensions")
#: Key of the checksum of the other arrays (:func:`array_checksum`).
CHECKSUM = "checksum"
#: Prefix of the keys of the extra arrays.
EXTRA_PREFIX = "extra."
#: Prefix of the keys of a model's per-cell arrays (``Colony.cell_data``; version 3).
DATA_PREFIX = "data."
_EXTRA_NAME = re.compile(r"[A-Za-z0-9_.\-]+")


@dataclass
class Snapshot:
    """Everything a snapshot holds (:func:`load_snapshot`).

    Attributes:
        colony: the colony.
        step: the step index (-1 if unknown).
        settings: the run's settings as a plain mapping (None if not stored).
        rng_state: ``bit_generator.state`` of the run's random generator (None if not stored).
        extra: the extra arrays, by name.
        version: the file's format version.
        path: where it was read from.
        mechanics: each cell's pressure and stress over the step that led to this state (None
            if not stored).
    """

    colony: Colony
    step: int
    settings: dict[str, Any] | None = None
    rng_state: dict[str, Any] | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    version: int = VERSION
    path: Path | None = None
    mechanics: CellMechanics | None = None

    def generator(self) -> np.random.Generator | None:
        """A random generator in the stored state (None if none is stored)."""
        return None if self.rng_state is None else restore_generator(self.rng_state, self.path)


def cell_arrays(cells: Cells) -> dict[str, Any]:
    """The arrays of :class:`~qpcontact.Cells`, by field name (:data:`CELL_FIELDS`)."""
    return {name: getattr(cells, name) for name in CELL_FIELDS}


def cells_from_arrays(data: Mapping[str, Any]) -> Cells:
    """:class:`~qpcontact.Cells` from arrays named as its fields (e.g. an opened NPZ file)."""
    return Cells(**{name: data[name] for name in CELL_FIELDS})


def npz_path(path: str | Path) -> Path:
    """``path`` with ``.npz`` appended unless it ends so (as NumPy does when it saves)."""
    path = Path(path)
    return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")


def file_path(path: str | Path) -> Path:
    """:func:`npz_path` of a path that names a file: an existing folder is refused rather than
    written beside (``run`` would become ``run.npz`` next to the folder ``run``).

    Raises:
        InvalidArgumentError: not a str or Path, or an existing folder.
    """
    if not isinstance(path, (str, Path)) or str(path) == "":
        raise InvalidArgumentError(f"path: expected a file name (str or pathlib.Path), got {path!r}")
    if Path(path).is_dir():
        raise InvalidArgumentError(f"path: {path} is a folder; give a file name, e.g. {Path(path) / 'colony.npz'}")
    return npz_path(path)


def save_cells(path: str | Path, cells: Cells) -> Path:
    """Write the cell arrays alone to ``path`` (``.npz`` appended if missing; uncompressed; parent
    folders are created), atomically. Returns the path written.

    Raises:
        InvalidArgumentError: ``cells`` is not :class:`~qpcontact.geometry.Cells`, or ``path`` is
            an existing folder (:func:`file_path`).
    """
    instance("cells", cells, Cells, "qpcontact.Cells")
    return atomic_write(file_path(path), lambda fh: np.savez(fh, **cell_arrays(cells)))


def load_cells(path: str | Path) -> Cells:
    """Read cells written by :func:`save_cells` (or the cell arrays of a colony snapshot).

    Raises:
        InvalidSnapshotError: the file is missing, corrupted or misses a cell array.
    """
    data = read_npz(path)
    if "format" in data:  # a colony snapshot: its version and checksum count here too
        _version(path, data)
    _verified(path, data)
    _require(path, data, CELL_FIELDS)
    return _checked(path, lambda: cells_from_arrays(data))


def save_colony(path: str | Path, colony: Colony, step: int = -1, *, settings: Mapping[str, Any] | None = None,
                rng: np.random.Generator | Mapping[str, Any] | None = None,
                extra: Mapping[str, Any] | None = None, mechanics: CellMechanics | None = None) -> Path:
    """Write ``colony`` to ``path`` (format version 3, module docstring), atomically.

    Args:
        path: the file; ``.npz`` is appended unless it ends so. Parent folders are created.
        colony: the colony.
        step: its step index (-1: unknown).
        settings: the run's settings (JSON-serialisable values), stored to continue the run.
        rng: the run's random generator (or its ``bit_generator.state``), stored to continue the
            run on the same random numbers.
        extra: extra arrays by name (e.g. a solver's warm-start data).
        mechanics: each cell's pressure and stress (:class:`~qpcontact.timestep.CellMechanics`),
            stored as ``pressure``, ``stress`` and ``stress_dimensions``.

    Returns:
        The path written.

    Raises:
        InvalidArgumentError: ``colony`` is not a :class:`~qpcontact.colony.Colony`, or ``path``
            is not a file name (an existing folder: the file would be written beside it, as
            ``FOLDER.npz``).
        InvalidSnapshotError: extra arrays that cannot be stored, or mechanics whose shapes do
            not match the colony.
    """
    instance("colony", colony, Colony, "a qpcontact.colony.Colony")
    path = file_path(path)
    arrays: dict[str, Any] = {"format": np.array(FORMAT), "version": np.array(VERSION), "time": np.array(float(colony.time)),
                              "step": np.array(int(step), dtype=np.int64), "next_id": np.array(colony.next_id, dtype=np.int64),
                              "qpcontact_version": np.array(_writer_version())}
    arrays.update(cell_arrays(colony.cells))
    arrays.update({name: getattr(colony, name) for name in COLONY_FIELDS})
    arrays["cell_types"] = colony.cell_types
    arrays.update({DATA_PREFIX + name: value for name, value in colony.cell_data.items()})
    if settings is not None:
        arrays["settings"] = np.array(json.dumps(dict(settings)))
    if rng is not None:
        state = rng.bit_generator.state if isinstance(rng, np.random.Generator) else dict(rng)
        arrays["rng_state"] = np.array(json.dumps(state))
    for name, value in (extra or {}).items():
        value = np.asarray(value)
        if not (isinstance(name, str) and _EXTRA_NAME.fullmatch(name)) or value.dtype.hasobject:
            raise InvalidSnapshotError(f"{path}: extra array {name!r}: names are letters, digits and _ . -, "
                                       "values numeric or boolean arrays")
        arrays[EXTRA_PREFIX + name] = value
    if mechanics is not None:
        n = colony.cells.n
        if np.shape(mechanics.pressure) != (n,) or np.shape(mechanics.stress) != (n, 3, 3):
            raise InvalidSnapshotError(f"{path}: mechanics: expected pressure ({n},) and stress ({n}, 3, 3), got "
                                       f"{np.shape(mechanics.pressure)} and {np.shape(mechanics.stress)}")
        arrays.update(pressure=np.asarray(mechanics.pressure, dtype=float), stress=np.asarray(mechanics.stress, dtype=float),
                      stress_dimensions=np.array(2 if mechanics.planar else 3, dtype=np.int64))
    arrays[CHECKSUM] = np.array(array_checksum({name: np.asarray(value) for name, value in arrays.items()}))
    return atomic_write(path, lambda fh: np.savez_compressed(fh, **arrays))


def array_checksum(arrays: Mapping[str, np.ndarray]) -> str:
    """SHA-256 (hex) of the arrays other than ``checksum``, in the order of their names: each
    name, dtype (``dtype.str``), shape and C-order bytes."""
    digest = hashlib.sha256()
    for name in sorted(arrays):
        if name == CHECKSUM:
            continue
        value = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}\0{value.dtype.str}\0{value.shape}\0".encode())
        digest.update(value.tobytes())
    return digest.hexdigest()


def _verified(path: str | Path, data: Mapping[str, np.ndarray]) -> None:
    """Raise if the file has a checksum and its arrays do not match it."""
    if CHECKSUM not in data:
        return
    stored = data[CHECKSUM]
    if stored.dtype.kind != "U" or stored.shape != () or str(stored) != array_checksum(data):
        raise InvalidSnapshotError(f"{path}: damaged: its arrays do not match the checksum stored with them "
                                   "(a changed value or a corrupted copy); not loaded")


def load_colony(path: str | Path) -> tuple[Colony, int]:
    """Read a snapshot (version 1, 2 or 3). Returns ``(colony, step)``; :func:`load_snapshot` gives
    everything.

    Raises:
        InvalidSnapshotError: see :func:`load_snapshot`.
    """
    snapshot = load_snapshot(path)
    return snapshot.colony, snapshot.step


def read_npz(path: str | Path) -> dict[str, np.ndarray]:
    """Every array of an NPZ file (no pickles), read now.

    Raises:
        InvalidSnapshotError: the file is missing, unreadable, truncated or corrupted, or is
            not an NPZ file.
    """
    try:
        data = np.load(Path(path), allow_pickle=False)
        if not isinstance(data, np.lib.npyio.NpzFile):  # a .npy file: one array, no container to close
            raise InvalidSnapshotError(f"{path}: a single .npy array, not an NPZ snapshot (save_colony writes .npz)")
        with data:
            return {name: data[name] for name in data.files}
    except InvalidSnapshotError:
        raise
    except FileNotFoundError:
        raise InvalidSnapshotError(f"{path}: no such file") from None
    except (OSError, EOFError, ValueError, zipfile.BadZipFile, zlib.error, KeyError) as exc:
        # np.load of a file that is no NPZ (e.g. 1 byte) falls back to a pickle, refused: ValueError.
        reason = "not an NPZ file" if "pickle" in str(exc) else f"{type(exc).__name__}: {exc}"
        raise InvalidSnapshotError(f"{path}: cannot be read, truncated or corrupted ({reason})") from None


def load_snapshot(path: str | Path) -> Snapshot:
    """Read and check a snapshot (version 1, 2 or 3, module docstring).

    Raises:
        InvalidSnapshotError: the file is missing, truncated or corrupted; not a qpcontact colony
            snapshot; of a newer version; misses a field; or holds inconsistent values (NaN
            time, a step or ids that are not integers, cells or lineage that fail their checks,
            settings or random state that are not JSON objects, ...).
    """
    data = read_npz(path)
    version = _version(path, data)
    _verified(path, data)
    _require(path, data, (*CELL_FIELDS, *COLONY_FIELDS, *SCALAR_FIELDS))
    time = data["time"]
    if time.shape != () or time.dtype.kind not in "fiu" or not np.isfinite(time):
        raise InvalidSnapshotError(f"{path}: time must be a finite number, got {time!r}")
    step = _integer(path, data, "step")
    if step < -1:
        raise InvalidSnapshotError(f"{path}: step must be >= -1, got {step}")
    next_id = _integer(path, data, "next_id")
    for name in ("ids", "parent_ids"):
        if data[name].dtype.kind not in "iu":
            raise InvalidSnapshotError(f"{path}: {name} must be integers, got dtype {data[name].dtype}")
    for name in (*CELL_FIELDS, "rates", "owed"):
        if data[name].dtype.kind not in "fiu":
            raise InvalidSnapshotError(f"{path}: {name} must be numbers, got dtype {data[name].dtype}")
    if np.any(data["ids"] < 0) or np.any(data["parent_ids"] < -1):
        raise InvalidSnapshotError(f"{path}: ids must be >= 0 and parent_ids >= -1")
    if version >= 3:
        _require(path, data, ("cell_types",))
    cell_data = {k[len(DATA_PREFIX):]: v for k, v in data.items() if k.startswith(DATA_PREFIX)}
    colony = _checked(path, lambda: Colony(cells_from_arrays(data), data["ids"], data["parent_ids"], data["rates"],
                                           data["owed"], time=float(time), next_id=next_id,
                                           cell_types=data.get("cell_types"), cell_data=cell_data))
    snapshot = Snapshot(colony, step, _json_object(path, data, "settings"), _json_object(path, data, "rng_state"),
                        {k[len(EXTRA_PREFIX):]: v for k, v in data.items() if k.startswith(EXTRA_PREFIX)}, version,
                        Path(path), _mechanics(path, data, colony.cells.n))
    if snapshot.rng_state is not None:
        snapshot.generator()  # checked now, not when the run is half set up
    return snapshot


def _version(path: str | Path, data: Mapping[str, np.ndarray]) -> int:
    """The format version of a colony snapshot; a file that is none, has no version, or one this
    qpcontact cannot read, raises."""
    if "format" not in data or data["format"].dtype.kind != "U" or str(data["format"]) != FORMAT:
        raise InvalidSnapshotError(f"{path}: not a {FORMAT} snapshot")
    _require(path, data, ("version",))
    version = _integer(path, data, "version")
    if version not in SUPPORTED_VERSIONS:
        newer = " (newer than this qpcontact: update qpcontact to read it)" if version > VERSION else ""
        raise InvalidSnapshotError(f"{path}: snapshot version {version}{newer}; this qpcontact reads versions "
                                   f"{', '.join(map(str, SUPPORTED_VERSIONS))}")
    return version


def restore_generator(state: Mapping[str, Any], path: str | Path | None = None) -> np.random.Generator:
    """A ``numpy.random.Generator`` in the given ``bit_generator.state``.

    Raises:
        InvalidSnapshotError: not the state of one of NumPy's bit generators.
    """
    name = state.get("bit_generator") if isinstance(state, Mapping) else None
    kind = getattr(np.random, name, None) if isinstance(name, str) else None
    if not (isinstance(kind, type) and issubclass(kind, np.random.BitGenerator)):
        raise InvalidSnapshotError(f"{path}: rng_state names no NumPy bit generator ({name!r})")
    bit_generator = kind()
    try:
        bit_generator.state = dict(state)
    except (TypeError, ValueError, KeyError, OverflowError) as exc:
        raise InvalidSnapshotError(f"{path}: rng_state is not a valid {name} state ({exc})") from None
    return np.random.Generator(bit_generator)


def _writer_version() -> str:
    try:
        return importlib.metadata.version("qpcontact")
    except importlib.metadata.PackageNotFoundError:  # run from a source tree that is not installed
        return "unknown"


def _require(path: str | Path, data: Mapping[str, Any], names: tuple[str, ...]) -> None:
    missing = [name for name in names if name not in data]
    if missing:
        raise InvalidSnapshotError(f"{path}: misses {', '.join(missing)}")


def _integer(path: str | Path, data: Mapping[str, np.ndarray], name: str) -> int:
    value = data[name]
    if value.shape != () or value.dtype.kind not in "iu":
        raise InvalidSnapshotError(f"{path}: {name} must be an integer, got {value!r}")
    return int(value)


def _json_object(path: str | Path, data: Mapping[str, np.ndarray], name: str) -> dict[str, Any] | None:
    if name not in data:
        return None
    try:
        value = json.loads(str(data[name])) if data[name].dtype.kind == "U" and data[name].shape == () else None
    except json.JSONDecodeError:
        value = None
    if not isinstance(value, dict):
        raise InvalidSnapshotError(f"{path}: {name} must be a JSON object (a string)")
    return value


def _mechanics(path: str | Path, data: Mapping[str, np.ndarray], n: int) -> CellMechanics | None:
    """The cells' pressure and stress, if the file has them (all three keys or none)."""
    if not any(name in data for name in MECHANICS_FIELDS):
        return None
    _require(path, data, MECHANICS_FIELDS)
    dimensions = _integer(path, data, "stress_dimensions")
    pressure, stress = data["pressure"], data["stress"]
    if dimensions not in (2, 3):
        raise InvalidSnapshotError(f"{path}: stress_dimensions must be 2 or 3, got {dimensions}")
    for name, value, shape in (("pressure", pressure, (n,)), ("stress", stress, (n, 3, 3))):
        if value.shape != shape or value.dtype.kind not in "fiu" or not np.all(np.isfinite(value)):
            raise InvalidSnapshotError(f"{path}: {name} must be {shape} finite numbers, got {value.dtype} of shape "
                                       f"{value.shape}")
    return CellMechanics(pressure.astype(float), stress.astype(float), dimensions == 2)


def _checked(path: str | Path, build: Any) -> Any:
    """``build()``, with the cells' and colony's own checks reported as a bad snapshot."""
    try:
        return build()
    except QPContactError as exc:
        raise InvalidSnapshotError(f"{path}: {exc}") from None
