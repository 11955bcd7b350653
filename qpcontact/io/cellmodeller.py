"""CellModeller's saved states as qpcontact colonies: :func:`read_cellmodeller` and the command
``qpcontact import-cellmodeller PICKLE_OR_RUN_FOLDER --out FILE``.

CellModeller (``cellmodeller/CellModeller`` on GitHub) saves a run as a folder of pickles,
``step-NNNNN.pickle``, each written by ``Simulator.writePickle`` during step ``NNNNN`` (counted
from 0), after its physics: the file holds the state after ``NNNNN + 1`` steps. A pickle is a
dict with ``cellStates`` (cell id → ``CellState``, whose attributes are the cell), ``stepNum``,
``lineage`` (daughter id → mother id), ``moduleName`` and ``moduleStr`` (the model and its
source) and, for models with signalling or integrators, their grids and levels (not read here).

What becomes what (CellModeller's ``CLBacterium`` physics, read for this reader at commit
1382c975):

=====================  ==================================================================
CellModeller           qpcontact
=====================  ==================================================================
``pos``                ``Cells.centers`` [µm]
``dir``                ``Cells.axes`` (normalized: CellModeller stores float32)
``length``             ``Cells.lengths``, unchanged: both are the cylinder between the cap
                       centres (``CLBacterium`` puts a cell's ends at ``pos ± dir·length/2``
                       and its caps around them; a daughter is born at
                       ``length/2 − radius``, as in :func:`qpcontact.divide`)
``radius``             ``Cells.radii`` [µm]
``growthRate``         ``Colony.rates``: both grow that length exponentially
                       (``CLBacterium`` sets ``dL/dt = growthRate·L``), in the pickle's own
                       time unit, which the colony's time then has too
``cellType``           ``Colony.cell_types``
``id``, ``lineage``    ``Colony.ids``, ``Colony.parent_ids`` (-1 for a founder)
``stepNum``            the snapshot's step, ``stepNum + 1``; its time is ``(stepNum + 1)·dt``
                       with ``dt = cell.time / stepNum`` (every cell's ``time`` is the start
                       of the last step), or the ``dt`` given
other numbers          ``Colony.cell_data``, by attribute name: the model's own per-cell
                       state (``targetVol``, signals, ``color`` as (N, 3), ...) and
                       CellModeller's ``cellAge``, ``effGrowth``, ``strainRate``, ``cellAdh``
=====================  ==================================================================

Left out, because each is derived from the above or is redone by the next step: ``idx`` (the
row in CellModeller's arrays; cells are ordered by it), ``ends``, ``volume`` (``CLBacterium``
sets it to the length), ``oldLen``, ``startVol``, ``vel``, ``time``, ``neighbours``, ``cts`` and
``divideFlag``. Per-cell values that are not numbers (strings, objects, values some cells lack)
are left out too, each named in :attr:`CellModellerState.left_out`, never silently.

A cell's mass is its volume (qpcontact's convention, :func:`qpcontact.colony.volumes`), its
growth inertia ``growth_inertia_ratio`` times that; the momenta are zero and no length is owed.
The snapshot's settings (:attr:`CellModellerState.settings`) are what the state fixes: the
dimensions (2 when every cell lies in the plane z = 0 along it, else 3), the radius where all
cells share one, the rate where all share one or else ``type_rates`` where the cells of each
type share one, and ``rate_noise`` 0 (CellModeller's daughters inherit their mother's
``growthRate``), so that ``qpcontact simulate --start FILE`` continues the colony as CellModeller
grew it; what the state does not fix is named in :attr:`CellModellerState.notes`, and the rest
(the division length, ...) is qpcontact's default or given on that command line.

**Safety.** Loading a pickle can run any code its author put in it. :func:`load_pickle` builds
only what a CellModeller state holds — ``CellState`` as a plain record of attributes
(:class:`CellState`, no behaviour), NumPy arrays, scalars and dtypes, and Python's plain
containers — and refuses anything else before it is built, with :class:`RefusedPickleError`
naming it (``posix.system``, ``builtins.eval``, ...).
"""

from __future__ import annotations

import argparse
import copyreg
import math
import pickle
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..checks import number
from ..cli import positive_float
from ..colony.growth import Colony, volumes
from ..errors import InvalidArgumentError, InvalidSnapshotError, OutputFolderError, QPContactError, RefusedPickleError
from ..geometry import Cells
from ..timestep.mechanics import CellMechanics  # noqa: F401  (the snapshot's annotations, resolved here by the API reference)
from .snapshots import Snapshot, npz_path, save_colony

