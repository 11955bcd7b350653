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

Besides the qpsolvers backends, ``solver="mprgp"`` is built in (:mod:`qpcontact.mprgp`): a
matrix-free solver of the complementarity/contact problem, the one that scales to 3D biofilms of
10⁵ cells, where every factorization fills in.

Why not ``P = MᵀM + εI``: ``MᵀM`` is singular, a small Euclidean ε does not pin ``Δp`` down to
solver tolerance, and forming it is slow (model.md, "What is already known"). The lifted forms
keep ``B̃`` as it is, and the minimum-W-norm choice is made exactly.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import qpsolvers
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..errors import InvalidArgumentError, SolverNotInstalledError, UnknownSolverError
from .linear import solve_min_norm
from .mprgp import mprgp
from ..assembly.system import ContactSystem

FORMULATIONS = ("least_squares", "complementarity")
FORMS = ("primal", "contact")

#: Every backend name qpsolvers 4.x knows; only some are installed (``available_solvers``).
KNOWN_BACKENDS = (
    "clarabel", "copt", "cvxopt", "daqp", "ecos", "gurobi", "highs", "hpipm", "jaxopt_osqp", "kvxopt",
    "mosek", "nppro", "osqp", "pdhcg", "piqp", "proxqp", "pyqpmad", "qpalm", "qpax", "qpoases", "qpswift",
    "qtqp", "quadprog", "scs", "sip",
)


#: Built-in solvers that take only the complementarity formulation in contact form.
CONTACT_SPACE_SOLVERS = ("mprgp",)


def _tolerance_settings(backend: str, tol: float, time_limit: float | None, formulation: str = "complementarity") -> dict[str, Any]:
    """Backend options that make it stop at (scaled, dimensionless) tolerance ``tol``.

    For least_squares the optimal objective ``½‖r‖²`` is (near) zero, so a duality-gap test at
    ``tol`` only bounds the residual by ``sqrt(tol)``; interior-point gap tolerances are therefore
    squared there (measured: Clarabel 5e-3 → 4e-6 distance to the exact answer at tol 1e-6)."""
    s: dict[str, Any]
    gap = max(tol * tol, 1e-15) if formulation == "least_squares" else tol
    if backend in CONTACT_SPACE_SOLVERS:  # qpcontact.mprgp's own arguments
        s = {"tol": tol, "time_limit": time_limit}
    elif backend == "osqp":
        # polish: after convergence OSQP solves the KKT system of its active set once; where that
        # succeeds the answer is exact (10⁵-cell colony: error 4e-7 → 5e-10 for +3 % time).
        s = {"eps_abs": tol, "eps_rel": tol, "max_iter": 200_000, "eps_prim_inf": min(1e-6, tol), "eps_dual_inf": min(1e-6, tol),
             "polish": True}
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
        if backend == "proxqp":
            # ProxQP does not test the duality gap unless asked; without it, it stopped after 2–3
            # iterations with gaps of 2e-4..1e-2 on most catalogue cases (docs/stability.md).
            s.update(check_duality_gap=True, eps_duality_gap_abs=gap, eps_duality_gap_rel=gap)
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
    """Solver names usable here: ``"linear"`` (the plain solve), ``"mprgp"`` (built in,
    complementarity only) and every installed qpsolvers backend, sorted."""
    return ["linear", *CONTACT_SPACE_SOLVERS, *sorted(qpsolvers.available_solvers)]


def formulations_of(solver: str) -> tuple[str, ...]:
    """The formulations a solver takes (``"linear"`` ignores the formulation: one entry)."""
    return ("complementarity",) if solver == "linear" or solver in CONTACT_SPACE_SOLVERS else FORMULATIONS


def check_solver(name: str) -> None:
    """Raise :class:`UnknownSolverError` or :class:`SolverNotInstalledError` for a bad name."""
    if name == "linear" or name in CONTACT_SPACE_SOLVERS or name in qpsolvers.available_solvers:
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
    return _problem(system.matrix, system.rhs, formulation, form, regularization)


