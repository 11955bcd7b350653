"""qpcontact: contact resolution between capsule cells as a constrained quadratic program.

Data flow: :class:`Cells` → :func:`find_contacts` / :func:`colliding` → :func:`build_system` →
:func:`resolve` (plain linear solve or a QP through qpsolvers) → :class:`Result`.
"""

from .assembly.system import ContactSystem, build_system
from .errors import (
    InvalidArgumentError,
    InvalidCellsError,
    QPContactError,
    SolverFailedError,
    SolverNotInstalledError,
    UnknownSolverError,
)
from .geometry.cells import Cells
from .geometry.contacts import Contacts, colliding, concatenate, find_contacts
from .resolve import Agreement, Result, compare_with_linear, reference_solution, resolve, solve_system
from .solvers.qpsolvers_bridge import FORMULATIONS, available_solvers

__version__ = "0.1.0"

__all__ = [
    "Agreement", "Cells", "ContactSystem", "Contacts", "FORMULATIONS", "InvalidArgumentError", "InvalidCellsError",
    "QPContactError", "Result", "SolverFailedError", "SolverNotInstalledError", "UnknownSolverError",
    "available_solvers", "build_system", "colliding", "compare_with_linear", "concatenate", "find_contacts",
    "reference_solution", "resolve", "solve_system",
]
