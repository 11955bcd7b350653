"""Load a CellModeller model script and run its ``setup(sim)``: :func:`load_model`.

The model is loaded as CellModeller loads it (a module whose ``setup(sim)`` builds the physics
and the regulation and adds the first cells), with qpcontact's stand-ins for CellModeller's
classes (:mod:`qpcontact.cellmodeller.standins`) and :class:`Simulation` as ``sim``. What it asks
for is checked before anything runs: a signalling grid or an integrator, an unknown
``CLBacterium`` option, a plane or sphere qpcontact cannot honour, or a module that does not
load refuses the model in one line (:class:`~qpcontact.cellmodeller.standins.ModelRefused`, an
:class:`~qpcontact.errors.InvalidArgumentError`: exit status 2 on the command line).

How CellModeller's semantics map onto qpcontact's: docs/cellmodeller.md.
"""

from __future__ import annotations

import importlib.util
import math
import random
import types
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..colony.hooks import _where
from ..errors import InvalidArgumentError
from ..geometry import Plane
from .standins import CLBacterium, ModelRefused, ModuleRegulator, PlaneAsked, SphereAsked, serving
from .state import CellState

#: CellModeller's time step when the model sets none (its Scripts/batch.py) [its time unit].
DEFAULT_DT = 0.025
#: Planes standing for a sphere's wall: a polygon in 2D, a polyhedron in 3D.
SPHERE_PLANES = {2: 64, 3: 256}


class Simulation:
    """The ``sim`` a model's ``setup(sim)`` is given, as CellModeller's ``Simulator``: ``init``,
    ``addCell``, ``addRenderer`` (ignored), ``dt``, ``pickleSteps``, ``moduleName``,
    ``is_gui`` (False), ``cellStates``, ``lineage``, ``saveOutput`` (ignored: the run folder
    and the pickles are always written)."""

    def __init__(self, module: types.ModuleType, name: str, dt: float) -> None:
        self.module = module
        self.moduleName = name
        self.moduleStr = None
        self.is_gui = False
        self.dt = dt
        self.pickleSteps = 50
        self.saveOutput = False
        self.cellStates: dict[int, CellState] = {}
        self.lineage: dict[int, int] = {}
        self.stepNum = 0
        self.phys: CLBacterium | None = None
        self.reg: ModuleRegulator | None = None
        self.sig: Any = None
        self.integ: Any = None
        self.renderers: list[Any] = []
        self.ignored: set[str] = set()
        self._next_id = 1

    def init(self, phys: Any, reg: Any, sig: Any, integ: Any) -> None:
        """CellModeller's ``sim.init(biophysics, regulation, signalling, integrator)``."""
        missing = [f"{what} ({type(obj).__name__})" for what, obj in (("signalling", sig), ("an integrator", integ))
                   if obj is not None]
        if missing:
            raise ModelRefused(f"sim.init: the model uses {' and '.join(missing)}: qpcontact runs CellModeller's "
                               "biophysics and regulation only (sim.init(biophys, regul, None, None))")
        if not isinstance(phys, CLBacterium):
            raise ModelRefused(f"sim.init: biophysics {type(phys).__name__}: qpcontact runs CLBacterium only")
        if not isinstance(reg, ModuleRegulator):
            raise ModelRefused(f"sim.init: regulation {type(reg).__name__}: qpcontact runs ModuleRegulator only")
        self.phys, self.reg = phys, reg
        phys.setRegulator(reg)
        reg.setBiophysics(phys)

    def next_id(self) -> int:
        cid, self._next_id = self._next_id, self._next_id + 1
        return cid

    def addCell(self, cellType: int = 0, cellAdh: float = 0, length: float = 3.5, **kwargs: Any) -> None:  # noqa: N802, N803
        """CellModeller's ``sim.addCell``: a cell of ``length`` (cylinder, µm) at ``pos`` along
        ``dir`` with radius ``rad``; the model's ``init(cell)`` runs first (CellModeller calls
        the regulation before the physics). Other keywords are ignored, as CellModeller's
        ``CLBacterium.addCell`` ignores them (``len=``, ``color=``)."""
        if self.phys is None:
            raise ModelRefused("sim.addCell before sim.init(biophys, regul, None, None)")
        pos, direction = kwargs.pop("pos", (0, 0, 0)), kwargs.pop("dir", (1, 0, 0))
        rad = kwargs.pop("rad", 0.5)
        self.ignored.update(kwargs)
        state = CellState(self.next_id())
        state.length, state.cellType, state.cellAdh = float(length), cellType, cellAdh
        state.idx = len(self.cellStates)
        self.cellStates[state.id] = state
        self.module.init(state)
        unit = np.asarray(direction, dtype=float)
        norm = float(np.linalg.norm(unit)) if unit.shape == (3,) else 0.0
        if not norm > 0 or np.asarray(pos, dtype=float).shape != (3,):
            raise ModelRefused(f"sim.addCell: pos and dir must be 3 numbers each (dir not zero), got {pos!r}, "
                               f"{direction!r}")
        place(state, np.asarray(pos, dtype=float), unit / norm, float(state.length), float(rad))

    def addRenderer(self, renderer: Any) -> None:  # noqa: N802
        self.renderers.append(renderer)

    def _no(self, what: str) -> None:
        raise ModelRefused(f"sim.{what}: not available in qpcontact; bring a CellModeller state with qpcontact "
                           "import-cellmodeller and continue it with qpcontact simulate --start")

    def loadFromPickle(self, data: Any) -> None:  # noqa: N802
        self._no("loadFromPickle")

    def loadGeometryFromPickle(self, data: Any) -> None:  # noqa: N802
        self._no("loadGeometryFromPickle")

    def setCellStates(self, states: Any) -> None:  # noqa: N802
        self._no("setCellStates")

    def importCells_file(self, filename: Any) -> None:  # noqa: N802
        self._no("importCells_file")