def _problem(matrix: sp.spmatrix, rhs: np.ndarray, formulation: str, form: str, regularization: float) -> qpsolvers.Problem:
    """:func:`build_problem` for ``B̃ = matrix``, ``b̃ = rhs`` (a whole system or one block)."""
    B = matrix.tocsc()
    k, n = B.shape
    if formulation == "complementarity" and form == "primal":
        return qpsolvers.Problem(P=sp.identity(n, format="csc"), q=np.zeros(n), G=-B, h=-rhs)
    if formulation == "complementarity" and form == "contact":
        # Sorted indices: PIQP misreads a CSC matrix with unsorted indices (what a sparse product
        # returns) and reported "dual infeasible" on 29 of 41 stability cases (docs/stability.md).
        return qpsolvers.Problem(P=(B @ B.T).tocsc().sorted_indices(), q=-rhs, lb=np.zeros(k), ub=np.full(k, np.inf))
    if formulation == "least_squares":
        if form == "primal":
            top, width = regularization * sp.identity(n, format="csc"), n
            eq = sp.hstack([B, -sp.identity(k)], format="csc")
        else:
            a = (B @ B.T).tocsc().sorted_indices()
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


def independent_blocks(matrix: sp.spmatrix, min_rows: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """The independent subproblems of ``B̃ ỹ ≥ b̃``: connected components of the contact graph
    (rows and columns linked by the non-zeros of ``B̃``), as ``(rows, columns)`` index arrays in
    increasing order. Consecutive components are merged into blocks of about ``min_rows`` rows
    (the components starting in the same window of ``min_rows`` rows; a component is never cut):
    fewer, larger backend calls, since each call has a fixed cost. Blocks without rows (columns
    with no non-zero, whose answer is 0) are left out."""
    k, n = matrix.shape
    pattern = sp.csr_matrix((np.ones(matrix.nnz, dtype=np.int8), matrix.indices, matrix.indptr), shape=(k, n))
    n_comp, label = connected_components(sp.bmat([[None, pattern], [pattern.T, None]], format="csr"), directed=False)
    sizes = np.bincount(label[:k], minlength=n_comp)
    block = np.unique((np.cumsum(sizes) - sizes) // max(min_rows, 1), return_inverse=True)[1][label]
    row_block, col_block = block[:k], block[k:]
    n_blocks = int(block.max()) + 1
    rows = np.split(np.argsort(row_block, kind="stable"), np.cumsum(np.bincount(row_block, minlength=n_blocks))[:-1])
    cols = np.split(np.argsort(col_block, kind="stable"), np.cumsum(np.bincount(col_block, minlength=n_blocks))[:-1])
    return [(r, c) for r, c in zip(rows, cols) if r.size]


#: Blocks handed to a backend have about this many contacts (see :func:`independent_blocks`).
BLOCK_ROWS = 2000


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
    split: bool = True,
) -> QPOutcome:
    """Solve the system's QP with one qpsolvers backend. Never raises for a backend failure:
    the outcome says what happened (``found``, ``status``, ``error``).

    With ``split`` (default) the independent components of the contact graph are solved as
    separate QPs (merged into blocks of about :data:`BLOCK_ROWS` contacts): the same problem,
    but each part stops when it is converged instead of waiting for the hardest one. ``found`` is
    true only if every block was solved; ``iterations`` is the largest of the blocks'."""
    check_solver(solver)
    if solver in CONTACT_SPACE_SOLVERS and set(settings or {}) - {"max_iterations", "proportioning"}:
        raise InvalidArgumentError(f"solver_settings: mprgp takes max_iterations and proportioning; got {sorted(settings)}")
    options = {**_tolerance_settings(solver, tolerance, time_limit, formulation), **(settings or {})}
    B, rhs = system.matrix, system.rhs
    k, n = B.shape
    t0 = time.perf_counter()
    blocks = independent_blocks(B, BLOCK_ROWS) if split else [(np.arange(k), np.arange(n))]
    if len(blocks) == 1:
        out = _solve_block(B, rhs, solver, formulation, form, regularization, options)
        out.setup_seconds = time.perf_counter() - t0 - out.solve_seconds  # includes finding the blocks
        out.extras["blocks"] = 1
        return out
    y, lam = np.zeros(n), np.zeros(k)
    has_lam, statuses, iterations, setup, solve = True, [], [], time.perf_counter() - t0, 0.0
    for rows, cols in blocks:
        if time_limit is not None:
            remaining = time_limit - (time.perf_counter() - t0)
            if remaining <= 0:
                return QPOutcome(None, None, False, "time limit reached", max(iterations, default=None), setup, solve,
                                 error=f"time limit of {time_limit} s reached after {len(statuses)} of {len(blocks)} blocks")
            options = {**options, **_tolerance_settings(solver, tolerance, remaining, formulation), **(settings or {})}
        t1 = time.perf_counter()
        sub = B[rows][:, cols]
        setup += time.perf_counter() - t1
        out = _solve_block(sub, rhs[rows], solver, formulation, form, regularization, options)
        setup, solve = setup + out.setup_seconds, solve + out.solve_seconds
        if out.y is None or not out.found:
            # The block's answer covers only its own rows and columns: report the failure, no partial ỹ.
            return QPOutcome(None, None, False, f"{out.status} (block of {rows.size} contacts)", out.iterations,
                             setup, solve, error=out.error)
        y[cols] = out.y
        if out.lam is None:
            has_lam = False
        else:
            lam[rows] = out.lam
        statuses.append(out.status)
        if out.iterations is not None:
            iterations.append(out.iterations)
    status = " / ".join(dict.fromkeys(statuses))
    return QPOutcome(y, lam if has_lam else None, True, status, max(iterations, default=None), setup, solve,
                     extras={"blocks": len(blocks)})


@contextlib.contextmanager
def _quiet_stdout():
    """Silence the C library's own prints for the duration (OSQP writes "Polishing not
    needed" to the process's stdout even with ``verbose=False``)."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def _solve_block(B: sp.spmatrix, rhs: np.ndarray, solver: str, formulation: str, form: str, regularization: float,
                 options: dict[str, Any]) -> QPOutcome:
    """One backend call on ``B̃ ỹ ≥ b̃`` (a whole system or one independent block)."""
    if solver in CONTACT_SPACE_SOLVERS:
        out = mprgp(B, rhs, **options)
        return QPOutcome(out.y, out.lam, out.converged, out.status, out.iterations, 0.0, out.seconds)
    t0 = time.perf_counter()
    problem = _problem(B, rhs, formulation, form, regularization)
    if solver in qpsolvers.dense_solvers and solver not in qpsolvers.sparse_solvers:
        problem = qpsolvers.Problem(*(m.toarray() if sp.issparse(m) else m for m in problem.unpack()))
    t1 = time.perf_counter()
    try:
        with warnings.catch_warnings(), (_quiet_stdout() if solver == "osqp" else contextlib.nullcontext()):
            warnings.simplefilter("ignore")  # the status is reported in the outcome instead
            solution = qpsolvers.solve_problem(problem, solver=solver, verbose=False, **options)
    except Exception as exc:  # backends raise many types; the failure is reported, not hidden
        return QPOutcome(None, None, False, "error", None, t1 - t0, time.perf_counter() - t1, error=f"{type(exc).__name__}: {exc}")
    status, iterations = _status(solution)
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
            projected = solve_min_norm(B, B @ x[:n], tol=1e-9)
            y, lam = projected.y, projected.lam
    return QPOutcome(y, lam, bool(solution.found), status, iterations, t1 - t0, time.perf_counter() - t1)


#: Objective of each formulation in scaled units, as a function of (system, ỹ).
OBJECTIVES: dict[str, Callable[[ContactSystem, np.ndarray], float]] = {
    "complementarity": lambda system, y: 0.5 * float(y @ y),
    "least_squares": lambda system, y: 0.5 * float(np.sum((system.matrix @ y - system.rhs) ** 2)),
}
