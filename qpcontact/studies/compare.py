"""``qpcontact compare``: every solver's error against its run time, on colony scenes.

For each scene (:mod:`qpcontact.studies.scenes`), the system is assembled once (:func:`build_system`);
then each *method* — a solver with a formulation and a form — solves it at each tolerance, and
the run is timed (median of repeats, setup and solve apart) and measured against a high-accuracy
reference of the same formulation (model.md, "Measuring error"). Methods:

every registered solver (:mod:`qpcontact.solvers`, baselines included) × each formulation and
form it declares:

- ``linear``: the plain minimum-W-norm solve (formulation ``linear``: ``Mx = b``, may pull);
- ``cg``, ``cg_euclidean``: CG on the normal equations from zero (CellModeller; in the
  kinetic-energy metric, and in raw impulses as CellModeller runs it), also formulation ``linear``;
- ``bbpgd``: projected gradient with Barzilai–Borwein steps on the contact-space complementarity
  problem; ``mprgp``: the built-in matrix-free solver of the same problem;
- every installed qpsolvers backend × formulation (``complementarity``, ``least_squares``) × form
  (``primal``, ``contact``); dense-only backends only on scenes with few unknowns.

Every run goes through :func:`qpcontact.resolve.solve_system`, so each answer passes the same
acceptance checks.

Every run becomes a row of the CSV, failures and time-outs included. A run *succeeds* when the
solver says it converged (and passes the package's own acceptance checks) and its answer is
within ``ACCURACY_FACTOR·tolerance`` of the reference; a run that says it converged but is not
that close is counted as *reported success, inaccurate*. Each run is made in a child process
with a hard time-out (:func:`qpcontact.studies.harness.guarded`), so a backend without a time
limit of its own (or one that crashes) cannot stop the comparison. With ``--scheduler ADDRESS``
or ``--workers N`` the runs are Dask tasks (:mod:`qpcontact.ensembles.cluster`), each still in its
guarded child process with the same time-out; the references are computed here meanwhile.

Outputs in ``--out``: ``solvers.csv`` (every run), ``solvers.png`` (error against time, log–log,
one panel per scene family and formulation), ``solvers_scenes.png`` (top views of the scenes),
``solvers.md`` (summary tables).
"""

from __future__ import annotations

import argparse
import csv
import math
import multiprocessing
import platform
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import qpsolvers

from ..assembly import ContactSystem, build_system
from ..cli import add_output_arguments, comma_list, positive_float, positive_int, run_standalone
from ..cli import tolerance as tolerance_type
from ..ensembles import cluster
from ..errors import InvalidArgumentError, UnknownSolverError
from ..geometry import colliding, find_contacts
from ..io.outputs import describe_written, prepare_folder, write_text
from ..io.outputs import write_csv as write_table
from ..resolve import metrics, solve_system
from ..solvers import QP_FORMS, available_solvers, get_solver
from . import harness
from .harness import Prepared
from .scenes import make_scene

#: A run is accurate when its distance to the reference is at most this many times the tolerance
#: (with the floor ``ACCURACY_FLOOR``: the references themselves are good to about 1e-9).
ACCURACY_FACTOR = 100.0
ACCURACY_FLOOR = 1e-7
#: Shift of the shifted geometric mean of times [s] (qpbenchmark's 10 ms).
SGM_SHIFT = 0.01
#: Dense-only backends run only on scenes with at most this many unknowns.
DENSE_MAX_UNKNOWNS = 2000
#: Stop repeating a run once its repeats took this long [s] (at least one run is always made).
REPEAT_BUDGET = 1.0


@dataclass(frozen=True)
class SceneCase:
    """One scene of the comparison.

    Attributes:
        name: label (also the ``--scenes`` name).
        family: panel of the plot (``hand-made``, ``colony_2d``, ``colony_3d``).
        generator: key of :data:`qpcontact.studies.scenes.SCENES`.
        n_cells: cell count handed to the generator (None: its default).
        position_correction, dt: ``b = −u + β·max(0, −d)/dt`` (β = 0: plain approach speeds,
            for which ``Mx = b`` is always consistent, since stopping every cell solves it).
    """

    name: str
    family: str
    generator: str
    n_cells: int | None = None
    position_correction: float = 0.0
    dt: float | None = None


def _colony(dimension: int, n: int) -> SceneCase:
    return SceneCase(f"colony_{dimension}d_{n}", f"colony_{dimension}d", f"colony_{dimension}d", n)


