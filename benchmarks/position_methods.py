"""Every method tried for the position step's QPs, on the same grown colonies (issue 22's
decision record in docs/model-notes.md, "A step that scales").

Usage (from the repository root; the states are those ``qpcontact bench-grown`` caches)::

    python benchmarks/position_methods.py ~/.cache/qpcontact-grown/2d-10000.npz \\
        ~/.cache/qpcontact-grown/3d-5000.npz --out /tmp/methods.md

For each state, two consecutive position steps are taken with the default step (division in
between, as in a run); the QP of each step's first linearization is kept, with the keys that
map contacts and unknowns from one step to the next. The second step's QP is then solved by
each method, cold and (where the method can use one) warm-started from the first step's answer:

- ``ipm`` in the unknowns (the default), and in the contact impulses (the solver until 2026-12);
- ``admm``: the splitting of OSQP written for this problem, one factorization of
  ``(1 + σ)I + ρB̃ᵀB̃ + ρ·bounds`` for the whole solve, relaxation 1.6;
- ``alm``: a semismooth Newton augmented Lagrangian (the idea of QPALM): Newton on
  ``½‖ỹ‖² + σ/2·dist²(Aỹ + μ/σ, [l, u])`` with an exact line search, multiplier updates;
- ``pgs``: projected Gauss–Seidel on the contact impulses and bound multipliers (needs numba);
- ``mprgp`` (registered, bounds as rows), ``clarabel`` and ``piqp`` (qpsolvers, primal form).

Each gets at most ``--time-limit`` seconds. The table gives seconds, iterations,
factorizations, the error of ``ỹ`` against a solve at tolerance 10⁻⁹ (largest difference over
the largest entry) and the penetration ``max(0, b̃ − B̃ỹ)``. Prints Markdown and writes it to
``--out``. A developer's tool: it captures the QPs by replacing the position step's ``solve``.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

import qpcontact.timestep.position as position
from qpcontact.colony import divide, grow_position, growth_time_step
from qpcontact.geometry import substrate
from qpcontact.io import load_colony
from qpcontact.solvers import Problem, solve
from qpcontact.solvers.cholesky import GramMatrix
from qpcontact.solvers.ipm import interior_point


# ---------------------------------------------------------------------------------------------
# The QPs of two consecutive steps
# ---------------------------------------------------------------------------------------------
def capture(path: Path) -> list[dict[str, Any]]:
    """The first linearization's QP of two consecutive position steps from the state ``path``."""
    colony, _ = load_colony(path)
    three_d = bool(np.any(np.abs(colony.cells.axes[:, 2]) > 1e-9)) or np.any(colony.cells.centers[:, 2] != 0)
    planes = [substrate(0.0)] if three_d else []
    captured: list[dict[str, Any]] = []
    real_solve, real_build = position.solve, position.build_system
    context: dict[str, Any] = {}

    def build(cells, contacts, b, **options):
        context["system"] = real_build(cells, contacts, b, **options)
        return context["system"]

    def spy(problem, *args, **options):
        system, ids = context["system"], context["ids"]
        c = system.contacts
        if context["first"]:
            captured.append(dict(
                B=sp.csr_matrix(problem.matrix), b=problem.rhs, lo=problem.lower, hi=problem.upper,
                key=((ids[c.cell_a].astype(np.int64) * 2**27 + np.where(c.cell_b >= 0, ids[np.maximum(c.cell_b, 0)],
                                                                       c.cell_b) + 2**26) * 8 + c.kind),
                column=ids[system.column_cell].astype(np.int64) * 8 + system.column_slot,
                w=system.column_inverse_mass, velocity=system.velocity_scale, operator=system.operator_scale))
            context["first"] = False
        return real_solve(problem, *args, **options)

    position.solve, position.build_system = spy, build
    rng, warm, motion = np.random.default_rng(1), None, None
    try:
        for _ in range(2):
            context.update(first=True, ids=colony.ids)
            grown, result = grow_position(colony, growth_time_step(colony), planes=planes,
                                          planar=None if three_d else True, warm=warm, motion=motion)
            warm, motion = result.warm, result.motion
            colony = divide(grown, 4.0, rng, axis_noise=0.02, rate_noise=0.1, base_rate=float(np.log(2)),
                            planar=not three_d)
    finally:
        position.solve, position.build_system = real_solve, real_build
    return captured