def place(state: CellState, pos: np.ndarray, direction: np.ndarray, length: float, radius: float) -> None:
    """What CellModeller's ``CLBacterium.initCellState`` sets on a new cell (a founder, a
    daughter): its geometry, ``volume = length``, ``oldLen``, ``startVol``, ``strainRate = 0``."""
    state.pos, state.dir = pos.tolist(), direction.tolist()
    state.radius, state.length = radius, length
    state.oldLen = state.volume = state.startVol = length
    state.ends = (pos - direction * length / 2, pos + direction * length / 2)
    state.strainRate = 0.0


@dataclass
class Model:
    """A loaded model and what its ``setup(sim)`` asked for.

    Attributes:
        path: the model file.
        source: its text (stored in the pickles, as CellModeller does).
        module: the loaded module (``init``, ``update``, ``divide``).
        sim: the :class:`Simulation` after ``setup``.
        physics: its ``CLBacterium`` (options, planes, spheres).
        founders: the cells ``setup`` added, in order.
        dt: the time step [the model's time unit] (:func:`load_model`).
        planar: ``jitter_z=False``: a monolayer in the plane z = 0 (2D); else 3D.
        planes: the walls of the run (its planes, and a sphere's wall as planes).
        notes: what is ignored or approximated, each said once.
    """

    path: Path
    source: str
    module: types.ModuleType
    sim: Simulation
    physics: CLBacterium
    founders: list[CellState]
    dt: float
    planar: bool
    planes: list[Plane] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def name(self) -> str:
        return self.sim.moduleName

    @property
    def max_cells(self) -> int:
        return int(self.physics.options["max_cells"])


def seed_model_random(seed: int, step: int) -> None:
    """Seed Python's and NumPy's global random numbers (the ones a model script draws from) for
    step ``step`` of a run with ``seed`` (``step = -1``: its ``setup``): each step draws the
    same numbers whether the run was resumed or not."""
    random.seed(f"qpcontact-cellmodeller:{seed}:{step}")
    np.random.seed(int(np.random.SeedSequence([seed, step + 1]).generate_state(1)[0]))  # noqa: NPY002 (the model's own)


def _call(path: Path, what: str, function: Any, *args: Any) -> Any:
    """Run the model's own code before the run: its refusal or error in one line."""
    try:
        return function(*args)
    except ModelRefused as exc:
        raise ModelRefused(f"model {path}: {exc}") from None
    except Exception as exc:  # the model's error: said with its line, before anything runs
        raise InvalidArgumentError(f"model {path}: {what} raised {_where(exc, path)}") from exc


