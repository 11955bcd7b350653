"""Error measures of model.md, all dimensionless and unit-invariant.

Scaled quantities (``ỹ``, ``λ̃``, ``B̃``, ``b̃``) come from :class:`qpcontact.assembly.ContactSystem`;
``max|b̃| = 1`` and the mean diagonal of ``Ã = B̃B̃ᵀ`` is 1, so velocities and impulses are both
of order one there.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..assembly.system import ContactSystem
from ..geometry.cells import Cells


def _least_squares_objective(system: ContactSystem, y: np.ndarray) -> float:
    return 0.5 * float(np.sum((system.matrix @ y - system.rhs) ** 2))


#: Objective of each formulation in scaled units, as a function of (system, ỹ). The plain
#: problem ("linear") is the least-squares fit of B̃ỹ = b̃ without the constraint.
OBJECTIVES: dict[str, Callable[[ContactSystem, np.ndarray], float]] = {
    "complementarity": lambda system, y: 0.5 * float(y @ y),
    "least_squares": _least_squares_objective,
    "linear": _least_squares_objective,
}


def penetration(system: ContactSystem, y: np.ndarray) -> float:
    """``max_k max(0, b_k − (Mx)_k) / max_k |b_k|``: how much the worst contact still approaches,
    relative to the largest approach speed (0 = no contact penetrates)."""
    gap = system.rhs - system.matrix @ y
    return float(max(0.0, gap.max(initial=0.0)) / np.max(np.abs(system.rhs)))


def complementarity_residual(system: ContactSystem, y: np.ndarray, lam: np.ndarray) -> float:
    """``‖min(λ̃, B̃ỹ − b̃)‖∞``: 0 exactly when ``λ ≥ 0``, ``Mx ≥ b`` and they are complementary."""
    slack = system.matrix @ y - system.rhs
    return float(np.max(np.abs(np.minimum(lam, slack)), initial=0.0))


def duality_gap(system: ContactSystem, y: np.ndarray, lam: np.ndarray) -> float:
    """Relative duality gap of the complementarity QP, ``|λ̃ᵀ(B̃ỹ − b̃)| / ‖ỹ‖²`` (with
    ``ỹ = B̃ᵀλ̃`` the primal objective minus the dual one, over twice the objective). Unlike the
    complementarity residual, which an interior-point method drives down only like the square root
    of its tolerance, this falls with the tolerance for every converged backend."""
    norm2 = float(y @ y)
    gap = abs(float(lam @ (system.matrix @ y - system.rhs)))
    return gap / norm2 if norm2 > 0 else gap


def multiplier_consistency(system: ContactSystem, y: np.ndarray, lam: np.ndarray) -> float:
    """``‖ỹ − B̃ᵀλ̃‖ / ‖ỹ‖``: how far the impulses are from equal and opposite contact impulses."""
    norm = float(np.linalg.norm(y))
    return float(np.linalg.norm(y - system.matrix.T @ lam)) / norm if norm > 0 else 0.0


def kkt_residuals(system: ContactSystem, y: np.ndarray, lam: np.ndarray, lower: np.ndarray | None = None,
                  upper: np.ndarray | None = None, gradient: np.ndarray | None = None) -> dict[str, float]:
    """How far ``(ỹ, λ̃)`` is from satisfying the KKT conditions of the complementarity QP
    ``min ½‖ỹ‖²  s.t. B̃ỹ ≥ b̃`` (model.md), with bounds ``l ≤ ỹ ≤ u`` when given (the
    position-level step's): a certificate of optimality that needs no other solver, since the QP
    is strictly convex and its KKT point is the unique optimum. Scaled units (``max b̃ = 1``);
    impulses relative to ``max(max |λ̃|, 1)``, ``ỹ`` to ``max(‖ỹ‖, 1)``:

    - ``stationarity``: ``‖ỹ − B̃ᵀλ̃ − α + β‖`` (the impulses are equal and opposite contact
      impulses); the bound multipliers ``α, β ≥ 0`` are those the answer implies, the positive and
      negative parts of ``ỹ − B̃ᵀλ̃`` on the columns with a lower or upper bound;
    - ``primal``: ``max(0, max(b̃ − B̃ỹ))`` (no contact approaches: the penetration);
    - ``dual``: ``max(0, −min λ̃)`` (no contact pulls);
    - ``complementarity``: ``max_k |λ̃_k (B̃ỹ − b̃)_k|`` (a contact that pushes is exactly stopped);
    - with bounds, ``bounds``: the largest violation of a bound, and ``bound complementarity``:
      ``max |α (ỹ − l)|, |β (u − ỹ)|`` (a bound that acts is met exactly).

    All are 0 exactly at the optimum. ``gradient``: the objective's gradient at ``ỹ`` when it is
    not ``½‖ỹ‖²``'s (a sequential QP's curvature, :attr:`qpcontact.solvers.Problem.gradient`):
    the stationarity is then ``gradient − B̃ᵀλ̃ − α + β``."""
    slack = system.matrix @ y - system.rhs
    scale = max(float(np.abs(lam).max(initial=0.0)), 1.0)
    residual = (y if gradient is None else gradient) - system.matrix.T @ lam
    out = {
        "primal": max(0.0, -float(slack.min(initial=0.0))),
        "dual": max(0.0, -float(lam.min(initial=0.0))) / scale,
        "complementarity": float(np.max(np.abs(lam * slack), initial=0.0)) / scale,
    }
    if lower is not None or upper is not None:
        residual, out["bounds"], gap = bound_residuals(y, residual, lower, upper)
        out["bound complementarity"] = gap / scale
    out["stationarity"] = float(np.linalg.norm(residual)) / max(float(np.linalg.norm(y)), 1.0)
    return out


def bound_residuals(y: np.ndarray, residual: np.ndarray, lower: np.ndarray | None,
                    upper: np.ndarray | None) -> tuple[np.ndarray, float, float]:
    """The bounds' part of :func:`kkt_residuals`: the stationarity residual ``ỹ − B̃ᵀλ̃`` with
    the bound multipliers ``α, β`` the answer implies taken out, the largest violation of a
    bound, and the largest ``|α (ỹ − l)|, |β (u − ỹ)|`` (not yet scaled)."""
    lo = np.full(y.size, -np.inf) if lower is None else np.asarray(lower, dtype=float)
    hi = np.full(y.size, np.inf) if upper is None else np.asarray(upper, dtype=float)
    alpha = np.where(np.isfinite(lo), np.maximum(residual, 0.0), 0.0)
    beta = np.where(np.isfinite(hi), np.maximum(-residual, 0.0), 0.0)
    with np.errstate(invalid="ignore"):
        violation = max(0.0, float(np.max(np.maximum(lo - y, y - hi), initial=0.0)))
        gaps = np.concatenate([np.where(alpha > 0, alpha * (y - lo), 0.0), np.where(beta > 0, beta * (hi - y), 0.0)])
    return residual - alpha + beta, violation, float(np.max(np.abs(gaps), initial=0.0))


def distance(y: np.ndarray, reference: np.ndarray) -> float:
    """``‖x − x*‖_W / ‖x*‖_W`` (``= ‖ỹ − ỹ*‖/‖ỹ*‖`` in the scaled unknowns)."""
    norm = float(np.linalg.norm(reference))
    diff = float(np.linalg.norm(y - reference))
    return diff / norm if norm > 0 else diff


def objective_gap(system: ContactSystem, formulation: str, y: np.ndarray, reference: np.ndarray) -> float:
    """``|f(ỹ) − f(ỹ*)| / (½‖b̃‖²)`` for the formulation's objective f."""
    f = OBJECTIVES[formulation]
    return abs(f(system, y) - f(system, reference)) / (0.5 * float(system.rhs @ system.rhs))


