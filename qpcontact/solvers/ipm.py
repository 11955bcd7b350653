"""IPM: a built-in primal-dual interior-point solver of the complementarity problem with bounds

    min ½‖ỹ‖²   s.t.   B̃ỹ ≥ b̃,   l ≤ ỹ ≤ u   (l, u optional, per column, may be ±inf),

the solver of the position-level colony step (:mod:`qpcontact.timestep.position`), which bounds the
turning and the shrinking of each cell per step. Why an interior-point method: the contact graph
of a grown, jammed colony is nearly isostatic, so many active contacts are redundant and their
impulses are not unique, and about 8 % of the contacts change between pushing and not pushing
from one step to the next. Active-set and semismooth Newton methods (PDAS, projected Newton,
Fischer–Burmeister Newton, a semismooth augmented Lagrangian warm-started from the last step),
first-order methods (ADMM with one factorization, projected Gauss–Seidel, MPRGP) and warm starts
of this method from the last step all cost more on those problems (docs/model-notes.md, "A step
that scales"); an interior-point method is indifferent to redundancy and needs 11–16
factorizations whatever the colony.

The bounds are rows like the contacts (:class:`_Rows`): ``ỹ_j ≥ l_j`` and ``−ỹ_j ≥ −u_j``, so the
constraints are ``Gỹ ≥ c`` with ``G = [B̃; S]`` and every row has a slack ``z ≥ 0`` and a
multiplier ``v ≥ 0`` (the contact impulses ``λ̃``, then the bound multipliers). Each iteration
solves one linear system in the unknowns ỹ, the normal equations of the Newton step (Mehrotra
predictor–corrector and Gondzio's centrality correctors, all from one factorization)::

    (I + Gᵀ diag(v/z) G) Δỹ = (I + diag(Sᵀ(v/z)) + B̃ᵀ diag(λ/s) B̃) Δỹ = r,

with ``s = B̃ỹ − b̃`` the contact slacks. The matrix has the sparsity of ``I + B̃ᵀB̃`` (the bound
rows add to its diagonal): a cell's unknowns coupled with those of the cells it touches, smaller
than the contacts' own normal matrix ``B̃B̃ᵀ`` (3× cheaper to factorize on a grown 3D biofilm,
where a cell has 11 contacts and 6 unknowns). The pattern, its nested-dissection ordering and
the symbolic analysis are computed once per problem
(:class:`~qpcontact.solvers.cholesky.GramMatrix`), and reused by the next problem with the same
pattern; the next linearization of a position step (a problem of the same
:attr:`~qpcontact.solvers.registry.Problem.family`) grows its pattern from the last one's and keeps
its ordering, so that only the symbolic analysis is done again. Each iteration refills the values
(one sparse product) and factorizes. Around the factorization an iteration
does a few passes over the vectors: the step lengths over the slacks and the multipliers, the
complementarity of a trial point from four dot products (docs/model-notes.md, "A lean step").

Stopping (all in the scaled units of :mod:`qpcontact.assembly.system`, ``max b̃ = 1``): the
largest of the penetration ``max(0, b̃ − B̃ỹ)``, the bound violation, the stationarity residual
``‖ỹ − B̃ᵀλ̃ − α + β‖∞ / max(1, ‖ỹ‖∞)`` and the complementarity residual
``‖min(λ̃ / max(1, ‖λ̃‖∞), B̃ỹ − b̃)‖∞`` (and the same for the bounds) is at most ``tolerance``.
Impulses are measured relative to the largest: in a jammed colony they reach hundreds of times
the scale of one collision, and only their relative precision is meaningful.

Registered as ``"ipm"``: complementarity in contact form, bounds on ``ỹ``, time limit honoured
(checked between iterations), solved per independent block. The iterations
(:func:`iterate_rows`) see the rows and the normal matrix only through ``@``, ``factor`` and
:class:`Reductions`, so the distributed solver ``"ipm-petsc"`` (:mod:`qpcontact.solvers.petsc`)
runs this same code on each process's part of the problem.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidArgumentError
from .cholesky import GramMatrix, quiet_numpy
from .registry import IterativeSolution, Problem, SolverOutput, SolverSpec, check_options, objective_gradient, register

#: Default cap on interior-point iterations.
MAX_ITERATIONS = 100
#: Iterations without a new best error after which the method stops (rounding has won). 5 stopped
#: linearizations of grown 3·10⁴-cell colonies on a plateau the method leaves after 5–6 more
#: iterations (docs/performance.md, "Failures found at 10⁵ cells").
STALL_ITERATIONS = 10
#: Centrality correctors per iteration (Gondzio): each is one more solve with the same
#: factorization (a solve costs a tenth of a factorization on grown colonies); two save a
#: linearization of a grown colony about one iteration in fifteen against one (docs/model-notes.md,
#: "A lean step").
CORRECTORS = 2
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
#: The compliance ``δ`` of the starting impulses, ``(B̃B̃ᵀ + δI)λ = b̃``: the impulses of a jammed
#: colony are hundreds of times the scale of one collision, and a small ``δ`` starts them nearer
#: that scale (δ = 1: 20 iterations on grown 2D colonies; 0.1, with the bounds' multipliers
#: started consistently: 15; docs/model-notes.md, "A lean step").
START_COMPLIANCE = 0.1


class Reductions:
    """The reductions of the vector work over every part of the rows and unknowns: here, in one
    process, each is its own value. A distributed solve (:mod:`qpcontact.solvers.petsc`) holds
    only its part of each vector and passes reductions over its processes, so that the one
    algorithm below serves both (the step lengths, the complementarity and the error are the
    only places where the parts meet, besides the products with ``B̃`` and the factorization)."""

    def total(self, value: float) -> float:
        """The sum of ``value`` over the parts."""
        return value

    def least(self, value: float) -> float:
        """The smallest ``value`` of the parts."""
        return value

    def most(self, value: float) -> float:
        """The largest ``value`` of the parts."""
        return value


#: The reductions of a solve in one process.
SERIAL = Reductions()


@dataclass(frozen=True)
class _Rows:
    """The constraints ``Gỹ ≥ c`` as one list of rows: the ``K`` contact rows ``B̃ỹ ≥ b̃``, then
    one row ``ỹ_j ≥ l_j`` per column with a lower bound and one row ``−ỹ_j ≥ −u_j`` per column
    with an upper bound. Each row has a slack ``z ≥ 0`` and a multiplier ``v ≥ 0`` (the contact
    impulses ``λ̃``, then the bound multipliers), so the method treats contacts and bounds alike."""

    B: sp.csr_matrix
    Bt: sp.csr_matrix
    lower: np.ndarray  # (L,) columns with a lower bound
    upper: np.ndarray  # (U,) columns with an upper bound
    c: np.ndarray  # (K + L + U,) right-hand sides
    reduce: Reductions = SERIAL  # over the parts of a distributed solve
    m: int = 0  # the number of rows over every part (make_rows counts them once)
    curvature: sp.csr_matrix | None = None  # R of the objective's ½‖R(ỹ − ỹ₀)‖² (None: none)
    anchor: np.ndarray | None = None  # ỹ₀
    curvature_values: np.ndarray | None = None  # RᵀR in the normal matrix's stored order

    def gradient(self, y: np.ndarray) -> np.ndarray:
        """The objective's gradient at ``ỹ`` (:func:`~qpcontact.solvers.registry.objective_gradient`)."""
        return objective_gradient(y, self.curvature, self.anchor)


    @property
    def k(self) -> int:
        return self.B.shape[0]

    @property
    def n(self) -> int:
        return self.B.shape[1]

    def apply(self, y: np.ndarray) -> np.ndarray:
        """``Gỹ`` (K + L + U,)."""
        return np.concatenate([self.B @ y, y[self.lower], -y[self.upper]])

    def transpose(self, v: np.ndarray) -> np.ndarray:
        """``Gᵀv`` (n,)."""
        out = self.Bt @ v[:self.k]
        self.add_bounds(out, v)
        return out

    def add_bounds(self, out: np.ndarray, v: np.ndarray) -> None:
        """``out += Sᵀv_S``, the bound rows' part of ``Gᵀv`` (each column at most once per kind)."""
        k, lo = self.k, self.lower.size
        out[self.lower] += v[k:k + lo]
        out[self.upper] -= v[k + lo:]


