"""The iterative solvers colony codes use today, written over a :class:`ContactSystem` so that
the comparison measures them on the same scaled problem as the QP backends.

- :func:`conjugate_gradient`: CG on the normal equations ``B̃ᵀB̃ ỹ = B̃ᵀb̃`` (CGNR), started from
  zero, unpreconditioned, stopped when ``‖B̃ᵀ(b̃ − B̃ỹ)‖ ≤ tol·‖B̃ᵀb̃‖`` — what CellModeller does
  for its contact step. From zero the iterates stay in the row space of the operator, so CG
  tends to the minimum-norm solution *in the metric of its unknowns*: with ``metric="W"`` (the
  scaled unknowns ``ỹ = W^{1/2}x``) that is the physical minimum-W-norm answer; with
  ``metric="euclidean"`` CG runs on the raw impulses ``x`` as CellModeller does, and picks the
  minimum-Euclidean-norm answer, which breaks momentum conservation when masses differ (model.md).
  CG solves the plain linear problem (all contacts active): it can pull.
- :func:`bbpgd`: projected gradient descent with Barzilai–Borwein steps on the contact-space
  complementarity problem ``min ½λ̃ᵀÃλ̃ − b̃ᵀλ̃, λ̃ ≥ 0`` (``Ã = B̃B̃ᵀ``, applied as two sparse
  products, never formed), stopped when the complementarity residual ``‖min(λ̃, Ãλ̃ − b̃)‖∞`` is
  at most ``tol`` (``max b̃ = 1``, so this is relative to the largest approach speed). This is
  the solver of constraint-based colony codes (BBPGD with alternating BB1/BB2 steps).

Both report their iterations, whether they met the tolerance, and why they stopped; an answer
that did not converge is returned with ``converged=False``, never passed off as a solution.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidArgumentError
from ..assembly.system import ContactSystem

BASELINES = ("cg", "cg_euclidean", "bbpgd")


@dataclass
class IterativeSolution:
    """Output of an iterative solver: the baselines here and :func:`qpcontact.mprgp.mprgp` (scaled
    units).

    Attributes:
        y: (n,) scaled unknowns ``ỹ`` (the last iterate, converged or not).
        lam: (K,) scaled contact impulses ``λ̃`` (BBPGD, MPRGP), or None (CG works in ``ỹ`` only).
        iterations: iterations done.
        converged: the stopping test was met.
        status: ``"converged"``, ``"max_iterations"``, ``"time_limit"`` or ``"breakdown"``.
        residual: the stopping measure at the last iterate.
        seconds: wall time.
    """

    y: np.ndarray
    lam: np.ndarray | None
    iterations: int
    converged: bool
    status: str
    residual: float
    seconds: float


def check_options(tol: float, max_iterations: int | None, time_limit: float | None) -> None:
    if not (np.isfinite(tol) and 0 < tol < 1):
        raise InvalidArgumentError(f"tol: must be in (0, 1), got {tol!r}")
    if max_iterations is not None and max_iterations < 1:
        raise InvalidArgumentError(f"max_iterations: must be >= 1, got {max_iterations!r}")
    if time_limit is not None and not time_limit > 0:
        raise InvalidArgumentError(f"time_limit: must be > 0 seconds, got {time_limit!r}")


def conjugate_gradient(
    system: ContactSystem,
    *,
    tol: float = 1e-6,
    metric: str = "W",
    max_iterations: int | None = None,
    time_limit: float | None = None,
) -> IterativeSolution:
    """CGNR from zero on ``B ỹ = b̃`` (see the module docstring).

    Args:
        system: the assembled system.
        tol: relative residual of the normal equations at which to stop.
        metric: ``"W"``: iterate on the scaled unknowns ``ỹ`` (minimum kinetic-energy answer);
            ``"euclidean"``: iterate on the raw impulses (CellModeller; minimum Euclidean norm).
        max_iterations: cap (default ``2·n``: exact arithmetic needs at most ``rank ≤ n``).
        time_limit: stop after this many seconds.
    """
    check_options(tol, max_iterations, time_limit)
    start = time.perf_counter()
    matrix, rhs = system.matrix, system.rhs
    k, n = matrix.shape
    if metric == "W":
        column = np.ones(n)
    elif metric == "euclidean":
        # ỹ = W^{1/2} x (times a constant), so the raw impulses are z = ỹ / sqrt(w): CG on
        # (B̃ D) z = b̃ with D = diag(1/sqrt(w)) is CG on the physical Δp, ΔL, Δg.
        column = 1.0 / np.sqrt(system.column_inverse_mass)
    else:
        raise InvalidArgumentError(f"metric: expected 'W' or 'euclidean', got {metric!r}")
    cap = max_iterations or 2 * n
    z = np.zeros(n)
    r = rhs.copy()  # b̃ − B̃ D z
    s = column * (matrix.T @ r)  # normal-equations residual D B̃ᵀ r
    target = tol * float(np.linalg.norm(s))
    p = s.copy()
    gamma = float(s @ s)
    status, iterations = "max_iterations", 0
    while iterations < cap:
        if np.sqrt(gamma) <= target:
            status = "converged"
            break
        if time_limit is not None and time.perf_counter() - start > time_limit:
            status = "time_limit"
            break
        q = matrix @ (column * p)
        qq = float(q @ q)
        if not qq > 0:
            status = "breakdown"
            break
        alpha = gamma / qq
        z += alpha * p
        r -= alpha * q
        s = column * (matrix.T @ r)
        gamma_new = float(s @ s)
        p = s + (gamma_new / gamma) * p
        gamma = gamma_new
        iterations += 1
    else:
        if np.sqrt(gamma) <= target:
            status = "converged"
    residual = np.sqrt(gamma) / max(target / tol, 1e-300)
    return IterativeSolution(column * z, None, iterations, status == "converged", status, float(residual),
                            time.perf_counter() - start)


def bbpgd(
    system: ContactSystem,
    *,
    tol: float = 1e-6,
    max_iterations: int | None = None,
    time_limit: float | None = None,
    initial: np.ndarray | None = None,
) -> IterativeSolution:
    """Barzilai–Borwein projected gradient on ``min ½λ̃ᵀÃλ̃ − b̃ᵀλ̃, λ̃ ≥ 0``.

    Steps alternate BB1 (``sᵀs/sᵀΔg``) and BB2 (``sᵀΔg/ΔgᵀΔg``), the first one is the exact
    line-search step along the projected gradient; no line search (non-monotone, as the colony
    codes run it).

    Args:
        system: the assembled system.
        tol: stop when ``‖min(λ̃, Ãλ̃ − b̃)‖∞ ≤ tol``.
        max_iterations: cap (default 100 000).
        time_limit: stop after this many seconds.
        initial: starting ``λ̃ ≥ 0`` (default zero).
    """
    check_options(tol, max_iterations, time_limit)
    start = time.perf_counter()
    matrix, rhs = system.matrix, system.rhs
    k = matrix.shape[0]
    cap = max_iterations or 100_000
    apply = lambda v: matrix @ (matrix.T @ v)  # noqa: E731  Ã v without forming Ã
    lam = np.zeros(k) if initial is None else np.maximum(np.asarray(initial, dtype=float), 0.0)
    grad = apply(lam) - rhs
    residual = float(np.max(np.abs(np.minimum(lam, grad)), initial=0.0))
    # First step: exact minimizer along the projected-gradient direction.
    direction = np.where((lam > 0) | (grad < 0), grad, 0.0)
    curvature = float(direction @ apply(direction))
    step = float(direction @ direction) / curvature if curvature > 0 else 1.0
    status, iterations = "max_iterations", 0
    while iterations < cap:
        if residual <= tol:
            status = "converged"
            break
        if time_limit is not None and time.perf_counter() - start > time_limit:
            status = "time_limit"
            break
        new_lam = np.maximum(lam - step * grad, 0.0)
        new_grad = apply(new_lam) - rhs
        s, g = new_lam - lam, new_grad - grad
        lam, grad = new_lam, new_grad
        iterations += 1
        residual = float(np.max(np.abs(np.minimum(lam, grad)), initial=0.0))
        sg = float(s @ g)
        if not sg > 0:  # no curvature along s (converged to rounding, or Ã singular along s)
            if residual <= tol:
                status = "converged"
            else:
                status = "breakdown"
            break
        step = float(s @ s) / sg if iterations % 2 else sg / float(g @ g)
    else:
        if residual <= tol:
            status = "converged"
    return IterativeSolution(matrix.T @ lam, lam, iterations, status == "converged", status, residual,
                            time.perf_counter() - start)


def solve_baseline(system: ContactSystem, name: str, *, tolerance: float, time_limit: float | None = None,
                   max_iterations: int | None = None) -> IterativeSolution:
    """Run the baseline ``name`` (one of :data:`BASELINES`)."""
    if name == "cg":
        return conjugate_gradient(system, tol=tolerance, time_limit=time_limit, max_iterations=max_iterations)
    if name == "cg_euclidean":
        return conjugate_gradient(system, tol=tolerance, metric="euclidean", time_limit=time_limit,
                                  max_iterations=max_iterations)
    if name == "bbpgd":
        return bbpgd(system, tol=tolerance, time_limit=time_limit, max_iterations=max_iterations)
    raise InvalidArgumentError(f"unknown baseline {name!r}; known: {BASELINES}")