__all__ = ["CellModellerState", "CellState", "load_pickle", "read_cellmodeller", "run_pickles"]

#: The extra arrays of an imported state's snapshot: CellModeller's step, time step and the
#: state's largest overlap [fraction of a diameter] (:meth:`CellModellerState.save`).
SOURCE_ARRAYS = ("cellmodeller.step", "cellmodeller.dt", "cellmodeller.max_overlap")
#: A CellModeller run's saved states: ``step-NNNNN.pickle``.
PICKLE_NAME = re.compile(r"step-(\d+)\.pickle")
#: CellState attributes that become the cells and their lineage.
MAPPED = ("id", "pos", "dir", "length", "radius", "growthRate", "cellType")
#: CellState attributes left out, and why.
DERIVED = {
    "idx": "CellModeller's array row (the cells are in its order)",
    "ends": "pos ± dir·length/2",
    "volume": "CLBacterium sets it to the length",
    "oldLen": "the length, kept for CellModeller's strain rate",
    "startVol": "the length at birth",
    "vel": "the last step's displacement",
    "time": "the start of the last step (the snapshot's time)",
    "neighbours": "the contacts, found again by the next step",
    "cts": "the number of contacts, found again by the next step",
    "divideFlag": "set again by the model before each step",
}


class CellState:
    """A CellModeller cell read from a pickle (``CellModeller.CellState.CellState``): its
    attributes, nothing else (no code of CellModeller's runs)."""

    id: int  # set from the pickle, like every other attribute (checked when read)

    def __repr__(self) -> str:
        return f"CellState(id={getattr(self, 'id', '?')})"


def _reconstructor(cls: Any, base: Any, state: Any) -> Any:
    """``copyreg._reconstructor`` (pickle protocols 0 and 1) for the stand-in classes only."""
    if cls is not CellState or base is not object or state is not None:
        raise RefusedPickleError(f"copyreg._reconstructor of {getattr(cls, '__name__', cls)!r}: only CellState is built")
    return copyreg._reconstructor(cls, base, state)  # type: ignore[attr-defined]


def _numpy_builders() -> dict[str, Any]:
    """The functions NumPy's own pickles call to rebuild arrays and scalars, taken from NumPy
    itself (their module is ``numpy.core`` in NumPy 1 and ``numpy._core`` in NumPy 2)."""
    array, scalar = np.zeros(2), np.float32(1.0)
    return {"_reconstruct": array.__reduce__()[0], "scalar": scalar.__reduce__()[0],
            "_frombuffer": array.__reduce_ex__(5)[0]}


def _latin1(text: Any, encoding: str) -> bytes:
    """``_codecs.encode`` as pickles of bytes at protocols 0-2 use it: latin-1 only."""
    if not isinstance(text, str) or encoding not in ("latin1", "latin-1"):
        raise RefusedPickleError(f"_codecs.encode with encoding {encoding!r}")
    return text.encode("latin1")


_NUMPY = _numpy_builders()
#: (module, name) -> what the unpickler builds for it: nothing else is built.
ALLOWED: dict[tuple[str, str], Any] = {
    ("CellModeller.CellState", "CellState"): CellState,
    # the pickles qpcontact cellmodeller writes (qpcontact.cellmodeller.pickles)
    ("qpcontact.cellmodeller.state", "CellState"): CellState,
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): np.dtype,
    **{(f"numpy.{core}.multiarray", name): _NUMPY[name] for core in ("core", "_core") for name in ("_reconstruct", "scalar")},
    **{(f"numpy.{core}.numeric", "_frombuffer"): _NUMPY["_frombuffer"] for core in ("core", "_core")},
    # Python's containers and copyreg: Python 3's names, and Python 2's (as Python 3 writes them
    # at protocols 0-2)
    **{(module, kind.__name__): kind for module in ("builtins", "__builtin__")
       for kind in (set, frozenset, complex, bytearray, object)},
    ("copyreg", "_reconstructor"): _reconstructor,
    ("copy_reg", "_reconstructor"): _reconstructor,
    ("_codecs", "encode"): _latin1,
}