@dataclass
class _Iterate:
    """A primal-dual point: unknowns ``y``, slacks ``z`` and multipliers ``v`` of the rows of
    :class:`_Rows` (``v[:K]`` the contact impulses)."""

    y: np.ndarray
    z: np.ndarray
    v: np.ndarray

    def moved(self, step: _Iterate, primal: float, dual: float) -> _Iterate:
        return _Iterate(self.y + primal * step.y, self.z + primal * step.z, self.v + dual * step.v)


def _max_step(value: np.ndarray, change: np.ndarray, reduce: Reductions) -> float:
    """Largest ``t ≤ 1`` with ``value + t·change ≥ 0`` (``value > 0``): one pass, one temporary."""
    worst = reduce.least(float(np.min(change / value, initial=np.inf)))
    return 1.0 if worst >= -1.0 else -1.0 / worst


def _lengths(rows: _Rows, x: _Iterate, d: _Iterate) -> tuple[float, float]:
    """Largest primal and dual step lengths (≤ 1) that keep slacks and multipliers ≥ 0."""
    return _max_step(x.z, d.z, rows.reduce), _max_step(x.v, d.v, rows.reduce)


def _complementarity(rows: _Rows, x: _Iterate, d: _Iterate | None = None, primal: float = 0.0,
                     dual: float = 0.0) -> float:
    """Mean complementarity product ``vᵀz/m`` of the iterate moved by ``d`` (if given), from four
    dot products: no moved iterate is built for a scalar."""
    total = float(x.v @ x.z)
    if d is not None:
        total += primal * float(x.v @ d.z) + dual * float(d.v @ x.z) + primal * dual * float(d.v @ d.z)
    return rows.reduce.total(total) / max(rows.m, 1)


