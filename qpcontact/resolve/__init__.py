"""Resolve: one call per timestep, and the checks of every answer.

- :mod:`.resolve`: :func:`resolve` (find the colliding contacts, assemble, solve through the
  solver registry, check, return a :class:`Result`), :func:`solve_system` (solve an assembled
  system and apply the acceptance checks: a :class:`SystemSolution`);
- :mod:`.metrics`: the dimensionless error measures of model.md;
- :mod:`.validation`: high-accuracy references (:func:`reference_solution`) and the comparison
  with the plain solve (:func:`compare_with_linear`).

Imports the geometry, assembly and solvers wings only. ``qpcontact.resolve`` itself is the
function (re-exported at the top level); import the modules with
``from qpcontact.resolve import metrics``.
"""

from . import metrics
from .resolve import (
    ACCEPT_CAP,
    ACCEPT_FACTOR,
    Result,
    SystemSolution,
    acceptance_failure,
    acceptance_limit,
    certified,
    resolve,
    solve_system,
)
from .validation import (
    ACTIVE_THRESHOLD,
    Agreement,
    Reference,
    UnverifiedReferenceWarning,
    active_set_polish,
    compare_with_linear,
    reference,
    reference_solution,
)

__all__ = [
    "ACCEPT_CAP", "ACCEPT_FACTOR", "ACTIVE_THRESHOLD", "Agreement", "Reference", "Result", "SystemSolution",
    "UnverifiedReferenceWarning", "acceptance_failure", "acceptance_limit", "active_set_polish", "certified",
    "compare_with_linear", "metrics", "reference", "reference_solution", "resolve", "solve_system",
]