class _Unpickler(pickle.Unpickler):
    """An unpickler that builds only :data:`ALLOWED`."""

    def find_class(self, module: str, name: str) -> Any:
        try:
            return ALLOWED[(module, name)]
        except KeyError:
            raise RefusedPickleError(f"{module}.{name}") from None

    def persistent_load(self, pid: Any) -> Any:
        raise RefusedPickleError("a persistent id (an object stored outside the pickle)")


def load_pickle(path: str | Path) -> Any:
    """The object a pickle holds, built by an unpickler that refuses everything but the classes
    and functions of a CellModeller state (module docstring, "Safety").

    Raises:
        RefusedPickleError: the pickle asks for anything else (nothing of it is run).
        InvalidSnapshotError: the file is missing, truncated or not a pickle.
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            return _Unpickler(fh, encoding="latin1").load()  # latin1: Python 2's str of NumPy's bytes
    except RefusedPickleError as exc:
        raise RefusedPickleError(f"{path}: refused: it asks to build {exc}, which a CellModeller state does not "
                                 "hold (a pickle can run code when loaded; only CellModeller's cell states, NumPy "
                                 "arrays and plain containers are built)") from None
    except FileNotFoundError:
        raise InvalidSnapshotError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InvalidSnapshotError(f"{path}: a folder, not a pickle") from None
    except (OSError, EOFError, pickle.UnpicklingError, ValueError, TypeError, AttributeError, IndexError,
            KeyError, MemoryError, UnicodeDecodeError) as exc:
        raise InvalidSnapshotError(f"{path}: cannot be read as a pickle, truncated or corrupted "
                                   f"({type(exc).__name__}: {exc})") from None


def run_pickles(folder: str | Path) -> dict[int, Path]:
    """The saved states of a CellModeller run folder, by ``stepNum`` (``step-NNNNN.pickle``),
    in order."""
    found = {int(m.group(1)): p for p in Path(folder).iterdir() if (m := PICKLE_NAME.fullmatch(p.name)) and p.is_file()}
    return dict(sorted(found.items()))


def pick_pickle(path: str | Path, step: int | None = None) -> Path:
    """The pickle to read: ``path`` itself, or in a run folder the one of CellModeller step
    ``step`` (its ``stepNum``, as in the file name), by default the last.

    Raises:
        InvalidArgumentError: a step given with a file, a folder without pickles, a step it does
            not have (the steps it has are named), or a path that does not exist.
    """
    path = Path(path)
    if path.is_dir():
        pickles = run_pickles(path)
        if not pickles:
            raise InvalidArgumentError(f"{path}: no CellModeller pickles (step-NNNNN.pickle) in this folder")
        if step is None:
            return pickles[max(pickles)]
        if step not in pickles:
            steps = list(pickles)
            shown = ", ".join(map(str, steps)) if len(steps) <= 12 else f"{len(steps)} steps from {steps[0]} to {steps[-1]}"
            raise InvalidArgumentError(f"{path}: no pickle of step {step} (it has {shown})")
        return pickles[step]
    if not path.exists():
        raise InvalidArgumentError(f"{path}: no such file or folder")
    if step is not None:
        raise InvalidArgumentError(f"{path}: a step is chosen only in a run folder; this is one pickle")
    return path


@dataclass
class CellModellerState(Snapshot):
    """A CellModeller state as a qpcontact snapshot (:class:`~qpcontact.io.Snapshot`:
    ``run_colony(settings, start=state)`` continues it, :meth:`save` writes it for
    ``qpcontact simulate --start``), with what the import left out.

    Attributes (besides the snapshot's):
        cellmodeller_step: the pickle's ``stepNum`` (the snapshot's ``step`` is one more).
        dt: CellModeller's time step [its time unit].
        model: the model's name (``moduleName``).
        left_out: per-cell attributes not imported, by name, with the reason (module docstring).
        notes: what the stored settings could not take from the state (cells that share no
            growth rate, nor one per type; radii that differ).
    """

    cellmodeller_step: int = 0
    dt: float = math.nan
    model: str = ""
    left_out: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def save(self, path: str | Path) -> Path:
        """Write the snapshot (:func:`qpcontact.io.save_colony`, no random state: a run
        started from it draws from its own seed), with where it came from among its extra arrays
        (:data:`SOURCE_ARRAYS`: CellModeller's step, ``dt`` and the largest overlap as measured,
        which ``qpcontact plot`` puts in its title). Returns the path written."""
        from ..geometry.overlap import largest_overlap

        extra = {"cellmodeller.step": np.array([self.cellmodeller_step]), "cellmodeller.dt": np.array([self.dt]),
                 "cellmodeller.max_overlap": np.array([largest_overlap(self.colony.cells)])}
        return save_colony(path, self.colony, self.step, settings=self.settings, extra=extra)


def read_cellmodeller(path: str | Path, *, step: int | None = None, dt: float | None = None,
                      growth_inertia_ratio: float | None = None) -> CellModellerState:
    """Read a CellModeller state (module docstring: what becomes what).

    Args:
        path: a pickle (``step-NNNNN.pickle``) or a run folder of them.
        step: in a run folder, the pickle of this CellModeller step (the ``NNNNN`` of its name;
            default: the last).
        dt: CellModeller's time step [its time unit]; needed only for a pickle of step 0 (the
            cells' time then tells nothing), else taken from the pickle and checked against it.
        growth_inertia_ratio: each cell's growth inertia as a multiple of its mass
            (``[model] growth_inertia_ratio``, dimensionless); default: the model's own
            (:func:`model_gamma`: CellModeller's ``gamma`` over ``muA·(l + 2ρ)`` at the cells'
            median length, as docs/cellmodeller.md explains; 1000 when the pickle holds no model).

    Returns:
        The state (:class:`CellModellerState`), its cells ordered as CellModeller's arrays.

    Raises:
        RefusedPickleError: the pickle asks to build something a CellModeller state does not hold.
        InvalidSnapshotError: not a CellModeller state, or one whose cells fail qpcontact's checks
            (naming the file, the cell and the attribute).
        InvalidArgumentError: bad arguments, a step the folder lacks, a ``dt`` the pickle contradicts.
    """
    dt = number("dt", dt, minimum=0.0, open_minimum=True, allow_none=True)
    growth_inertia_ratio = number("growth_inertia_ratio", growth_inertia_ratio, minimum=0.0, open_minimum=True,
                                  allow_none=True)
    source = pick_pickle(path, step)
    data = load_pickle(source)
    states, step_number, lineage = _contents(source, data)
    cells = sorted(states.values(), key=lambda s: (getattr(s, "idx", 0), s.id))
    columns = {name: _column(source, cells, name) for name in MAPPED}
    centers, axes = _vectors(source, cells, columns["pos"], "pos"), _vectors(source, cells, columns["dir"], "dir")
    lengths, radii = _numbers(source, cells, columns["length"], "length"), _numbers(source, cells, columns["radius"], "radius")
    dt = _time_step(source, cells, step_number, dt)
    model_notes: list[str] = []
    if growth_inertia_ratio is None:
        growth_inertia_ratio = _ratio_of(str(data.get("moduleStr") or ""), lengths, radii, model_notes)
    ids = np.array(columns["id"], dtype=np.int64)
    cell_data, left_out = _own_data(cells)
    try:
        shapes = Cells(centers=centers, axes=axes, lengths=lengths, radii=radii, normalize_axes=True)
        mass = volumes(shapes)
        colony = Colony(
            shapes.replace(masses=mass, growth_inertia=growth_inertia_ratio * mass), ids,
            np.array([lineage.get(int(i), -1) for i in ids], dtype=np.int64),
            _numbers(source, cells, columns["growthRate"], "growthRate"), 0.0, time=(step_number + 1) * dt,
            next_id=max([int(ids.max(initial=-1)), *map(int, lineage), *map(int, lineage.values())]) + 1,
            cell_types=_integers(source, cells, columns["cellType"], "cellType"),
            cell_data=cell_data)
    except QPContactError as exc:
        raise InvalidSnapshotError(f"{source}: {exc}") from None
    settings, notes = _settings(colony)
    settings["model"]["growth_inertia_ratio"] = growth_inertia_ratio
    notes += model_notes + _division_notes(colony, settings, source, dt)
    return CellModellerState(colony, step_number + 1, settings, path=source, cellmodeller_step=step_number, dt=dt,
                             model=str(data.get("moduleName", "")), left_out={**DERIVED, **left_out}, notes=notes)


def model_gamma(source: str) -> tuple[float, float] | None:
    """``(gamma, muA)`` of the ``CLBacterium(...)`` call in a model's source (CellModeller's
    defaults 10 and 1 for those it does not give), or None when the source has no such call or
    gives them as expressions, not numbers."""
    import ast

    try:
        tree = ast.parse(source)
    except (SyntaxError, ValueError):
        return None
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", "")) == "CLBacterium":
            given = {k.arg: k.value for k in node.keywords if k.arg in ("gamma", "muA")}
            try:
                values = {name: float(ast.literal_eval(value)) for name, value in given.items()}
            except (ValueError, TypeError, SyntaxError):
                return None
            return values.get("gamma", 10.0), values.get("muA", 1.0)
    return None


def _ratio_of(source: str, lengths: np.ndarray, radii: np.ndarray, notes: list[str]) -> float:
    """The growth inertia ratio that weighs growth against motion as the model's ``gamma`` does
    (CellModeller's drag: ``muA·(l + 2ρ)`` for motion, ``gamma`` for growth; qpcontact's: the
    mass, the volume, and ``ratio ×`` it), at the cells' median length."""
    found = model_gamma(source)
    if found is None:
        notes.append("the pickle holds no model with a CLBacterium(gamma=...): growth_inertia_ratio is qpcontact's "
                     "1000 (cells keep growing and push their neighbours), not CellModeller's")
        return 1000.0
    gamma, mu = found
    length, radius = float(np.median(lengths)), float(np.median(radii))
    ratio = gamma / (mu * (length + 2 * radius))  # G/m of CellModeller's drag matrix
    notes.append(f"growth_inertia_ratio {ratio:.3g}: CellModeller's gamma {gamma:g} over muA·(length + 2·radius) = "
                 f"{mu * (length + 2 * radius):.3g} at the median length {length:.3g} µm (its growth drag against its "
                 "drag of motion; docs/cellmodeller.md)")
    return float(ratio)


