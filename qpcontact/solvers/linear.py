"""The plain linear solve: the minimum-W-norm least-squares solution of ``M x = b``.

In the scaled unknowns of :mod:`qpcontact.assembly.system` (``ỹ = W^{1/2}x``, up to constants) this is
the minimum-Euclidean-norm least-squares solution of ``B̃ ỹ = b̃``, i.e. ``ỹ = B̃⁺ b̃``. It is
the limit of ``(MᵀM + εW)⁻¹Mᵀb`` as ε → 0 (model.md), computed without forming ``MᵀM``:

1. *Contact space* (default): factorize the K × K Delassus operator ``Ã = B̃B̃ᵀ`` (sparse LU,
   SuperLU with a symmetric ordering), solve ``Ã λ̃ = b̃`` and set ``ỹ = B̃ᵀλ̃``. ``ỹ`` lies in
   the row space of ``B̃`` by construction, so it is the minimum-norm solution; equal and
   opposite impulses ``λ̃ n`` act at each contact, so momentum is conserved exactly.
2. *LSMR* on ``B̃ ỹ = b̃`` from zero, whose iterates stay in the row space and converge to the
   minimum-norm least-squares solution. Used when ``Ã`` is singular (redundant contacts, jammed
   packings where ``M x = b`` has no solution) or when the factorized answer fails the check.

Either answer is accepted only if it passes the stopping test of LSQR/LSMR (:func:`optimality`:
a consistent solution, or a least-squares one) at ``tolerance``; otherwise
:class:`~qpcontact.errors.SolverFailedError` is raised.

Registered as the solver ``"linear"`` (formulation ``"linear"``): the contact form is the
Delassus route 1 (LSMR as fallback), the primal form LSMR on ``B̃`` alone (2; no factorization).
Its solver setting ``estimate_condition`` also estimates ``cond₁(Ã)`` from the LU.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InvalidArgumentError, SolverFailedError
from .registry import Problem, SolverOutput, SolverSpec, register


@dataclass
class LinearSolution:
    """Output of :func:`solve_min_norm` (all in scaled units).

    Attributes:
        y: (n,) scaled unknowns ``ỹ``.
        lam: (K,) scaled contact impulses ``λ̃`` with ``ỹ = B̃ᵀλ̃``.
        method: ``"lu"`` or ``"lsmr"``.
        iterations: LSMR iterations (0 for LU).
        optimality: the relative least-squares optimality residual that was checked.
        consistent: whether ``B̃ỹ = b̃`` holds (to ``tolerance``); False for over-determined contacts.
        condition_estimate: 1-norm condition estimate of ``Ã`` (LU path only, else None).
        seconds: wall time of the solve.
    """

    y: np.ndarray
    lam: np.ndarray
    method: str
    iterations: int
    optimality: float
    consistent: bool
    condition_estimate: float | None
    seconds: float


def operator_norm_bound(matrix: sp.spmatrix) -> float:
    """A cheap upper bound of ``‖B̃‖₂``: ``sqrt(‖B̃B̃ᵀ‖∞)`` without forming the product."""
    abs_m = abs(matrix)
    return float(np.sqrt(np.max(abs_m @ (abs_m.T @ np.ones(matrix.shape[0])), initial=0.0)))


def optimality(matrix: sp.spmatrix, y: np.ndarray, rhs: np.ndarray, norm: float) -> tuple[float, float]:
    """(optimality, relative residual) of ``ỹ`` for ``B̃ỹ ≈ b̃``, as LSQR/LSMR judge it: the
    smaller of the consistent-system measure ``‖r‖/(‖b̃‖ + ‖B̃‖‖ỹ‖)`` and the least-squares
    measure ``‖B̃ᵀr‖/(‖B̃‖‖r‖)``, with ``r = B̃ỹ − b̃``."""
    residual = matrix @ y - rhs
    res_norm = float(np.linalg.norm(residual))
    rhs_norm = float(np.linalg.norm(rhs))
    consistent = res_norm / max(rhs_norm + norm * float(np.linalg.norm(y)), 1e-300)
    if res_norm == 0.0:
        return 0.0, 0.0
    least_squares = float(np.linalg.norm(matrix.T @ residual)) / max(norm * res_norm, 1e-300)
    return min(consistent, least_squares), res_norm / max(rhs_norm, 1e-300)


def _condition_estimate(delassus: sp.csc_matrix, lu: spla.SuperLU) -> float:
    inverse = spla.LinearOperator(delassus.shape, matvec=lu.solve, rmatvec=lambda v: lu.solve(v, trans="T"), dtype=float)
    return float(spla.onenormest(delassus) * spla.onenormest(inverse))


def solve_min_norm(
    matrix: sp.spmatrix,
    rhs: np.ndarray,
    *,
    tolerance: float = 1e-10,
    method: str = "auto",
    delassus: sp.csc_matrix | None = None,
    estimate_condition: bool = False,
    max_iterations: int | None = None,
) -> LinearSolution:
    """Minimum-norm least-squares solution of ``B̃ ỹ = b̃`` (see the module docstring).

    Args:
        matrix: (K, n) sparse ``B̃``.
        rhs: (K,) ``b̃``.
        tolerance: relative tolerance of the optimality check (and of LSMR).
        method: ``"auto"`` (LU, LSMR if that fails), ``"lu"`` or ``"lsmr"``.
        delassus: ``B̃B̃ᵀ`` if the caller already has it.
        estimate_condition: also estimate ``cond₁(Ã)`` (a few extra triangular solves).
        max_iterations: LSMR iteration cap (default ``10·(K + n)``).
    """
    start = time.perf_counter()
    norm = operator_norm_bound(matrix)
    failures: list[str] = []
    if method in ("auto", "lu"):
        a = delassus if delassus is not None else (matrix @ matrix.T).tocsc()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error", spla.MatrixRankWarning)
                lu = spla.splu(a, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
            lam = lu.solve(rhs)
            y = matrix.T @ lam
            opt, rel = optimality(matrix, y, rhs, norm)
            if np.all(np.isfinite(y)) and opt <= tolerance:
                cond = _condition_estimate(a, lu) if estimate_condition else None
                return LinearSolution(y, lam, "lu", 0, opt, rel <= max(tolerance, 1e-12) * 10, cond, time.perf_counter() - start)
            failures.append(f"LU answer failed the optimality check ({opt:.3g} > {tolerance:.3g})")
        except (RuntimeError, spla.MatrixRankWarning) as exc:  # exactly singular Delassus operator
            failures.append(f"LU: {exc}")
        if method == "lu":
            raise SolverFailedError("linear solve (lu): " + "; ".join(failures))
    elif method != "lsmr":
        raise InvalidArgumentError(f"method: expected 'auto', 'lu' or 'lsmr', got {method!r}")

    cap = max_iterations or 10 * (matrix.shape[0] + matrix.shape[1])
    out = spla.lsmr(matrix, rhs, atol=tolerance * 1e-2, btol=tolerance * 1e-2, maxiter=cap)
    y, istop, iterations = out[0], out[1], out[2]
    opt, rel = optimality(matrix, y, rhs, norm)
    if not np.all(np.isfinite(y)) or opt > tolerance:
        failures.append(f"LSMR stopped with istop={istop} after {iterations} iterations, optimality {opt:.3g} > {tolerance:.3g}")
        raise SolverFailedError("linear solve did not converge: " + "; ".join(failures))
    # Contact impulses: the minimum-norm λ̃ with B̃ᵀλ̃ = ỹ (consistent, since ỹ is in the row space).
    lam = spla.lsmr(matrix.T.tocsr(), y, atol=tolerance * 1e-2, btol=tolerance * 1e-2, maxiter=cap)[0]
    return LinearSolution(y, lam, "lsmr", int(iterations), opt, rel <= max(tolerance, 1e-12) * 10, None, time.perf_counter() - start)


def _solve(problem: Problem, formulation: str, form: str, *, tolerance: float, time_limit: float | None,
           settings: Mapping[str, Any], initial: np.ndarray | None) -> SolverOutput:
    """The registered solve: the optimality check at ``1e-4·tolerance`` (never looser than
    1e-10, never tighter than 1e-12), so that its answer stays within the QPs' tolerance even on
    an ill-conditioned system (the relative error is up to ``cond(B̃)`` times the optimality:
    side-by-side rods in loops give ``cond(B̃B̃ᵀ)`` of 10⁶–10⁷, where an optimality of 1e-8 left
    LSMR 5e-6 from the exact answer; 1e-10 costs 6 % more iterations)."""
    start = time.perf_counter()
    try:
        lin = solve_min_norm(problem.matrix, problem.rhs, tolerance=max(min(tolerance, 1e-6) * 1e-4, 1e-12),
                             method="lsmr" if form == "primal" else "auto",
                             estimate_condition=bool(settings.get("estimate_condition", False)))
    except SolverFailedError as exc:
        return SolverOutput(None, None, False, "failed", None, 0.0, time.perf_counter() - start, error=str(exc))
    status = f"solved ({lin.method}{'' if lin.consistent else ', least squares'})"
    return SolverOutput(lin.y, lin.lam, True, status, lin.iterations, 0.0, lin.seconds,
                        extras={"condition_estimate": lin.condition_estimate, "consistent": lin.consistent,
                                "optimality": lin.optimality})


register(SolverSpec(
    "linear", formulations=("linear",), forms=("contact", "primal"), warm_start=False, time_limit=False, solve=_solve,
    description="plain minimum-kinetic-energy solve of Mx = b (may pull): sparse LU of the Delassus operator "
                "(contact form) or LSMR (primal form)",
    settings=("estimate_condition",), matrix_free=("primal",), bundled=True,
))
