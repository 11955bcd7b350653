"""The old import paths of what moved, kept working until :data:`REMOVED_IN`: each warns with a
:class:`DeprecationWarning` that names the new home.

- a moved module (``qpcontact.colony.simulate``, ``qpcontact.cluster``, ``qpcontact.arguments``,
  ...: :data:`MODULES`) is found by a finder on :data:`sys.meta_path` that hands back the module
  at its new home (the same module object, so patching either path patches both);
- a name moved out of a module or package that stays (``qpcontact.colony.run_colony``,
  ``qpcontact.simulation.simulate.run_colony``, ...: :data:`NAMES`) is served by that module's
  ``__getattr__`` (:func:`attribute`), from its new home (under its new name where it was
  renamed: ``qpcontact.timestep.advance`` is :func:`qpcontact.geometry.motion.move`).

Two moves: the layout by concern (the wings, issue 20) and the house finished (issue 35: every
module one job). Imports nothing of the wings; the new homes are imported only when an old path
is used. Importing this module installs the finder (:func:`install`), before the wings are
imported (one of them may still use an old path).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from collections.abc import Sequence
from types import FrameType, ModuleType
from typing import Any

#: The version that removes the old paths (they work, and warn, until then).
REMOVED_IN = "0.2.0"

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
    # issue 35
    "qpcontact.arguments": "qpcontact.cli",
    "qpcontact.described": "qpcontact.schema",
    "qpcontact.outputs": "qpcontact.io.outputs",
}


def _names(home: str, names: str) -> dict[str, str]:
    return {name: f"{home}.{name}" for name in names.split()}


_STEPS = "qpcontact.simulation.steps"
_LOOP = "qpcontact.simulation.loop"
_RECORDING = "qpcontact.simulation.recording"
_PICTURE = "qpcontact.simulation.picture"
_GRID = "qpcontact.ensembles.grid"
_TASKS = "qpcontact.ensembles.tasks"
_SUBMIT = "qpcontact.ensembles.submit"

#: module or package that stays -> {name that moved out of it: its new home, as a full dotted path}.
NAMES: dict[str, dict[str, str]] = {
    "qpcontact.colony": {
        **_names("qpcontact.timestep", "CellMechanics CellMotion ContactImpulses PositionSettings PositionStepResult "
                 "StepResult cell_forces cell_pressure cell_stress fit_parabola position_step radial_profile step"),
        **_names("qpcontact.io", "CellModellerState RunFolder Snapshot colony_columns colony_frame load_colony "
                 "load_snapshot read_cellmodeller run_frame save_colony"),
        **_names("qpcontact.simulation", "ModelSettings OutputSettings Run RunSettings Settings StepOutcome run_colony"),
        **_names("qpcontact.geometry", "largest_overlap overlap_fractions"),
        "VelocitySettings": "qpcontact.timestep.VelocitySettings",
        "advance": "qpcontact.geometry.motion.move",
        "move": "qpcontact.geometry.motion.move",
        "rotate": "qpcontact.geometry.motion.rotate",
    },
    # issue 35: the misplaced code
    "qpcontact.timestep": {
        **_names("qpcontact.colony", "PressureGrowth pressure_growth_rate"),
        **_names("qpcontact.geometry", "largest_overlap overlap_fractions"),
        "advance": "qpcontact.geometry.motion.move",
        "move": "qpcontact.geometry.motion.move",
    },
    "qpcontact.timestep.mechanics": {
        **_names("qpcontact.colony.pressure", "GROWTH_LAWS PressureGrowth pressure_growth_rate"),
        "is_planar": "qpcontact.timestep.mechanics.is_monolayer_scene",  # (assembly's is_planar is another test)
    },
    "qpcontact.timestep.step": {
        **_names("qpcontact.geometry.overlap", "largest_overlap"),
        "advance": "qpcontact.geometry.motion.move",
    },
    "qpcontact.io.runs": {"Interrupt": "qpcontact.simulation.signals.Interrupt"},
    "qpcontact.simulation": {"VelocitySettings": "qpcontact.timestep.VelocitySettings"},
    # issue 35: simulate.py by job (the command stays)
    "qpcontact.simulation.simulate": {
        **_names(_STEPS, "MOTION_ARRAYS WARM_ARRAYS StepFunction StepOutcome flags_to_try grow_with_retries "
                 "position_step_function pressure_growth_of sink_drive step_function step_mechanics turning_reach"),
        **_names(_LOOP, "Run attempt_step check_target check_types founder initial_state most_cells prepare_step "
                 "run_colony start_run take_one_step"),
        **_names(_RECORDING, "RunState history_row record_step save_state"),
        **_names(_PICTURE, "colony_picture describe_run draw_pictures"),
        "HISTORY_FIELDS": "qpcontact.io.runs.HISTORY_FIELDS",
        "Settings": "qpcontact.simulation.settings.Settings",
    },
    # issue 35: sweep.py by job (the command and the sweep's folder stay)
    "qpcontact.ensembles.sweep": {
        **_names(_GRID, "Grid grid_layer label parse_vary plan_runs read_config run_name varied_values"),
        **_names(_TASKS, "ATTEMPTS_FILE EVENT_TOPIC LOCK_FILE MEASURES RESULT_FILE STOP_FILE attempts_of nematic_order "
                 "open_folder read_json run_lock run_measures run_task stoppable"),
        **_names(_SUBMIT, "STOP_WAIT execute stop with_unsubscribe"),
        "plot_ensemble": "qpcontact.io.plots.plot_ensemble",
    },
}


def warn(old: str, new: str, stacklevel: int = 1) -> None:
    """The one warning of an old path, attributed to the frame ``stacklevel`` above the caller."""
    warnings.warn(f"{old} has moved to {new}; the old path works until qpcontact {REMOVED_IN}",
                  DeprecationWarning, stacklevel=stacklevel + 2)


def attribute(package: str, name: str, names: dict[str, str]) -> Any:
    """``package.name`` for a module ``__getattr__``: a moved name (``names``: name -> its new
    home's full dotted path; warns, then from its new home) or a moved submodule (imported
    through :class:`MovedModules`, which warns)."""
    if name in names:
        home, _, new_name = names[name].rpartition(".")
        warn(f"{package}.{name}", names[name], stacklevel=2)  # the caller of __getattr__
        return getattr(importlib.import_module(home), new_name)
    if f"{package}.{name}" in MODULES:
        return importlib.import_module(f"{package}.{name}")
    raise AttributeError(f"module {package!r} has no attribute {name!r}")


def _imported_by_the_package() -> bool:
    """Whether the import being run is one of qpcontact's own modules: such a use of an old path
    works without a warning (a user could do nothing about it); tests/test_package.py finds it
    (no module of the package names a moved path)."""
    frame: FrameType | None = sys._getframe(1)
    while frame is not None and (frame.f_code.co_filename.startswith("<frozen")
                                 or frame.f_globals.get("__name__") == __name__):
        frame = frame.f_back
    return frame is not None and str(frame.f_globals.get("__name__", "")).startswith("qpcontact.")


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
        if not _imported_by_the_package():
            warn(module.__name__, new)
        # The import system returns what sys.modules holds under the old name once this returns.
        sys.modules[module.__name__] = importlib.import_module(new)


def install() -> None:
    """Put :class:`MovedModules` first on :data:`sys.meta_path` (once): before the path finders,
    so that a stale file at an old path (an older install left behind) is not imported instead."""
    if not any(isinstance(finder, MovedModules) for finder in sys.meta_path):
        sys.meta_path.insert(0, MovedModules())


install()
