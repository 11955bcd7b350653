"""Solvers of the scaled contact problem ``B̃ ỹ ≥ b̃``, behind one registry.

Every solver is one module here that registers a
:class:`~qpcontact.solvers.registry.SolverSpec` at import; the imports below register them, in
the order the listings show them: the plain solve (:mod:`.linear`), the built-in matrix-free QP
solver (:mod:`.mprgp`), the built-in interior-point solver that takes bounds (:mod:`.ipm`) and
every qpsolvers backend (:mod:`.qpsolvers_bridge`). The study baselines (:mod:`.baselines`:
``cg``, ``cg_euclidean``, ``bbpgd``) are registered when a study asks for them
(:func:`~qpcontact.solvers.registry.load_baselines`: ``available_solvers(include_baselines=True)``
or ``get_solver("cg")``), not by ``import qpcontact``. Everything that picks a solver asks the
registry: :func:`solve` (the one dispatch), :func:`get_solver`, :func:`available_solvers`.

Adding a solver
---------------
Write one module, ``qpcontact/solvers/mysolver.py``::

    import numpy as np
    from .registry import QP_FORMULATIONS, SolverOutput, SolverSpec, register

    def _solve(problem, formulation, form, *, tolerance, time_limit, settings, initial):
        ...  # solve B̃ ỹ ≥ b̃ (problem.matrix, problem.rhs) to the dimensionless tolerance
        return SolverOutput(y, lam, found, status, iterations, setup_seconds, solve_seconds)

    register(SolverSpec("mysolver", formulations=("complementarity",), forms=("contact",),
                        warm_start=False, time_limit=False, solve=_solve))

and add ``from . import mysolver`` below. :func:`qpcontact.resolve` (``solver="mysolver"``),
:func:`available_solvers`, the demo, ``qpcontact compare``, ``qpcontact stability`` and
``qpcontact bench`` then use it; every answer still passes the acceptance checks of
:func:`qpcontact.resolve.solve_system` before it is applied. docs/architecture.md has a worked
example.
"""

# The order of these imports is the order of the listings (available_solvers, demo, compare).
# isort: off
from . import linear  # noqa: F401  (registers "linear")
from . import mprgp  # noqa: F401  (registers "mprgp")
from . import ipm  # noqa: F401  (registers "ipm")
from . import petsc  # noqa: F401  (registers "ipm-petsc", usable where petsc4py is installed)
from . import qpsolvers_bridge  # noqa: F401  (registers every qpsolvers backend)
# isort: on
from .blocks import BLOCK_ROWS, independent_blocks
from .linear import LinearSolution, solve_min_norm
from .registry import (
    DEFAULT_FORM,
    FORMS,
    FORMULATIONS,
    QP_FORMS,
    QP_FORMULATIONS,
    IterativeSolution,
    Problem,
    SolverOutput,
    SolverSpec,
    available_solvers,
    get_solver,
    load_baselines,
    register,
    registered_solvers,
    solve,
    unregister,
)

__all__ = [
    "BLOCK_ROWS", "DEFAULT_FORM", "FORMS", "FORMULATIONS", "IterativeSolution", "LinearSolution", "Problem", "QP_FORMS",
    "QP_FORMULATIONS", "SolverOutput", "SolverSpec", "available_solvers", "get_solver", "independent_blocks",
    "load_baselines", "register", "registered_solvers", "solve", "solve_min_norm", "unregister",
]