def load_model(path: str | Path, *, seed: int = 1, dt: float | None = None) -> Model:
    """Load the model script ``path`` and run its ``setup(sim)`` (module docstring), with the
    model's random numbers seeded by ``seed`` (:func:`seed_model_random`). ``dt``: the time step
    [the model's time unit], which wins over the model's ``sim.dt``; default: ``sim.dt`` as
    ``setup`` leaves it (0.025, CellModeller's ``Scripts/batch.py``, unless it sets one).

    Raises:
        ModelRefused: what qpcontact does not run (a signalling grid, an integrator, an unknown
            ``CLBacterium`` option, a sphere with cells outside it, ...), in one line.
        InvalidArgumentError: the file is missing, does not load or its ``setup`` raises (its
            line and error), it lacks ``setup``, ``init`` or ``update``, or adds no cell.
    """
    path = Path(path)
    if not path.is_file():
        raise InvalidArgumentError(f"model {path}: no such file")
    source = path.read_text(errors="replace")
    spec = importlib.util.spec_from_file_location(path.stem, path)
    if spec is None or spec.loader is None:
        raise InvalidArgumentError(f"model {path}: not a Python file")
    module = importlib.util.module_from_spec(spec)
    with serving():
        seed_model_random(seed, -1)
        try:
            spec.loader.exec_module(module)
        except ModelRefused as exc:
            raise ModelRefused(f"model {path}: {exc}") from None
        except Exception as exc:  # the model's own error, but it stops the run before it starts
            raise InvalidArgumentError(f"model {path}: does not load: {_where(exc, path)}") from exc
        for name in ("setup", "init", "update"):
            if not callable(getattr(module, name, None)):
                raise InvalidArgumentError(f"model {path}: defines no function {name} (a CellModeller model has "
                                           "setup(sim), init(cell), update(cells) and, optionally, divide(parent, "
                                           "d1, d2))")
        sim = Simulation(module, path.stem, DEFAULT_DT if dt is None else dt)
        _call(path, "setup(sim)", module.setup, sim)
    if sim.phys is None:
        raise InvalidArgumentError(f"model {path}: setup(sim) never called sim.init(biophys, regul, None, None)")
    if not sim.cellStates:
        raise InvalidArgumentError(f"model {path}: setup(sim) added no cell (sim.addCell)")
    dt = sim.dt if dt is None else dt
    if isinstance(dt, bool) or not (isinstance(dt, (int, float)) and np.isfinite(dt) and dt > 0):
        raise InvalidArgumentError(f"model {path}: sim.dt must be a number > 0, got {sim.dt!r}")
    model = Model(path, source, module, sim, sim.phys, list(sim.cellStates.values()), float(dt),
                  planar=not sim.phys.options["jitter_z"])
    _check_founders(model)
    model.planes = walls(model)
    model.notes += option_notes(model)
    return model


def _check_founders(model: Model) -> None:
    """A 2D model's cells lie in the plane z = 0 along it (a monolayer)."""
    if not model.planar:
        return
    for state in model.founders:
        if abs(state.pos[2]) > 1e-12 or abs(state.dir[2]) > 1e-12:
            raise ModelRefused(f"model {model.path}: jitter_z=False makes a monolayer in the plane z = 0 here, but "
                               f"cell {state.id} is added at pos {tuple(state.pos)} along {tuple(state.dir)}")


def option_notes(model: Model) -> list[str]:
    """What the model's ``CLBacterium`` options and ``addCell`` keywords become, said once."""
    from .standins import NO_MEANING

    given = model.physics.given
    notes = [f"CLBacterium {name}={given[name]!r}: no meaning here ({NO_MEANING[name]})"
             for name in given if name in NO_MEANING]
    if model.sim.ignored:
        notes.append(f"sim.addCell ignores {', '.join(sorted(model.sim.ignored))} (as CellModeller does; the length "
                     "is length=, the radius rad=)")
    return notes


