"""Checks of a result against the plain linear solve, and high-accuracy reference solutions."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ..assembly.system import ContactSystem
from ..solvers import LinearSolution, Problem, solve, solve_min_norm
from . import metrics
from .resolve import Result

#: Contact impulses below this (scaled) count as inactive in the linear solve.
ACTIVE_THRESHOLD = 1e-9


@dataclass
class Agreement:
    """How a result compares with the plain linear solve of the same system.

    Attributes:
        all_active: every contact is active in the linear solve, so the formulation's answer
            must equal it: for complementarity every ``λ_k > 0``; for least_squares ``Mx = b``
            is consistent.
        distance: ``‖x − x_lin‖_W / ‖x_lin‖_W``.
        max_difference: largest impulse component difference relative to the largest linear
            impulse component.
        inactive: number of contacts with ``λ_k ≤ 0`` in the linear solve (pulling impulses).
        agrees: ``all_active`` and ``distance <= tolerance``; None when not all active (then
            the two legitimately differ and only the difference is reported).
    """

    all_active: bool
    distance: float
    max_difference: float
    inactive: int
    agrees: bool | None


def compare_with_linear(result: Result, *, tolerance: float = 1e-5, linear: LinearSolution | None = None) -> Agreement:
    """Compare a converged QP result with the plain linear solve of the same system.

    The linear solve is done once per result and kept on it (``result.linear_solution``): a
    second comparison (another ``tolerance``) reuses it. ``linear``: a solve the caller already
    has (then nothing is solved)."""
    system = result.system
    if system is None or result.scaled_solution is None:
        return Agreement(True, 0.0, 0.0, 0, True if system is None else None)
    if linear is None:
        if result.linear_solution is None:
            result.linear_solution = solve_min_norm(system.matrix, system.rhs)
        linear = result.linear_solution
    lin = linear
    lam_scale = max(float(np.max(np.abs(lin.lam), initial=0.0)), 1e-300)
    inactive = int(np.sum(lin.lam <= ACTIVE_THRESHOLD * lam_scale))
    if result.formulation == "least_squares":
        all_active = lin.consistent
    else:
        all_active = lin.consistent and inactive == 0
    dist = metrics.distance(result.scaled_solution, lin.y)
    imp_lin = system.to_impulses(lin.y)
    max_diff = float(np.max(np.abs(result.impulses - imp_lin))) / max(float(np.max(np.abs(imp_lin))), 1e-300)
    return Agreement(all_active, dist, max_diff, inactive, (dist <= tolerance) if all_active else None)


def active_set_polish(system: ContactSystem, lam: np.ndarray, *,
                      thresholds: tuple[float, ...] = (1e-5, 1e-7, 1e-9, 1e-11)) -> np.ndarray | None:
    """The exact complementarity optimum for the active set of approximate contact impulses
    ``λ̃``, or None if no candidate set verifies.

    Candidate active sets are the contacts with ``λ̃_k > t·max λ̃`` for each threshold ``t`` in
    turn (colonies have contacts whose optimal impulse is 1e-7 of the largest: a coarse threshold
    leaves them out and the answer penetrates there). On the active rows ``B̃_𝒜ỹ = b̃_𝒜`` is solved
    exactly (minimum norm); the answer is kept only if it satisfies the KKT conditions to 1e-12:
    consistent on the active rows, feasible on all rows, non-negative impulses. Those conditions
    identify the unique optimum, so a verified answer does not depend on how accurate ``λ̃``
    was, only on its active set."""
    scale = max(float(lam.max(initial=0.0)), 1e-300)
    for threshold in thresholds:
        active = lam > threshold * scale
        if not active.any():
            continue
        try:
            polished = solve_min_norm(system.matrix[active], system.rhs[active], tolerance=1e-12)
        except Exception:
            continue
        feasible = np.all(system.matrix @ polished.y - system.rhs >= -1e-12)
        pushes = np.all(polished.lam >= -1e-12)
        if polished.consistent and feasible and pushes:
            return polished.y
    return None


class UnverifiedReferenceWarning(UserWarning):
    """:func:`reference_solution` could not verify its answer (no active-set polish satisfied
    the KKT conditions): it returned Clarabel's own answer, which is then no independent
    reference for grading Clarabel (or anything to better than Clarabel's tolerance)."""


@dataclass
class Reference:
    """A reference solution (:func:`reference`).

    Attributes:
        y: the scaled unknowns ``ỹ*``.
        method: how it was found (``"linear solve"``, ``"active-set polish of <solver>"``,
            ``"clarabel, unpolished"``).
        verified: it satisfies the formulation's optimality conditions to 1e-12 (the linear
            solve, consistent and, for complementarity, with every impulse pushing; or an
            active-set polish that verified), so it is the optimum whatever solver guessed it;
            False: only a solver's answer at its tolerance.
    """

    y: np.ndarray
    method: str
    verified: bool


def reference(system: ContactSystem, formulation: str, *, tolerance: float = 1e-10,
              guess: np.ndarray | None = None) -> Reference:
    """A high-accuracy ``ỹ*`` for a formulation, and how it was found: the linear solve for the
    plain problem (``"linear"``) and wherever it already satisfies the formulation's optimality
    conditions (all contacts active), else Clarabel at ``tolerance`` followed by an exact
    active-set polish (of Clarabel's contact impulses, else of MPRGP's) that is kept only if it
    verifies (feasible, and for complementarity, non-negative contact impulses). When no polish
    verifies, Clarabel's answer is returned with ``verified=False``.

    ``guess``: contact impulses ``λ̃`` from a faster solve (complementarity only). If the polish of
    their active set verifies (:func:`active_set_polish`), that exact optimum is returned and the
    Clarabel solve (minutes at 10⁵ cells) is skipped."""
    # At 1e-12 LSMR cannot certify the least-squares answer of a jammed packing (it stops at 3e-11).
    lin = solve_min_norm(system.matrix, system.rhs, tolerance=min(tolerance, 1e-10))
    if formulation == "linear" or (formulation == "least_squares" and lin.consistent):
        return Reference(lin.y, "linear solve", lin.consistent or formulation == "linear")
    if formulation == "complementarity" and lin.consistent and np.all(lin.lam > 0):
        return Reference(lin.y, "linear solve (every contact pushes)", True)
    if formulation == "complementarity" and guess is not None:
        polished = active_set_polish(system, guess)
        if polished is not None:
            return Reference(polished, "active-set polish of the guess", True)
    out = solve(Problem.of(system), "clarabel", formulation, "primal", tolerance=tolerance)
    if out.y is None:
        raise RuntimeError(f"reference solve failed: {out.status} {out.error or ''}")
    if formulation != "complementarity" or out.lam is None:
        # least_squares: Clarabel's answer (its r ≥ 0 part has no simple active-set polish)
        return Reference(out.y, "clarabel, unpolished", False)
    polished = active_set_polish(system, out.lam)
    if polished is not None:
        return Reference(polished, "active-set polish of clarabel", True)
    # Redundant contacts (side-by-side rods in a loop: Ã singular to 1e-6) leave the contact
    # impulses non-unique; an interior point spreads them, so its active set may not verify,
    # while MPRGP's vertex-like answer does.
    second = solve(Problem.of(system), "mprgp", formulation, "contact", tolerance=min(tolerance, 1e-12))
    polished = active_set_polish(system, second.lam) if second.lam is not None else None
    if polished is not None:
        return Reference(polished, "active-set polish of mprgp", True)
    return Reference(out.y, "clarabel, unpolished", False)


def reference_solution(system: ContactSystem, formulation: str, *, tolerance: float = 1e-10,
                       guess: np.ndarray | None = None) -> np.ndarray:
    """``reference(...).y`` (:func:`reference`); warns (:class:`UnverifiedReferenceWarning`) when
    the answer could not be verified, i.e. when it is Clarabel's own answer, never silently.
    Least-squares answers of inconsistent systems have no verification and do not warn (their
    reference is Clarabel at ``tolerance``, documented as such)."""
    found = reference(system, formulation, tolerance=tolerance, guess=guess)
    if not found.verified and formulation == "complementarity":
        warnings.warn(f"reference_solution: no active-set polish verified; this is {found.method}'s answer at "
                      f"tolerance {tolerance:g}, not an independent reference", UnverifiedReferenceWarning, stacklevel=2)
    return found.y
