"""IPM: a built-in primal-dual interior-point solver of the complementarity problem with bounds

    min ½‖ỹ‖²   s.t.   B̃ỹ ≥ b̃,   l ≤ ỹ ≤ u   (l, u optional, per column, may be ±inf),

the solver of the position-level colony step (:mod:`qpcontact.colony.position`), which bounds the
turning and the shrinking of each cell per step. Why an interior-point method: the contact graph
of a grown, jammed colony is nearly isostatic, so many active contacts are redundant and their
impulses are not unique, and about 8 % of the contacts change between pushing and not pushing
from one step to the next. Active-set and semismooth Newton methods (PDAS, projected Newton,
Fischer–Burmeister Newton, a semismooth augmented Lagrangian warm-started from the last step),
first-order methods (ADMM with one factorization, projected Gauss–Seidel, MPRGP) and warm starts
of this method from the last step all cost more on those problems (docs/model-notes.md, "A step
that scales"); an interior-point method is indifferent to redundancy and needs 10–20
factorizations whatever the colony.

Each iteration solves one linear system in the unknowns ỹ, the normal equations of the Newton
step (Mehrotra predictor–corrector, both directions from one factorization)::

    (I + diag(α/p + β/q) + B̃ᵀ diag(λ/s) B̃) Δỹ = r,

with ``s = B̃ỹ − b̃`` the contact slacks, ``λ`` their impulses and ``α, β`` (``p, q``) the bound
multipliers (slacks). The matrix has the sparsity of ``I + B̃ᵀB̃``: a cell's unknowns coupled with
those of the cells it touches, smaller than the contacts' own normal matrix ``B̃B̃ᵀ`` (the one
this solver factorized until 2026-12; 3× cheaper to factorize on a grown 3D biofilm, where a
cell has 11 contacts and 6 unknowns). The pattern, its nested-dissection ordering and CHOLMOD's
symbolic analysis are computed once per problem (:class:`~qpcontact.solvers.cholesky.GramMatrix`),
and reused by the next problem with the same pattern (the next linearization of a position step
with the same contacts); each iteration refills the values and factorizes.

Stopping (all in the scaled units of :mod:`qpcontact.assembly.system`, ``max b̃ = 1``): the
largest of the penetration ``max(0, b̃ − B̃ỹ)``, the bound violation, the stationarity residual
``‖ỹ − B̃ᵀλ̃ − α + β‖∞ / max(1, ‖ỹ‖∞)`` and the complementarity residual
``‖min(λ̃ / max(1, ‖λ̃‖∞), B̃ỹ − b̃)‖∞`` (and the same for the bounds) is at most ``tolerance``.
Impulses are measured relative to the largest: in a jammed colony they reach hundreds of times
the scale of one collision, and only their relative precision is meaningful.

Registered as ``"ipm"``: complementarity in contact form, bounds on ``ỹ``, time limit honoured
(checked between iterations), solved per independent block.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidArgumentError
from .cholesky import GramMatrix, quiet_numpy
from .registry import IterativeSolution, Problem, SolverOutput, SolverSpec, check_options, register

#: Default cap on interior-point iterations.
MAX_ITERATIONS = 100
#: Iterations without a new best error after which the method stops (rounding has won). 5 stopped
#: linearizations of grown 3·10⁴-cell colonies on a plateau the method leaves after 5–6 more
#: iterations (docs/performance.md, "Failures found at 10⁵ cells").
STALL_ITERATIONS = 10
#: Centrality correctors per iteration (Gondzio): each is one more solve with the same factorization.
CORRECTORS = 1
#: Iterative refinement steps of each Newton direction (one more solve each, no factorization).
REFINEMENTS = 3
#: The smallest contact compliance ``ρ`` of the Newton systems (``s + ρλ`` for ``s``), in the
#: scaled units: it bounds the weights ``λ/s`` of the normal matrix in the unknowns by ``1/ρ``.
REGULARIZATION = 1e-10
#: ``ρ`` of the normal equations in the contact impulses, relative to :data:`REGULARIZATION`.
CONTACTS_REGULARIZATION = 1e-4
#: Below this error the normal equations in the unknowns lose the dual equation to rounding
#: (measured: stalls at 10⁻⁷–5·10⁻⁵ on grown colonies); a solve asked for more continues in
#: the contact impulses (:class:`_InContacts`).
UNKNOWNS_ACCURACY = 1e-4
#: Fraction of the way to the boundary an iterate may go (keeps it interior).
STEP_FRACTION = 0.995


def _max_step(value: np.ndarray, change: np.ndarray) -> float:
    """Largest ``t ≤ 1`` with ``value + t·change ≥ 0`` (``value > 0``)."""
    shrinking = change < 0
    if not shrinking.any():
        return 1.0
    return min(1.0, float(np.min(-value[shrinking] / change[shrinking])))


@dataclass
class _Iterate:
    """A primal-dual point: unknowns ``y``, contact slacks ``s`` and impulses ``lam``, bound
    slacks ``p = y − l``, ``q = u − y`` and multipliers ``alpha``, ``beta`` (1 and unused where a
    column has no bound)."""

    y: np.ndarray
    s: np.ndarray
    lam: np.ndarray
    p: np.ndarray
    q: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray

    def moved(self, step: _Iterate, primal: float, dual: float) -> _Iterate:
        return _Iterate(self.y + primal * step.y, self.s + primal * step.s, self.lam + dual * step.lam,
                        self.p + primal * step.p, self.q + primal * step.q, self.alpha + dual * step.alpha,
                        self.beta + dual * step.beta)


class _Newton:
    """The Newton system of one iteration, factorized once, solved for several targets: the
    residuals, the step lengths and the complementarity, whatever the space of the linear
    system (:class:`_InUnknowns`, :class:`_InContacts`)."""

    def __init__(self, B: sp.csr_matrix, Bt: sp.csr_matrix, b: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                 has_lo: np.ndarray, has_hi: np.ndarray, x: _Iterate, regularization: float) -> None:
        self.B, self.Bt, self.x, self.regularization = B, Bt, x, regularization
        self.has_lo, self.has_hi = has_lo, has_hi
        self.r_dual = x.y - Bt @ x.lam - x.alpha + x.beta
        self.r_primal = B @ x.y - b - x.s
        self.r_lower = np.where(has_lo, x.y - lo - x.p, 0.0)
        self.r_upper = np.where(has_hi, hi - x.y - x.q, 0.0)
        self.solve: Callable[[np.ndarray], np.ndarray] = lambda v: v

    def factor(self, matrix: GramMatrix) -> None:
        """Factorize this iteration's system (raises ArithmeticError, CHOLMOD's)."""
        raise NotImplementedError

    def direction(self, target_c: np.ndarray, target_l: np.ndarray, target_u: np.ndarray) -> _Iterate:
        """Newton direction for complementarity targets ``λs → target_c``, ``αp → target_l``,
        ``βq → target_u`` (the primal, dual and bound residuals are driven to zero too)."""
        raise NotImplementedError

    def lengths(self, d: _Iterate) -> tuple[float, float]:
        """Largest primal and dual step lengths (≤ 1) that keep slacks and multipliers ≥ 0."""
        x, lo, hi = self.x, self.has_lo, self.has_hi
        primal = min(_max_step(x.s, d.s), _max_step(x.p[lo], d.p[lo]), _max_step(x.q[hi], d.q[hi]))
        dual = min(_max_step(x.lam, d.lam), _max_step(x.alpha[lo], d.alpha[lo]), _max_step(x.beta[hi], d.beta[hi]))
        return primal, dual

    def complementarity(self, d: _Iterate | None = None, primal: float = 0.0, dual: float = 0.0) -> float:
        """Mean complementarity product of the iterate (moved by ``d`` if given)."""
        x = self.x if d is None else self.x.moved(d, primal, dual)
        lo, hi = self.has_lo, self.has_hi
        total = x.lam @ x.s + x.alpha[lo] @ x.p[lo] + x.beta[hi] @ x.q[hi]
        return float(total) / max(x.lam.size + int(lo.sum()) + int(hi.sum()), 1)


class _InUnknowns(_Newton):
    """The Newton system as normal equations in the unknowns (module docstring): eliminated
    ``Δs = B̃Δỹ + r_p``, ``Δλ = (target_c − λΔs)/s``, ``Δα = (t_l − αΔỹ)/p``,
    ``Δβ = (t_u + βΔỹ)/q``; what is left is the dual equation. ``s``, ``p`` and ``q`` are
    regularized (``s + ρλ``: a tiny contact compliance) alike in the matrix and in the
    elimination, so the dual equation holds up to the rounding of ``Δλ``, which is recovered
    from Δỹ through the weight λ/s. That weight grows without bound as the method converges, so
    below :data:`UNKNOWNS_ACCURACY` the method continues in :class:`_InContacts`."""

    def factor(self, matrix: GramMatrix) -> None:
        x, rho = self.x, self.regularization
        self.slack, self.p, self.q = x.s + rho * x.lam, x.p + rho * x.alpha, x.q + rho * x.beta
        diagonal = 1.0 + np.where(self.has_lo, x.alpha / self.p, 0.0) + np.where(self.has_hi, x.beta / self.q, 0.0)
        self.solve = matrix.factor(x.lam / self.slack, diagonal)

    def direction(self, target_c: np.ndarray, target_l: np.ndarray, target_u: np.ndarray) -> _Iterate:
        x, has_lo, has_hi = self.x, self.has_lo, self.has_hi
        t_l = target_l - x.alpha * self.r_lower
        t_u = target_u - x.beta * self.r_upper
        h = -self.r_dual + np.where(has_lo, t_l / self.p, 0.0) - np.where(has_hi, t_u / self.q, 0.0)
        d_y = self.solve(h + self.Bt @ ((target_c - x.lam * self.r_primal) / self.slack))
        d_s = self.B @ d_y + self.r_primal
        return _Iterate(
            y=d_y, s=d_s, lam=(target_c - x.lam * d_s) / self.slack,
            p=np.where(has_lo, d_y + self.r_lower, 0.0), q=np.where(has_hi, -d_y + self.r_upper, 0.0),
            alpha=np.where(has_lo, (t_l - x.alpha * d_y) / self.p, 0.0),
            beta=np.where(has_hi, (t_u + x.beta * d_y) / self.q, 0.0))


class _InContacts(_Newton):
    """The Newton system as normal equations in the contact impulses,
    ``(B̃ diag(w) B̃ᵀ + diag(s/λ + ρ)) Δλ = r`` with ``w = 1/(1 + α/p + β/q)``: Δỹ is recovered
    from Δλ through ``w ≤ 1``, so rounding stays small however far the method converges; the
    matrix is larger than in the unknowns (a contact for each row and column) and costlier to
    factorize (3× on a grown 3D biofilm), so only the last iterations of a tight solve use it."""

    def factor(self, matrix: GramMatrix) -> None:
        x = self.x
        self.w = 1.0 / (1.0 + np.where(self.has_lo, x.alpha / x.p, 0.0) + np.where(self.has_hi, x.beta / x.q, 0.0))
        # Its own regularization is far smaller: rounding is no issue here (a pivot lost to it
        # raises, and the loop regularizes more).
        self.solve = matrix.factor(self.w, x.s / x.lam + self.regularization * CONTACTS_REGULARIZATION)

    def direction(self, target_c: np.ndarray, target_l: np.ndarray, target_u: np.ndarray) -> _Iterate:
        x, has_lo, has_hi = self.x, self.has_lo, self.has_hi
        t_l = target_l - x.alpha * self.r_lower
        t_u = target_u - x.beta * self.r_upper
        h = -self.r_dual + np.where(has_lo, t_l / x.p, 0.0) - np.where(has_hi, t_u / x.q, 0.0)
        d_lam = self.solve(-self.r_primal + target_c / x.lam - self.B @ (self.w * h))
        d_y = self.w * (h + self.Bt @ d_lam)
        return _Iterate(
            y=d_y, s=(target_c - x.s * d_lam) / x.lam, lam=d_lam,
            p=np.where(has_lo, d_y + self.r_lower, 0.0), q=np.where(has_hi, -d_y + self.r_upper, 0.0),
            alpha=np.where(has_lo, (t_l - x.alpha * d_y) / x.p, 0.0),
            beta=np.where(has_hi, (t_u + x.beta * d_y) / x.q, 0.0))


def interior_point(
    matrix: sp.spmatrix,
    rhs: np.ndarray,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
    *,
    tolerance: float = 1e-6,
    max_iterations: int | None = None,
    time_limit: float | None = None,
    initial: np.ndarray | None = None,
    warm_shift: float = 1e-2,
    space: str = "auto",
) -> IterativeSolution:
    """Solve ``min ½‖ỹ‖² s.t. B̃ỹ ≥ b̃, l ≤ ỹ ≤ u`` (module docstring).

    Args:
        matrix: (K, n) sparse ``B̃``.
        rhs: (K,) ``b̃``.
        lower, upper: (n,) bounds on ``ỹ`` (``-inf``/``inf`` where there is none), or None.
        tolerance: stopping tolerance (module docstring).
        max_iterations: cap on iterations (default :data:`MAX_ITERATIONS`).
        time_limit: stop after this many seconds.
        initial: (K,) contact impulses ``λ̃`` to start from (shifted into the interior by
            ``warm_shift`` of the largest); None: Mehrotra's start.
        space: the space of the Newton systems: ``"unknowns"`` (:class:`_InUnknowns`),
            ``"contacts"`` (:class:`_InContacts`), or ``"auto"``: the unknowns, then the contacts
            below :data:`UNKNOWNS_ACCURACY` (the default; the others are for measurements).

    Returns:
        :class:`~qpcontact.solvers.registry.IterativeSolution` with the best iterate (smallest
        error); status ``"converged"``, ``"max_iterations"``, ``"time_limit"``, ``"stalled"``
        (no progress: rounding, or a problem with no solution — conflicting bounds and
        contacts), ``"breakdown"`` (the factorization failed even regularized) or
        ``"infeasible"`` (a bound interval is empty).
    """
    with quiet_numpy():  # numpy's BLAS threads out of the factorization's way
        return _iterate(matrix, rhs, lower, upper, tolerance, max_iterations, time_limit, initial, warm_shift, space)


def _iterate(matrix: sp.spmatrix, rhs: np.ndarray, lower: np.ndarray | None, upper: np.ndarray | None,
             tolerance: float, max_iterations: int | None, time_limit: float | None, initial: np.ndarray | None,
             warm_shift: float, space: str) -> IterativeSolution:
    """The iterations of :func:`interior_point`."""
    check_options(tolerance, max_iterations, time_limit)
    if space not in ("auto", "unknowns", "contacts"):
        raise InvalidArgumentError(f"space: expected 'auto', 'unknowns' or 'contacts', got {space!r}")
    start = time.perf_counter()
    B = sp.csr_matrix(matrix)
    Bt = B.T.tocsr()
    b = np.asarray(rhs, dtype=float)
    k, n = B.shape
    lo = np.full(n, -np.inf) if lower is None else np.asarray(lower, dtype=float)
    hi = np.full(n, np.inf) if upper is None else np.asarray(upper, dtype=float)
    if lo.shape != (n,) or hi.shape != (n,):
        raise InvalidArgumentError(f"bounds: expected shape ({n},), got lower {lo.shape}, upper {hi.shape}")
    has_lo, has_hi = np.isfinite(lo), np.isfinite(hi)
    if np.any(lo > hi):
        return IterativeSolution(np.zeros(n), np.zeros(k), 0, False, "infeasible", np.inf, time.perf_counter() - start)
    cap = max_iterations or MAX_ITERATIONS
    # The normal matrices in the unknowns and in the contacts, made when first needed.
    normal: GramMatrix | None = None if space == "contacts" else _gram_matrix(B)
    contact_matrix: GramMatrix | None = GramMatrix(Bt) if space == "contacts" else None

    # Start (Mehrotra's heuristic): the least-squares impulses of (B̃B̃ᵀ + I)λ = b̃, ỹ = B̃ᵀλ moved
    # inside the bounds (a hundredth of the interval), then impulses and slacks shifted to be
    # positive and balanced. It saves about a sixth of the iterations on grown colonies against
    # unit impulses (docs/performance.md). Infeasible starts are fine: the residuals enter the
    # Newton equations. Bound slacks start at the distance to the bound.
    margin = np.where(has_lo & has_hi, 0.01 * (hi - lo), 0.01)
    if initial is None:
        # (B̃B̃ᵀ + I)⁻¹b̃ = b̃ − B̃(I + B̃ᵀB̃)⁻¹B̃ᵀb̃ (Woodbury), with the factorization of the unknowns
        if normal is not None:
            lam0 = b - B @ normal.factor(np.ones(k), np.ones(n))(Bt @ b)
        else:
            assert contact_matrix is not None
            lam0 = contact_matrix.factor(np.ones(n), np.ones(k))(b)
        y = np.clip(Bt @ lam0, np.where(has_lo, lo + margin, -np.inf), np.where(has_hi, hi - margin, np.inf))
        s0 = B @ y - b
        lam0 = lam0 + max(-1.5 * float(lam0.min(initial=0.0)), 0.0)
        s0 = s0 + max(-1.5 * float(s0.min(initial=0.0)), 0.0)
        product = float(lam0 @ s0)
        lam0 = lam0 + 0.5 * product / max(float(s0.sum()), 1e-300) + 1e-3
        s0 = s0 + 0.5 * product / max(float(lam0.sum()), 1e-300) + 1e-3
    else:
        lam0 = np.maximum(np.asarray(initial, dtype=float), 0.0)
        y = np.clip(Bt @ lam0, np.where(has_lo, lo + margin, -np.inf), np.where(has_hi, hi - margin, np.inf))
        scale = max(1.0, float(lam0.max(initial=0.0)))
        lam0 = np.maximum(lam0, warm_shift * scale)
        s0 = np.maximum(B @ y - b, warm_shift)
    x = _Iterate(y=y, s=s0, lam=lam0,
                 p=np.where(has_lo, np.maximum(y - lo, margin), 1.0), q=np.where(has_hi, np.maximum(hi - y, margin), 1.0),
                 alpha=has_lo.astype(float), beta=has_hi.astype(float))
    best_error, best, best_iteration = np.inf, x, 0
    status, iteration, regularization = "max_iterations", 0, REGULARIZATION
    for iteration in range(cap + 1):
        error = _error(x, B @ x.y - b, lo, hi, has_lo, has_hi, x.y - Bt @ x.lam - x.alpha + x.beta)
        if error < best_error:
            best_error, best, best_iteration = error, x, iteration
        if error <= tolerance:
            status = "converged"
            break
        if iteration == cap:
            break
        if iteration - best_iteration >= STALL_ITERATIONS:
            status = "stalled"
            break
        if time_limit is not None and time.perf_counter() - start > time_limit:
            status = "time_limit"
            break
        # Normal equations in the unknowns (the smaller and cheaper system) until the last
        # iterations of a tight solve, which need the stability of the contacts' (_InUnknowns).
        in_contacts = space == "contacts" or (space == "auto" and error <= UNKNOWNS_ACCURACY
                                              and tolerance < UNKNOWNS_ACCURACY)
        newton: _Newton = (_InContacts if in_contacts else _InUnknowns)(B, Bt, b, lo, hi, has_lo, has_hi, x,
                                                                          regularization)
        if in_contacts and contact_matrix is None:
            contact_matrix = GramMatrix(Bt)
        matrix = contact_matrix if in_contacts else normal
        assert matrix is not None
        while True:
            try:
                newton.factor(matrix)
                break
            except ArithmeticError:  # a pivot lost to rounding: regularize more
                regularization *= 100.0
                if regularization > 1e-4:
                    return _result(best, best_error, iteration, "breakdown", start)
                newton.regularization = regularization
        mu = newton.complementarity()
        affine = newton.direction(-x.lam * x.s, -x.alpha * x.p, -x.beta * x.q)
        sigma = min(1.0, (newton.complementarity(affine, *newton.lengths(affine)) / mu) ** 3) if mu > 0 else 0.0
        targets = (sigma * mu - x.lam * x.s - affine.lam * affine.s,
                   sigma * mu - x.alpha * x.p - affine.alpha * affine.p,
                   sigma * mu - x.beta * x.q - affine.beta * affine.q)
        step = newton.direction(*targets)
        primal, dual = newton.lengths(step)
        for _ in range(CORRECTORS):
            # Gondzio's centrality corrector: aim at a longer step, pull the complementarity
            # products of that trial point back into [0.1, 10]·σμ, and keep the correction when
            # the step gets longer (one more solve with the same factorization).
            trial = x.moved(step, min(1.0, 1.5 * primal + 0.1), min(1.0, 1.5 * dual + 0.1))
            box = (0.1 * sigma * mu, 10.0 * sigma * mu)
            products = (trial.lam * trial.s, trial.alpha * trial.p, trial.beta * trial.q)
            shifts = [np.clip(v, *box) - v for v in products]
            shifts = [np.maximum(v, -box[1]) for v in shifts]
            better = newton.direction(*(t + d for t, d in zip(targets, shifts, strict=True)))
            p2, d2 = newton.lengths(better)
            if min(p2, d2) < 1.01 * min(primal, dual):
                break
            step, primal, dual = better, p2, d2
            targets = tuple(t + d for t, d in zip(targets, shifts, strict=True))
        x = x.moved(step, STEP_FRACTION * primal, STEP_FRACTION * dual)
    return _result(best, best_error, iteration, status, start)


def _error(x: _Iterate, slack: np.ndarray, lo: np.ndarray, hi: np.ndarray, has_lo: np.ndarray, has_hi: np.ndarray,
           r_dual: np.ndarray) -> float:
    """The stopping measure of the module docstring."""
    scale = max(1.0, float(np.max(np.abs(x.lam), initial=0.0)))
    worst = [
        max(0.0, -float(slack.min(initial=0.0))),
        float(np.max(np.abs(np.minimum(x.lam / scale, slack)), initial=0.0)),
        float(np.max(np.abs(r_dual), initial=0.0)) / max(1.0, float(np.max(np.abs(x.y), initial=0.0))),
    ]
    for mask, gap, multiplier in ((has_lo, x.y - lo, x.alpha), (has_hi, hi - x.y, x.beta)):
        if mask.any():
            worst += [max(0.0, -float(gap[mask].min())),
                      float(np.max(np.abs(np.minimum(multiplier[mask] / scale, gap[mask]))))]
    return max(worst)


def _result(best: _Iterate, error: float, iteration: int, status: str, start: float) -> IterativeSolution:
    return IterativeSolution(best.y, np.maximum(best.lam, 0.0), iteration, status == "converged", status, error,
                             time.perf_counter() - start)


#: The normal matrix of the last problem: the next one reuses it (its ordering and symbolic
#: factorization) when its matrix has the same pattern (the linearizations of one position step).
_LAST: list[GramMatrix] = []


def _gram_matrix(matrix: sp.csr_matrix) -> GramMatrix:
    if _LAST and _LAST[0].refresh(matrix):
        return _LAST[0]
    _LAST[:] = [GramMatrix(matrix)]
    return _LAST[0]


def _solve(problem: Problem, formulation: str, form: str, *, tolerance: float, time_limit: float | None,
           settings: Mapping[str, Any], initial: np.ndarray | None) -> SolverOutput:
    out = interior_point(problem.matrix, problem.rhs, problem.lower, problem.upper, tolerance=tolerance,
                         time_limit=time_limit, max_iterations=settings.get("max_iterations"))
    return out.output()


register(SolverSpec(
    "ipm", formulations=("complementarity",), forms=("contact",), warm_start=False, time_limit=True, solve=_solve,
    description="built-in primal-dual interior point (sparse Cholesky of the normal equations in the unknowns), "
                "takes bounds on ỹ",
    settings=("max_iterations",), blockwise=True, bounds=("contact",), bundled=True,
))