class _Newton:
    """The Newton system of one iteration, factorized once, solved for several complementarity
    targets ``t`` (``v∘Δz + z∘Δv = t``; the primal and dual residuals are driven to zero too),
    whatever the space of the linear system (:class:`_InUnknowns`, :class:`_InContacts`)."""

    def __init__(self, rows: _Rows, x: _Iterate, r_primal: np.ndarray, r_dual: np.ndarray,
                 regularization: float) -> None:
        self.rows, self.x, self.regularization = rows, x, regularization
        self.r_primal, self.r_dual = r_primal, r_dual  # Gy − c − z, y − Gᵀv
        self.solve: Callable[[np.ndarray], np.ndarray] = lambda v: v

    def factor(self, matrix: GramMatrix) -> None:
        """Factorize this iteration's system (raises ArithmeticError, CHOLMOD's)."""
        raise NotImplementedError

    def direction(self, target: np.ndarray) -> _Iterate:
        """The Newton direction for complementarity target ``target`` (m,)."""
        raise NotImplementedError


class _InUnknowns(_Newton):
    """The Newton system as normal equations in the unknowns (module docstring): eliminated
    ``Δz = GΔỹ + r_p`` and ``Δv = (t − v∘Δz)/z̃``; what is left is the dual equation
    ``(I + Gᵀ diag(v/z̃) G) Δỹ = −r_d + Gᵀ((t − v∘r_p)/z̃)``. The slacks are regularized
    (``z̃ = z + ρv``: a tiny compliance) alike in the matrix and in the elimination, so the dual
    equation holds up to the rounding of ``Δv``, which is recovered from Δỹ through the weight
    v/z̃. That weight grows without bound as the method converges, so below
    :data:`UNKNOWNS_ACCURACY` the method continues in :class:`_InContacts`."""

    def factor(self, matrix: GramMatrix) -> None:
        x, rows = self.x, self.rows
        self.slack = x.z + self.regularization * x.v
        weight = x.v / self.slack
        self.solve = matrix.factor(weight[:rows.k], _bound_diagonal(rows, weight), rows.curvature_values)

    def direction(self, target: np.ndarray) -> _Iterate:
        x, rows = self.x, self.rows
        d_y = self.solve(rows.transpose((target - x.v * self.r_primal) / self.slack) - self.r_dual)
        d_z = rows.apply(d_y)
        d_z += self.r_primal
        return _Iterate(y=d_y, z=d_z, v=(target - x.v * d_z) / self.slack)