def walls(model: Model) -> list[Plane]:
    """The run's planes from the model's ``addPlane`` and ``addSphere`` (module docstring of
    docs/cellmodeller.md, "Planes and spheres"): hard walls, each said in a note where it
    differs from CellModeller's."""
    radius = max(float(s.radius) for s in model.founders)
    asked = list(model.physics.planes)
    kept: list[PlaneAsked] = []
    for plane in asked:
        normal = np.asarray(plane.normal) / np.linalg.norm(plane.normal)
        if model.planar and abs(normal[2]) > 1e-9:
            if np.linalg.norm(normal[:2]) > 1e-9:
                raise ModelRefused(f"model {model.path}: addPlane{plane.point, plane.normal}: a plane oblique to a 2D "
                                   "(jitter_z=False) colony")
            if (0.0 - plane.point[2]) * normal[2] < radius - 1e-9:
                raise ModelRefused(f"model {model.path}: addPlane{plane.point, plane.normal}: the 2D colony in z = 0 "
                                   "lies on its wrong side")
            model.notes.append(f"addPlane{plane.point, plane.normal}: the 2D colony in z = 0 keeps to it already")
            continue
        kept.append(plane)
    kept = _without_conflicts(model, kept, radius)
    if any(p.coeff != 1 for p in kept):
        model.notes.append("addPlane coefficients are not used: qpcontact's planes are hard walls (no cell crosses "
                           "one), CellModeller's are weighted by the coefficient")
    planes = [Plane(p.point, p.normal) for p in kept]
    for sphere in model.physics.spheres:
        planes += _sphere_planes(model, sphere)
    return planes


def _without_conflicts(model: Model, planes: list[PlaneAsked], radius: float) -> list[PlaneAsked]:
    """Two planes facing each other closer than a cell's diameter leave no room: the one with the
    smaller coefficient is dropped (CellModeller's weighting lets the stiffer one win)."""
    dropped: set[int] = set()
    for i, a in enumerate(planes):
        for j, b in enumerate(planes[i + 1:], start=i + 1):
            na, nb = (np.asarray(p.normal) / np.linalg.norm(p.normal) for p in (a, b))
            room = float(np.dot(np.subtract(b.point, a.point), na)) - 2 * radius
            if i in dropped or j in dropped or np.dot(na, nb) > -0.999 or room >= 0:
                continue
            weak, strong = (i, j) if a.coeff < b.coeff else (j, i)
            dropped.add(weak)
            model.notes.append(
                f"addPlane{planes[weak].point, planes[weak].normal} (coefficient {planes[weak].coeff:g}) leaves no "
                f"room for a cell with addPlane{planes[strong].point, planes[strong].normal} (coefficient "
                f"{planes[strong].coeff:g}): qpcontact's planes are hard walls, so only the stiffer one is kept")
    return [p for k, p in enumerate(planes) if k not in dropped]


def _sphere_planes(model: Model, sphere: SphereAsked) -> list[Plane]:
    """A sphere's wall with the cells inside (``norm = -1``) as planes tangent to it: a
    polygon of 64 sides in 2D (its corners 0.12 % of the radius outside the circle), a
    polyhedron of 256 faces in 3D (about 0.6 %)."""
    if sphere.norm >= 0:
        raise ModelRefused(f"model {model.path}: addSphere{sphere.center, sphere.radius} with norm {sphere.norm:g} "
                           "(cells outside a sphere): qpcontact's walls are planes and keep cells inside only (norm -1)")
    center = np.asarray(sphere.center)
    if model.planar:
        if abs(center[2]) >= sphere.radius:
            raise ModelRefused(f"model {model.path}: addSphere{sphere.center, sphere.radius} does not cut the 2D "
                               "colony's plane z = 0")
        reach = math.sqrt(sphere.radius**2 - center[2] ** 2)
        angle = 2 * np.pi * np.arange(SPHERE_PLANES[2]) / SPHERE_PLANES[2]
        out = np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=1)
        center = np.array([center[0], center[1], 0.0])
    else:
        reach = sphere.radius
        k = np.arange(SPHERE_PLANES[3]) + 0.5  # a Fibonacci lattice: nearly even directions
        polar, turn = np.arccos(1 - 2 * k / SPHERE_PLANES[3]), np.pi * (1 + 5**0.5) * k
        out = np.stack([np.cos(turn) * np.sin(polar), np.sin(turn) * np.sin(polar), np.cos(polar)], axis=1)
    model.notes.append(f"addSphere{tuple(sphere.center), sphere.radius}: its wall is {len(out)} planes tangent to it "
                       f"({'a polygon' if model.planar else 'a polyhedron'}); coefficient not used (hard walls)")
    return [Plane(tuple(center + reach * u), tuple(-u)) for u in out]
