"""The study harness: what the solver comparison and the stability report share.

- :func:`prepare`: a scene assembled once, with its high-accuracy references
  (:class:`Prepared`);
- :func:`guarded`: run a function in a child process with a hard time-out, so that a backend
  without a time limit of its own (or one that crashes) cannot stop a study. Children start
  from a *forkserver*: forking a process that has already run Clarabel (the references) can
  deadlock on the inherited thread pool (measured: a 20 s guard hit on a solve that takes
  0.08 s in a fresh process).

(The tables' CSV writer is :func:`qpcontact.io.outputs.write_csv`.)
"""

from __future__ import annotations

import multiprocessing
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..assembly import ContactSystem, build_system
from ..geometry import Cells, Contacts, colliding, find_contacts
from ..resolve import ACTIVE_THRESHOLD, metrics, reference_solution
from ..solvers import solve_min_norm
from ..solvers.baselines import bbpgd

#: Optimality tolerance of the reference linear solve (LSMR cannot reach 1e-12 on jammed
#: packings: it stops at 3e-11).
REFERENCE_TOLERANCE = 1e-10


@dataclass
class Prepared:
    """A scene assembled once, with its references.

    Attributes:
        case: what the scene is (a :class:`~qpcontact.studies.scenes.Scene` or a
            :class:`~qpcontact.studies.compare.SceneCase`; both have ``name`` and ``family``).
        cells: the scene.
        contacts: the contacts to hand to resolve (None: resolve finds them).
        system: the scaled system of the colliding contacts (None if nothing collides).
        references: formulation (``"linear"``, ``"least_squares"``, ``"complementarity"``) ->
            reference ``ỹ*``.
        reference_penetration: formulation -> penetration of its reference.
        reference_residual: complementarity KKT residual of the refined reference (NaN when not
            refined).
        all_active: the linear solve pushes at every contact (then every formulation equals it).
        condition: ``cond₁`` estimate of the scaled Delassus operator (None: not asked for, or
            singular so that the LU failed).
        assemble_seconds: contact detection and assembly.
        reference_seconds: all the references (the condition estimate included).
        linear_seconds: the reference linear solve alone.
        condition_seconds: the same solve with the condition estimate.
    """

    case: Any
    cells: Cells
    contacts: Contacts | None
    system: ContactSystem | None
    references: dict[str, np.ndarray]
    reference_penetration: dict[str, float]
    reference_residual: float
    all_active: bool
    condition: float | None
    assemble_seconds: float
    reference_seconds: float
    linear_seconds: float
    condition_seconds: float


def complementarity_reference(system: ContactSystem) -> tuple[np.ndarray, float]:
    """``(ỹ*, residual)``: :func:`~qpcontact.resolve.reference_solution`, then refined by BBPGD
    to a complementarity residual of 1e-12, started from its own contact impulses; the
    refinement is kept only if it certifies a smaller residual ``‖min(λ̃, B̃ỹ − b̃)‖∞`` (with
    ``ỹ = B̃ᵀλ̃``, λ̃ ≥ 0)."""
    y = reference_solution(system, "complementarity")
    lam = solve_min_norm(system.matrix.T.tocsr(), y, tolerance=1e-12, method="lsmr").y
    residual = max(metrics.complementarity_residual(system, y, lam), float(np.max(-lam, initial=0.0)))
    refined = bbpgd(system.matrix, system.rhs, tolerance=1e-12, initial=np.maximum(lam, 0.0), max_iterations=50_000,
                    time_limit=60.0)
    if refined.converged and refined.residual < residual:
        return refined.y, refined.residual
    return y, residual


def prepare(case: Any, cells: Cells, contacts: Contacts | None = None, *, position_correction: float = 0.0,
            dt: float | None = None, refine: bool = False, condition: bool = False) -> Prepared:
    """Find the colliding contacts (or take ``contacts``), assemble, and compute the references.

    Args:
        case: what the scene is (kept in the result).
        cells: the scene.
        contacts: the contacts to use (None: :func:`~qpcontact.geometry.find_contacts`).
        position_correction, dt: ``b = −u + β·max(0, −d)/dt``.
        refine: refine the complementarity reference with BBPGD
            (:func:`complementarity_reference`) instead of taking
            :func:`~qpcontact.resolve.reference_solution` as it is.
        condition: also estimate the condition number (and time the linear solve with it).
    """
    t0 = time.perf_counter()
    found = contacts if contacts is not None else find_contacts(cells)
    active, b = colliding(found, position_correction=position_correction, dt=dt)
    if len(active) == 0:
        return Prepared(case, cells, contacts, None, {}, {}, float("nan"), True, None, time.perf_counter() - t0,
                        0.0, 0.0, 0.0)
    system = build_system(cells, active, b)
    t1 = time.perf_counter()
    lin = solve_min_norm(system.matrix, system.rhs, tolerance=REFERENCE_TOLERANCE)  # as reference_solution does
    t2 = time.perf_counter()
    estimate, t3 = None, t2
    if condition:
        estimate = solve_min_norm(system.matrix, system.rhs, tolerance=REFERENCE_TOLERANCE,
                                  estimate_condition=True).condition_estimate
        t3 = time.perf_counter()
    residual = float("nan")
    if refine:
        complementarity, residual = complementarity_reference(system)
    else:
        complementarity = reference_solution(system, "complementarity")
    references = {"linear": lin.y, "least_squares": reference_solution(system, "least_squares"),
                  "complementarity": complementarity}
    penetration = {name: metrics.penetration(system, y) for name, y in references.items()}
    lam_scale = max(float(np.max(np.abs(lin.lam), initial=0.0)), 1e-300)
    all_active = bool(lin.consistent and np.all(lin.lam > ACTIVE_THRESHOLD * lam_scale))
    return Prepared(case, cells, contacts, system, references, penetration, residual, all_active, estimate, t1 - t0,
                    time.perf_counter() - t1, t2 - t1, t3 - t2)


def _child(conn: Any, fn: Callable[..., Any], args: Sequence[Any]) -> None:
    try:
        conn.send(("ok", fn(*args)))
    except BaseException as exc:  # report everything to the parent, which records it as a row
        conn.send(("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}"))
    finally:
        conn.close()


def guarded(fn: Callable[..., Any], args: Sequence[Any] = (), timeout: float = 60.0, *,
            preload: Iterable[str] = ("qpcontact",)) -> tuple[str, Any]:
    """``fn(*args)`` in a child process started from a forkserver (module docstring), with a
    hard ``timeout`` [s]. ``fn`` and ``args`` must be picklable (a module-level function).

    Returns:
        ``("ok", result)``, ``("error", text)`` (the child raised; type, message and traceback),
        ``("timeout", None)`` (killed after ``timeout``) or ``("crashed", exit code)``.
    """
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(list(preload))  # imported once, in the server
    parent, child = context.Pipe(duplex=False)
    process = context.Process(target=_child, args=(child, fn, tuple(args)), daemon=True)
    process.start()
    child.close()
    try:
        if parent.poll(timeout):
            try:
                answer = parent.recv()
            except EOFError:
                process.join(5)
                return "crashed", process.exitcode
            process.join(1.0)
            return answer
        return "timeout", None
    finally:
        if process.is_alive():
            process.kill()
        process.join()
        parent.close()
