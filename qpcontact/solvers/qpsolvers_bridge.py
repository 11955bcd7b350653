"""The two QP formulations of model.md, in two forms each, handed to qpsolvers.

Every qpsolvers backend is registered here as a solver of its own name (one spec per backend
that qpsolvers knows; :func:`~qpcontact.solvers.registry.available_solvers` lists the installed
ones). Problems are posed in the scaled unknowns of :mod:`qpcontact.assembly.system`
(``B̃ ỹ ≥ b̃``, dimensionless, kinetic-energy metric made Euclidean). Which form a formulation
uses is an internal choice (``form=``) that the studies can change:

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
solver tolerance, and forming it is slow (docs/model.md, "The QP formulations"). The lifted forms
keep ``B̃`` as it is, and the minimum-W-norm choice is made exactly.

:func:`tolerance_settings` translates the one dimensionless tolerance into each backend's own
options; ``solver_settings`` are passed to the backend unchecked (they are its own options).
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
import warnings
from collections.abc import Iterator, Mapping
from functools import partial
from typing import Any

import numpy as np
import qpsolvers
import scipy.sparse as sp

from .linear import solve_min_norm
from .registry import QP_FORMS, QP_FORMULATIONS, Problem, SolverOutput, SolverSpec, register

#: Every backend name qpsolvers 4.x knows; only some are installed.
KNOWN_BACKENDS = (
    "clarabel", "copt", "cvxopt", "daqp", "ecos", "gurobi", "highs", "hpipm", "jaxopt_osqp", "kvxopt",
    "mosek", "nppro", "osqp", "pdhcg", "piqp", "proxqp", "pyqpmad", "qpalm", "qpax", "qpoases", "qpswift",
    "qtqp", "quadprog", "scs", "sip",
)
#: Backends whose time limit :func:`tolerance_settings` passes on.
TIME_LIMITED = ("clarabel", "highs", "osqp", "scs")
#: Backends installed with qpcontact itself (required dependencies in pyproject.toml).
BUNDLED = ("clarabel", "osqp")
#: Backends that print to the process's stdout whatever their options say: OSQP ("Polishing not
#: needed"), HiGHS (its banner, once per process: in every child of the studies).
CHATTY = ("osqp", "highs")


def tolerance_settings(backend: str, tolerance: float, time_limit: float | None,
                       formulation: str = "complementarity") -> dict[str, Any]:
    """Backend options that make it stop at (scaled, dimensionless) ``tolerance``.

    Interior-point gap tolerances are squared: a duality gap of ``tolerance`` bounds the
    complementarity residual (what ``tolerance`` promises, :func:`qpcontact.resolve.acceptance_failure`)
    and, for least_squares whose optimal ``½‖r‖²`` is near zero, the residual, only by
    ``sqrt(tolerance)``. Measured at tolerance 1e-6: least_squares, Clarabel 5e-3 → 4e-6 from the
    exact answer; complementarity, Clarabel's residual 1e-4–1e-3 → 1e-8–1e-7 (PIQP alike) for
    one or two more iterations. Floors: 1e-14 for complementarity (Clarabel ended
    "AlmostSolved" at 1e-15), 1e-15 for least_squares."""
    s: dict[str, Any]
    gap = max(tolerance * tolerance, 1e-15 if formulation == "least_squares" else 1e-14)
    if backend == "osqp":
        # polish: after convergence OSQP solves the KKT system of its active set once; where that
        # succeeds the answer is exact (10⁵-cell colony: error 4e-7 → 5e-10 for +3 % time).
        s = {"eps_abs": tolerance, "eps_rel": tolerance, "max_iter": 200_000, "eps_prim_inf": min(1e-6, tolerance),
             "eps_dual_inf": min(1e-6, tolerance), "polish": True}
        if time_limit:
            s["time_limit"] = time_limit
    elif backend == "clarabel":
        s = {"tol_gap_abs": gap, "tol_gap_rel": gap, "tol_feas": tolerance, "tol_ktratio": min(1e-6, tolerance),
             "max_iter": 500}
        if time_limit:
            s["time_limit"] = time_limit
    elif backend in ("piqp", "proxqp", "qpalm"):
        s = {"eps_abs": tolerance, "eps_rel": tolerance}
        if backend == "piqp":
            s.update(max_iter=500, eps_duality_gap_abs=gap, eps_duality_gap_rel=gap)
        if backend == "proxqp":
            # ProxQP does not test the duality gap unless asked; without it, it stopped after 2–3
            # iterations with gaps of 2e-4..1e-2 on most catalogue cases (docs/stability.md).
            s.update(check_duality_gap=True, eps_duality_gap_abs=gap, eps_duality_gap_rel=gap)
    elif backend == "scs":
        s = {"eps_abs": tolerance, "eps_rel": tolerance, "max_iters": 200_000}
        if time_limit:
            s["time_limit_secs"] = time_limit
    elif backend == "highs":
        s = {"primal_feasibility_tolerance": tolerance, "dual_feasibility_tolerance": tolerance}
        if time_limit:
            s["time_limit"] = float(time_limit)
    elif backend in ("cvxopt", "kvxopt", "ecos"):
        s = {"abstol": gap, "reltol": gap, "feastol": tolerance}
    else:  # backends without a tolerance option (quadprog, daqp, ...) solve to their own accuracy
        s = {}
    return s


#: Backends that need ``rank([P; A; G])`` = the number of variables (CVXOPT's ``coneqp``): a
#: least_squares problem whose ``B̃`` has dependent columns (a jammed packing's rigid motions no
#: contact resists: 119 of 122 on the 61-cell ``jammed_packing``) or rows has none there at ε = 0,
#: and CVXOPT stopped with "Terminated (singular KKT matrix)", status "unknown" (issue 28). Such a
#: least_squares solve that finds nothing is solved once more with :data:`RIDGE` on the first block
#: of the lifted problem (its status then says so).
NEEDS_FULL_RANK = ("cvxopt", "kvxopt")
#: The ridge of :data:`NEEDS_FULL_RANK` (scaled units, against the residual's weight 1): ``½·RIDGE·‖ỹ‖²``
#: (primal form; the exact minimum-norm selection that follows keeps only ``B̃ỹ``) or
#: ``½·RIDGE·‖λ̃‖²`` (contact form). It moves the fit by O(RIDGE), far inside any tolerance.
RIDGE = 1e-10


def qp_problem(matrix: sp.spmatrix, rhs: np.ndarray, formulation: str, form: str,
               regularization: float = 0.0, lower: np.ndarray | None = None,
               upper: np.ndarray | None = None, ridge: float = 0.0) -> qpsolvers.Problem:
    """The qpsolvers Problem for ``B̃ = matrix``, ``b̃ = rhs`` in a formulation and form (see the
    module docstring); ``lower``/``upper`` bound ``ỹ`` (complementarity, primal form only);
    ``ridge``: ``ridge·I`` added to the first block of a lifted least_squares problem
    (:data:`NEEDS_FULL_RANK`)."""
    B = matrix.tocsc()
    k, n = B.shape
    if formulation == "complementarity" and form == "primal":
        bounded = lower is not None or upper is not None
        lb = (np.full(n, -np.inf) if lower is None else lower) if bounded else None
        ub = (np.full(n, np.inf) if upper is None else upper) if bounded else None
        return qpsolvers.Problem(P=sp.identity(n, format="csc"), q=np.zeros(n), G=-B, h=-rhs, lb=lb, ub=ub)
    if formulation == "complementarity" and form == "contact":
        # Sorted indices: PIQP misreads a CSC matrix with unsorted indices (what a sparse product
        # returns) and reported "dual infeasible" on 29 of 41 stability cases (docs/stability.md).
        return qpsolvers.Problem(P=(B @ B.T).tocsc().sorted_indices(), q=-rhs, lb=np.zeros(k), ub=np.full(k, np.inf))
    if formulation == "least_squares":
        if form == "primal":
            top, width = (regularization + ridge) * sp.identity(n, format="csc"), n
            eq = sp.hstack([B, -sp.identity(k)], format="csc")
        else:
            a = (B @ B.T).tocsc().sorted_indices()
            top, width = (regularization * a + ridge * sp.identity(k, format="csc")).tocsc(), k
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


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    """Silence the C library's own prints for the duration (:data:`CHATTY`: OSQP writes
    "Polishing not needed" to the process's stdout even with ``verbose=False``, HiGHS its banner
    when its first solver object is made, before any option applies)."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def _dense(matrix: Any) -> Any:
    """A sparse matrix as a dense array (other entries of a problem as they are)."""
    return matrix.toarray() if sp.issparse(matrix) else matrix


