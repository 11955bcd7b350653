"""MPRGP: a matrix-free solver for the contact-space complementarity problem

    min ½λ̃ᵀÃλ̃ − b̃ᵀλ̃   s.t. λ̃ ≥ 0,     Ã = B̃B̃ᵀ (applied as two sparse products, never formed),

the only solver here whose cost per step grows like the number of contacts on a 3D biofilm:
factorizations (the LU of the plain solve, OSQP's and Clarabel's KKT factorizations) fill in on a
3D contact graph, and at 10⁵ cells none of them finishes within minutes (docs/performance.md).

Algorithm: modified proportioning with reduced gradient projections (Dostál & Schöberl, Comput.
Optim. Appl. 30, 2005; Dostál, *Optimal Quadratic Programming Algorithms*, 2009, ch. 5). It is
conjugate gradients on the face of the contacts currently pushing, with two ways to change the
face:

- *expansion*: when the CG step would make a pushing contact pull, go to the bound along the CG
  direction, then take one projected-gradient step of fixed length ``ᾱ ≤ 2/‖Ã‖`` (adds contacts
  that should stop pushing to the bound, several at once);
- *proportioning*: when the gradient of the contacts at the bound that want to push (the chopped
  gradient ``β``) is large against the free gradient ``φ`` (``‖β‖² > Γ²φ̃ᵀφ``), step along ``β``
  (releases contacts from the bound).

Between face changes it is plain CG, so it converges at a CG rate where the active set has
settled (colonies: a few hundred iterations at 10⁵ cells, docs/performance.md).

Scaling: the unknowns are ``μ = √diag(Ã) λ̃``. A positive diagonal change of variables keeps the
bounds ``λ̃ ≥ 0`` as bounds and gives ``Ã`` a unit diagonal (Jacobi preconditioning that the
projections survive).

Stopping: the complementarity residual ``‖min(λ̃, Ãλ̃ − b̃)‖∞ ≤ tolerance`` in the unscaled
impulses, the test of :func:`qpcontact.solvers.baselines.bbpgd` (``max b̃ = 1``, so relative to
the largest approach speed), checked on a freshly computed gradient before an answer is called
converged.

Registered as the solver ``"mprgp"``: complementarity in contact form, solved per independent
block, warm start (``λ̃``) and time limit honoured; settings ``max_iterations`` and
``proportioning``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidArgumentError
from .registry import IterativeSolution, Problem, SolverOutput, SolverSpec, check_options, register

#: Power iterations for the estimate of ‖Ã‖ behind the expansion step.
POWER_ITERATIONS = 10


def _expansion_step(apply: Callable[[np.ndarray], np.ndarray], k: int) -> float:
    """``ᾱ = 1.9/‖Ã‖`` from a power-iteration estimate of ‖Ã‖ (a lower bound, so inflated by
    10 %; a step that still increases the cost is halved in :func:`mprgp`)."""
    v = np.random.default_rng(0).standard_normal(k)
    estimate = 1.0
    for _ in range(POWER_ITERATIONS):
        w = apply(v)
        norm_w = float(np.linalg.norm(w))
        if not norm_w > 0:
            break
        estimate = norm_w / float(np.linalg.norm(v))
        v = w / norm_w
    return 1.9 / (1.1 * estimate)


def mprgp(
    matrix: sp.spmatrix,
    rhs: np.ndarray,
    *,
    tolerance: float = 1e-6,
    max_iterations: int | None = None,
    time_limit: float | None = None,
    initial: np.ndarray | None = None,
    proportioning: float = 1.0,
) -> IterativeSolution:
    """Solve ``min ½λ̃ᵀB̃B̃ᵀλ̃ − b̃ᵀλ̃, λ̃ ≥ 0`` (see the module docstring).

    Args:
        matrix: (K, n) sparse ``B̃`` (scaled, :class:`qpcontact.assembly.ContactSystem`).
        rhs: (K,) ``b̃``.
        tolerance: stop when ``‖min(λ̃, Ãλ̃ − b̃)‖∞ ≤ tolerance``.
        max_iterations: cap on CG, expansion and proportioning steps together (default 100 000).
        time_limit: stop after this many seconds.
        initial: starting ``λ̃`` (negative entries are set to 0; default zero).
        proportioning: ``Γ > 0``; larger releases contacts from the bound less eagerly.

    Returns:
        :class:`~qpcontact.solvers.registry.IterativeSolution` with ``ỹ = B̃ᵀλ̃`` and ``λ̃``; status
        ``"converged"``, ``"max_iterations"``, ``"time_limit"``, ``"infeasible"`` (a contact row
        of ``B̃`` is zero but asks for ``b̃ > 0``) or ``"breakdown"`` (no curvature along a
        search direction).
    """
    check_options(tolerance, max_iterations, time_limit)
    if not (np.isfinite(proportioning) and proportioning > 0):
        raise InvalidArgumentError(f"proportioning: must be finite and > 0, got {proportioning!r}")
    start = time.perf_counter()
    B = sp.csr_matrix(matrix)
    Bt = B.T.tocsr()
    rhs = np.asarray(rhs, dtype=float)
    k = B.shape[0]
    diagonal = np.asarray(B.multiply(B).sum(axis=1)).ravel()
    # A zero row (a contact between cells that cannot move) has no impulse to give: λ̃ = 0 there,
    # which is optimal if it asks for nothing (b̃ ≤ 0) and leaves the problem infeasible otherwise.
    empty = diagonal <= 0
    scale = np.where(empty, 0.0, 1.0 / np.sqrt(np.where(empty, 1.0, diagonal)))

    def apply(v: np.ndarray) -> np.ndarray:
        return scale * (B @ (Bt @ (scale * v)))

    b = scale * rhs
    x = np.zeros(k) if initial is None else np.maximum(np.asarray(initial, dtype=float), 0.0) / np.where(empty, 1.0, scale)
    x[empty] = 0.0
    cap = max_iterations or 100_000
    if np.any(rhs[empty] > 0):
        return IterativeSolution(np.zeros(B.shape[1]), np.zeros(k), 0, False, "infeasible", float(rhs[empty].max()),
                                 time.perf_counter() - start)
    if not np.any(b > 0) and initial is None:  # nothing approaches: λ̃ = 0 is optimal
        return IterativeSolution(np.zeros(B.shape[1]), np.zeros(k), 0, True, "converged", 0.0, time.perf_counter() - start)
    step = _expansion_step(apply, k)
    inverse_scale = np.where(empty, 0.0, 1.0 / np.where(empty, 1.0, scale))

    def residual(x: np.ndarray, g: np.ndarray) -> float:
        # In λ̃ = scale·x the gradient is g/scale; zero rows have λ̃ = 0 and are fine (b̃ ≤ 0).
        return float(np.max(np.abs(np.minimum(scale * x, g * inverse_scale)), initial=0.0))

    def cost(x: np.ndarray, g: np.ndarray) -> float:
        return 0.5 * float(x @ (g - b))  # ½xᵀÃx − bᵀx with g = Ãx − b

    g = apply(x) - b
    free = x > 0
    phi = np.where(free, g, 0.0)  # free gradient
    beta = np.where(free, 0.0, np.minimum(g, 0.0))  # chopped gradient: contacts at 0 that want to push
    p = phi.copy()
    status, iterations, res = "max_iterations", 0, residual(x, g)
    while True:
        if res <= tolerance:
            g = apply(x) - b  # the recurrence drifts: confirm on a fresh gradient
            free = x > 0
            phi, beta = np.where(free, g, 0.0), np.where(free, 0.0, np.minimum(g, 0.0))
            res = residual(x, g)
            if res <= tolerance:
                status = "converged"
                break
            p = phi.copy()
        if iterations >= cap:
            break
        if time_limit is not None and time.perf_counter() - start > time_limit:
            status = "time_limit"
            break
        iterations += 1
        reduced = np.where(free, np.minimum(x / step, phi), 0.0)
        if float(beta @ beta) <= proportioning**2 * float(reduced @ phi):
            Ap = apply(p)
            curvature = float(p @ Ap)
            if not curvature > 0:
                status = "breakdown"
                break
            alpha = float(g @ p) / curvature
            leaving = p > 0
            feasible = float(np.min(x[leaving] / p[leaving])) if leaving.any() else np.inf
            if alpha <= feasible:  # conjugate gradient step, stays in the face
                x -= alpha * p
                np.maximum(x, 0.0, out=x)
                g -= alpha * Ap
                free = x > 0
                phi, beta = np.where(free, g, 0.0), np.where(free, 0.0, np.minimum(g, 0.0))
                p = phi - (float(phi @ Ap) / curvature) * p
            else:  # expansion: to the bound along p, then a projected step along the free gradient
                x -= feasible * p
                np.maximum(x, 0.0, out=x)
                g -= feasible * Ap
                free = x > 0
                phi = np.where(free, g, 0.0)
                before = cost(x, g)
                for _ in range(30):
                    trial = np.maximum(x - step * phi, 0.0)
                    trial_g = apply(trial) - b
                    if cost(trial, trial_g) <= before:
                        break
                    step *= 0.5  # ‖Ã‖ was underestimated
                x, g = trial, trial_g
                free = x > 0
                phi, beta = np.where(free, g, 0.0), np.where(free, 0.0, np.minimum(g, 0.0))
                p = phi.copy()
        else:  # proportioning: release contacts at the bound along the chopped gradient
            Ad = apply(beta)
            curvature = float(beta @ Ad)
            if not curvature > 0:
                status = "breakdown"
                break
            alpha = float(g @ beta) / curvature
            x -= alpha * beta
            g -= alpha * Ad
            free = x > 0
            phi, beta = np.where(free, g, 0.0), np.where(free, 0.0, np.minimum(g, 0.0))
            p = phi.copy()
        res = residual(x, g)
    lam = scale * x
    return IterativeSolution(Bt @ lam, lam, iterations, status == "converged", status, res, time.perf_counter() - start)


def _solve(problem: Problem, formulation: str, form: str, *, tolerance: float, time_limit: float | None,
           settings: Mapping[str, Any], initial: np.ndarray | None) -> SolverOutput:
    if not problem.bounded:
        return mprgp(problem.matrix, problem.rhs, tolerance=tolerance, time_limit=time_limit, initial=initial,
                     **settings).output()
    # Bounds on ỹ as more rows (Problem.bounds_as_rows); their impulses start at 0.
    matrix, rhs = problem.bounds_as_rows()
    k = problem.shape[0]
    start = None if initial is None else np.concatenate([initial, np.zeros(matrix.shape[0] - k)])
    out = mprgp(matrix, rhs, tolerance=tolerance, time_limit=time_limit, initial=start, **settings).output()
    if out.lam is not None:
        out.lam = out.lam[:k]
    return out


register(SolverSpec(
    "mprgp", formulations=("complementarity",), forms=("contact",), warm_start=True, time_limit=True, solve=_solve,
    description="built-in matrix-free MPRGP on the contact-space complementarity QP (no factorization)",
    settings=("max_iterations", "proportioning"), blockwise=True, matrix_free=("contact",), bundled=True,
    bounds=("contact",),
))
