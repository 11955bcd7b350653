"""One call per timestep: :func:`resolve` finds the colliding contacts of a scene, builds the
system, solves it and returns the impulses with diagnostics."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..assembly.system import ContactSystem, build_system
from ..checks import flag, instance, mapping, number
from ..errors import InvalidArgumentError, InvalidCellsError, SolverFailedError
from ..geometry.cells import Cells
from ..geometry.contacts import Contacts, check_contacts, colliding, find_contacts
from ..solvers import FORMS, FORMULATIONS, LinearSolution, Problem, get_solver, solve, solve_min_norm
from ..solvers.registry import check_options
from . import metrics

#: An answer is accepted when each measure of :func:`acceptance_failure` is at most this many
#: times the tolerance ...
ACCEPT_FACTOR = 100.0
#: ... and at most this, whatever the tolerance: a loose tolerance (``100·tolerance >= 1`` from
#: 0.01 on) must still reject answers that are wrong (issue 13, item 8).
ACCEPT_CAP = 0.1


#: An answer the solver calls converged that fails the checks is asked for once more at this
#: fraction of the tolerance (:func:`solve_system`), down to :data:`MIN_RETRY_TOLERANCE`.
RETRY_FACTOR = 0.1
MIN_RETRY_TOLERANCE = 1e-12


def acceptance_limit(tolerance: float) -> float:
    """The bound every accepted answer meets in each measure of :func:`acceptance_failure`:
    ``min(ACCEPT_FACTOR·tolerance, ACCEPT_CAP)`` (dimensionless)."""
    return min(ACCEPT_FACTOR * tolerance, ACCEPT_CAP)


@dataclass
class Result:
    """The outcome of one :func:`resolve` call.

    Attributes:
        impulses: (N, 7) ``(Δp_x, Δp_y, Δp_z, ΔL_x, ΔL_y, ΔL_z, Δg)`` per cell; zeros for cells
            left out [momentum units].
        cells: the cells with the impulses applied (a copy of the input cells, unchanged, when
            the result is not converged).
        contacts: the colliding contacts that entered the system (row order).
        contact_impulses: (K,) normal impulse ``λ_k`` at each colliding contact [momentum], or
            None where the solver gives none.
        solver, formulation, form: what was solved and how.
        converged: the answer passed the checks (:func:`acceptance_failure`) and the solver
            reported success, or, for complementarity, whatever the solver's status word (the
            checks certify such an answer: :func:`certified`; ``status`` then says so).
        status: the solver's own status text (``"no_contact"`` when nothing collided).
        iterations: solver iterations where known.
        times: seconds per phase: ``detect``, ``assemble``, ``setup``, ``solve``, ``check``,
            ``total``.
        errors: dimensionless error measures (see :mod:`qpcontact.resolve.metrics`): ``penetration``,
            ``complementarity`` and ``duality_gap`` (complementarity formulation), ``multiplier_consistency``,
            ``momentum_change``, ``angular_momentum_change``, ``energy_change``,
            ``energy_change_relative``.
        n_unknowns: columns of the reduced system.
        planar: whether the planar reduction was used.
        condition_estimate: ``cond₁`` of the scaled Delassus operator, when estimated.
        message: why the result is not converged, if it is not.
        system: the assembled system (None when nothing collided).
        scaled_solution: the scaled unknowns ``ỹ`` (for comparisons).
        pulling: how many contact impulses pull (``λ_k < 0``); only the plain solve
            (``solver="linear"``) gives them, and warns
            (:class:`~qpcontact.errors.PullingImpulseWarning`): its all-active answer is then no
            physical resolution.
        linear_solution: the plain linear solve of ``system``, once :func:`compare_with_linear`
            has computed it (kept so that a second comparison does not solve again).
    """

    impulses: np.ndarray
    cells: Cells
    contacts: Contacts
    contact_impulses: np.ndarray | None
    solver: str
    formulation: str
    form: str
    converged: bool
    status: str
    iterations: int | None
    times: dict[str, float]
    errors: dict[str, float]
    n_unknowns: int
    planar: bool
    condition_estimate: float | None = None
    message: str = ""
    system: ContactSystem | None = field(default=None, repr=False)
    scaled_solution: np.ndarray | None = field(default=None, repr=False)
    pulling: int = 0
    linear_solution: LinearSolution | None = field(default=None, repr=False, compare=False)

    def summary(self) -> str:
        """One line: solver, status, contacts, unknowns, time, penetration."""
        return (
            f"{self.solver}/{self.formulation}: {self.status} ({'converged' if self.converged else 'NOT converged'}), "
            f"{len(self.contacts)} contacts, {self.n_unknowns} unknowns, {self.times.get('total', 0.0) * 1e3:.2f} ms, "
            f"penetration {self.errors.get('penetration', 0.0):.2e}"
        )


def _check_options(solver: str, formulation: str, form: str, tolerance: float, time_limit: float | None,
                   on_failure: str) -> tuple[str, str]:
    """Named errors for bad arguments; returns the ``(formulation, form)`` the solver solves."""
    spec = get_solver(solver)
    if formulation not in FORMULATIONS:
        raise InvalidArgumentError(f"formulation: expected one of {FORMULATIONS}, got {formulation!r}")
    if form not in (*FORMS, "auto"):
        raise InvalidArgumentError(f"form: expected 'auto' or one of {FORMS}, got {form!r}")
    check_options(tolerance, None, time_limit)
    planned = spec.plan(formulation, form)
    if on_failure not in ("raise", "return"):
        raise InvalidArgumentError(f"on_failure: expected 'raise' or 'return', got {on_failure!r}")
    return planned


def acceptance_failure(system: ContactSystem, formulation: str, y: np.ndarray, lam: np.ndarray | None,
                       tolerance: float, lower: np.ndarray | None = None, upper: np.ndarray | None = None,
                       gradient: np.ndarray | None = None) -> str:
    """Why a reported solution is not accepted, or ``""`` when it is (docs/model-notes.md,
    "Accepting an answer"). What ``tolerance`` promises: each measure below, in the scaled units
    of :mod:`qpcontact.assembly.system` (``max b̃ = 1``), is at most
    :func:`acceptance_limit` ``= min(ACCEPT_FACTOR·tolerance, ACCEPT_CAP)``, for every solver:

    - every formulation, the plain one included: the penetration
      ``max(0, max(b̃ − B̃ỹ))`` (the plain solve of an inconsistent ``Mx = b``, e.g. a cell
      squeezed between fixed cells with position correction, leaves contacts approaching: not
      an answer);
    - complementarity: the complementarity residual ``‖min(λ̃, B̃ỹ − b̃)‖∞`` (the error measure
      of the problem: 0 exactly at the optimum; an answer without contact impulses is refused,
      since it cannot be checked), the relative duality gap, the multiplier inconsistency and the
      most negative (pulling) contact impulse relative to the largest;
    - least_squares, when ``Mx = b`` is consistent: the overshoot of ``B̃ỹ = b̃``.

    The plain problem's answer may pull by design (negative contact impulses are not checked).

    With bounds on ``ỹ`` (``lower``, ``upper``: the position-level step's turning and shrinking),
    a complementarity answer is judged by the KKT conditions with bounds
    (:func:`~qpcontact.resolve.metrics.kkt_residuals`: complementarity with the impulses relative
    to the largest, stationarity with the bound multipliers the answer implies, bound violation
    and bound complementarity) in place of the duality gap and the multiplier consistency, which
    assume no bounds. An objective with curvature (``gradient``, its gradient at ``ỹ``:
    :attr:`qpcontact.solvers.Problem.gradient`) is judged by the same KKT conditions."""
    limit = acceptance_limit(tolerance)
    if system.owned_rows is not None and gradient is not None:
        raise InvalidArgumentError("gradient: a system shared among processes is judged without curvature")
    if system.owned_rows is not None:
        return _shared_acceptance(system, formulation, y, lam, limit, lower, upper)
    checks = {"penetrates by": metrics.penetration(system, y)}
    bounded = lower is not None or upper is not None
    if formulation == "complementarity" and lam is None:
        return "the answer has no contact impulses, so its complementarity cannot be checked"
    if formulation == "complementarity" and (bounded or gradient is not None):
        assert lam is not None
        kkt = metrics.kkt_residuals(system, y, lam, lower, upper, gradient)
        # Impulses relative to the largest, as the solvers measure them: in a jammed colony they
        # reach hundreds of times the scale of one collision, and an absolute λ̃ of 10⁻⁵ at a
        # contact that does not push is rounding of that scale.
        checks.update({"has complementarity residual": kkt["complementarity"],
                       "pulls with relative contact impulse": kkt["dual"],
                       "has stationarity residual (bounds included)": kkt["stationarity"],
                       "violates a bound by": kkt.get("bounds", 0.0),
                       "has bound complementarity residual": kkt.get("bound complementarity", 0.0)})
    elif formulation == "complementarity":
        assert lam is not None
        checks["has complementarity residual"] = metrics.complementarity_residual(system, y, lam)
        # Feasible but not optimal (e.g. impulses larger than needed) shows up here.
        checks["has relative duality gap"] = metrics.duality_gap(system, y, lam)
        # Impulses that are not equal and opposite contact impulses (primal form: ỹ and the
        # duals disagree), or contact impulses that pull: both seen without scaling
        # (docs/stability.md), where they cancel inside the duality gap.
        checks["has multiplier inconsistency"] = metrics.multiplier_consistency(system, y, lam)
        checks["pulls with relative contact impulse"] = max(0.0, -float(lam.min(initial=0.0))) / max(
            float(np.abs(lam).max(initial=0.0)), 1e-300)
    overshoot = float(np.max(system.matrix @ y - system.rhs)) / float(np.max(np.abs(system.rhs)))
    if formulation == "least_squares" and overshoot > limit:
        # Feasible is not optimal: when Mx = b is consistent the optimum has B̃ỹ = b̃, and an
        # answer overshooting it (seen without scaling, docs/stability.md) must not pass. The
        # linear solve that decides consistency runs only for answers with such a slack.
        try:
            consistent = solve_min_norm(system.matrix, system.rhs, tolerance=1e-10).consistent
        except SolverFailedError:
            consistent = False
        if consistent:
            checks["overshoots by"] = overshoot
    for what, value in checks.items():
        if not value <= limit:
            if formulation == "linear" and what == "penetrates by":
                return (f"the answer {what} {value:.3g} (> {limit:.3g}): Mx = b has no solution (more contacts "
                        "than the cells can satisfy, e.g. with position correction); use a QP formulation")
            return f"the answer {what} {value:.3g} (> {limit:.3g} = min({ACCEPT_FACTOR:g}·tolerance, {ACCEPT_CAP:g}))"
    return ""


def _shared_acceptance(system: ContactSystem, formulation: str, y: np.ndarray, lam: np.ndarray | None, limit: float,
                       lower: np.ndarray | None, upper: np.ndarray | None) -> str:
    """:func:`acceptance_failure` of a system shared among processes, each holding its own rows
    (the position step's, :func:`~qpcontact.assembly.system.build_system` with ``split``): the
    measures of rows are reduced over the processes, ``B̃ᵀλ̃`` is summed; every process gets the
    same verdict. The complementarity formulation with bounds only (the position step's)."""
    split, rows = system.split, system.owned_rows
    assert rows is not None
    if formulation != "complementarity" or lam is None:
        return f"a system shared among processes is checked in the complementarity formulation, with impulses; got {formulation}"
    slack = (system.matrix @ y)[rows] - system.rhs[rows]
    largest_rhs = split.most(float(np.max(np.abs(system.rhs[rows]), initial=0.0)))
    scale = max(float(np.abs(lam).max(initial=0.0)), 1.0)
    residual = y - split.summed(system.matrix.T @ lam)
    checks = {"penetrates by": split.most(max(0.0, -float(slack.min(initial=0.0)))) / largest_rhs,
              "has complementarity residual": split.most(float(np.max(np.abs(lam[rows] * slack), initial=0.0))) / scale,
              "pulls with relative contact impulse": max(0.0, -float(lam.min(initial=0.0))) / scale}
    residual, checks["violates a bound by"], gap = metrics.bound_residuals(y, residual, lower, upper)
    checks["has bound complementarity residual"] = gap / scale
    checks["has stationarity residual (bounds included)"] = float(np.linalg.norm(residual)) / max(
        float(np.linalg.norm(y)), 1.0)
    for what, value in checks.items():
        if not value <= limit:
            return f"the answer {what} {value:.3g} (> {limit:.3g} = min({ACCEPT_FACTOR:g}·tolerance, {ACCEPT_CAP:g}))"
    return ""


@dataclass
class SystemSolution:
    """The outcome of one :func:`solve_system`: the answer and what the solve did.

    Attributes:
        y: the scaled unknowns ``ỹ`` (None if the solver returned no answer).
        lam: the scaled contact impulses ``λ̃`` with ``ỹ = B̃ᵀλ̃`` (None where the solver gives none).
        converged: the answer passed the acceptance checks and the solver reported success (or,
            for a formulation they certify, :func:`certified`, whatever its status word).
        status: the solver's own status text (``"... (again at T)"`` after the retry).
        iterations: solver iterations where known.
        setup_seconds, solve_seconds: time in the solver's setup and solve [s] (both attempts).
        message: why the answer is not accepted ("" if it is).
        formulation, form: what was solved and how (after :meth:`SolverSpec.plan`).
        condition_estimate: ``cond₁`` of the scaled Delassus operator, when asked for.
        extras: what the solver reported besides (e.g. ``blocks``, ``residual``).
    """

    y: np.ndarray | None
    lam: np.ndarray | None
    converged: bool
    status: str
    iterations: int | None
    setup_seconds: float
    solve_seconds: float
    message: str
    formulation: str
    form: str
    condition_estimate: float | None = None
    extras: dict[str, Any] = field(default_factory=dict)


def certified(formulation: str) -> bool:
    """Whether :func:`acceptance_failure` certifies an answer of this formulation by itself, so
    that it is accepted whatever the solver's status word: complementarity, whose checks are its
    KKT conditions (penetration = primal feasibility, sign of λ = dual feasibility,
    complementarity residual and duality gap, ỹ = B̃ᵀλ̃). Not least_squares (optimality is not
    checked where ``Mx = b`` has no solution) nor the plain solve (its own test decides)."""
    return formulation == "complementarity"


def solve_system(
    system: ContactSystem,
    *,
    solver: str = "osqp",
    formulation: str = "complementarity",
    form: str = "auto",
    tolerance: float = 1e-6,
    time_limit: float | None = None,
    regularization: float = 0.0,
    solver_settings: dict[str, Any] | None = None,
    estimate_condition: bool = False,
) -> SystemSolution:
    """Solve an assembled system with a registered solver and check the answer
    (:func:`acceptance_failure`); an answer the solver does not call converged is accepted when
    the checks certify it (:func:`certified`: complementarity), whatever the status word;
    an answer the solver calls converged but that fails the checks
    is solved for once more at ``RETRY_FACTOR·tolerance`` (within what is left of
    ``time_limit``) and kept if it passes them at ``tolerance``. Used by :func:`resolve` and by
    the studies (which assemble once and solve many times).

    Returns:
        A :class:`SystemSolution` (never raises for a failure to solve: ``converged`` is False
        and ``message`` says why).
    """
    spec = get_solver(solver)
    formulation, form = spec.plan(formulation, form)
    settings = mapping("solver_settings", solver_settings)
    estimate_condition = flag("estimate_condition", estimate_condition)
    # A solver that can estimate the condition from its own factorization takes the setting.
    own_estimate = "estimate_condition" in (spec.settings or ())
    if estimate_condition and own_estimate:
        settings["estimate_condition"] = True
    problem = Problem.of(system, regularization)
    start = time.perf_counter()
    out = solve(problem, solver, formulation, form, tolerance=tolerance, time_limit=time_limit, settings=settings)
    status, iterations, extras = out.status, out.iterations, out.extras
    setup, solve_seconds = out.setup_seconds, out.solve_seconds
    if out.y is None:
        failure = out.error or f"{solver} returned no solution (status {out.status})"
    elif not out.found:
        # The status word is the backend's own stopping test, not the promise: an answer whose
        # residuals certify it (the KKT conditions of complementarity) is accepted whatever the
        # word (issue 19: Clarabel's "AlmostSolved" at penetration 1e-9, complementarity 3e-8 on
        # examples/channel.py). least_squares' checks do not certify optimality where Mx = b has
        # no solution, so there the word stands.
        failure = acceptance_failure(system, formulation, out.y, out.lam, tolerance) if certified(formulation) else (
            "its formulation's checks do not certify an answer")
        if failure:
            failure = f"{solver} did not converge (status {out.status}); {failure}"
        else:
            status = f"{out.status} (accepted by its residuals)"
    else:
        failure = acceptance_failure(system, formulation, out.y, out.lam, tolerance)
        left = None if time_limit is None else time_limit - (time.perf_counter() - start)
        tighter = tolerance * RETRY_FACTOR
        if failure and formulation != "linear" and tighter >= MIN_RETRY_TOLERANCE and (left is None or left > 0):
            # The solver's own stopping test is not the promise: once, ask it for RETRY_FACTOR
            # of the tolerance, and keep that answer if it keeps the promise at the tolerance
            # asked for (a grown 2D colony, 7,000 contacts: Clarabel's residual 1.04e-4 at 1e-6,
            # 1e-6 at 1e-7, for 0.35 s more; OSQP's 2.3e-4, then 5.7e-5).
            again = solve(problem, solver, formulation, form, tolerance=tighter, time_limit=left, settings=settings)
            setup, solve_seconds = setup + again.setup_seconds, solve_seconds + again.solve_seconds
            if again.y is not None and again.found and not acceptance_failure(system, formulation, again.y, again.lam,
                                                                                 tolerance):
                out, failure = again, ""
                status, iterations, extras = f"{again.status} (again at {tighter:g})", again.iterations, again.extras
        if failure:
            failure = f"{solver} reported success but {failure}"
    condition = None
    if estimate_condition:
        condition = (out.extras.get("condition_estimate") if own_estimate else solve_min_norm(
            system.matrix, system.rhs, method="auto", estimate_condition=True).condition_estimate)
    return SystemSolution(out.y, out.lam, not failure, status, iterations, setup, solve_seconds, failure, formulation,
                          form, condition, extras)


def resolve(
    cells: Cells,
    *,
    solver: str = "osqp",
    formulation: str = "complementarity",
    form: str = "auto",
    tolerance: float = 1e-6,
    margin: float = 0.0,
    position_correction: float = 0.0,
    dt: float | None = None,
    contacts: Contacts | None = None,
    reduce: bool = True,
    planar: bool | None = None,
    scale: bool = True,
    time_limit: float | None = None,
    regularization: float = 0.0,
    solver_settings: dict[str, Any] | None = None,
    estimate_condition: bool = False,
    on_failure: str = "raise",
    keep_separating: bool = False,
) -> Result:
    """Resolve the contacts of one timestep.

    Args:
        cells: the scene (positions, shapes, masses, momenta before contact).
        solver: a registered solver (:func:`qpcontact.available_solvers`): ``"linear"`` (plain
            minimum-W-norm solve of ``Mx = b``), ``"mprgp"`` (built-in matrix-free QP solver,
            complementarity only: :mod:`qpcontact.solvers.mprgp`) or an installed qpsolvers
            backend (``"clarabel"``, ``"osqp"``, ...).
        formulation: ``"complementarity"`` (impulses only push; default), ``"least_squares"``, or
            ``"linear"`` (the plain problem). A plain solver (``solver="linear"``) solves the
            plain problem whatever formulation is asked for.
        form: ``"primal"``, ``"contact"`` or ``"auto"`` (see
            :mod:`qpcontact.solvers.qpsolvers_bridge`; ``"auto"``:
            :data:`qpcontact.solvers.DEFAULT_FORM`).
        tolerance: what the answer promises (dimensionless: the problem is scaled so that
            ``max b = 1``): its penetration and, for complementarity, its complementarity
            residual ``‖min(λ̃, B̃ỹ − b̃)‖∞`` (with its duality gap, multiplier inconsistency and
            pulling) are at most ``min(100·tolerance, 0.1)``
            (:func:`~qpcontact.resolve.resolve.acceptance_failure`), whatever the solver; an
            answer that the solver calls converged but that fails this is solved for once more
            at a tenth of the tolerance (:func:`solve_system`), otherwise it is not accepted.
        margin: contacts closer than this also count [length]. The default counts only contacts
            that touch: on a state that :func:`qpcontact.position_step` (``qpcontact
            simulate``) left, whose contacts rest touching to within the solver's accuracy (some
            a hair apart), it misses those; pass ``margin=0.05`` µm or more there
            (docs/solvers.md).
        position_correction: β in ``b = −u + β·max(0, −d)/dt`` (0 = off); needs ``dt``.
        dt: the time step [time], for position correction.
        contacts: precomputed contacts (e.g. cell–cell plus cell–plane); found from ``cells`` if
            None.
        reduce: leave out unknowns the scene does not need (default True).
        planar: force (True) or forbid (False) the planar reduction; None detects it, for the
            detection of contacts (:meth:`Cells.is_monolayer`) and for the system alike.
        scale: nondimensionalize the system (default; see :mod:`qpcontact.assembly.system`). ``False``
            hands the solvers the system in the caller's units (for measurements only).
        time_limit: seconds the solver may take, where it supports a limit
            (:attr:`SolverSpec.time_limit`); a factorization is not interrupted (Clarabel,
            OSQP), and PIQP, ProxQP and the plain solve take none: docs/solvers.md, "Time
            limits".
        regularization: ε of the least_squares formulation (dimensionless; default 0 = the exact
            minimum-W-norm selection).
        solver_settings: extra solver options: a qpsolvers backend's own options, passed
            through; for the built-in solvers the names their spec lists (``"mprgp"``:
            ``max_iterations``, ``proportioning``), others raise.
        estimate_condition: also estimate the condition number of the scaled Delassus operator.
        on_failure: ``"raise"`` a :class:`~qpcontact.errors.SolverFailedError` (default), or
            ``"return"`` the unconverged result (with ``cells`` unchanged).
        keep_separating: also put the contacts that do not collide (``b <= 0``) into the system
            when any contact collides, so impulses elsewhere cannot drive them into approach
            (:func:`qpcontact.geometry.colliding`). Complementarity QPs only: the plain solve and
            least_squares would pull separating contacts together.

    Returns:
        A :class:`Result`.

    Raises:
        InvalidArgumentError, UnknownSolverError, SolverNotInstalledError: bad arguments.
        SolverFailedError: the solver failed, did not converge, or its answer fails the checks.
    """
    solved, solved_form = _check_options(solver, formulation, form, tolerance, time_limit, on_failure)
    instance("cells", cells, Cells, "qpcontact.Cells", InvalidCellsError)
    reduce, scale, estimate_condition, keep_separating = (flag(name, value) for name, value in (
        ("reduce", reduce), ("scale", scale), ("estimate_condition", estimate_condition),
        ("keep_separating", keep_separating)))
    planar = flag("planar", planar, allow_none=True)
    regularization = number("regularization", regularization, minimum=0.0)
    solver_settings = mapping("solver_settings", solver_settings)
    t_start = time.perf_counter()
    contacts = _contacts_of(cells, contacts, number("margin", margin, minimum=0.0), planar)
    if keep_separating and solved != "complementarity":
        raise InvalidArgumentError("keep_separating needs a QP solver with formulation='complementarity' "
                                   f"(got solver {solver!r}, formulation {formulation!r})")
    active, b = colliding(contacts, position_correction=position_correction, dt=dt, keep_separating=keep_separating)
    t_detect = time.perf_counter()
    if len(active) == 0:  # nothing to solve: never hand an unconstrained QP to a backend
        return Result(np.zeros((cells.n, 7)), cells.copy(), active, np.zeros(0), solver, solved, solved_form, True,
                      "no_contact", 0,
                      {"detect": t_detect - t_start, "assemble": 0.0, "setup": 0.0, "solve": 0.0, "check": 0.0,
                       "total": time.perf_counter() - t_start}, {"penetration": 0.0}, 0, bool(planar))
    system = build_system(cells, active, b, reduce=reduce, planar=planar, scale=scale)
    t_assemble = time.perf_counter()
    solution = solve_system(system, solver=solver, formulation=formulation, form=form, tolerance=tolerance,
                            time_limit=time_limit, regularization=regularization, solver_settings=solver_settings,
                            estimate_condition=estimate_condition)
    y, lam = solution.y, solution.lam
    t_solve = time.perf_counter()
    impulses, contact_impulses, errors = _measured(cells, system, y, lam, solved)
    t_check = time.perf_counter()
    converged = solution.converged
    result = Result(
        impulses=impulses,
        # Unconverged: a copy of the caller's cells, never the object itself (issue 19).
        cells=cells.with_impulses(impulses) if converged else cells.copy(),
        contacts=active,
        contact_impulses=contact_impulses,
        solver=solver,
        formulation=solved,
        form=solved_form,
        converged=converged,
        status=solution.status,
        iterations=solution.iterations,
        times={"detect": t_detect - t_start, "assemble": t_assemble - t_detect, "setup": solution.setup_seconds,
               "solve": solution.solve_seconds, "check": t_check - t_solve, "total": t_check - t_start},
        errors=errors,
        n_unknowns=system.shape[1],
        planar=system.planar,
        condition_estimate=solution.condition_estimate,
        message=solution.message,
        system=system,
        scaled_solution=y,
        pulling=int(solution.extras.get("pulling", 0)),
    )
    if not converged and on_failure == "raise":
        raise SolverFailedError(f"{solver}/{formulation}: {solution.message}", result)
    return result


def _contacts_of(cells: Cells, contacts: Contacts | None, margin: float, planar: bool | None) -> Contacts:
    """The given contacts, checked, or those found within ``margin``."""
    if contacts is not None:
        check_contacts(contacts, cells)
        return contacts
    # Detection gets the planar decision the system will make (issue 13, item 2): a monolayer's
    # crossing axes must not get the out-of-plane normal â × b̂.
    return find_contacts(cells, margin, planar=planar)


def _measured(cells: Cells, system: ContactSystem, y: np.ndarray | None, lam: np.ndarray | None,
              solved: str) -> tuple[np.ndarray, np.ndarray | None, dict[str, float]]:
    """``(impulses (N, 7), contact impulses, errors)`` of an answer (zeros and no errors without
    one): the error measures of :mod:`qpcontact.resolve.metrics`."""
    errors: dict[str, float] = {}
    if y is None:
        return np.zeros((cells.n, 7)), None, errors
    impulses = system.to_impulses(y)
    contact_impulses = system.to_contact_impulses(lam) if lam is not None else None
    errors["penetration"] = metrics.penetration(system, y)
    if lam is not None:
        errors["multiplier_consistency"] = metrics.multiplier_consistency(system, y, lam)
        if solved == "complementarity":
            errors["complementarity"] = metrics.complementarity_residual(system, y, lam)
            errors["duality_gap"] = metrics.duality_gap(system, y, lam)
    errors.update(metrics.physics(cells, system, impulses, contact_impulses))
    return impulses, contact_impulses, errors