HAND_MADE = [
    SceneCase("two_rods", "hand-made", "two_rods"),
    SceneCase("rod_chain", "hand-made", "rod_chain", 20),
    SceneCase("rod_across_many", "hand-made", "rod_across_many", 12),
    SceneCase("jammed_packing", "hand-made", "jammed_packing", 61),
    # With position correction (uneven overlaps) the jammed packing's Mx = b has no solution.
    SceneCase("jammed_packing_pc", "hand-made", "jammed_packing", 61, position_correction=0.5, dt=1.0),
]
# The 3D colony of 10⁴ cells is left out of the default set to keep it under 10 minutes on 2
# cores (its reference alone takes ~18 s); name it with --scenes colony_3d_10000.
DEFAULT_SCENES = HAND_MADE + [_colony(d, n) for d in (2, 3) for n in (100, 1000, 10_000) if (d, n) != (3, 10_000)]
QUICK_SCENES = [HAND_MADE[0], HAND_MADE[3], HAND_MADE[4], _colony(2, 100), _colony(3, 100)]
ALL_SCENES = {case.name: case for case in DEFAULT_SCENES + [_colony(d, n) for d, n in ((3, 10_000), (2, 100_000), (3, 100_000))]}

DEFAULT_TOLERANCES = (1e-3, 1e-6, 1e-9)


@dataclass(frozen=True)
class Method:
    """A solver with the formulation and form it solves."""

    solver: str
    formulation: str  # "linear" (Mx = b), "complementarity" or "least_squares"
    form: str  # "primal", "contact" or "normal_equations" (CG)

    @property
    def label(self) -> str:
        return f"{self.solver}/{self.formulation}/{self.form}"


def all_methods(solvers: list[str] | None = None) -> list[Method]:
    """Methods for these solver names (default: every installed solver, baselines included, in
    registry order): each formulation and form the solver declares, except that the plain
    solvers run in their default form only."""
    names = solvers or available_solvers(include_baselines=True)
    out = []
    for name in names:
        if name not in available_solvers(include_baselines=True):
            raise UnknownSolverError(f"unknown or uninstalled solver {name!r}; "
                                     f"known: {', '.join(available_solvers(include_baselines=True))}")
        spec = get_solver(name)
        forms = spec.forms[:1] if spec.plain else spec.forms
        out += [Method(name, f, form) for f in spec.formulations for form in forms]
    return out


# ------------------------------------------------------------------------------------------
# Scenes and references
# ------------------------------------------------------------------------------------------
def prepare(case: SceneCase) -> Prepared:
    """Generate, assemble and solve the references of one scene (the complementarity reference
    refined by BBPGD, :func:`~qpcontact.studies.harness.complementarity_reference`)."""
    kwargs = {} if case.n_cells is None else {"n_cells": case.n_cells}
    cells = make_scene(case.generator, **kwargs)
    return harness.prepare(case, cells, position_correction=case.position_correction, dt=case.dt, refine=True)


# ------------------------------------------------------------------------------------------
# One run
# ------------------------------------------------------------------------------------------
def solve_once(system: ContactSystem, method: Method, tolerance: float, time_limit: float) -> dict[str, Any]:
    """Solve once through :func:`~qpcontact.resolve.solve_system`; returns y, lam, converged,
    status, iterations, setup, solve, message."""
    out = solve_system(system, solver=method.solver, formulation=method.formulation, form=method.form,
                       tolerance=tolerance, time_limit=time_limit)
    return {"y": out.y, "lam": out.lam, "converged": out.converged, "status": out.status, "iterations": out.iterations,
            "setup": out.setup_seconds, "solve": out.solve_seconds, "message": out.message}


def repeated(system: ContactSystem, method: Method, tolerance: float, time_limit: float, repeats: int) -> dict[str, Any]:
    """Up to ``repeats`` solves (fewer once they took ``REPEAT_BUDGET``); medians of the times."""
    setups: list[float] = []
    solves: list[float] = []
    out: dict[str, Any] = {}
    while len(solves) < repeats and (not solves or sum(setups) + sum(solves) < REPEAT_BUDGET):
        out = solve_once(system, method, tolerance, time_limit)
        setups.append(out["setup"])
        solves.append(out["solve"])
    out.update(setup=float(np.median(setups)), solve=float(np.median(solves)), repeats=len(solves))
    return out


