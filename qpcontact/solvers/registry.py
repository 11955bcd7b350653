"""The solver registry: every solver is one entry, looked up by name.

A solver module calls :func:`register` once, at import, with a :class:`SolverSpec`: its name,
the formulations and forms it solves, whether it takes a warm start and honours a time limit,
and one ``solve`` function. Everything that picks or lists solvers asks the registry
(:func:`get_solver`, :func:`available_solvers`, :func:`solve`): :func:`qpcontact.resolve`, the
demo, the comparison, the stability report, the benchmark and the command-line help. See the
docstring of :mod:`qpcontact.solvers` for how to add a solver.

All problems are posed in the scaled unknowns of :mod:`qpcontact.assembly.system`
(``B̃ ỹ ≥ b̃``, dimensionless, kinetic-energy metric made Euclidean), as a :class:`Problem`.

Formulations (:data:`FORMULATIONS`):

- ``"complementarity"``: ``min ½‖ỹ‖² s.t. B̃ỹ ≥ b̃`` (impulses only push);
- ``"least_squares"``: the least-squares fit of ``B̃ỹ = b̃`` with ``B̃ỹ ≥ b̃`` (the minimum-norm
  one among the fits);
- ``"linear"``: the plain problem ``B̃ỹ = b̃``, its minimum-norm least-squares solution (it may
  pull contacts together). A solver whose only formulation is ``"linear"`` (:attr:`SolverSpec.plain`)
  answers the plain problem whatever formulation it is asked for.

Forms (:data:`FORMS`): ``"primal"`` (in ``ỹ``), ``"contact"`` (in the contact impulses ``λ̃``,
through ``Ã = B̃B̃ᵀ``) and ``"normal_equations"`` (``B̃ᵀB̃ỹ = B̃ᵀb̃``, conjugate gradients).
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import scipy.sparse as sp

from ..checks import mapping, number
from ..errors import InvalidArgumentError, SolverNotInstalledError, UnknownSolverError
from . import blocks

if TYPE_CHECKING:
    from ..assembly.system import ContactSystem

#: Every formulation a solver can declare (module docstring).
FORMULATIONS = ("least_squares", "complementarity", "linear")
#: The two QP formulations of model.md.
QP_FORMULATIONS = ("least_squares", "complementarity")
#: Every form a solver can declare (module docstring).
FORMS = ("primal", "contact", "normal_equations")
#: The two forms of the QP formulations.
QP_FORMS = ("primal", "contact")
#: The form ``form="auto"`` picks, per formulation, when the solver takes it (else its first
#: form); chosen from the measurements in docs/solvers.md.
DEFAULT_FORM = {"complementarity": "contact", "least_squares": "primal", "linear": "contact"}


def objective_gradient(y: np.ndarray, curvature: sp.spmatrix | None, anchor: np.ndarray | None) -> np.ndarray:
    """The gradient at ``ỹ`` of ``½‖ỹ‖² + ½‖R(ỹ − ỹ₀)‖²``: ``ỹ + RᵀR(ỹ − ỹ₀)`` (``ỹ`` without a
    curvature ``R``)."""
    if curvature is None:
        return y
    assert anchor is not None
    return y + curvature.T @ (curvature @ (y - anchor))


@dataclass(frozen=True)
class Problem:
    """``B̃ ỹ ≥ b̃`` in scaled units: a whole system or one independent block of it.

    Attributes:
        matrix: (K, n) sparse ``B̃``.
        rhs: (K,) ``b̃``.
        column_inverse_mass: (n,) the diagonal of ``W`` per column (for solvers that work in the
            raw impulses ``x = W^{-1/2} ỹ``), or None.
        regularization: ε of the least_squares formulation (0: the exact minimum-norm choice).
        lower, upper: (n,) bounds ``l ≤ ỹ ≤ u`` on the scaled unknowns (``∓inf`` where a column
            has none), or None: only solvers declaring :attr:`SolverSpec.bounds` take them (the
            position-level step bounds the turning and shrinking of cells with them). With
            bounds, ``ỹ = B̃ᵀλ̃ + α − β`` (the bound multipliers), not ``B̃ᵀλ̃``.
        curvature, anchor: ``R`` (r, n) sparse and ``ỹ₀`` (n,): the objective is
            ``½‖ỹ‖² + ½‖R(ỹ − ỹ₀)‖²`` (a sequential QP's curvature of its constraints:
            :mod:`qpcontact.assembly.curvature`), or None: ``½‖ỹ‖²``. Only solvers declaring
            :attr:`SolverSpec.curvature` take it; the stationarity is then
            ``ỹ + RᵀR(ỹ − ỹ₀) = B̃ᵀλ̃ (+ α − β)`` (:meth:`gradient`).
        family: problems given the same object (the linearizations of one position step: the
            same unknowns, each with the contacts of the last and a few more) may share what a
            solver sets up for their pattern (``ipm``: the ordering of the first, the pattern grown
            from the last, :class:`~qpcontact.solvers.cholesky.GramMatrix`); None: set up from the
            problem's own pattern alone. A solver's answer does not depend on it beyond rounding.
    """

    matrix: sp.csr_matrix
    rhs: np.ndarray
    column_inverse_mass: np.ndarray | None = None
    regularization: float = 0.0
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None
    curvature: sp.csr_matrix | None = None
    anchor: np.ndarray | None = None
    family: object | None = None

    def gradient(self, y: np.ndarray) -> np.ndarray:
        """The objective's gradient at ``ỹ`` (:func:`objective_gradient`)."""
        return objective_gradient(y, self.curvature, self.anchor)

    @property
    def bounded(self) -> bool:
        """Some column has a finite bound."""
        return any(v is not None and bool(np.isfinite(v).any()) for v in (self.lower, self.upper))

    @classmethod
    def of(cls, system: ContactSystem, regularization: float = 0.0) -> Problem:
        """The problem of an assembled :class:`~qpcontact.assembly.ContactSystem`."""
        return cls(system.matrix, system.rhs, system.column_inverse_mass, regularization)

    @property
    def shape(self) -> tuple[int, int]:
        """``(K, n)``: contact rows, unknowns."""
        k, n = self.matrix.shape
        return int(k), int(n)

    def bounds_as_rows(self) -> tuple[sp.csr_matrix, np.ndarray]:
        """``(B̃', b̃')``: the bounds written as more rows of the contact problem, ``ỹ_j ≥ l_j``
        as the row ``e_jᵀ`` with right-hand side ``l_j`` and ``ỹ_j ≤ u_j`` as ``−e_jᵀ`` with
        ``−u_j``, after the contact rows. ``min ½‖ỹ‖² s.t. B̃'ỹ ≥ b̃'`` is this problem, so any
        contact-form solver takes bounds this way (its ``λ̃'`` for the first K rows are the
        contact impulses, ``ỹ = B̃'ᵀλ̃'``)."""
        k, n = self.shape
        lower = np.full(n, -np.inf) if self.lower is None else self.lower
        upper = np.full(n, np.inf) if self.upper is None else self.upper
        low, high = np.flatnonzero(np.isfinite(lower)), np.flatnonzero(np.isfinite(upper))
        rows = sp.csr_matrix((np.concatenate([np.ones(low.size), -np.ones(high.size)]),
                              (np.arange(low.size + high.size), np.concatenate([low, high]))),
                             shape=(low.size + high.size, n))
        return (sp.vstack([sp.csr_matrix(self.matrix), rows], format="csr"),
                np.concatenate([self.rhs, lower[low], -upper[high]]))

    def block(self, rows: np.ndarray, columns: np.ndarray) -> Problem:
        """The sub-problem on these rows and columns (an independent block)."""
        def part(values: np.ndarray | None) -> np.ndarray | None:
            return None if values is None else values[columns]

        curvature = None
        if self.curvature is not None:  # its rows couple the cells of one contact: one block
            curvature = sp.csr_matrix(self.curvature)[:, columns]
            curvature = curvature[np.flatnonzero(np.diff(curvature.indptr))]
        return Problem(self.matrix[rows][:, columns], self.rhs[rows], part(self.column_inverse_mass),
                       self.regularization, part(self.lower), part(self.upper), curvature, part(self.anchor))