def _dense_only(backend: str) -> bool:
    return backend in qpsolvers.dense_solvers and backend not in qpsolvers.sparse_solvers


def solve_backend(backend: str, problem: Problem, formulation: str, form: str, *, tolerance: float,
                  time_limit: float | None, settings: Mapping[str, Any], initial: np.ndarray | None) -> SolverOutput:
    """One backend call on ``B̃ ỹ ≥ b̃`` (a whole system or one independent block): the
    registered solve of each backend, with the backend name bound."""
    options = {**tolerance_settings(backend, tolerance, time_limit, formulation), **settings}
    B, rhs = problem.matrix, problem.rhs
    t0 = time.perf_counter()
    setup = 0.0

    def attempt(ridge: float) -> qpsolvers.Solution:
        nonlocal setup
        start = time.perf_counter()
        qp = qp_problem(B, rhs, formulation, form, problem.regularization, problem.lower, problem.upper, ridge=ridge)
        if _dense_only(backend):
            qp = qpsolvers.Problem(*(_dense(m) for m in qp.unpack()))
        setup += time.perf_counter() - start
        with warnings.catch_warnings(), (_quiet_stdout() if backend in CHATTY else contextlib.nullcontext()):
            warnings.simplefilter("ignore")  # the status is reported in the output instead
            return qpsolvers.solve_problem(qp, solver=backend, verbose=False, **options)

    ridged = False
    try:
        solution = attempt(0.0)
        if not solution.found and backend in NEEDS_FULL_RANK and formulation == "least_squares":
            # A singular KKT matrix (NEEDS_FULL_RANK): once more with the ridge; only then, so
            # that every problem CVXOPT solves without it is solved exactly as before.
            solution, ridged = attempt(RIDGE), True
    except Exception as exc:  # backends raise many types; the failure is reported, not hidden
        return SolverOutput(None, None, False, "error", None, setup, time.perf_counter() - t0 - setup,
                            error=f"{type(exc).__name__}: {exc}")
    t1 = t0 + setup
    status, iterations = _status(solution)
    if ridged:
        status += f" (with a ridge of {RIDGE:g})"
    x = solution.x
    k, n = B.shape
    y = lam = None
    if x is not None and np.all(np.isfinite(x)):
        if formulation == "complementarity" and form == "primal":
            y = x
            lam = None if solution.z is None or len(solution.z) != k else np.asarray(solution.z)
        elif form == "contact":
            lam = x[:k]
            y = B.T @ lam
        else:  # least_squares, primal: exact minimum-norm selection of the solver's ỹ
            projected = solve_min_norm(B, B @ x[:n], tolerance=1e-9)
            y, lam = projected.y, projected.lam
    return SolverOutput(y, lam, bool(solution.found), status, iterations, t1 - t0, time.perf_counter() - t1)


def _installed(backend: str) -> bool:
    return backend in qpsolvers.available_solvers


for _backend in sorted(set(KNOWN_BACKENDS) | set(qpsolvers.available_solvers)):
    register(SolverSpec(
        _backend, formulations=QP_FORMULATIONS, forms=QP_FORMS, warm_start=False, time_limit=_backend in TIME_LIMITED,
        solve=partial(solve_backend, _backend), available=partial(_installed, _backend),
        description=f"{_backend} through qpsolvers", settings=None, blockwise=True, dense=_dense_only(_backend),
        bundled=_backend in BUNDLED, bounds=("primal",),
        install_hint="is a qpsolvers backend but its package is not installed (pip install 'qpcontact[solvers]' or "
                     "the backend's own package)",
    ))