def mapped(source: dict[str, Any], target: dict[str, Any], lam: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
    """The first step's answer (scaled ``λ̃``, ``ỹ``) in the second step's scaled units, matched
    contact by contact and unknown by unknown (0 where there is no match)."""
    def match(keys_from, keys_to, values):
        order = np.argsort(keys_from)
        at = np.minimum(np.searchsorted(keys_from[order], keys_to), keys_from.size - 1)
        return np.where(keys_from[order][at] == keys_to, values[order][at], 0.0)
    physical_lam = lam * source["velocity"] / source["operator"] ** 2
    physical_x = y / np.sqrt(source["w"]) * source["velocity"] / source["operator"]
    lam_to = match(source["key"], target["key"], physical_lam) * target["operator"] ** 2 / target["velocity"]
    y_to = match(source["column"], target["column"], physical_x) * np.sqrt(target["w"]) * target["operator"] / target[
        "velocity"]
    return lam_to, y_to


# ---------------------------------------------------------------------------------------------
# The methods that are not registered solvers
# ---------------------------------------------------------------------------------------------
def rows_and_bounds(qp: dict[str, Any]) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """``A = [B̃; I_bounded]`` and its bounds ``l ≤ Aỹ ≤ u``."""
    B, n = qp["B"], qp["B"].shape[1]
    lo = np.full(n, -np.inf) if qp["lo"] is None else qp["lo"]
    hi = np.full(n, np.inf) if qp["hi"] is None else qp["hi"]
    bounded = np.flatnonzero(np.isfinite(lo) | np.isfinite(hi))
    A = sp.vstack([B, sp.csr_matrix((np.ones(bounded.size), (np.arange(bounded.size), bounded)),
                                    shape=(bounded.size, n))]).tocsr()
    return A, np.concatenate([qp["b"], lo[bounded]]), np.concatenate([np.full(B.shape[0], np.inf), hi[bounded]])


def admm(qp: dict[str, Any], warm: tuple | None, limit: float, tolerance: float = 1e-4,
         rho: float = 10.0, sigma: float = 1e-6, alpha: float = 1.6) -> dict[str, Any]:
    """OSQP's iteration for min ½‖ỹ‖² s.t. l ≤ Aỹ ≤ u, one factorization for the whole solve."""
    A, lower, upper = rows_and_bounds(qp)
    At, (m, n), start = A.T.tocsr(), A.shape, time.perf_counter()
    solve_with = GramMatrix(A).factor(np.full(m, rho), np.full(n, 1.0 + sigma))
    x, dual = np.zeros(n), np.zeros(m)
    if warm is not None:
        dual[:qp["B"].shape[0]] = -warm[0]
        x = warm[1].copy()
    z = np.clip(A @ x, lower, upper)
    iteration = 0
    while time.perf_counter() - start < limit:
        iteration += 1
        x_tilde = solve_with(sigma * x + At @ (rho * z - dual))
        z_tilde = A @ x_tilde
        x = alpha * x_tilde + (1 - alpha) * x
        relaxed = alpha * z_tilde + (1 - alpha) * z
        z_new = np.clip(relaxed + dual / rho, lower, upper)
        dual += rho * (relaxed - z_new)
        z = z_new
        if iteration % 10 == 0:
            scale = max(1.0, float(np.max(np.abs(x))))
            if np.max(np.abs(A @ x - z)) <= tolerance and np.max(np.abs(x + At @ dual)) <= tolerance * scale:
                break
    return dict(y=x, iterations=iteration, factorizations=1, seconds=time.perf_counter() - start)


def alm(qp: dict[str, Any], warm: tuple | None, limit: float, tolerance: float = 1e-4,
        sigma0: float = 1e4) -> dict[str, Any]:
    """A semismooth Newton augmented Lagrangian (QPALM's idea): exact line search along Newton
    directions of the augmented Lagrangian, one factorization per Newton step, σ raised where a
    constraint's violation does not fall to a quarter."""
    A, lower, upper = rows_and_bounds(qp)
    At, (m, n), start = A.T.tocsr(), A.shape, time.perf_counter()
    gram, sigma, mu = GramMatrix(A), np.full(m, sigma0), np.zeros(m)
    y = np.zeros(n)
    if warm is not None:
        mu[:qp["B"].shape[0]] = -warm[0]
        y = warm[1].copy()
    newton = factorizations = 0
    previous = np.full(m, np.inf)
    while time.perf_counter() - start < limit:
        for _ in range(200):
            ay = A @ y
            shifted = ay + mu / sigma
            excess = shifted - np.clip(shifted, lower, upper)
            gradient = y + At @ (sigma * excess)
            if np.max(np.abs(gradient)) <= 0.1 * tolerance * max(1.0, float(np.max(np.abs(y)))) or \
                    time.perf_counter() - start > limit:
                break
            d = -gram.factor(np.where(excess != 0, sigma, 0.0), np.ones(n))(gradient)
            factorizations += 1
            newton += 1
            y = y + _exact_step(y, d, shifted, A @ d, sigma, lower, upper) * d
        ay = A @ y
        shifted = ay + mu / sigma
        violation = np.abs(ay - np.clip(ay, lower, upper))
        mu = sigma * (shifted - np.clip(shifted, lower, upper))
        if violation.max(initial=0.0) <= tolerance:
            break
        slow = (violation > 0.25 * previous) & (violation > tolerance)
        sigma[slow] = np.minimum(10.0 * sigma[slow], 1e8)
        previous = violation
    return dict(y=y, iterations=newton, factorizations=factorizations, seconds=time.perf_counter() - start)


def _exact_step(y, d, shifted, ad, sigma, lower, upper) -> float:
    """The minimizer along ``d`` of the augmented Lagrangian: the root of its derivative, a
    piecewise linear increasing function with breakpoints where a row crosses its bounds."""
    def slope(t: float) -> float:
        r = shifted + t * ad
        return float(y @ d + t * (d @ d) + np.sum(sigma * ad * (r - np.clip(r, lower, upper))))
    with np.errstate(divide="ignore", invalid="ignore"):
        crossings = np.concatenate([(lower - shifted) / ad, (upper - shifted) / ad])
    points = np.unique(crossings[np.isfinite(crossings) & (crossings > 0)])
    if slope(0.0) >= 0:
        return 0.0
    low, high = 0, points.size
    while low < high:  # the first breakpoint where the slope is no longer negative
        middle = (low + high) // 2
        low, high = (low, middle) if slope(points[middle]) >= 0 else (middle + 1, high)
    t0 = 0.0 if low == 0 else float(points[low - 1])
    t1 = float(points[low]) if low < points.size else t0 + 1.0
    s0, s1 = slope(t0), slope(t1)
    return t0 - s0 * (t1 - t0) / (s1 - s0)


def pgs(qp: dict[str, Any], warm: tuple | None, limit: float, tolerance: float = 1e-4) -> dict[str, Any]:
    """Projected Gauss–Seidel on the multipliers of ``l ≤ Aỹ ≤ u`` (rows one at a time, ỹ kept
    equal to ``Aᵀ`` times them): what game engines and NSCD codes iterate. Needs numba."""
    from numba import njit

    @njit(cache=True)
    def sweeps(indptr, indices, data, norms, lower, upper, multiplier, y, count):  # pragma: no cover
        # Each row's multiplier minimizes the dual with the others held: ỹ without the row is
        # y' (product p' = a·y'); the multiplier is (l − p')/‖a‖² if that is positive, else
        # (u − p')/‖a‖² if that is negative, else 0.
        for _ in range(count):
            for row in range(lower.size):
                product = 0.0
                for p in range(indptr[row], indptr[row + 1]):
                    product += data[p] * y[indices[p]]
                old = multiplier[row]
                without = product - norms[row] * old
                new = 0.0
                if (lower[row] - without) / norms[row] > 0.0:
                    new = (lower[row] - without) / norms[row]
                elif (upper[row] - without) / norms[row] < 0.0:
                    new = (upper[row] - without) / norms[row]
                if new != old:
                    multiplier[row] = new
                    for p in range(indptr[row], indptr[row + 1]):
                        y[indices[p]] += data[p] * (new - old)

    A, lower, upper = rows_and_bounds(qp)
    start, multiplier = time.perf_counter(), np.zeros(A.shape[0])
    if warm is not None:
        multiplier[:qp["B"].shape[0]] = warm[0]
    y = A.T @ multiplier
    norms = np.asarray(A.multiply(A).sum(axis=1)).ravel()
    done = 0
    while time.perf_counter() - start < limit:
        sweeps(A.indptr, A.indices, A.data, norms, np.where(np.isfinite(lower), lower, -1e300),
               np.where(np.isfinite(upper), upper, 1e300), multiplier, y, 20)
        done += 20
        ay = A @ y
        if np.max(np.maximum(lower - ay, 0.0)) <= tolerance and np.max(np.maximum(ay - upper, 0.0)) <= tolerance:
            break
    return dict(y=y, iterations=done, factorizations=0, seconds=time.perf_counter() - start)


def registered(name: str, form: str = "auto", **options: Any) -> Callable[..., dict[str, Any]]:
    """A method of the solver registry."""
    def run(qp: dict[str, Any], warm: tuple | None, limit: float) -> dict[str, Any]:
        problem = Problem(qp["B"], qp["b"], qp["w"], lower=qp["lo"], upper=qp["hi"])
        start = time.perf_counter()
        out = solve(problem, name, "complementarity", form, tolerance=1e-4, time_limit=limit,
                    initial=None if warm is None else warm[0], settings=options or None)
        return dict(y=out.y, iterations=out.iterations, factorizations=None, seconds=time.perf_counter() - start,
                    status=out.status)
    return run


def ipm(space: str) -> Callable[..., dict[str, Any]]:
    def run(qp: dict[str, Any], warm: tuple | None, limit: float) -> dict[str, Any]:
        start = time.perf_counter()
        out = interior_point(qp["B"], qp["b"], qp["lo"], qp["hi"], tolerance=1e-4, time_limit=limit, space=space,
                             initial=None if warm is None else warm[0])
        return dict(y=out.y, iterations=out.iterations, factorizations=out.iterations + 1,
                    seconds=time.perf_counter() - start, status=out.status)
    return run


#: The methods by name: ``ipm-unknowns`` is the default solver, ``ipm-contacts`` the one until
#: 2026-12 (normal equations in the contact impulses).
METHODS: dict[str, Callable[..., dict[str, Any]]] = {
    "ipm-unknowns": ipm("unknowns"), "ipm-contacts": ipm("contacts"), "admm": admm, "alm": alm, "pgs": pgs,
    "mprgp": registered("mprgp"), "clarabel": registered("clarabel", "primal"), "piqp": registered("piqp", "primal"),
}
#: The methods that can start from the previous step's answer.
WARM = ("ipm-unknowns", "admm", "alm", "pgs", "mprgp")


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("states", nargs="+", type=Path, help="grown colony states (.npz)")
    parser.add_argument("--time-limit", type=float, default=60.0, help="seconds per method and QP (default 60)")
    parser.add_argument("--methods", default=",".join(METHODS), help="comma-separated (default: all)")
    parser.add_argument("--out", type=Path, required=True, help="the Markdown table is written here")
    args = parser.parse_args()
    lines = [f"Measured {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; second step's first linearization; "
             f"time limit {args.time_limit:g} s; error of ỹ against ipm at 10⁻⁹ (relative to its largest entry).", "",
             "| state | K × n | method | start | seconds | iterations | factorizations | error of ỹ | penetration | status |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for path in args.states:
        first, second = capture(path)
        reference = interior_point(second["B"], second["b"], second["lo"], second["hi"], tolerance=1e-9)
        previous = interior_point(first["B"], first["b"], first["lo"], first["hi"], tolerance=1e-4)
        warm = mapped(first, second, previous.lam, previous.y)
        scale = float(np.max(np.abs(reference.y)))
        for name in args.methods.split(","):
            for start_from in ("cold", "warm") if name in WARM else ("cold",):
                try:
                    out = METHODS[name](second, warm if start_from == "warm" else None, args.time_limit)
                except ImportError as exc:
                    lines.append(f"| {path.name} | | {name} | {start_from} | not run: {exc} | | | | | |")
                    continue
                y = out["y"]
                error = float(np.max(np.abs(y - reference.y))) / scale if y is not None else float("nan")
                penetration = float(np.max(np.maximum(second["b"] - second["B"] @ y, 0.0))) if y is not None else float(
                    "nan")
                status = out.get("status", "time limit" if out["seconds"] >= args.time_limit else "")
                lines.append(f"| {path.name} | {second['B'].shape[0]:,} × {second['B'].shape[1]:,} | {name} | "
                             f"{start_from} | {out['seconds']:.2f} | {out['iterations']} | "
                             f"{'' if out['factorizations'] is None else out['factorizations']} | {error:.1e} | "
                             f"{penetration:.1e} | {status} |")
                print(lines[-1], flush=True)
    args.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
