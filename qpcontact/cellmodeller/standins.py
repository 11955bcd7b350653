"""The names a CellModeller model script imports, served by qpcontact while the model runs.

A model imports ``CellModeller.Regulation.ModuleRegulator``,
``CellModeller.Biophysics.BacterialModels.CLBacterium`` and ``CellModeller.GUI.Renderers``;
:func:`serving` puts a finder first on ``sys.meta_path`` that answers those imports (and those of
CellModeller's signalling and integrator modules, whose classes refuse the model in one line)
with this module's stand-ins, and takes it away afterwards with every ``CellModeller`` module it
served: nothing named ``CellModeller`` is installed, and a CellModeller installed beside qpcontact
is left as it was.

The stand-ins record what the model asks for; :mod:`qpcontact.cellmodeller.model` turns that into
a qpcontact run. ``CellState`` is :class:`qpcontact.cellmodeller.state.CellState`.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys
import types
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InvalidArgumentError
from .state import CellState


class ModelRefused(InvalidArgumentError):
    """A model asks for something qpcontact does not run (a signalling grid, an integrator, an
    unknown ``CLBacterium`` option): said in one line before anything runs."""


#: CLBacterium's options (CellModeller at commit 1382c975) and their defaults there.
CLBACTERIUM_OPTIONS: dict[str, Any] = dict(
    max_substeps=8, max_cells=10000, max_contacts=24, max_planes=1, max_spheres=1, max_sqs=192**2, grid_spacing=5.0,
    muA=1.0, gamma=10.0, dt=None, cgs_tol=5e-3, jitter_z=True, alternate_divisions=False, printing=True,
    compNeighbours=False)

#: The options that have no meaning in qpcontact's step, and what replaces them.
NO_MEANING = {
    "max_substeps": "qpcontact's position step re-linearizes until no contact overlaps by more than its tolerance",
    "cgs_tol": "qpcontact solves each step's contact QP to its own tolerance (an interior point method), not by "
               "conjugate gradients",
    "max_contacts": "qpcontact has no per-cell contact limit",
    "max_sqs": "qpcontact's contact search has no grid limit",
    "grid_spacing": "qpcontact's contact search needs no grid",
    "dt": "CLBacterium's physics substep: qpcontact's step is the model's sim.dt, halved only if a step fails",
    "printing": "qpcontact shows a progress bar (--quiet: none)",
    "max_planes": "capacity only",
    "max_spheres": "capacity only",
}


@dataclass
class PlaneAsked:
    """``biophys.addPlane(pt, norm, coeff)``: cells stay on the side ``norm`` points to."""

    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    coeff: float


@dataclass
class SphereAsked:
    """``biophys.addSphere(pt, rad, coeff, norm)``: ``norm = -1`` keeps cells inside the sphere."""

    center: tuple[float, float, float]
    radius: float
    coeff: float
    norm: float


def _vector(name: str, value: Any) -> tuple[float, float, float]:
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.size != 3 or not np.all(np.isfinite(arr)):
        raise ModelRefused(f"{name}: expected 3 finite numbers, got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


class CLBacterium:
    """CellModeller's ``CLBacterium(sim, ...)``: its options are recorded (and checked: an
    unknown one refuses the model), its planes and spheres kept; the physics is qpcontact's."""

    def __init__(self, simulator: Any, **options: Any) -> None:
        unknown = sorted(set(options) - set(CLBACTERIUM_OPTIONS))
        if unknown:
            raise ModelRefused(f"CLBacterium: unknown option {', '.join(unknown)} (CellModeller's CLBacterium takes "
                               f"{', '.join(CLBACTERIUM_OPTIONS)})")
        self.simulator = simulator
        self.given = dict(options)
        self.options = {**CLBACTERIUM_OPTIONS, **options}
        if self.options["alternate_divisions"]:
            raise ModelRefused("CLBacterium: alternate_divisions=True (daughters turned by 90°) is not available in "
                               "qpcontact")
        for name in ("gamma", "muA"):
            value = self.options[name]
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise ModelRefused(f"CLBacterium: {name} must be a number > 0, got {value!r}")
        self.planes: list[PlaneAsked] = []
        self.spheres: list[SphereAsked] = []
        self.regulator: Any = None

    def addPlane(self, pt: Any, norm: Any, coeff: Any) -> None:  # noqa: N802 (CellModeller's name)
        normal = _vector("addPlane norm", norm)
        if not np.linalg.norm(normal) > 0:
            raise ModelRefused(f"addPlane: the normal {norm!r} is zero")
        self.planes.append(PlaneAsked(_vector("addPlane pt", pt), normal, float(coeff)))

    def addSphere(self, pt: Any, rad: Any, coeff: Any, norm: Any) -> None:  # noqa: N802
        self.spheres.append(SphereAsked(_vector("addSphere pt", pt), float(rad), float(coeff), float(norm)))

    def setRegulator(self, regulator: Any) -> None:  # noqa: N802
        self.regulator = regulator

    def hasNeighbours(self) -> bool:  # noqa: N802
        return bool(self.options["compNeighbours"])


