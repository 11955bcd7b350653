"""The plain linear solve: the minimum-W-norm least-squares solution of ``M x = b``.

In the scaled unknowns of :mod:`qpcontact.assembly.system` (``ỹ = W^{1/2}x``, up to constants) this is
the minimum-Euclidean-norm least-squares solution of ``B̃ ỹ = b̃``, i.e. ``ỹ = B̃⁺ b̃``. It is
the limit of ``(MᵀM + εW)⁻¹Mᵀb`` as ε → 0 (model.md), computed without forming ``MᵀM``:

1. *Cholesky* (default): a sparse Cholesky factorization (CHOLMOD, through
   :class:`~qpcontact.solvers.cholesky.GramMatrix`) of the K × K Delassus operator
   ``Ã = B̃B̃ᵀ`` plus ``δI``, ``δ`` = :data:`REGULARIZATION` of its largest diagonal entry, and
   iterative refinement (iterated Tikhonov): ``λ̃ ← λ̃ + (Ã + δI)⁻¹(b̃ − B̃ỹ)``, ``ỹ = B̃ᵀλ̃``.
   ``ỹ`` lies in the row space of ``B̃`` by construction, so it is the minimum-norm solution; each
   refinement divides the error by ``1 + σ²/δ`` for every singular value σ of ``B̃``, so it
   converges also where ``Ã`` is singular (redundant contacts in jammed packings) as long as
   ``M x = b`` has a solution (without position correction it always has: ``b = −u`` is in the
   range). Where it has none (position correction in a jammed packing), the residual's part
   outside the range of ``B̃`` is amplified by ``1/δ`` into ``λ̃`` and the refinement stalls; the
   stall is seen after a step or two, and LSMR takes over. Equal and opposite impulses ``λ̃ n``
   act at each contact, so momentum is conserved exactly. On grown colonies of thousands of
   cells this takes seconds where LSMR took minutes (docs/solvers.md, "The plain solve at colony
   scale").
2. *LU*: sparse LU of ``Ã`` (SuperLU, symmetric ordering), no refinement; fails where ``Ã`` is
   singular. Used for ``method="lu"`` and to estimate ``cond₁(Ã)``.
3. *LSMR* on ``B̃ ỹ = b̃`` from zero, whose iterates stay in the row space and converge to the
   minimum-norm least-squares solution, matrix-free. Used for the primal form and when the
   Cholesky answer fails the check.

Either answer is accepted only if it passes the stopping test of LSQR/LSMR (:func:`optimality`:
a consistent solution, or a least-squares one) at ``tolerance``; otherwise
:class:`~qpcontact.errors.SolverFailedError` is raised.

The all-active answer may pull (``λ̃_k < 0``): then the registered solve warns
(:class:`~qpcontact.errors.PullingImpulseWarning`) and says so (``extras["pulling"]``, the number
of pulling contacts; ``Result.pulling``).

Registered as the solver ``"linear"`` (formulation ``"linear"``): the contact form is the
Cholesky route 1 (LSMR as fallback), the primal form LSMR on ``B̃`` alone (3; no factorization).
Its solver setting ``estimate_condition`` also estimates ``cond₁(Ã)`` from an LU.
"""

from __future__ import annotations

import contextlib
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InvalidArgumentError, PullingImpulseWarning, SolverFailedError
from .cholesky import GramMatrix
from .registry import Problem, SolverOutput, SolverSpec, register