def physics(cells: Cells, system: ContactSystem, impulses: np.ndarray, contact_impulses: np.ndarray | None) -> dict[str, float]:
    """Momentum and energy checks of physical impulses.

    Returns:
        ``momentum_change``: ``|ΣΔp + reactions| / Σ|λ|`` where reactions are the impulses taken
            by immovable bodies (planes, fixed cells) through the contact impulses λ; 0 for
            equal and opposite contact impulses.
        ``angular_momentum_change``: the same for angular momentum about the centroid of the
            contact points, relative to ``Σ|λ|·R`` (R = largest lever arm).
        ``energy_change``: ``ΔKE = xᵀWp + ½xᵀWx`` [energy], computed without cancellation.
        ``energy_change_relative``: ``ΔKE / (½xᵀWx)``; ≤ 0 for inelastic contact (−1 when every
            contact is active and exactly stopped).
    """
    contacts = system.contacts
    touched = np.unique(system.column_cell)
    dp, dl = impulses[touched, 0:3], impulses[touched, 3:6]
    centres = cells.centers[touched]
    points = cells.centers[contacts.cell_a] + contacts.offset_a
    origin = points.mean(axis=0) if len(points) else np.zeros(3)
    linear = dp.sum(axis=0)
    angular = (np.cross(centres - origin, dp) + dl).sum(axis=0)
    total_lambda = 0.0
    if contact_impulses is not None and len(contact_impulses):
        lam = contact_impulses
        total_lambda = float(np.abs(lam).sum())
        # Immovable sides (a static body or a fixed cell) take the reaction of their contacts.
        fixed_a = ~np.isfinite(cells.masses[contacts.cell_a])
        fixed_b = (contacts.cell_b < 0) | ~np.isfinite(cells.masses[np.maximum(contacts.cell_b, 0)])
        sign = fixed_a * 1.0 - fixed_b * 1.0
        reaction = (sign * lam)[:, None] * contacts.normal
        linear = linear + reaction.sum(axis=0)
        angular = angular + np.cross(points - origin, reaction).sum(axis=0)
    lever = float(np.max(np.linalg.norm(np.vstack([points, centres]) - origin, axis=1), initial=0.0))
    momentum_scale = total_lambda if total_lambda > 0 else float(np.abs(dp).sum()) or 1.0
    angular_scale = momentum_scale * (lever if lever > 0 else 1.0)

    velocities = np.hstack([cells.velocities, cells.angular_velocities, cells.growth_rates[:, None]])
    work = float(np.einsum("ij,ij->", impulses[touched], velocities[touched]))
    own = 0.5 * float(
        np.einsum("ij,ij->", dp, cells.inverse_masses[touched, None] * dp)
        + np.einsum("ij,ij->", dl, cells.subset(touched).apply_inverse_inertia(dl))
        + np.dot(impulses[touched, 6] ** 2, cells.inverse_growth_inertia[touched])
    )
    return {
        "momentum_change": float(np.linalg.norm(linear)) / momentum_scale,
        "angular_momentum_change": float(np.linalg.norm(angular)) / angular_scale,
        "energy_change": work + own,
        "energy_change_relative": (work + own) / own if own > 0 else 0.0,
    }