class ModuleRegulator:
    """CellModeller's ``ModuleRegulator(sim, ...)``: the model module is the regulation (its
    ``init``, ``update`` and ``divide``)."""

    def __init__(self, sim: Any, biophys: Any = None, signalling: Any = None) -> None:
        self.sim = sim
        self.module = getattr(sim, "module", None)
        self.modName = getattr(sim, "moduleName", "")
        self.biophys = biophys if isinstance(biophys, CLBacterium) else None
        if signalling is not None:
            raise ModelRefused(f"ModuleRegulator: signalling {type(signalling).__name__}: {NOT_RUN}")

    def setBiophysics(self, biophys: Any) -> None:  # noqa: N802
        self.biophys = biophys


class _Renderer:
    """A GUI renderer: qpcontact draws its own pictures, so renderers are accepted and ignored."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        pass


NOT_RUN = ("qpcontact runs CellModeller's biophysics (CLBacterium) and regulation (ModuleRegulator) only: no "
           "signalling grid and no intracellular integrator")


def _refusing(what: str) -> type:
    """A class that refuses the model when it is built: ``what`` is not run by qpcontact."""

    def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
        raise ModelRefused(f"{what}: {NOT_RUN}")

    return type(what.split(" ")[-1], (), {"__init__": __init__, "__doc__": f"Refuses the model: {what}."})


#: module name -> its attributes. Every package on the way is a module too.
MODULES: dict[str, dict[str, Any]] = {
    "CellModeller.Regulation.ModuleRegulator": {"ModuleRegulator": ModuleRegulator},
    "CellModeller.Biophysics.BacterialModels.CLBacterium": {"CLBacterium": CLBacterium},
    "CellModeller.GUI.Renderers": {"GLBacteriumRenderer": _Renderer, "GLGridRenderer": _Renderer,
                                   "GLStaticMeshRenderer": _Renderer, "GLPlaneRenderer": _Renderer,
                                   "GLSphereRenderer": _Renderer, "GLCellRenderer": _Renderer},
    "CellModeller.CellState": {"CellState": CellState},
    **{f"CellModeller.Integration.{name}": {name: _refusing(f"the integrator {name}")}
       for name in ("CLEulerIntegrator", "CLCrankNicIntegrator", "CLEulerSigIntegrator")},
    **{f"CellModeller.Signalling.{name}": {name: _refusing(f"the signalling {name}")}
       for name in ("GridDiffusion", "NeighbourDiffusion")},
}


def _packages(names: Sequence[str]) -> list[str]:
    found = {".".join(name.split(".")[:k]) for name in names for k in range(1, name.count(".") + 1)}
    return sorted(found)


PACKAGES = _packages(list(MODULES))


class _Finder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Serves :data:`MODULES` (and their packages) under CellModeller's names."""

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> importlib.machinery.ModuleSpec | None:
        if fullname == "CellModeller" or fullname.startswith("CellModeller."):
            if fullname in MODULES or fullname in PACKAGES:
                return importlib.machinery.ModuleSpec(fullname, self, is_package=fullname in PACKAGES)
            raise ModelRefused(f"import {fullname}: not one of CellModeller's modules that qpcontact stands in for "
                               f"({', '.join(MODULES)})")
        return None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType:
        module = types.ModuleType(spec.name, f"qpcontact's stand-in for {spec.name} (qpcontact.cellmodeller)")
        module.__dict__.update(MODULES.get(spec.name, {}))
        return module

    def exec_module(self, module: types.ModuleType) -> None:
        pass


@contextmanager
def serving() -> Iterator[None]:
    """While inside, ``import CellModeller...`` gives qpcontact's stand-ins (module docstring);
    afterwards the finder and every ``CellModeller`` module are gone, and any that were loaded
    before are back."""
    ours = [n for n in sys.modules if n == "CellModeller" or n.startswith("CellModeller.")]
    saved = {name: sys.modules.pop(name) for name in ours}
    finder = _Finder()
    sys.meta_path.insert(0, finder)
    try:
        yield
    finally:
        sys.meta_path.remove(finder)
        for name in [n for n in sys.modules if n == "CellModeller" or n.startswith("CellModeller.")]:
            del sys.modules[name]
        sys.modules.update(saved)