@dataclass
class LinearSolution:
    """Output of :func:`solve_min_norm` (all in scaled units).

    Attributes:
        y: (n,) scaled unknowns ``ỹ``.
        lam: (K,) scaled contact impulses ``λ̃`` with ``ỹ = B̃ᵀλ̃``.
        method: ``"cholesky"``, ``"lu"`` or ``"lsmr"``.
        iterations: LSMR iterations, or the Cholesky route's refinement steps (0 for LU).
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


#: ``δ`` of the Cholesky route, relative to the largest diagonal entry of ``B̃B̃ᵀ``: large enough
#: that ``B̃B̃ᵀ + δI`` factorizes where ``B̃B̃ᵀ`` is singular, small enough that each refinement
#: step gains many digits (the error shrinks by ``δ/(σ² + δ)`` a step; ``cond(B̃B̃ᵀ)`` is 10⁶–10⁷
#: on colonies, so at least 10³ a step). Tried 100× larger, once, if CHOLMOD finds the matrix not
#: positive definite.
REGULARIZATION = 1e-10

#: Most refinement steps of the Cholesky route (it stops at rounding, or when a step no longer
#: halves the optimality).
MAX_REFINEMENT = 30


def _cholesky(matrix: sp.spmatrix, rhs: np.ndarray,
              norm: float) -> tuple[np.ndarray, np.ndarray, int, float, float]:
    """Route 1 of the module docstring: ``(ỹ, λ̃, refinement steps, optimality, relative
    residual)``. Raises ArithmeticError if ``B̃B̃ᵀ + δI`` does not factorize."""
    k = matrix.shape[0]
    # GramMatrix factorizes diag(d) + Aᵀdiag(w)A; with A = B̃ᵀ that is B̃B̃ᵀ + diag(d).
    gram = GramMatrix(sp.csr_matrix(matrix.T))
    diagonal = np.asarray(abs(matrix).power(2).sum(axis=1)).ravel()
    scale = max(float(diagonal.max(initial=0.0)), 1e-300)
    ones = np.ones(matrix.shape[1])
    solve = None
    for delta in (REGULARIZATION, 100 * REGULARIZATION):
        try:
            solve = gram.factor(ones, np.full(k, delta * scale))
            break
        except ArithmeticError:
            continue
    if solve is None:
        raise ArithmeticError("B̃B̃ᵀ + δI is not numerically positive definite")
    lam = np.zeros(k)
    residual = np.asarray(rhs, dtype=float).copy()
    best: tuple[np.ndarray, np.ndarray, int, float, float] | None = None
    for steps in range(1, MAX_REFINEMENT + 1):
        lam = lam + solve(residual)
        y = matrix.T @ lam
        residual = rhs - matrix @ y
        opt, rel = optimality(matrix, y, rhs, norm)
        if not np.isfinite(opt):
            break
        # Refined to rounding, not only to the tolerance (each step is two triangular solves, and
        # the answer is then as exact as LU's where LU works): stop at 1e-15, or when a step no
        # longer halves the optimality (rounding reached, or an inconsistent system: module
        # docstring), keeping the best answer.
        improved = best is None or opt < best[3]
        stalled = best is not None and opt > 0.5 * best[3]
        if improved:
            best = (y, lam.copy(), steps, opt, rel)
        if opt <= 1e-15 or stalled:
            break
    if best is None:
        raise ArithmeticError("the refinement diverged (non-finite answer)")
    y, lam, steps, opt, rel = best
    return y, lam, steps, opt, rel


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
        method: ``"auto"`` (Cholesky, LSMR if that fails), ``"cholesky"``, ``"lu"`` or ``"lsmr"``
            (module docstring).
        delassus: ``B̃B̃ᵀ`` if the caller already has it.
        estimate_condition: also estimate ``cond₁(Ã)`` (from an LU of ``Ã``: not where it is
            singular).
        max_iterations: LSMR iteration cap (default ``10·(K + n)``).
    """
    start = time.perf_counter()
    if method not in ("auto", "cholesky", "lu", "lsmr"):
        raise InvalidArgumentError(f"method: expected 'auto', 'cholesky', 'lu' or 'lsmr', got {method!r}")
    norm = operator_norm_bound(matrix)
    failures: list[str] = []
    if method in ("auto", "cholesky") and matrix.shape[0] > 0:
        try:
            y, lam, steps, opt, rel = _cholesky(matrix, rhs, norm)
            if np.all(np.isfinite(y)) and opt <= tolerance:
                cond = None
                if estimate_condition:
                    with contextlib.suppress(SolverFailedError):  # a singular Ã has no LU: no estimate
                        cond = solve_min_norm(matrix, rhs, tolerance=np.inf, method="lu", delassus=delassus,
                                              estimate_condition=True).condition_estimate
                return LinearSolution(y, lam, "cholesky", steps, opt, rel <= max(tolerance, 1e-12) * 10, cond,
                                      time.perf_counter() - start)
            failures.append(f"Cholesky answer failed the optimality check ({opt:.3g} > {tolerance:.3g} "
                            f"after {steps} refinement steps)")
        except ArithmeticError as exc:
            failures.append(f"Cholesky: {exc}")
        if method == "cholesky":
            raise SolverFailedError("linear solve (cholesky): " + "; ".join(failures))
    if method == "lu":
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
        raise SolverFailedError("linear solve (lu): " + "; ".join(failures))

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
    pulling = pulling_contacts(lin.lam)
    if pulling:
        # One text (the count is in the status and Result.pulling), so that Python's default
        # filter says it once per place, not once per step of a loop.
        warnings.warn("the plain linear solve's answer pulls at some contacts (Result.pulling: how many): its "
                      "all-active answer is no physical resolution, only a check where every contact pushes; use a "
                      "QP solver (e.g. solver='clarabel')", PullingImpulseWarning, stacklevel=5)  # resolve's caller
        status += f", pulls at {pulling} contacts"
    return SolverOutput(lin.y, lin.lam, True, status, lin.iterations, 0.0, lin.seconds,
                        extras={"condition_estimate": lin.condition_estimate, "consistent": lin.consistent,
                                "optimality": lin.optimality, "pulling": pulling})


#: A contact impulse pulls when below ``−PULL_THRESHOLD`` times the largest impulse magnitude
#: (below that it is rounding).
PULL_THRESHOLD = 1e-9


def pulling_contacts(lam: np.ndarray) -> int:
    """How many scaled contact impulses ``λ̃`` pull (:data:`PULL_THRESHOLD`)."""
    scale = float(np.max(np.abs(lam), initial=0.0))
    return int(np.sum(lam < -PULL_THRESHOLD * scale)) if scale > 0 else 0


register(SolverSpec(
    "linear", formulations=("linear",), forms=("contact", "primal"), warm_start=False, time_limit=False, solve=_solve,
    description="plain minimum-kinetic-energy solve of Mx = b (may pull: then it warns): sparse Cholesky of "
                "the Delassus operator with refinement (contact form) or LSMR (primal form)",
    settings=("estimate_condition",), matrix_free=("primal",), bundled=True,
))