@dataclass
class SolverOutput:
    """What a solver returned, in scaled units. Solvers never raise for a failure to solve:
    the output says what happened.

    Attributes:
        y: (n,) scaled unknowns ``ỹ`` (None if the solver returned nothing).
        lam: (K,) scaled contact impulses ``λ̃`` with ``ỹ = B̃ᵀλ̃`` (None if not available).
        found: the solver's own success flag.
        status: the solver's status text.
        iterations: iteration count where the solver reports one.
        setup_seconds: building the problem and handing it to the solver.
        solve_seconds: the solve itself.
        error: the exception text if the solver raised.
        extras: anything else the solver reports (``blocks``, ``residual``,
            ``condition_estimate``, ...).
    """

    y: np.ndarray | None
    lam: np.ndarray | None
    found: bool
    status: str
    iterations: int | None
    setup_seconds: float
    solve_seconds: float
    error: str | None = None
    extras: dict[str, Any] = field(default_factory=dict)


@dataclass
class IterativeSolution:
    """Output of the iterative algorithms (:func:`~qpcontact.solvers.mprgp.mprgp` and the
    baselines of :mod:`qpcontact.solvers.baselines`), in scaled units.

    Attributes:
        y: (n,) scaled unknowns ``ỹ`` (the last iterate, converged or not).
        lam: (K,) scaled contact impulses ``λ̃`` (BBPGD, MPRGP), or None (CG works in ``ỹ`` only).
        iterations: iterations done.
        converged: the stopping test was met.
        status: ``"converged"``, ``"max_iterations"``, ``"time_limit"``, ``"breakdown"`` or
            ``"infeasible"``.
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

    def output(self) -> SolverOutput:
        """As a :class:`SolverOutput` (the residual goes into ``extras``)."""
        return SolverOutput(self.y, self.lam, self.converged, self.status, self.iterations, 0.0, self.seconds,
                            extras={"residual": self.residual})


def check_options(tolerance: float, max_iterations: int | None = None, time_limit: float | None = None) -> None:
    """Raise :class:`~qpcontact.errors.InvalidArgumentError` for a tolerance that is not a number
    in (0, 1), an iteration cap that is not an integer >= 1 or a time limit that is not a
    positive number of seconds."""
    number("tolerance", tolerance, minimum=0.0, maximum=1.0, open_minimum=True, open_maximum=True)
    if max_iterations is not None and not (isinstance(max_iterations, (int, np.integer))
                                           and not isinstance(max_iterations, bool) and max_iterations >= 1):
        raise InvalidArgumentError(f"max_iterations: expected an integer >= 1, got {max_iterations!r}")
    number("time_limit", time_limit, minimum=0.0, open_minimum=True, allow_none=True)


class SolveFunction(Protocol):
    """The one function of a solver (see :class:`SolverSpec`)."""

    def __call__(self, problem: Problem, formulation: str, form: str, *, tolerance: float,
                 time_limit: float | None, settings: Mapping[str, Any],
                 initial: np.ndarray | None) -> SolverOutput: ...


def _installed() -> bool:
    return True


def _words(names: tuple[str, ...]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


@dataclass(frozen=True)
class SolverSpec:
    """One registered solver.

    Attributes:
        name: the name :func:`qpcontact.resolve` takes (``solver=``).
        formulations: the formulations it solves (a subset of :data:`FORMULATIONS`).
        forms: the forms it takes (a subset of :data:`FORMS`); the first is its default where
            :data:`DEFAULT_FORM` names one it does not take.
        warm_start: it takes an initial guess (``initial``: ``λ̃`` in the contact form, ``ỹ`` in
            the others).
        time_limit: it honours a time limit.
        solve: ``solve(problem, formulation, form, *, tolerance, time_limit, settings, initial)
            -> SolverOutput`` (:class:`SolveFunction`): solve a :class:`Problem` to the
            dimensionless ``tolerance``; never raises for a failure to solve, only for bad
            settings.
        available: whether it can run here (its package is installed).
        description: one line for listings.
        settings: the ``solver_settings`` names it takes (checked, with a named error), or None to
            pass them on unchecked (a backend's own options).
        blockwise: the independent blocks of the contact graph may be solved one by one
            (:func:`solve` with ``split=True``): the same problem, each part stopping when it has
            converged.
        matrix_free: the forms it solves without a factorization (the cost of an iteration grows
            like the non-zeros of ``B̃``; used to extrapolate run times).
        dense: it needs dense matrices (only worth running on small problems).
        baseline: a method measured for comparison (what colony codes use today), run by the
            studies but not listed by :func:`available_solvers`.
        bundled: installed with qpcontact itself (its own code or a required dependency): the
            demo and the tests expect it to work.
        install_hint: how to install it, said when ``available()`` is false.
        bounds: the forms in which it takes bounds on ``ỹ`` (:attr:`Problem.lower`,
            :attr:`Problem.upper`).
        curvature: it takes the objective's curvature (:attr:`Problem.curvature`).
    """

    name: str
    formulations: tuple[str, ...]
    forms: tuple[str, ...]
    warm_start: bool
    time_limit: bool
    solve: SolveFunction
    available: Callable[[], bool] = _installed
    description: str = ""
    settings: tuple[str, ...] | None = None
    blockwise: bool = False
    matrix_free: tuple[str, ...] = ()
    dense: bool = False
    baseline: bool = False
    bundled: bool = False
    install_hint: str = "is not installed"
    bounds: tuple[str, ...] = ()
    curvature: bool = False

    @property
    def plain(self) -> bool:
        """It solves only the plain problem ``B̃ỹ = b̃`` (formulation ``"linear"``)."""
        return self.formulations == ("linear",)

    def plan(self, formulation: str, form: str = "auto") -> tuple[str, str]:
        """The ``(formulation, form)`` this solver solves when asked for these.

        A plain solver answers the plain problem whatever formulation is asked for; ``"auto"``
        picks :data:`DEFAULT_FORM` (or the solver's first form if it does not take that one).

        Raises:
            InvalidArgumentError: the solver does not solve this formulation or form.
        """
        if self.plain:
            formulation = "linear"
        if formulation not in self.formulations or (form != "auto" and form not in self.forms):
            plural = "s" if len(self.formulations) > 1 else ""
            raise InvalidArgumentError(
                f"solver {self.name!r} solves the {_words(self.formulations)} formulation{plural} in "
                f"{_words(self.forms)} form only (got formulation {formulation!r}, form {form!r})")
        if form == "auto":
            form = DEFAULT_FORM[formulation] if DEFAULT_FORM[formulation] in self.forms else self.forms[0]
        return formulation, form

    def check_settings(self, settings: Mapping[str, Any]) -> None:
        """Raise :class:`~qpcontact.errors.InvalidArgumentError` for settings it does not take."""
        if self.settings is None:
            return
        unknown = sorted(set(settings) - set(self.settings))
        if unknown:
            takes = _words(self.settings) if self.settings else "no settings"
            raise InvalidArgumentError(f"solver_settings: {self.name} takes {takes}; got {sorted(settings)}")


#: name -> spec, in registration order (the order of the listings).
_SOLVERS: dict[str, SolverSpec] = {}


def register(spec: SolverSpec, *, replace: bool = False) -> SolverSpec:
    """Add a solver to the registry (at import of its module). Returns ``spec``.

    Raises:
        ValueError: the name is taken (unless ``replace``), or the spec declares a formulation or
            form the registry does not know.
    """
    if not spec.name or not isinstance(spec.name, str):
        raise ValueError(f"solver name: expected a non-empty string, got {spec.name!r}")
    if spec.name in _SOLVERS and not replace:
        raise ValueError(f"solver {spec.name!r} is already registered")
    for what, values, known in (("formulations", spec.formulations, FORMULATIONS), ("forms", spec.forms, FORMS),
                                ("matrix_free", spec.matrix_free, spec.forms), ("bounds", spec.bounds, spec.forms)):
        if (not values and what not in ("matrix_free", "bounds")) or not set(values) <= set(known):
            raise ValueError(f"solver {spec.name!r}: {what} must be a non-empty subset of {known}, got {values!r}")
    _SOLVERS[spec.name] = spec
    return spec


def unregister(name: str) -> SolverSpec:
    """Remove a solver from the registry (for tests registering a solver for a while)."""
    return _SOLVERS.pop(name)


def registered_solvers() -> list[str]:
    """Every registered name, installed or not, in registration order."""
    return list(_SOLVERS)


#: The module of the study baselines (``cg``, ``cg_euclidean``, ``bbpgd``): imported, and so
#: registered, only when a study asks for them (:func:`load_baselines`), not by ``import qpcontact``.
BASELINES_MODULE = "qpcontact.solvers.baselines"


def load_baselines() -> None:
    """Register the study baselines (:data:`BASELINES_MODULE`; once, on first use)."""
    importlib.import_module(BASELINES_MODULE)


def available_solvers(*, include_baselines: bool = False) -> list[str]:
    """The solver names usable here, in registration order: the plain solve ``"linear"``, the
    built-in ``"mprgp"`` and ``"ipm"``, then every installed qpsolvers backend (sorted), then
    solvers registered later. ``include_baselines`` adds, at the end, the baselines the studies
    compare against (``cg``, ``cg_euclidean``, ``bbpgd``; loaded now if they were not)."""
    if include_baselines:
        load_baselines()
    usable = [name for name, spec in _SOLVERS.items() if spec.available()]
    return ([name for name in usable if not _SOLVERS[name].baseline]
            + ([name for name in usable if _SOLVERS[name].baseline] if include_baselines else []))


def get_solver(name: str) -> SolverSpec:
    """The spec of an installed solver.

    Raises:
        UnknownSolverError: no solver of that name is registered.
        SolverNotInstalledError: it is registered but cannot run here.
    """
    if isinstance(name, str) and name not in _SOLVERS:
        load_baselines()  # a baseline asked for by name
    spec = _SOLVERS.get(name) if isinstance(name, str) else None
    if spec is None:
        raise UnknownSolverError(f"unknown solver {name!r}; installed: {available_solvers()}")
    if not spec.available():
        raise SolverNotInstalledError(f"solver {name!r} {spec.install_hint}; installed: {available_solvers()}")
    return spec


def solve(
    problem: Problem,
    solver: str,
    formulation: str = "complementarity",
    form: str = "auto",
    *,
    tolerance: float = 1e-6,
    time_limit: float | None = None,
    settings: Mapping[str, Any] | None = None,
    initial: np.ndarray | None = None,
    split: bool = True,
) -> SolverOutput:
    """Solve ``problem`` with a registered solver: the one dispatch of qpcontact.

    Checks the name, formulation, form and settings (named errors), then calls the solver's
    ``solve``; a blockwise solver (:attr:`SolverSpec.blockwise`) with ``split`` solves each
    independent block of the contact graph on its own (:func:`solve_by_blocks`). Never raises
    for a failure to solve: the output says what happened; it is not checked here (see
    :func:`qpcontact.resolve.solve_system` for the acceptance checks).
    """
    spec = get_solver(solver)
    formulation, form = spec.plan(formulation, form)
    check_options(tolerance, None, time_limit)
    settings = mapping("solver_settings", settings)
    spec.check_settings(settings)
    if initial is not None and not spec.warm_start:
        raise InvalidArgumentError(f"initial: solver {solver!r} takes no initial guess")
    if problem.bounded and form not in spec.bounds:
        where = f"in {_words(spec.bounds)} form only" if spec.bounds else "none"
        raise InvalidArgumentError(f"bounds: solver {solver!r} takes bounds on ỹ {where} (form {form!r})")
    if (problem.curvature is None) != (problem.anchor is None):
        raise InvalidArgumentError("curvature, anchor: give both (the objective's R and ỹ₀) or neither")
    if problem.curvature is not None and not spec.curvature:
        raise InvalidArgumentError(f"curvature: solver {solver!r} takes no curvature of the objective (ipm does)")
    if spec.blockwise:
        return solve_by_blocks(spec, problem, formulation, form, tolerance=tolerance, time_limit=time_limit,
                               settings=settings, initial=initial, split=split)
    return spec.solve(problem, formulation, form, tolerance=tolerance, time_limit=time_limit, settings=settings,
                      initial=initial)


def solve_by_blocks(
    spec: SolverSpec,
    problem: Problem,
    formulation: str,
    form: str,
    *,
    tolerance: float,
    time_limit: float | None,
    settings: Mapping[str, Any],
    initial: np.ndarray | None = None,
    split: bool = True,
) -> SolverOutput:
    """Solve the independent components of the contact graph as separate problems, merged into
    blocks of about :data:`qpcontact.solvers.blocks.BLOCK_ROWS` contacts
    (:func:`~qpcontact.solvers.blocks.independent_blocks`): the same problem, but each part stops
    when it has converged instead of waiting for the hardest one. Each block gets the time that
    is left of ``time_limit``. ``found`` is true only if every block was solved; when a block
    returns no answer, the output carries no ``ỹ`` (a block's answer covers only its own rows
    and columns); a block that returns an answer without its solver's success flag (Clarabel's
    "AlmostSolved") keeps it, so that the caller can judge the whole answer by its residuals
    (:func:`qpcontact.resolve.resolve.solve_system`).
    ``iterations`` is the largest of the blocks'. ``split=False`` solves the whole problem in
    one call (``extras["blocks"] = 1``)."""
    k, n = problem.shape
    t0 = time.perf_counter()
    parts = blocks.independent_blocks(problem.matrix, blocks.BLOCK_ROWS) if split else [(np.arange(k), np.arange(n))]
    if len(parts) == 1:
        out = spec.solve(problem, formulation, form, tolerance=tolerance, time_limit=time_limit, settings=settings,
                         initial=initial)
        out.setup_seconds = time.perf_counter() - t0 - out.solve_seconds  # includes finding the blocks
        out.extras["blocks"] = 1
        return out
    y, lam = np.zeros(n), np.zeros(k)
    has_lam, found = True, True
    statuses: list[str] = []
    iterations: list[int] = []
    setup, solve_seconds = time.perf_counter() - t0, 0.0
    limit = time_limit
    for rows, cols in parts:
        if time_limit is not None:
            limit = time_limit - (time.perf_counter() - t0)
            if limit <= 0:
                return SolverOutput(None, None, False, "time limit reached", max(iterations, default=None), setup,
                                    solve_seconds, error=f"time limit of {time_limit} s reached after {len(statuses)} "
                                                         f"of {len(parts)} blocks")
        t1 = time.perf_counter()
        sub = problem.block(rows, cols)
        guess = None if initial is None else initial[rows if form == "contact" else cols]
        setup += time.perf_counter() - t1
        out = spec.solve(sub, formulation, form, tolerance=tolerance, time_limit=limit, settings=settings,
                         initial=guess)
        setup, solve_seconds = setup + out.setup_seconds, solve_seconds + out.solve_seconds
        if out.y is None:
            return SolverOutput(None, None, False, f"{out.status} (block of {rows.size} contacts)", out.iterations,
                                setup, solve_seconds, error=out.error)
        found = found and out.found
        y[cols] = out.y
        if out.lam is None:
            has_lam = False
        else:
            lam[rows] = out.lam
        statuses.append(out.status)
        if out.iterations is not None:
            iterations.append(out.iterations)
    status = " / ".join(dict.fromkeys(statuses))
    return SolverOutput(y, lam if has_lam else None, found, status, max(iterations, default=None), setup,
                        solve_seconds, extras={"blocks": len(parts)})