def timed_runs(system: ContactSystem, method: Method, tolerance: float, time_limit: float, repeats: int,
               warm: ContactSystem | None = None) -> dict[str, Any]:
    """What a child process of :func:`run_one` does: solve the small ``warm`` system once with
    the method (untimed: first-call initialization stays out of the times; a failure there
    shows again in the timed runs), then :func:`repeated`."""
    if warm is not None:
        try:
            solve_once(warm, method, 1e-6, 5.0)
        except Exception:  # noqa: BLE001 - recorded by the timed runs
            pass
    return repeated(system, method, tolerance, time_limit, repeats)


def measure(prepared: Prepared, method: Method, tolerance: float, y: np.ndarray | None, lam: np.ndarray | None) -> dict[str, float]:
    """The error measures of model.md for one answer (NaN where not defined)."""
    nan = float("nan")
    keys = ("penetration", "complementarity", "duality_gap", "distance", "objective_gap", "distance_complementarity",
            "distance_linear", "momentum_change", "angular_momentum_change", "energy_change_relative")
    if y is None or not np.all(np.isfinite(y)):
        return dict.fromkeys(keys, nan)
    system = prepared.system
    assert system is not None, "every scene of the comparison has colliding contacts"
    reference = prepared.references[method.formulation]
    impulses = system.to_impulses(y)
    physics = metrics.physics(prepared.cells, system, impulses, None if lam is None else system.to_contact_impulses(lam))
    comp = lam if method.formulation == "complementarity" else None  # contact impulses to measure, if any
    return {
        "penetration": metrics.penetration(system, y),
        "complementarity": nan if comp is None else metrics.complementarity_residual(system, y, comp),
        "duality_gap": nan if comp is None else metrics.duality_gap(system, y, comp),
        "distance": metrics.distance(y, reference),
        "objective_gap": metrics.objective_gap(system, method.formulation, y, reference),
        "distance_complementarity": metrics.distance(y, prepared.references["complementarity"]),
        "distance_linear": metrics.distance(y, prepared.references["linear"]),
        "momentum_change": physics["momentum_change"],
        "angular_momentum_change": physics["angular_momentum_change"],
        "energy_change_relative": physics["energy_change_relative"],
    }


COLUMNS = (
    "scene", "family", "n_cells", "contacts", "unknowns", "planar", "all_active", "method", "solver", "formulation", "form",
    "tolerance", "repeats", "setup_s", "solve_s", "total_s", "outcome", "status", "converged", "accurate", "success",
    "iterations", "penetration", "complementarity", "duality_gap", "distance", "objective_gap", "distance_complementarity",
    "distance_linear", "momentum_change", "angular_momentum_change", "energy_change_relative", "message",
)


def run_one(prepared: Prepared, method: Method, tolerance: float, *, time_limit: float, repeats: int,
            warm: ContactSystem | None = None) -> dict[str, Any]:
    """One row of the CSV (never raises for a solver failure). The solves run in a child
    process (:func:`~qpcontact.studies.harness.guarded`), warmed up on ``warm`` first."""
    system = prepared.system
    assert system is not None, "every scene of the comparison has colliding contacts"
    k, n = system.shape
    row: dict[str, Any] = {
        "scene": prepared.case.name, "family": prepared.case.family, "n_cells": prepared.cells.n, "contacts": k,
        "unknowns": n, "planar": system.planar, "all_active": prepared.all_active, "method": method.label,
        "solver": method.solver, "formulation": method.formulation, "form": method.form, "tolerance": tolerance,
    }
    # Repeats stop once they took REPEAT_BUDGET, so a child needs at most that plus one solve.
    hard_timeout = 1.5 * time_limit + REPEAT_BUDGET + 5.0
    start = time.perf_counter()
    outcome, payload = harness.guarded(timed_runs, (system, method, tolerance, time_limit, repeats, warm), hard_timeout,
                                       preload=("qpcontact.studies.compare",))
    y: Any = None
    lam: Any = None
    if outcome == "ok":
        y, lam = payload["y"], payload["lam"]
        row.update(repeats=payload["repeats"], setup_s=payload["setup"], solve_s=payload["solve"],
                   total_s=payload["setup"] + payload["solve"], status=payload["status"], converged=payload["converged"],
                   iterations=payload["iterations"], message=payload["message"])
        if payload["status"] in ("time_limit", "TIME_LIMIT", "MaxTime", "time limit reached") or (
                not payload["converged"] and row["total_s"] >= 0.95 * time_limit):
            outcome = "time_limit"
        elif not payload["converged"]:
            outcome = "not_converged"
    else:
        elapsed = time.perf_counter() - start
        row.update(repeats=0, setup_s=math.nan, solve_s=math.nan, total_s=elapsed if outcome == "timeout" else math.nan,
                   status=outcome, converged=False, iterations=None,
                   message=(f"killed after {hard_timeout:.0f} s" if outcome == "timeout" else str(payload))[:300])
    if (y is not None and np.shape(y) != (n,)) or (lam is not None and np.shape(lam) != (k,)):
        row.update(converged=False, message=f"{method.solver} returned ỹ of shape {np.shape(y)}, λ̃ of shape "
                   f"{None if lam is None else np.shape(lam)} for a system of shape {system.shape}; "
                   f"status {row['status']}; {row['message']}"[:300])
        outcome = "error" if outcome == "ok" else outcome
        y = lam = None
    try:
        errors = measure(prepared, method, tolerance, y, lam)
    except Exception as exc:  # a malformed answer is a failed run, recorded like the others
        row.update(converged=False, message=f"measuring the answer failed: {type(exc).__name__}: {exc}"[:300])
        outcome = "error" if outcome == "ok" else outcome
        errors = measure(prepared, method, tolerance, None, None)
    accurate = bool(errors["distance"] <= max(ACCURACY_FACTOR * tolerance, ACCURACY_FLOOR))
    row.update(errors, accurate=accurate, success=bool(row["converged"] and accurate))
    if outcome == "ok":
        outcome = "success" if row["success"] else "converged_inaccurate"
    row["outcome"] = outcome
    return row


