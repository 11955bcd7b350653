"""The old import paths of what the layout by concern moved (docs/architecture.md), kept working
for one release: each warns with a :class:`DeprecationWarning` that names the new home.

- a moved module (``qpcontact.colony.simulate``, ``qpcontact.cluster``, ...) is found by a finder
  on :data:`sys.meta_path` that hands back the module at its new home (the same module object,
  so patching either path patches both);
- a name the old package exported (``qpcontact.colony.run_colony``, ...) is served by that
  package's module ``__getattr__`` (:func:`attribute`).

Imports nothing of the wings; the new homes are imported only when an old path is used.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from collections.abc import Sequence
from types import ModuleType
from typing import Any

#: old module -> its new home.
MODULES = {
    "qpcontact.cluster": "qpcontact.ensembles.cluster",
    "qpcontact.colony.sweep": "qpcontact.ensembles.sweep",
    "qpcontact.colony.position": "qpcontact.timestep.position",
    "qpcontact.colony.step": "qpcontact.timestep.step",
    "qpcontact.colony.mechanics": "qpcontact.timestep.mechanics",
    "qpcontact.colony.settings": "qpcontact.simulation.settings",
    "qpcontact.colony.simulate": "qpcontact.simulation.simulate",
    "qpcontact.colony.picture": "qpcontact.simulation.picture",
    "qpcontact.colony.runs": "qpcontact.io.runs",
    "qpcontact.colony.snapshots": "qpcontact.io.snapshots",
    "qpcontact.colony.paraview": "qpcontact.io.paraview",
    "qpcontact.colony.plots": "qpcontact.io.plots",
    "qpcontact.colony.tables": "qpcontact.io.tables",
    "qpcontact.colony.cellmodeller": "qpcontact.io.cellmodeller",
}

#: name that ``qpcontact.colony`` exported before the move -> the package that exports it now.
COLONY_NAMES = {
    **dict.fromkeys(["CellMechanics", "CellMotion", "ContactImpulses", "PositionSettings", "PositionStepResult",
                     "PressureGrowth", "StepResult", "advance", "cell_forces", "cell_pressure", "cell_stress",
                     "fit_parabola", "largest_overlap", "move", "overlap_fractions", "position_step",
                     "pressure_growth_rate", "radial_profile", "step"], "qpcontact.timestep"),
    **dict.fromkeys(["CellModellerState", "RunFolder", "Snapshot", "colony_columns", "colony_frame", "load_colony",
                     "load_snapshot", "read_cellmodeller", "run_frame", "save_colony"], "qpcontact.io"),
    **dict.fromkeys(["ModelSettings", "OutputSettings", "Run", "RunSettings", "Settings", "StepOutcome",
                     "VelocitySettings", "run_colony"], "qpcontact.simulation"),
    "rotate": "qpcontact.geometry.motion",
}


def warn(old: str, new: str, stacklevel: int = 1) -> None:
    """The one warning of an old path, attributed to the frame ``stacklevel`` above the caller."""
    warnings.warn(f"{old} has moved to {new}; the old path works for this release only",
                  DeprecationWarning, stacklevel=stacklevel + 2)


def attribute(package: str, name: str, names: dict[str, str]) -> Any:
    """``package.name`` for a module ``__getattr__``: a moved name (warns, then from its new
    home) or a moved submodule (imported through :class:`MovedModules`, which warns)."""
    if name in names:
        warn(f"{package}.{name}", f"{names[name]}.{name}", stacklevel=2)  # the caller of __getattr__
        return getattr(importlib.import_module(names[name]), name)
    if f"{package}.{name}" in MODULES:
        return importlib.import_module(f"{package}.{name}")
    raise AttributeError(f"module {package!r} has no attribute {name!r}")


class MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds the old path of a moved module; loading it warns and puts the module of the new
    home in its place in :data:`sys.modules`."""

    def find_spec(self, fullname: str, path: Sequence[str] | None = None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        return importlib.machinery.ModuleSpec(fullname, self) if fullname in MODULES else None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> None:
        return None  # the default module, replaced in exec_module

    def exec_module(self, module: ModuleType) -> None:
        new = MODULES[module.__name__]
        warn(module.__name__, new)
        # The import system returns what sys.modules holds under the old name once this returns.
        sys.modules[module.__name__] = importlib.import_module(new)


def install() -> None:
    """Put :class:`MovedModules` first on :data:`sys.meta_path` (once): before the path finders,
    so that a stale file at an old path (an older install left behind) is not imported instead."""
    if not any(isinstance(finder, MovedModules) for finder in sys.meta_path):
        sys.meta_path.insert(0, MovedModules())
