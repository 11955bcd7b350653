"""qpcontact: contact resolution between capsule cells as a constrained quadratic program.

Data flow, one wing each (a wing imports only from itself and the wings before it):
:mod:`~qpcontact.geometry` (:class:`Cells` → :func:`find_contacts` / :func:`colliding`) →
:mod:`~qpcontact.assembly` (:func:`build_system`) → :mod:`~qpcontact.solvers` (one registry:
the plain linear solve, MPRGP, every qpsolvers backend) → :mod:`~qpcontact.resolve`
(:func:`resolve`, one call per step, every answer checked → :class:`Result`) →
:mod:`~qpcontact.timestep` (the per-timestep calls, each with its settings: the position-level
step :func:`position_step` (:class:`PositionSettings`) — what ``qpcontact simulate`` runs — and
the velocity-level :func:`step` (:class:`VelocitySettings`); the stress and
pressure of each cell from the contact forces: :func:`cell_stress`, :func:`cell_pressure`) →
:mod:`~qpcontact.colony` (the colony model: :class:`Colony`, :func:`grow_position`,
:func:`grow`, :func:`divide`, time-step rules, growth slowed by pressure
(:func:`pressure_growth_rate`), model hooks) → :mod:`~qpcontact.io` (what a run
writes and reads: snapshots, run folders, CellModeller's states (:func:`read_cellmodeller`),
tables of a snapshot's cells and of a run's steps as pandas DataFrames: :func:`colony_frame`,
:func:`run_frame`) → :mod:`~qpcontact.simulation` (the run of a colony: its settings, step
policy, loop ``run_colony`` and recording) → :mod:`~qpcontact.ensembles` (sweeps on Dask). A
missing optional part raises :class:`NotInstalledError`, one line naming what to install. The studies
(:mod:`qpcontact.studies`: scenes, catalogue, comparison, stability, benchmark, demo) sit on
top and are not imported here. docs/architecture.md describes the layout.
"""

from typing import Any

from . import moved  # first: it installs the old paths of moved modules, for one release
from .assembly import ContactSystem, build_system
from .colony import (
    Colony,
    colony_statistics,
    divide,
    expansion_time_step,
    grow,
    grow_position,
    growth_time_step,
    pressure_growth_rate,
)
from .errors import (
    InvalidArgumentError,
    InvalidCellsError,
    NotInstalledError,
    PullingImpulseWarning,
    QPContactError,
    SolverFailedError,
    SolverNotInstalledError,
    StepFailedError,
    TooManyContactsError,
    UnknownSolverError,
)
from .geometry import Cells, Contacts, Plane, channel, colliding, concatenate, find_contacts, plane_contacts, substrate
from .io import colony_frame, load_colony, read_cellmodeller, run_frame, save_colony
from .resolve import Agreement, Result, SystemSolution, compare_with_linear, reference_solution, resolve, solve_system
from .solvers import FORMS, FORMULATIONS, SolverSpec, available_solvers, get_solver
from .timestep import (
    CellMotion,
    ContactImpulses,
    PositionSettings,
    PositionStepResult,
    StepResult,
    VelocitySettings,
    cell_forces,
    cell_pressure,
    cell_stress,
    position_step,
    step,
)

__version__ = "0.1.0"

__all__ = [
    "FORMS", "FORMULATIONS", "Agreement", "CellMotion", "Cells", "Colony", "ContactImpulses", "PositionSettings",
    "PositionStepResult", "StepFailedError", "VelocitySettings", "grow_position", "growth_time_step", "position_step", "ContactSystem", "Contacts", "InvalidArgumentError", "PullingImpulseWarning",
    "InvalidCellsError", "NotInstalledError", "Plane", "QPContactError", "Result", "SolverFailedError", "SolverNotInstalledError",
    "SolverSpec", "StepResult", "SystemSolution", "TooManyContactsError", "UnknownSolverError", "available_solvers",
    "build_system", "cell_forces", "cell_pressure", "cell_stress", "channel", "colliding",
    "colony_frame", "colony_statistics", "compare_with_linear", "concatenate", "divide", "expansion_time_step", "find_contacts", "get_solver", "grow",
    "load_colony", "plane_contacts", "pressure_growth_rate", "read_cellmodeller", "reference_solution", "resolve", "run_frame", "save_colony", "solve_system", "step",
    "substrate",
]


def __getattr__(name: str) -> Any:
    """A submodule that moved out of the top level (deprecated; :mod:`qpcontact.moved`)."""
    return moved.attribute(__name__, name, {})