def _division_notes(colony: Colony, settings: dict[str, Any], source: Path, dt: float) -> list[str]:
    """What qpcontact simulate does instead of the model's division and time unit, said."""
    notes = [f"time is CellModeller's own unit (growthRate per that unit; its step dt {dt:g}), not qpcontact's "
             "doubling times"]
    target = colony.cell_data.get("targetVol")
    if target is not None and target.ndim == 1 and target.size:
        length = float(np.median(target))
        if length > 2 * float(np.max(colony.cells.radii)):
            settings["model"]["division_length"] = length
        notes.append(f"qpcontact simulate divides at one division_length ({length:.3g} µm, the cells' median "
                     f"targetVol), not at each cell's targetVol, and newborns keep their mother's; to continue with "
                     f"the model's own rules: qpcontact cellmodeller MODEL.py --start {source} (the model's source "
                     "is in the pickle, moduleStr)")
    return notes


def _settings(colony: Colony) -> tuple[dict[str, Any], list[str]]:
    """The settings the state fixes (module docstring), and what it could not fix."""
    cells, rates, types = colony.cells, colony.rates, colony.cell_types
    planar = bool(np.all(cells.centers[:, 2] == 0.0) and np.all(cells.axes[:, 2] == 0.0))
    model: dict[str, Any] = {"rate_noise": 0.0}
    notes = []
    if np.all(cells.radii == cells.radii[0]):
        model["radius"] = float(cells.radii[0])
    else:
        notes.append("the cells' radii differ: newborn cells keep their mother's, [model] radius is not used")
    per_type = [np.unique(rates[types == k]) for k in range(int(types.max()) + 1)]
    if np.all(rates == rates[0]):
        model["rate"] = float(rates[0])
    elif all(r.size == 1 and r[0] > 0 for r in per_type):  # one rate per type: CellModeller's per-type models
        model["type_rates"] = [float(r[0]) for r in per_type]
    else:
        notes.append("the cells share no growth rate, nor one per type: newborn cells grow at [model] rate "
                     "(--rate, or --type-rates one per type)")
    return {"run": {"dimensions": 2 if planar else 3}, "model": model}, notes