# ------------------------------------------------------------------------------------------
# Summary, plot
# ------------------------------------------------------------------------------------------
def shifted_geometric_mean(times: np.ndarray, shift: float = SGM_SHIFT) -> float:
    """``exp(mean(log(t + shift))) − shift`` (qpbenchmark)."""
    times = np.asarray(times, dtype=float)
    return float(np.exp(np.mean(np.log(times + shift))) - shift) if times.size else math.nan


def summarize(rows: list[dict[str, Any]], time_limit: float) -> list[dict[str, Any]]:
    """Per method: runs, success rate, reported-but-inaccurate runs, median time and error,
    shifted geometric mean of the time (an unsuccessful run counts as ``time_limit``, as in
    qpbenchmark) and its ratio to the best method's."""
    table = []
    for label in dict.fromkeys(r["method"] for r in rows):
        mine = [r for r in rows if r["method"] == label]
        success = np.array([r["success"] for r in mine])
        times = np.array([r["total_s"] if r["success"] else time_limit for r in mine])
        measured = np.array([r["total_s"] for r in mine if np.isfinite(r["total_s"])])
        errors = np.array([r["distance"] for r in mine if np.isfinite(r["distance"])])
        table.append({
            "method": label, "runs": len(mine), "success_rate": float(success.mean()),
            "inaccurate": sum(1 for r in mine if r["outcome"] == "converged_inaccurate"),
            "failed": sum(1 for r in mine if r["outcome"] not in ("success", "converged_inaccurate")),
            "median_time_s": float(np.median(measured)) if measured.size else math.nan,
            "median_distance": float(np.median(errors)) if errors.size else math.nan,
            "sgm_time_s": shifted_geometric_mean(times),
        })
    best = min((t["sgm_time_s"] for t in table), default=math.nan)
    for t in table:
        t["sgm_ratio"] = t["sgm_time_s"] / best if best > 0 else math.nan
    table.sort(key=lambda t: t["sgm_time_s"])
    return table


def markdown_table(summary: list[dict[str, Any]]) -> str:
    head = ("| method (solver/formulation/form) | runs | success | reported success, inaccurate | failed or time-out "
            "| median time [ms] | median distance | SGM time [ms] | SGM ratio |\n|---|---|---|---|---|---|---|---|---|")
    lines = [head]
    for t in summary:
        lines.append(f"| {t['method']} | {t['runs']} | {100 * t['success_rate']:.0f} % | {t['inaccurate']} | {t['failed']} "
                     f"| {1e3 * t['median_time_s']:.3g} | {t['median_distance']:.1e} | {1e3 * t['sgm_time_s']:.3g} "
                     f"| {t['sgm_ratio']:.1f} |")
    return "\n".join(lines)


def scene_table(rows: list[dict[str, Any]], scene: str, tolerance: float) -> str:
    """Time and error of every method on one scene at one tolerance."""
    mine = sorted((r for r in rows if r["scene"] == scene and r["tolerance"] == tolerance),
                  key=lambda r: (not r["success"], r["total_s"] if np.isfinite(r["total_s"]) else math.inf))
    lines = ["| method | outcome | setup [ms] | solve [ms] | distance | penetration | distance to complementarity |",
             "|---|---|---|---|---|---|---|"]
    for r in mine:
        lines.append(f"| {r['method']} | {r['outcome']} | {1e3 * r['setup_s']:.3g} | {1e3 * r['solve_s']:.3g} "
                     f"| {r['distance']:.1e} | {r['penetration']:.1e} | {r['distance_complementarity']:.1e} |")
    return "\n".join(lines)