class _InContacts(_Newton):
    """The Newton system as normal equations in the contact impulses,
    ``(B̃ diag(ω) B̃ᵀ + diag(z/λ + ρ)) Δλ = r`` with ``ω = 1/(1 + Sᵀ diag(v/z) S)`` the bound rows
    ``S`` eliminated: Δỹ is recovered from Δλ through ``ω ≤ 1``, so rounding stays small however
    far the method converges; the matrix is larger than in the unknowns (a contact for each row
    and column) and costlier to factorize (3× on a grown 3D biofilm), so only the last iterations
    of a tight solve use it."""

    def factor(self, matrix: GramMatrix) -> None:
        x, k = self.x, self.rows.k
        self.omega = 1.0 / _bound_diagonal(self.rows, x.v / x.z)
        # Its own regularization is far smaller: rounding is no issue here (a pivot lost to it
        # raises, and the loop regularizes more).
        self.solve = matrix.factor(self.omega, x.z[:k] / x.v[:k] + self.regularization * CONTACTS_REGULARIZATION)

    def direction(self, target: np.ndarray) -> _Iterate:
        x, rows, k = self.x, self.rows, self.rows.k
        # The bound rows' part of Gᵀ((t − v∘r_p)/z), with the dual residual.
        eliminated = (target - x.v * self.r_primal) / x.z
        h = -self.r_dual
        rows.add_bounds(h, eliminated)
        d_lam = self.solve(-self.r_primal[:k] + target[:k] / x.v[:k] - rows.B @ (self.omega * h))
        d_y = self.omega * (h + rows.Bt @ d_lam)
        d_z = rows.apply(d_y)
        d_z += self.r_primal
        d_z[:k] = (target[:k] - x.z[:k] * d_lam) / x.v[:k]
        d_v = (target - x.v * d_z) / x.z
        d_v[:k] = d_lam
        return _Iterate(y=d_y, z=d_z, v=d_v)