def _contents(path: Path, data: Any) -> tuple[dict[int, CellState], int, dict[int, int]]:
    """The cell states, ``stepNum`` and lineage of a CellModeller pickle, checked."""
    if not isinstance(data, dict) or "cellStates" not in data:
        kind = f"a dict with {', '.join(map(repr, list(data)[:6]))}" if isinstance(data, dict) else type(data).__name__
        raise InvalidSnapshotError(f"{path}: not a CellModeller state (expected a dict with cellStates, stepNum and "
                                   f"lineage; got {kind})")
    states, step, lineage = data["cellStates"], data.get("stepNum"), data.get("lineage", {})
    if not isinstance(states, dict) or not states:
        raise InvalidSnapshotError(f"{path}: cellStates must be a non-empty dict of cells")
    if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or step < 0:
        raise InvalidSnapshotError(f"{path}: stepNum must be an integer >= 0, got {step!r}")
    if not isinstance(lineage, dict) or not all(_is_id(k) and _is_id(v) for k, v in lineage.items()):
        raise InvalidSnapshotError(f"{path}: lineage must map cell ids to their mothers' ids (integers >= 0)")
    for key, state in states.items():
        if not isinstance(state, CellState):
            raise InvalidSnapshotError(f"{path}: cellStates[{key!r}] is a {type(state).__name__}, not a CellState")
        if not _is_id(getattr(state, "id", None)) or state.id != key:
            raise InvalidSnapshotError(f"{path}: cellStates[{key!r}] has id {getattr(state, 'id', None)!r}; "
                                       "expected its key, an integer >= 0")
    return states, int(step), {int(k): int(v) for k, v in lineage.items()}