def fastest_table(rows: list[dict[str, Any]]) -> str:
    """Per scene and tolerance, the fastest successful method of each formulation."""
    groups = (("complementarity", ("complementarity",)), ("least_squares", ("least_squares",)), ("plain (Mx = b)", ("linear",)))
    lines = ["| scene | tolerance | " + " | ".join(g for g, _ in groups) + " |", "|---|---|" + "---|" * len(groups)]
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for tolerance in sorted({r["tolerance"] for r in rows}, reverse=True):
            cells = []
            for _, formulations in groups:
                ok = [r for r in rows if r["scene"] == scene and r["tolerance"] == tolerance and r["success"]
                      and r["formulation"] in formulations]
                best = min(ok, key=lambda r: r["total_s"], default=None)
                cells.append("none succeeded" if best is None else
                             f"{best['solver']}/{best['form']} {1e3 * best['total_s']:.3g} ms")
            lines.append(f"| {scene} | {tolerance:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def form_table(rows: list[dict[str, Any]]) -> str:
    """Per backend and formulation: how often each form succeeded, and the median over the runs
    where both did of time(primal)/time(contact) and distance(primal)/distance(contact)."""
    lines = ["| backend | formulation | primal success | contact success | median time primal/contact "
             "| median distance primal/contact |", "|---|---|---|---|---|---|"]
    index = {(r["scene"], r["tolerance"], r["solver"], r["formulation"], r["form"]): r for r in rows}
    for solver, formulation in dict.fromkeys((r["solver"], r["formulation"]) for r in rows if r["form"] in QP_FORMS):
        pairs: list[tuple[dict[str, Any], dict[str, Any]]] = []
        for sc, t in dict.fromkeys((r["scene"], r["tolerance"]) for r in rows):
            primal, contact = index.get((sc, t, solver, formulation, "primal")), index.get((sc, t, solver, formulation, "contact"))
            if primal is not None and contact is not None:
                pairs.append((primal, contact))
        if not pairs:
            continue
        both = [(p, c) for p, c in pairs if p["success"] and c["success"]]
        t_ratio = [p["total_s"] / c["total_s"] for p, c in both if c["total_s"] > 0]
        d_ratio = [max(p["distance"], 1e-16) / max(c["distance"], 1e-16) for p, c in both]
        primal_rate = np.mean([p["success"] for p, _ in pairs])
        contact_rate = np.mean([c["success"] for _, c in pairs])
        lines.append(f"| {solver} | {formulation} | {100 * primal_rate:.0f} % | {100 * contact_rate:.0f} % "
                     f"| {np.median(t_ratio) if t_ratio else math.nan:.2g} | {np.median(d_ratio) if d_ratio else math.nan:.2g} |")
    return "\n".join(lines)


SOLVER_STYLE = {
    "linear": ("k", "*"), "cg": ("tab:gray", "v"), "cg_euclidean": ("tab:brown", "1"), "bbpgd": ("tab:pink", "P"),
    "clarabel": ("tab:blue", "o"), "osqp": ("tab:orange", "s"), "piqp": ("tab:green", "D"), "proxqp": ("tab:red", "^"),
    "highs": ("tab:purple", "x"), "scs": ("tab:olive", "<"),
}


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    """Distance to the reference against total time (log–log): one panel per scene family
    (columns) and formulation (rows; the plain linear problem goes with least_squares), one
    marker per solver, one line per tolerance sweep (a method on one scene), solid for the primal
    form, dashed for the contact form. Failed runs are not drawn (they are in the CSV)."""
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    families = list(dict.fromkeys(r["family"] for r in rows))
    panel_rows = [("complementarity", ("complementarity",)), ("least_squares and linear", ("least_squares", "linear"))]
    fig = Figure(figsize=(5.2 * len(families), 4.4 * len(panel_rows)))
    axes = fig.subplots(len(panel_rows), len(families), squeeze=False, sharex=True, sharey=True)
    floor, ceiling = 1e-13, 10.0  # errors beyond are drawn at the edge (the CSV has the values)
    handles = {}
    for i, (title, formulations) in enumerate(panel_rows):
        for j, family in enumerate(families):
            ax = axes[i, j]
            mine = [r for r in rows if r["family"] == family and r["formulation"] in formulations]
            for (scene, label) in dict.fromkeys((r["scene"], r["method"]) for r in mine):
                sweep = sorted((r for r in mine if r["scene"] == scene and r["method"] == label),
                               key=lambda r: -r["tolerance"])
                pts = [(r["total_s"], min(max(r["distance"], floor), ceiling), r["success"]) for r in sweep
                       if np.isfinite(r["total_s"]) and np.isfinite(r["distance"]) and r["outcome"] != "time_limit"]
                if not pts:
                    continue
                solver, form = sweep[0]["solver"], sweep[0]["form"]
                color, marker = SOLVER_STYLE.get(solver, ("tab:cyan", "h"))
                t, d, ok = map(np.array, zip(*pts, strict=True))
                ax.plot(t, d, color=color, lw=0.8, alpha=0.6, ls="--" if form == "contact" else "-")
                ax.scatter(t[ok], d[ok], color=color, marker=marker, s=22, zorder=3)
                ax.scatter(t[~ok], d[~ok], facecolors="none", edgecolors=color, marker="o", s=40, zorder=3)
                handles[solver] = Line2D([], [], color=color, marker=marker, ls="")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_ylim(floor / 3, ceiling * 3)
            ax.grid(True, which="major", alpha=0.3)
            ax.set_title(f"{family}: {title}", fontsize=10)
            if i == len(panel_rows) - 1:
                ax.set_xlabel("time (setup + solve) [s]")
            if j == 0:
                ax.set_ylabel("‖x − x*‖_W / ‖x*‖_W")
    handles["failed check (hollow)"] = Line2D([], [], color="k", marker="o", markerfacecolor="none", ls="")
    handles["contact form (dashed)"] = Line2D([], [], color="k", ls="--")
    fig.legend(handles.values(), handles.keys(), loc="lower center", ncol=min(7, len(handles)), fontsize=9)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    fig.savefig(path, dpi=110)


def plot_scenes(cases: list[SceneCase], path: Path, max_cells: int = 1000) -> None:
    """Top views of the scenes (colonies up to ``max_cells`` cells): each rod drawn as a segment
    as thick as its diameter with round caps, coloured by orientation (planar scenes) or by
    height (3D scenes; higher cells drawn on top)."""
    from matplotlib import colormaps
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure

    shown = [c for c in cases if (c.n_cells or 0) <= max_cells and c.position_correction == 0]
    columns = min(4, len(shown))
    n_rows = -(-len(shown) // columns)
    fig = Figure(figsize=(3.6 * columns, 3.6 * n_rows))
    axes = fig.subplots(n_rows, columns, squeeze=False)
    for ax in axes.flat[len(shown):]:
        ax.set_visible(False)
    for ax, case in zip(axes.flat, shown, strict=False):  # the grid may have more panels than scenes
        cells = make_scene(case.generator, case.n_cells)
        half = 0.5 * cells.lengths[:, None] * cells.axes
        ends = np.stack([cells.centers - half, cells.centers + half], axis=1)[:, :, :2]
        z = cells.centers[:, 2]
        if np.ptp(z) > 0:
            colour = colormaps["viridis"]((z - z.min()) / np.ptp(z))
        else:
            colour = colormaps["hsv"]((np.arctan2(cells.axes[:, 1], cells.axes[:, 0]) % np.pi) / np.pi)
        rho = float(cells.radii.max())
        lo, hi = ends.reshape(-1, 2).min(axis=0) - 2 * rho, ends.reshape(-1, 2).max(axis=0) + 2 * rho
        centre, span = 0.5 * (lo + hi), float((hi - lo).max())
        ax.set_xlim(centre[0] - span / 2, centre[0] + span / 2)
        ax.set_ylim(centre[1] - span / 2, centre[1] + span / 2)
        ax.set_aspect("equal")
        width_in = ax.get_position().width * fig.get_figwidth()
        points_per_unit = 72.0 * width_in / span
        order = np.argsort(z, kind="stable")
        rods = order[cells.lengths[order] > 0]
        spheres = order[cells.lengths[order] == 0]  # zero-length segments are not drawn: discs
        ax.add_collection(LineCollection(list(ends[rods]), colors=colour[rods], capstyle="round",
                                         linewidths=2 * cells.radii[rods] * points_per_unit))
        ax.scatter(cells.centers[spheres, 0], cells.centers[spheres, 1], c=colour[spheres],
                   s=(2 * cells.radii[spheres] * points_per_unit) ** 2, linewidths=0)
        ax.set_title(f"{case.name} ({cells.n} cells)", fontsize=9)
        ax.tick_params(labelsize=7)
    fig.savefig(path, dpi=110)


# ------------------------------------------------------------------------------------------
# Command
# ------------------------------------------------------------------------------------------
def _select_scenes(names: list[str] | None, quick: bool) -> list[SceneCase]:
    if not names:
        return QUICK_SCENES if quick else DEFAULT_SCENES
    out = []
    for name in names:
        matches = [c for c in ALL_SCENES.values() if name in (c.name, c.family, c.generator)]
        if not matches:
            raise InvalidArgumentError(f"unknown scene {name!r}; known: {', '.join(ALL_SCENES)} "
                                       "(or a family: hand-made, colony_2d, colony_3d)")
        out += [m for m in matches if m not in out]
    return out


def warm_up_system() -> ContactSystem:
    """The small system each timed child solves once before its runs (a two-rod scene)."""
    cells = make_scene("two_rods")
    active, b = colliding(find_contacts(cells))
    return build_system(cells, active, b)


def read_csv(path: Path) -> list[dict[str, Any]]:
    """Rows of a CSV written by :func:`write_csv`, with numbers and flags parsed back."""
    numeric = {"tolerance", "setup_s", "solve_s", "total_s", "penetration", "complementarity", "duality_gap",
               "distance", "objective_gap", "distance_complementarity", "distance_linear", "momentum_change",
               "angular_momentum_change", "energy_change_relative"}
    flags = {"planar", "all_active", "converged", "accurate", "success"}
    with path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    for row in rows:
        for key in numeric:
            row[key] = float(row[key]) if row[key] not in ("", "None") else math.nan
        for key in flags:
            row[key] = row[key] == "True"
    return rows


def write_csv(rows: list[dict[str, Any]], path: Path) -> None:
    write_table(rows, path, COLUMNS, digits=6)


#: The files ``qpcontact compare`` writes in its folder.
OUTPUTS = ("solvers.csv", "solvers.png", "solvers_scenes.png", "solvers.md")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``qpcontact compare``."""
    parser.description = ("Solver comparison: every solver's error against its run time on colony snapshots and "
                          "hand-made scenes. Writes solvers.csv (every run), solvers.png (error against time), "
                          "solvers_scenes.png and solvers.md (summary tables) into --out. Ctrl-C stops and writes "
                          "what was done.")
    parser.add_argument("--scenes", type=comma_list(), metavar="LIST",
                        help=f"comma-separated scene names or families (default: the default set; known: "
                             f"{', '.join(ALL_SCENES)}; families: hand-made, colony_2d, colony_3d)")
    parser.add_argument("--solvers", type=comma_list(), metavar="LIST",
                        help="comma-separated solvers (default: every installed one, baselines included: "
                             f"{', '.join(available_solvers(include_baselines=True))})")
    parser.add_argument("--tolerances", type=comma_list(tolerance_type), metavar="LIST",
                        help="comma-separated solver tolerances [dimensionless, scaled units] (default: 1e-3,1e-6,1e-9; "
                             "--quick: 1e-3,1e-6)")
    parser.add_argument("--repeats", type=positive_int, default=None,
                        help="repeats per run; the median time is kept (default: 3; --quick: 1)")
    parser.add_argument("--time-limit", type=positive_float, default=5.0,
                        help="time limit per solve [s], passed to the backends that take one; a run is killed after "
                             "1.5× this plus a few seconds (default: 5)")
    add_output_arguments(parser, "compare", "the CSV, plots and tables")
    parser.add_argument("--quick", action="store_true", help="a small set: five small scenes, tolerances 1e-3 and 1e-6, "
                        "one repeat (about a minute)")
    parser.add_argument("--replot", type=Path, metavar="CSV",
                        help="only redraw solvers.png in --out from a CSV of an earlier run (no solving)")
    cluster.add_cluster_arguments(parser, local_by_default=False)


def run_command(args: argparse.Namespace) -> int:
    """``qpcontact compare``."""
    if args.replot:
        if not args.replot.is_file():
            raise InvalidArgumentError(f"{args.replot}: no such file")
        prepare_folder(args.out, ("solvers.png",), overwrite=args.overwrite)
        plot(read_csv(args.replot), args.out / "solvers.png")
        print(describe_written([args.out / "solvers.png"]))
        return 0
    cases = _select_scenes(args.scenes, args.quick)
    methods = all_methods(args.solvers)
    prepare_folder(args.out, OUTPUTS, overwrite=args.overwrite)
    from tqdm import tqdm

    tolerances = args.tolerances or ([1e-3, 1e-6] if args.quick else list(DEFAULT_TOLERANCES))
    repeats = args.repeats or (1 if args.quick else 3)
    started = datetime.now(UTC)
    scene_lines = []
    done: list[SceneCase] = []
    warm = warm_up_system()
    with cluster.client_if_asked(args) as client, \
            tqdm(total=len(cases) * len(methods) * len(tolerances), unit="run", dynamic_ncols=True) as bar:

        def runs() -> Iterator[tuple[Prepared, Method, float]]:
            """Each case's references (prepared here), then its runs (here, or as Dask tasks)."""
            for case in cases:
                bar.set_description(f"{case.name}: references")
                prepared = prepare(case)
                assert prepared.system is not None, f"{case.name}: nothing collides"
                done.append(case)
                k, n = prepared.system.shape
                scene_lines.append(f"| {case.name} | {prepared.cells.n} | {k} | {n} | {'yes' if prepared.system.planar else 'no'} "
                                   f"| {'yes' if prepared.all_active else 'no'} | {prepared.reference_residual:.1e} "
                                   f"| {1e3 * prepared.assemble_seconds:.3g} | {1e3 * prepared.reference_seconds:.3g} |")
                for method in methods:
                    dense_only = get_solver(method.solver).dense
                    for tolerance in tolerances:
                        bar.set_description(f"{case.name}: {method.label} {tolerance:g}")
                        if dense_only and n > DENSE_MAX_UNKNOWNS:
                            bar.update()
                            continue  # dense-only backends are not run on large scenes (stated in the report)
                        yield prepared, method, tolerance

        rows, interrupted = cluster.results_in_order(
            run_one, runs(), client=client, kwargs={"time_limit": args.time_limit, "repeats": repeats, "warm": warm},
            each=bar.update)
    finished = datetime.now(UTC)
    if not rows:
        print("qpcontact compare: interrupted before any run finished; nothing written", file=sys.stderr)
        return 130
    write_csv(rows, args.out / "solvers.csv")
    plot(rows, args.out / "solvers.png")
    plot_scenes(done, args.out / "solvers_scenes.png")
    summary = summarize(rows, args.time_limit)
    ran = [c for c in done if any(r["scene"] == c.name for r in rows)]
    largest = max(ran, key=lambda c: next((r["unknowns"] for r in rows if r["scene"] == c.name), 0)).name
    mid_tol = sorted(tolerances)[len(tolerances) // 2]
    text = "\n".join([
        f"# Solver comparison ({started:%Y-%m-%d %H:%M} to {finished:%H:%M} UTC)",
        "",
        *([f"**Interrupted (Ctrl-C) after {len(rows)} runs: the tables hold the runs that were done.**", ""]
          if interrupted else []),
        f"Machine: {platform.machine()}, {multiprocessing.cpu_count()} cores, Python {platform.python_version()}, "
        f"qpsolvers {qpsolvers.__version__}. Times are medians of up to {repeats} repeats (fewer once a run's repeats "
        f"took {REPEAT_BUDGET:g} s), time limit {args.time_limit:g} s per solve. Tolerances: "
        f"{', '.join(f'{t:g}' for t in tolerances)}.",
        "",
        "## Scenes",
        "",
        "| scene | cells | colliding contacts | unknowns | planar | all contacts active | reference KKT residual "
        "| assemble [ms] | references [ms] |",
        "|---|---|---|---|---|---|---|---|---|",
        *scene_lines,
        "",
        "## Summary per method",
        "",
        f"Success: converged (the solver's flag and the package's checks) and distance to the reference ≤ "
        f"max({ACCURACY_FACTOR:g}·tolerance, {ACCURACY_FLOOR:g}). SGM: shifted geometric mean of setup + solve time "
        f"(shift {1e3 * SGM_SHIFT:g} ms), unsuccessful runs counted at the time limit; ratio to the best.",
        "",
        markdown_table(summary),
        "",
        "## Fastest successful method per scene and tolerance",
        "",
        fastest_table(rows),
        "",
        "## Primal against contact form",
        "",
        form_table(rows),
        "",
        f"## Largest scene ({largest}) at tolerance {mid_tol:g}",
        "",
        scene_table(rows, largest, mid_tol),
        "",
    ])
    write_text(args.out / "solvers.md", text)
    print(text)
    print(describe_written(args.out / name for name in OUTPUTS))
    return 130 if interrupted else 0


def main(argv: list[str] | None = None) -> int:
    return run_standalone("qpcontact compare", add_arguments, run_command, argv)