def _bound_diagonal(rows: _Rows, weight: np.ndarray) -> np.ndarray:
    """``1 + diag(Sᵀ diag(weight) S)`` (n,): the identity plus the bound rows' weights."""
    diagonal = np.ones(rows.n)
    k, lo = rows.k, rows.lower.size
    diagonal[rows.lower] += weight[k:k + lo]
    diagonal[rows.upper] += weight[k + lo:]
    return diagonal


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
    curvature: tuple[sp.spmatrix, np.ndarray] | None = None,
    family: object | None = None,
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
        curvature: ``(R, ỹ₀)``: the objective is ``½‖ỹ‖² + ½‖R(ỹ − ỹ₀)‖²`` (a sequential
            QP's curvature of the constraints); the Newton systems are then in the unknowns.
        family: :attr:`~qpcontact.solvers.registry.Problem.family`: a problem of the family of the
            last one grows its normal matrix from the last one's (:func:`_gram_matrix`).

    Returns:
        :class:`~qpcontact.solvers.registry.IterativeSolution` with the best iterate (smallest
        error); status ``"converged"``, ``"max_iterations"``, ``"time_limit"``, ``"stalled"``
        (no progress: rounding, or a problem with no solution — conflicting bounds and
        contacts), ``"breakdown"`` (the factorization failed even regularized) or
        ``"infeasible"`` (a bound interval is empty).
    """
    with quiet_numpy():  # numpy's BLAS threads out of the factorization's way
        return _iterate(matrix, rhs, lower, upper, tolerance, max_iterations, time_limit, initial, warm_shift, space,
                        curvature, family)


def _start(rows: _Rows, normal: GramMatrix | None, contact_matrix: GramMatrix | None, lo: np.ndarray,
           hi: np.ndarray, initial: np.ndarray | None, warm_shift: float) -> _Iterate:
    """The starting point (Mehrotra's heuristic, over contacts and bounds alike).

    The impulses of ``(B̃B̃ᵀ + δI)λ = b̃`` (:data:`START_COMPLIANCE`), ``ỹ = B̃ᵀλ`` moved inside the
    bounds (a hundredth of the interval), each bound's multiplier what that move took (so the dual
    equation holds), then all slacks and all multipliers shifted to be positive and balanced.
    Infeasible starts are fine: the residuals enter the Newton equations."""
    B, Bt, b, k, n = rows.B, rows.Bt, rows.c[:rows.k], rows.k, rows.n
    has_lo, has_hi = np.isfinite(lo), np.isfinite(hi)
    margin = np.where(has_lo & has_hi, 0.01 * (hi - lo), 0.01)
    inside = (np.where(has_lo, lo + margin, -np.inf), np.where(has_hi, hi - margin, np.inf))
    reduce = rows.reduce
    if initial is not None:
        lam = np.maximum(np.asarray(initial, dtype=float), 0.0)
        y = np.clip(Bt @ lam, *inside)
        scale = max(1.0, reduce.most(float(lam.max(initial=0.0))))
        z = np.maximum(rows.apply(y) - rows.c, np.concatenate([np.full(k, warm_shift), margin[rows.lower],
                                                                margin[rows.upper]]))
        v = np.concatenate([np.maximum(lam, warm_shift * scale), np.ones(rows.lower.size + rows.upper.size)])
        return _Iterate(y, z, v)
    delta = START_COMPLIANCE
    # (B̃B̃ᵀ + δI)⁻¹b̃ = (b̃ − B̃(δI + B̃ᵀB̃)⁻¹B̃ᵀb̃)/δ (Woodbury), with the factorization of the unknowns
    if normal is not None:
        lam = (b - B @ normal.factor(np.ones(k), np.full(n, delta))(Bt @ b)) / delta
    else:
        assert contact_matrix is not None
        lam = contact_matrix.factor(np.ones(n), np.full(k, delta))(b)
    free = Bt @ lam
    y = np.clip(free, *inside)
    z = rows.apply(y) - rows.c
    v = np.concatenate([lam, np.maximum(y - free, 0.0)[rows.lower], np.maximum(free - y, 0.0)[rows.upper]])
    z += max(-1.5 * reduce.least(float(z.min(initial=0.0))), 0.0)
    v += max(-1.5 * reduce.least(float(v.min(initial=0.0))), 0.0)
    product = reduce.total(float(z @ v))
    z_sum, v_sum = reduce.total(float(z.sum())), reduce.total(float(v.sum()))
    z += 0.5 * product / max(v_sum, 1e-300) + 1e-3
    v += 0.5 * product / max(z_sum, 1e-300) + 1e-3
    return _Iterate(y, z, v)


def _iterate(matrix: sp.spmatrix, rhs: np.ndarray, lower: np.ndarray | None, upper: np.ndarray | None,
             tolerance: float, max_iterations: int | None, time_limit: float | None, initial: np.ndarray | None,
             warm_shift: float, space: str, curvature: tuple[sp.spmatrix, np.ndarray] | None = None,
             family: object | None = None) -> IterativeSolution:
    """:func:`interior_point` in one process: its rows and normal matrix, then :func:`iterate_rows`."""
    check_options(tolerance, max_iterations, time_limit)
    if space not in ("auto", "unknowns", "contacts"):
        raise InvalidArgumentError(f"space: expected 'auto', 'unknowns' or 'contacts', got {space!r}")
    start = time.perf_counter()
    B = sp.csr_matrix(matrix)
    b = np.asarray(rhs, dtype=float)
    k, n = B.shape
    lo, hi = bounds_of(lower, upper, n)
    rows = make_rows(B, B.T.tocsr(), b, lo, hi, SERIAL)
    if rows is None:
        return IterativeSolution(np.zeros(n), np.zeros(k), 0, False, "infeasible", np.inf, time.perf_counter() - start)
    # The normal matrices in the unknowns and in the contacts, made when first needed.
    normal: GramMatrix | None = None if space == "contacts" else _gram_matrix(B, family)
    if curvature is not None:
        # The curvature's RᵀR lies in the normal matrix's pattern (a row of R couples the cells
        # of one contact, as the row of B̃ does: the pattern and its analysis are kept): added to
        # each refill, in the unknowns only.
        R = sp.csr_matrix(curvature[0])
        if normal is None:
            normal = _gram_matrix(B, family)
        values = normal.stored(R.T @ R)
        if values is None:  # it couples unknowns no contact couples: a pattern for both
            normal = GramMatrix(sp.vstack([B, R], format="csr"))
            values = normal.stored(R.T @ R)
        rows = dataclasses.replace(rows, curvature=R, anchor=np.asarray(curvature[1], dtype=float),
                                   curvature_values=values)
        space = "unknowns"
    return iterate_rows(rows, normal, lo, hi, start=start, tolerance=tolerance, max_iterations=max_iterations,
                        time_limit=time_limit, initial=initial, warm_shift=warm_shift, space=space)


def bounds_of(lower: np.ndarray | None, upper: np.ndarray | None, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The (n,) bounds ``l, u`` (``∓inf`` for None).

    Raises:
        InvalidArgumentError: a bound of another shape.
    """
    lo = np.full(n, -np.inf) if lower is None else np.asarray(lower, dtype=float)
    hi = np.full(n, np.inf) if upper is None else np.asarray(upper, dtype=float)
    if lo.shape != (n,) or hi.shape != (n,):
        raise InvalidArgumentError(f"bounds: expected shape ({n},), got lower {lo.shape}, upper {hi.shape}")
    return lo, hi


def make_rows(B: Any, Bt: Any, b: np.ndarray, lo: np.ndarray, hi: np.ndarray, reduce: Reductions) -> _Rows | None:
    """The rows of the problem (:class:`_Rows`) from ``B̃`` and ``B̃ᵀ`` (anything with ``@``: a
    distributed solve passes its part of each), ``b̃`` and the bounds; None when a bound
    interval is empty (in any part)."""
    if reduce.most(float(np.any(lo > hi))):
        return None
    lower_columns, upper_columns = np.flatnonzero(np.isfinite(lo)), np.flatnonzero(np.isfinite(hi))
    c = np.concatenate([b, lo[lower_columns], -hi[upper_columns]])
    return _Rows(B, Bt, lower_columns, upper_columns, c, reduce, int(reduce.total(float(c.size))))


def iterate_rows(rows: _Rows, normal: Any, lo: np.ndarray, hi: np.ndarray, *, start: float, tolerance: float,
                 max_iterations: int | None, time_limit: float | None, initial: np.ndarray | None,
                 warm_shift: float, space: str) -> IterativeSolution:
    """The iterations over ``rows`` (:func:`make_rows`) with the normal matrix in the unknowns
    ``normal`` (:class:`~qpcontact.solvers.cholesky.GramMatrix`, or a distributed one with the
    same ``factor``; None with ``space="contacts"``), from :func:`_start`: each one error, one
    factorization, a predictor, a corrector and up to :data:`CORRECTORS` centrality correctors.
    ``start`` is the :func:`time.perf_counter` the time limit counts from."""
    k, reduce = rows.k, rows.reduce
    cap = max_iterations or MAX_ITERATIONS
    contact_matrix: GramMatrix | None = GramMatrix(rows.Bt) if space == "contacts" else None
    x = _start(rows, normal, contact_matrix, lo, hi, initial, warm_shift)
    best_error, best, best_iteration = np.inf, x, 0
    status, iteration, regularization = "max_iterations", 0, REGULARIZATION
    for iteration in range(cap + 1):
        gap = rows.apply(x.y) - rows.c
        r_dual = rows.gradient(x.y) - rows.transpose(x.v)
        error = _error(rows, x, gap, r_dual)
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
        if time_limit is not None and reduce.most(float(time.perf_counter() - start > time_limit)):
            status = "time_limit"
            break
        # Normal equations in the unknowns (the smaller and cheaper system) until the last
        # iterations of a tight solve, which need the stability of the contacts' (_InContacts).
        in_contacts = space == "contacts" or (space == "auto" and error <= UNKNOWNS_ACCURACY
                                              and tolerance < UNKNOWNS_ACCURACY)
        gap -= x.z  # now the primal residual Gy − c − z
        newton: _Newton = (_InContacts if in_contacts else _InUnknowns)(rows, x, gap, r_dual, regularization)
        if in_contacts and contact_matrix is None:
            contact_matrix = GramMatrix(rows.Bt)
        system = contact_matrix if in_contacts else normal
        assert system is not None
        while True:
            try:
                newton.factor(system)
                break
            except ArithmeticError:  # a pivot lost to rounding: regularize more
                regularization *= 100.0
                if regularization > 1e-4:
                    return _result(best, best_error, iteration, "breakdown", k, start)
                newton.regularization = regularization
        x = _step(x, newton)
    return _result(best, best_error, iteration, status, k, start)


def _step(x: _Iterate, newton: _Newton) -> _Iterate:
    """One iteration's move: Mehrotra's predictor–corrector with Gondzio's centrality correctors,
    all with the one factorization of ``newton``."""
    rows = newton.rows
    mu = _complementarity(rows, x)
    products = x.v * x.z
    affine = newton.direction(-products)
    sigma = min(1.0, (_complementarity(rows, x, affine, *_lengths(rows, x, affine)) / mu) ** 3) if mu > 0 else 0.0
    target = sigma * mu - products - affine.v * affine.z
    step = newton.direction(target)
    primal, dual = _lengths(rows, x, step)
    box = (0.1 * sigma * mu, 10.0 * sigma * mu)
    for _ in range(CORRECTORS):
        # Gondzio's centrality corrector: aim at a longer step, pull the complementarity products
        # of that trial point back into [0.1, 10]·σμ, and keep the correction when the step gets
        # longer (one more solve with the same factorization).
        a_p, a_d = min(1.0, 1.5 * primal + 0.1), min(1.0, 1.5 * dual + 0.1)
        trial = (x.v + a_d * step.v) * (x.z + a_p * step.z)
        shift = np.clip(trial, *box)
        shift -= trial
        np.maximum(shift, -box[1], out=shift)
        shift += target
        better = newton.direction(shift)
        p2, d2 = _lengths(rows, x, better)
        if min(p2, d2) < 1.01 * min(primal, dual):
            break
        step, primal, dual, target = better, p2, d2, shift
    return x.moved(step, STEP_FRACTION * primal, STEP_FRACTION * dual)


def _error(rows: _Rows, x: _Iterate, gap: np.ndarray, r_dual: np.ndarray) -> float:
    """The stopping measure of the module docstring: the largest of the violation of any row
    (penetration or bound), the complementarity ``|min(v/scale, gap)|`` of any row (impulses
    relative to the largest contact impulse) and the relative dual residual."""
    most = rows.reduce.most
    scale = max(1.0, most(float(np.max(np.abs(x.v[:rows.k]), initial=0.0))))
    violation = max(0.0, -rows.reduce.least(float(gap.min(initial=0.0))))
    complementarity = most(float(np.max(np.abs(np.minimum(x.v / scale, gap)), initial=0.0)))
    dual = most(float(np.max(np.abs(r_dual), initial=0.0))) / max(1.0, most(float(np.max(np.abs(x.y), initial=0.0))))
    return max(violation, complementarity, dual)


def _result(best: _Iterate, error: float, iteration: int, status: str, k: int, start: float) -> IterativeSolution:
    return IterativeSolution(best.y, np.maximum(best.v[:k], 0.0), iteration, status == "converged", status, error,
                             time.perf_counter() - start)


#: The normal matrix of the last problem and that problem's family: the next problem reuses it (its
#: ordering and symbolic factorization) when its matrix has the same pattern, and grows its own from
#: it when it is of the same family (:attr:`~qpcontact.solvers.registry.Problem.family`).
_LAST: list[GramMatrix] = []
_LAST_FAMILY: list[object | None] = [None]


def _gram_matrix(matrix: sp.csr_matrix, family: object | None = None) -> GramMatrix:
    """The normal matrix of ``matrix``: the last one refreshed where the pattern is the same (and
    its ordering was its own, or the family is the same: what a run computes never depends on
    which problems came before its step, so a resumed run takes the same steps); grown from the
    last one within a family (:class:`~qpcontact.solvers.cholesky.GramMatrix`); else made anew."""
    same_family = family is not None and family is _LAST_FAMILY[0]
    if not (_LAST and (same_family or not _LAST[0].inherited) and _LAST[0].refresh(matrix)):
        _LAST[:] = [GramMatrix(matrix, grown_from=_LAST[0] if _LAST and same_family else None)]
    _LAST_FAMILY[0] = family
    return _LAST[0]


def _solve(problem: Problem, formulation: str, form: str, *, tolerance: float, time_limit: float | None,
           settings: Mapping[str, Any], initial: np.ndarray | None) -> SolverOutput:
    curvature = None
    if problem.curvature is not None:
        assert problem.anchor is not None  # solve() refuses one without the other
        curvature = (problem.curvature, problem.anchor)
    out = interior_point(problem.matrix, problem.rhs, problem.lower, problem.upper, tolerance=tolerance,
                         time_limit=time_limit, max_iterations=settings.get("max_iterations"), curvature=curvature,
                         family=problem.family)
    return out.output()


register(SolverSpec(
    "ipm", formulations=("complementarity",), forms=("contact",), warm_start=False, time_limit=True, solve=_solve,
    description="built-in primal-dual interior point (sparse Cholesky of the normal equations in the unknowns), "
                "takes bounds on ỹ",
    settings=("max_iterations",), blockwise=True, bounds=("contact",), bundled=True, curvature=True,
))