def _is_id(value: Any) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool) and bool(value >= 0)


def _column(path: Path, cells: list[CellState], name: str) -> list[Any]:
    """Attribute ``name`` of every cell; a cell without it raises, naming it."""
    try:
        return [getattr(cell, name) for cell in cells]
    except AttributeError:
        missing = next(cell for cell in cells if not hasattr(cell, name))
        raise InvalidSnapshotError(f"{path}: cell {missing.id} has no {name}") from None


def _numbers(path: Path, cells: list[CellState], values: list[Any], name: str) -> np.ndarray:
    out = _numeric(values)
    if out is None or out.shape != (len(cells),) or not np.all(np.isfinite(out)):
        raise InvalidSnapshotError(f"{path}: {name} must be one finite number per cell, got "
                                   f"{_first_bad(cells, values)}")
    return out.astype(np.float64)


def _integers(path: Path, cells: list[CellState], values: list[Any], name: str) -> np.ndarray:
    out = _numeric(values)
    if out is None or out.shape != (len(cells),) or out.dtype.kind not in "iu":
        raise InvalidSnapshotError(f"{path}: {name} must be one integer per cell, got {_first_bad(cells, values)}")
    return out.astype(np.int64)


def _vectors(path: Path, cells: list[CellState], values: list[Any], name: str) -> np.ndarray:
    out = _numeric(values)
    if out is None or out.shape != (len(cells), 3) or not np.all(np.isfinite(out)):
        raise InvalidSnapshotError(f"{path}: {name} must be three finite numbers per cell, got "
                                   f"{_first_bad(cells, values)}")
    return out.astype(np.float64)


def _numeric(values: list[Any]) -> np.ndarray | None:
    """The values as one array of numbers (bool, int, float; NumPy's too), or None if they are
    not (strings, objects, ragged)."""
    try:
        out = np.array(values)
    except (TypeError, ValueError):
        return None
    return out if out.dtype.kind in "biuf" else None


def _first_bad(cells: list[CellState], values: list[Any]) -> str:
    return "; ".join(f"cell {cell.id}: {value!r}"[:80] for cell, value in list(zip(cells, values, strict=True))[:2])


def _time_step(path: Path, cells: list[CellState], step_number: int, dt: float | None) -> float:
    """CellModeller's time step: every cell's ``time`` is ``stepNum·dt`` (the start of the step
    during which the pickle was written)."""
    times = _numeric([getattr(cell, "time", math.nan) for cell in cells])
    if times is None or times.dtype.kind not in "iuf" or not np.all(np.isfinite(times)) or np.ptp(times) != 0:
        if dt is None:
            raise InvalidArgumentError(f"{path}: the cells carry no common time; give CellModeller's time step "
                                       "(dt, --dt)")
        return dt
    if step_number == 0:
        if dt is None:
            raise InvalidArgumentError(f"{path}: a pickle of step 0 does not tell CellModeller's time step; give it "
                                       "(dt, --dt; CellModeller's Scripts/batch.py uses 0.025)")
        return dt
    found = float(times[0]) / step_number
    if dt is not None and not math.isclose(dt, found, rel_tol=1e-6):
        raise InvalidArgumentError(f"{path}: dt {dt:g} contradicts the pickle, whose cells are at time {times[0]:g} "
                                   f"at step {step_number} (dt {found:g})")
    if not found > 0:
        raise InvalidSnapshotError(f"{path}: the cells' time {times[0]!r} at step {step_number} gives no time step > 0")
    return found


