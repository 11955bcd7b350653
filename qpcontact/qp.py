"""The two QP formulations of model.md, in two forms each, handed to qpsolvers.

All problems are posed in the scaled unknowns of :mod:`qpcontact.system` (``B̃ ỹ ≥ b̃``,
dimensionless, kinetic-energy metric made Euclidean). Which form a formulation uses is an
internal choice (``form=``) that the benchmarks can change:

========================  =================================================================
complementarity, primal   ``min ½‖ỹ‖²  s.t. B̃ỹ ≥ b̃``; ``λ̃`` = the inequality duals.
complementarity, contact  ``min ½λ̃ᵀÃλ̃ − b̃ᵀλ̃  s.t. λ̃ ≥ 0``; ``ỹ = B̃ᵀλ̃``.
least_squares, primal     lifted: ``min ½‖r‖² + ½ε‖ỹ‖²  s.t. B̃ỹ − r = b̃, r ≥ 0``, then ỹ is
                          replaced by the minimum-norm solution of ``B̃ỹ' = B̃ỹ`` (the ε → 0
                          selection, exact, by the linear solve).
least_squares, contact    lifted: ``min ½‖r‖² + ½ελ̃ᵀÃλ̃  s.t. Ãλ̃ − r = b̃, r ≥ 0``;
                          ``ỹ = B̃ᵀλ̃`` (unique even where λ̃ is not).
========================  =================================================================

Why not ``P = MᵀM + εI``: ``MᵀM`` is singular, a small Euclidean ε does not pin ``Δp`` down to
solver tolerance, and forming it is slow (model.md, "What is already known"). The lifted forms
keep ``B̃`` as it is, and the minimum-W-norm choice is made exactly.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import qpsolvers
import scipy.sparse as sp

from .errors import SolverNotInstalledError, UnknownSolverError
from .linear import solve_min_norm
from .system import ContactSystem

FORMULATIONS = ("least_squares", "complementarity")
FORMS = ("primal", "contact")

#: Every backend name qpsolvers 4.x knows; only some are installed (``available_solvers``).
KNOWN_BACKENDS = (
    "clarabel", "copt", "cvxopt", "daqp", "ecos", "gurobi", "highs", "hpipm", "jaxopt_osqp", "kvxopt",
    "mosek", "nppro", "osqp", "pdhcg", "piqp", "proxqp", "pyqpmad", "qpalm", "qpax", "qpoases", "qpswift",
    "qtqp", "quadprog", "scs", "sip",
)


def _tolerance_settings(backend: str, tol: float, time_limit: float | None, formulation: str = "complementarity") -> dict[str, Any]:
    """Backend options that make it stop at (scaled, dimensionless) tolerance ``tol``.

    For least_squares the optimal objective ``½‖r‖²`` is (near) zero, so a duality-gap test at
    ``tol`` only bounds the residual by ``sqrt(tol)``; interior-point gap tolerances are therefore
    squared there (measured: Clarabel 5e-3 → 4e-6 distance to the exact answer at tol 1e-6)."""
    s: dict[str, Any]
    gap = max(tol * tol, 1e-15) if formulation == "least_squares" else tol
    if backend == "osqp":
        s = {"eps_abs": tol, "eps_rel": tol, "max_iter": 200_000, "eps_prim_inf": min(1e-6, tol), "eps_dual_inf": min(1e-6, tol)}
        if time_limit:
            s["time_limit"] = time_limit
    elif backend == "clarabel":
        s = {"tol_gap_abs": gap, "tol_gap_rel": gap, "tol_feas": tol, "tol_ktratio": min(1e-6, tol), "max_iter": 500}
        if time_limit:
            s["time_limit"] = time_limit
    elif backend in ("piqp", "proxqp", "qpalm"):
        s = {"eps_abs": tol, "eps_rel": tol}
        if backend == "piqp":
            s.update(max_iter=500, eps_duality_gap_abs=gap, eps_duality_gap_rel=gap)
    elif backend == "scs":
        s = {"eps_abs": tol, "eps_rel": tol, "max_iters": 200_000}
        if time_limit:
            s["time_limit_secs"] = time_limit
    elif backend == "highs":
        s = {"primal_feasibility_tolerance": tol, "dual_feasibility_tolerance": tol}
        if time_limit:
            s["time_limit"] = float(time_limit)
    elif backend in ("cvxopt", "kvxopt", "ecos"):
        s = {"abstol": tol, "reltol": tol, "feastol": tol}
    else:  # backends without a tolerance option (quadprog, daqp, ...) solve to their own accuracy
        s = {}
    return s


def available_solvers() -> list[str]:
    """Solver names usable here: ``"linear"`` (the plain solve) and every installed qpsolvers
    backend, sorted."""
    return ["linear", *sorted(qpsolvers.available_solvers)]


def check_solver(name: str) -> None:
    """Raise :class:`UnknownSolverError` or :class:`SolverNotInstalledError` for a bad name."""
    if name == "linear" or name in qpsolvers.available_solvers:
        return
    if name in KNOWN_BACKENDS:
        raise SolverNotInstalledError(
            f"solver {name!r} is a qpsolvers backend but its package is not installed "
            f"(pip install 'qpcontact[solvers]' or the backend's own package); installed: {available_solvers()}"
        )
    raise UnknownSolverError(f"unknown solver {name!r}; installed: {available_solvers()}")


@dataclass
class QPOutcome:
    """What a backend returned, translated back to the scaled unknowns.

    Attributes:
        y: (n,) scaled unknowns ``ỹ`` (None if the backend returned nothing).
        lam: (K,) scaled contact impulses ``λ̃`` (None if not available).
        found: the backend's own success flag.
        status: the backend's status text.
        iterations: iteration count where the backend reports one.
        setup_seconds: building the problem and handing it to the backend.
        solve_seconds: the backend's solve (and, for least_squares/primal, the projection).
        error: the exception text if the backend raised.
    """

    y: np.ndarray | None
    lam: np.ndarray | None
    found: bool
    status: str
    iterations: int | None
    setup_seconds: float
    solve_seconds: float
    error: str | None = None
    extras: dict = field(default_factory=dict)


def build_problem(system: ContactSystem, formulation: str, form: str, regularization: float = 0.0) -> qpsolvers.Problem:
    """The qpsolvers Problem for a formulation and form (see the module docstring)."""
    B, rhs = system.matrix.tocsc(), system.rhs
    k, n = B.shape
    if formulation == "complementarity" and form == "primal":
        return qpsolvers.Problem(P=sp.identity(n, format="csc"), q=np.zeros(n), G=-B, h=-rhs)
    if formulation == "complementarity" and form == "contact":
        return qpsolvers.Problem(P=system.delassus(), q=-rhs, lb=np.zeros(k), ub=np.full(k, np.inf))
    if formulation == "least_squares":
        if form == "primal":
            top, width = regularization * sp.identity(n, format="csc"), n
            eq = sp.hstack([B, -sp.identity(k)], format="csc")
        else:
            a = system.delassus()
            top, width = regularization * a, k
            eq = sp.hstack([a, -sp.identity(k)], format="csc")
        P = sp.block_diag([top, sp.identity(k)], format="csc")
        lb = np.concatenate([np.full(width, -np.inf), np.zeros(k)])
        ub = np.full(width + k, np.inf)
        return qpsolvers.Problem(P=P, q=np.zeros(width + k), A=eq, b=rhs, lb=lb, ub=ub)
    raise ValueError(f"formulation {formulation!r} / form {form!r}")


def _status(solution: qpsolvers.Solution) -> tuple[str, int | None]:
    extras = solution.extras or {}
    info = extras.get("info") if isinstance(extras, dict) else None
    status, iterations = extras.get("status") if isinstance(extras, dict) else None, None
    if info is not None:
        status = getattr(info, "status", status)
        iterations = getattr(info, "iter", None)
    if isinstance(extras, dict) and "iter" in extras:  # SCS returns its info dict as extras
        iterations = extras.get("iter")
        status = extras.get("status", status)
    if status is None:
        status = "solved" if solution.found else "not solved"
    # Enum reprs such as "Status.PIQP_SOLVED" read better without the class name.
    return str(status).rsplit(".", 1)[-1], None if iterations is None else int(iterations)


def solve_qp_system(
    system: ContactSystem,
    solver: str,
    formulation: str,
    form: str,
    *,
    tolerance: float,
    time_limit: float | None = None,
    regularization: float = 0.0,
    settings: dict[str, Any] | None = None,
) -> QPOutcome:
    """Solve the system's QP with one qpsolvers backend. Never raises for a backend failure:
    the outcome says what happened (``found``, ``status``, ``error``)."""
    check_solver(solver)
    t0 = time.perf_counter()
    problem = build_problem(system, formulation, form, regularization)
    if solver in qpsolvers.dense_solvers and solver not in qpsolvers.sparse_solvers:
        problem = qpsolvers.Problem(*(m.toarray() if sp.issparse(m) else m for m in problem.unpack()))
    options = {**_tolerance_settings(solver, tolerance, time_limit, formulation), **(settings or {})}
    t1 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the status is reported in the outcome instead
            solution = qpsolvers.solve_problem(problem, solver=solver, verbose=False, **options)
    except Exception as exc:  # backends raise many types; the failure is reported, not hidden
        return QPOutcome(None, None, False, "error", None, t1 - t0, time.perf_counter() - t1, error=f"{type(exc).__name__}: {exc}")
    status, iterations = _status(solution)
    x = solution.x
    k, n = system.shape
    y = lam = None
    if x is not None and np.all(np.isfinite(x)):
        B = system.matrix
        if formulation == "complementarity" and form == "primal":
            y = x
            lam = None if solution.z is None or len(solution.z) != k else np.asarray(solution.z)
        elif form == "contact":
            lam = x[:k]
            y = B.T @ lam
        else:  # least_squares, primal: exact minimum-norm selection of the solver's ỹ
            projected = solve_min_norm(B, B @ x[:n], tol=1e-9)
            y, lam = projected.y, projected.lam
    return QPOutcome(y, lam, bool(solution.found), status, iterations, t1 - t0, time.perf_counter() - t1)


#: Objective of each formulation in scaled units, as a function of (system, ỹ).
OBJECTIVES: dict[str, Callable[[ContactSystem, np.ndarray], float]] = {
    "complementarity": lambda system, y: 0.5 * float(y @ y),
    "least_squares": lambda system, y: 0.5 * float(np.sum((system.matrix @ y - system.rhs) ** 2)),
}