def _own_data(cells: list[CellState]) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """The per-cell numbers that are neither mapped nor derived (:data:`MAPPED`,
    :data:`DERIVED`), as ``Colony.cell_data``; and what else is left out, with the reason."""
    names = sorted({name for cell in cells for name in vars(cell)} - set(MAPPED) - set(DERIVED))
    data, left_out = {}, {}
    for name in names:
        if not all(name in vars(cell) for cell in cells):
            left_out[name] = "only some cells have it"
            continue
        values = _numeric([vars(cell)[name] for cell in cells])
        if values is None or not name.isidentifier():
            left_out[name] = "not a number (or a list of numbers) per cell"
            continue
        data[name] = values
    return data, left_out


OUTPUTS_HELP = "the snapshot to write (.npz appended if missing), for qpcontact simulate --start"


def _show(value: Any) -> str:
    return ", ".join(f"{v:g}" for v in value) if isinstance(value, list) else f"{value:g}"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = ("Read a CellModeller state (a step-NNNNN.pickle, or a run folder of them: its last step, "
                          "or --step) into a qpcontact snapshot that 'qpcontact simulate --start FILE' continues: "
                          "cells, lineage, growth rates, cell types and the model's own per-cell numbers. Only "
                          "what a CellModeller state holds is built from the pickle; anything else is refused.")
    parser.add_argument("source", type=Path, metavar="PICKLE_OR_RUN_FOLDER",
                        help="a CellModeller pickle (step-NNNNN.pickle) or a run folder of them")
    parser.add_argument("--out", type=Path, required=True, metavar="FILE", help=OUTPUTS_HELP)
    parser.add_argument("--step", type=int, metavar="N",
                        help="in a run folder, the pickle of CellModeller step N (step-N.pickle; default: the last)")
    parser.add_argument("--dt", type=positive_float, metavar="DT",
                        help="CellModeller's time step [its time unit]; needed only for a pickle of step 0 (default: "
                             "from the pickle)")
    parser.add_argument("--growth-inertia-ratio", type=positive_float, metavar="R",
                        help="each cell's growth inertia as a multiple of its mass [dimensionless] (default: the "
                             "model's CLBacterium gamma as that ratio, docs/cellmodeller.md; 1000 without a model)")
    parser.add_argument("--overwrite", action="store_true", help="replace --out if it exists (default: refuse)")


def run_command(args: argparse.Namespace) -> int:
    from .outputs import prepare_folder

    if args.out.is_dir():
        raise InvalidArgumentError(f"--out {args.out}: a folder; give the snapshot's file name")
    out = npz_path(args.out)
    if out.exists() and not args.overwrite:
        raise OutputFolderError(f"--out {out} exists; pass --overwrite to replace it, or choose another file")
    state = read_cellmodeller(args.source, step=args.step, dt=args.dt, growth_inertia_ratio=args.growth_inertia_ratio)
    prepare_folder(out.parent)  # created and writable; the snapshot replaces the file atomically
    state.save(out)
    colony = state.colony
    types = ", ".join(f"{t}: {c}" for t, c in zip(*np.unique(colony.cell_types, return_counts=True), strict=True))
    own = [name for name in state.left_out if name not in DERIVED]
    print(f"{state.path}: CellModeller step {state.cellmodeller_step} of {state.model or 'its model'} (dt {state.dt:g}): "
          f"{colony.cells.n} cells (types {types}) at t = {colony.time:.6g}, snapshot step {state.step}")
    print(f"  per-cell data kept: {', '.join(colony.cell_data) or 'none'}"
          + (f"; left out (not numbers per cell): {', '.join(own)}" if own else ""))
    print("  settings stored: " + "; ".join(f"{table}.{key} = {_show(value)}" for table, values in
                                            (state.settings or {}).items() for key, value in values.items()))
    for note in state.notes:
        print(f"  note: {note}")
    print(f"wrote {out}\ncontinue it with: qpcontact simulate --start {out} --out FOLDER")
    return 0

