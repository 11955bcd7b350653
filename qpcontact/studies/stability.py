"""The stability report: every installed solver × formulation on the catalogue of stiff and
extreme cases (:mod:`qpcontact.studies.catalogue`), with and without the internal scaling.

``qpcontact stability [--cases PATTERNS] [--quick] [--out FOLDER]`` writes ``FOLDER/stability.csv``
(one row per case × solver × formulation × form × scaling, every measure) and
``FOLDER/stability.md`` (the case × solver matrix and the failures with their messages); the
default folder is ``./stability-out`` (``--out docs/data --overwrite`` updates the committed
report). Ctrl-C stops the report and writes the runs that were done.

Each run is classified as one of

- ``ok``: :func:`qpcontact.resolve` returned a converged result and every check below passed;
- ``refused``: the solver does not take that formulation or form (e.g. MPRGP on least squares),
  which it says before solving: not run, not a failure;
- ``error``: resolve raised a documented :class:`~qpcontact.errors.QPContactError` (for a solver
  that did not deliver, :class:`~qpcontact.errors.SolverFailedError`); its message is kept;
- ``wrong``: resolve returned a converged result that fails a check: silent garbage, a bug;
- ``crash``: resolve raised something that is not a QPContactError: a bug;
- ``timeout``: the run did not finish within the wall-clock guard (the backend ignored its time
  limit): a hang.

Checks of a converged result (all dimensionless, computed on the *scaled* system of the case, so
that runs with ``scale=False`` are measured the same way):

- every impulse finite;
- penetration ≤ the reference's + :data:`KKT_LIMIT`;
- distance ``‖x − x*‖_W/‖x*‖_W`` to the reference ``x*`` of the same formulation
  (:func:`qpcontact.resolve.reference_solution`; for the plain linear solve the
  minimum-norm solve at :data:`qpcontact.studies.harness.REFERENCE_TOLERANCE`) ≤
  :data:`DISTANCE_LIMIT`;
- relative duality gap and multiplier consistency (where the solver gives contact impulses)
  ≤ :data:`KKT_LIMIT` (the complementarity residual is reported, not checked: interior-point
  methods drive it down only like the square root of their tolerance, measured 1e-4–5e-4 on
  the jammed packings with distances to the reference below 1e-5);
- linear and angular momentum change ≤ :data:`KKT_LIMIT`;
- relative kinetic energy change ≤ :data:`KKT_LIMIT` (inelastic contact; skipped for cases with
  position correction, which legitimately adds energy to clear overlaps).

Every run happens in a child process killed after the guard
(:func:`qpcontact.studies.harness.guarded`), so no backend can hang the report. With
``--scheduler ADDRESS`` or ``--workers N`` the runs are Dask tasks
(:mod:`qpcontact.ensembles.cluster`), each still in its guarded child process with the same guard.
"""

from __future__ import annotations

import argparse
import fnmatch
import multiprocessing
import platform
import sys
import time
import traceback
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from ..cli import (
    add_output_arguments,
    comma_list,
    non_negative_int,
    on_off,
    positive_float,
    positive_int,
    run_standalone,
)
from ..ensembles import cluster
from ..errors import InvalidArgumentError, QPContactError
from ..io.outputs import describe_written, prepare_folder, write_text
from ..io.outputs import write_csv as write_table
from ..resolve import metrics, resolve
from ..solvers import DEFAULT_FORM, QP_FORMS, QP_FORMULATIONS, available_solvers, get_solver
from . import harness
from .catalogue import CATALOGUE
from .harness import Prepared
from .scenes import Scene

#: Solver tolerance of every run (dimensionless).
TOLERANCE = 1e-6
#: Largest accepted residual of the optimality conditions (penetration above the reference's,
#: complementarity, multiplier consistency, momentum, energy): 100 × the tolerance, the same
#: factor resolve's acceptance test uses.
KKT_LIMIT = 100 * TOLERANCE
#: Largest accepted distance to the reference solution, ``‖x − x*‖_W/‖x*‖_W``: what resolve's
#: acceptance test guarantees. For complementarity (objective ½‖ỹ‖², strongly convex), a
#: feasible ỹ = B̃ᵀλ̃ with λ̃ ≥ 0 has ``‖ỹ − ỹ*‖² ≤ 2 λ̃ᵀ(B̃ỹ − b̃)``, so a relative duality gap
#: ≤ KKT_LIMIT bounds the relative distance by ``sqrt(2·KKT_LIMIT)`` = 1.4e-2 at tolerance 1e-6
#: (docs/stability.md). The measured distances are reported; most are far smaller.
DISTANCE_LIMIT = float(np.sqrt(2 * KKT_LIMIT))
#: Runs faster than this [s] are repeated (``--repeats``) and timed by their median.
REPEAT_BELOW = 1.0
#: Outcomes, best first.
OUTCOMES = ("ok", "refused", "error", "wrong", "crash", "timeout")
#: Cases of ``--quick``: the hardest of most families, none of the large ones.
QUICK_CASES = ("mass_ratio_1e-08", "aspect_10000", "growth_inertia_1e+08", "parallel_1e-12", "crossing", "overlap_mixed",
               "velocity_mixed", "units_um_pg_s", "jammed_disks", "duplicate_contacts")


def prepare(case: Scene, seed: int = 0, size: dict[str, Any] | None = None) -> Prepared:
    """Build the case's scene and system, and compute the references and condition estimate
    (:func:`qpcontact.studies.harness.prepare`)."""
    cells = case.make(seed=seed, **(size or {}))
    contacts = case.contacts(cells) if case.contacts else None
    opts = {k: v for k, v in case.options.items() if k in ("position_correction", "dt")}
    return harness.prepare(case, cells, contacts, condition=True, **opts)


def runs(solvers: list[str], formulations: list[str], forms: list[str]) -> list[tuple[str, str, str]]:
    """(solver, formulation, form) triples: a plain solver (formulation ``"linear"``) once in its
    default form, every other solver with every formulation and form asked for, those it does not
    take included (their documented error is part of the report)."""
    out: list[tuple[str, str, str]] = []
    for solver in solvers:
        spec = get_solver(solver)
        if spec.plain:
            out.append((solver, *spec.plan("linear")))
            continue
        for formulation in formulations:
            for form in forms:
                out.append((solver, formulation, DEFAULT_FORM[formulation] if form == "auto" else form))
    return out


def check(prep: Prepared, formulation: str, impulses: np.ndarray, contact_impulses: np.ndarray | None) -> dict[str, Any]:
    """Every measure of a converged answer (on the case's scaled system) and the checks that
    failed (``failed``: list of names)."""
    system = prep.system
    assert system is not None, "only cases with colliding contacts have answers to check"
    y = system.from_impulses(impulses)
    measures: dict[str, Any] = {"penetration": metrics.penetration(system, y),
                                "distance": metrics.distance(y, prep.references[formulation])}
    failed = []
    if not (np.all(np.isfinite(impulses)) and (contact_impulses is None or np.all(np.isfinite(contact_impulses)))):
        return {**measures, "failed": ["finite"]}
    if contact_impulses is not None:
        lam = system.from_contact_impulses(contact_impulses)
        measures["multiplier_consistency"] = metrics.multiplier_consistency(system, y, lam)
        if formulation == "complementarity":
            measures["complementarity"] = metrics.complementarity_residual(system, y, lam)
            measures["duality_gap"] = metrics.duality_gap(system, y, lam)
    physics = metrics.physics(prep.cells, system, impulses, contact_impulses)
    measures.update(momentum_change=physics["momentum_change"], angular_momentum_change=physics["angular_momentum_change"],
                    energy_change_relative=physics["energy_change_relative"])
    if measures["penetration"] > prep.reference_penetration[formulation] + KKT_LIMIT:
        failed.append("penetration")
    if measures["distance"] > DISTANCE_LIMIT:
        failed.append("distance")
    for name in ("multiplier_consistency", "duality_gap", "momentum_change", "angular_momentum_change"):
        if measures.get(name, 0.0) > KKT_LIMIT:
            failed.append(name)
    if not prep.case.options.get("position_correction") and measures["energy_change_relative"] > KKT_LIMIT:
        failed.append("energy")
    measures["failed"] = failed
    return measures


def run_one(prep: Prepared, solver: str, formulation: str, form: str, scale: bool, time_limit: float,
            repeats: int = 1) -> dict[str, Any]:
    """Resolve the case and classify the outcome (see the module docstring). A run that
    converges in under :data:`REPEAT_BELOW` seconds is repeated ``repeats`` times in all and its
    times are the medians."""
    row: dict[str, Any] = {"case": prep.case.name, "family": prep.case.family, "solver": solver,
                           "formulation": formulation, "form": form, "scale": scale}
    refused = refusal(solver, formulation, form)
    if refused:
        return {**row, "outcome": "refused", "seconds": 0.0, "message": refused}
    kwargs: dict[str, Any] = {"formulation": formulation, "form": form, **prep.case.options}
    t0 = time.perf_counter()
    try:
        result = resolve(prep.cells, solver=solver, contacts=prep.contacts, tolerance=TOLERANCE, time_limit=time_limit,
                         scale=scale, **kwargs)
    except QPContactError as exc:
        return {**row, "outcome": "error", "seconds": time.perf_counter() - t0,
                "message": f"{type(exc).__name__}: {exc}"}
    except Exception as exc:  # noqa: BLE001 - anything else is a bug, reported as such
        return {**row, "outcome": "crash", "seconds": time.perf_counter() - t0,
                "message": f"{type(exc).__name__}: {exc} | {traceback.format_exc(limit=3)}"}
    totals, solves = [result.times["total"]], [result.times["solve"]]
    while result.converged and totals[0] < REPEAT_BELOW and len(totals) < repeats:
        again = resolve(prep.cells, solver=solver, contacts=prep.contacts, tolerance=TOLERANCE, time_limit=time_limit,
                        scale=scale, **kwargs)
        totals.append(again.times["total"])
        solves.append(again.times["solve"])
    row.update(seconds=float(np.median(totals)), solve_seconds=float(np.median(solves)), repeats=len(totals),
               status=result.status, iterations=result.iterations)
    if prep.system is None:
        return {**row, "outcome": "ok" if result.status == "no_contact" else "wrong", "message": "no colliding contact"}
    measures = check(prep, formulation, result.impulses, result.contact_impulses)
    failed = measures.pop("failed")
    row.update(measures)
    row["outcome"] = "wrong" if failed else "ok"
    row["message"] = f"converged, but fails: {', '.join(failed)}" if failed else ""
    return row


def refusal(solver: str, formulation: str, form: str) -> str:
    """Why the solver does not take this formulation and form ("" if it does)."""
    try:
        get_solver(solver).plan(formulation, form)
    except InvalidArgumentError as exc:
        return str(exc)
    return ""


def guarded(prep: Prepared, solver: str, formulation: str, form: str, scale: bool, time_limit: float,
            guard: float, repeats: int = 1) -> dict[str, Any]:
    """:func:`run_one` in a child process (:func:`qpcontact.studies.harness.guarded`), killed
    after ``guard`` seconds (outcome ``timeout``); a refused combination is not run at all."""
    refused = refusal(solver, formulation, form)
    if refused:
        return {"case": prep.case.name, "family": prep.case.family, "solver": solver, "formulation": formulation,
                "form": form, "scale": scale, "outcome": "refused", "seconds": 0.0, "message": refused}
    t0 = time.perf_counter()
    status, payload = harness.guarded(run_one, (prep, solver, formulation, form, scale, time_limit, repeats), guard,
                                      preload=("qpcontact.studies.stability",))
    base = {"case": prep.case.name, "family": prep.case.family, "solver": solver, "formulation": formulation,
            "form": form, "scale": scale}
    elapsed = time.perf_counter() - t0
    if status == "ok":
        return {**base, **payload}
    if status == "timeout":
        return {**base, "outcome": "timeout", "seconds": elapsed,
                "message": f"no answer within the {guard:g} s guard (time_limit {time_limit:g} s was not honoured)"}
    if status == "crashed":
        return {**base, "outcome": "crash", "seconds": elapsed, "message": f"child process died (exit code {payload})"}
    return {**base, "outcome": "crash", "seconds": elapsed, "message": str(payload)}


# ------------------------------------------------------------------------------------------
# Output
# ------------------------------------------------------------------------------------------
CSV_FIELDS = ("case", "family", "solver", "formulation", "form", "scale", "outcome", "seconds", "solve_seconds", "repeats",
              "status", "iterations", "penetration", "distance", "complementarity", "duality_gap", "multiplier_consistency",
              "momentum_change", "angular_momentum_change", "energy_change_relative", "message")


def write_csv(rows: list[dict[str, Any]], path: Path) -> None:
    write_table(rows, path, CSV_FIELDS, digits=3)


def _column(row: dict[str, Any]) -> str:
    if row["formulation"] == "linear":
        return row["solver"]
    short = {"complementarity": "C", "least_squares": "LS"}[row["formulation"]]
    return f"{row['solver']} {short}" + ("" if row["form"] == DEFAULT_FORM[row["formulation"]] else f" ({row['form']})")


def _cell(row: dict[str, Any]) -> str:
    outcome = row["outcome"]
    if outcome == "ok":
        return f"ok {row['seconds'] * 1e3:.3g}ms"
    if outcome == "wrong":
        return "**WRONG** " + row["message"].removeprefix("converged, but fails: ")
    return {"refused": "refused", "error": "error", "crash": "**CRASH**", "timeout": "**TIMEOUT**"}[outcome]


def matrix_markdown(rows: list[dict[str, Any]], preps: dict[str, Prepared], scale: bool) -> str:
    """The case × solver matrix of one scaling."""
    rows = [r for r in rows if r["scale"] == scale]
    columns = list(dict.fromkeys(_column(r) for r in rows))
    cases = list(dict.fromkeys(r["case"] for r in rows))
    table = {(r["case"], _column(r)): _cell(r) for r in rows}
    lines = ["| case | K × n | cond₁(Ã) | " + " | ".join(columns) + " |", "|---" * (len(columns) + 3) + "|"]
    for case in cases:
        prep = preps[case]
        shape = "×".join(map(str, prep.system.shape)) if prep.system is not None else "0"
        cond = "singular" if prep.condition is None else f"{prep.condition:.1e}"
        lines.append(f"| {case} | {shape} | {cond} | " + " | ".join(table.get((case, c), "") for c in columns) + " |")
    return "\n".join(lines)


def summary_markdown(rows: list[dict[str, Any]]) -> str:
    """Per solver column and scaling: counts of each outcome, median time and distance of the
    correct answers."""
    columns = list(dict.fromkeys(_column(r) for r in rows))
    kinds = " / ".join(OUTCOMES)
    lines = [f"| solver | scaled: {kinds} | median ms | median distance | unscaled: {kinds} | median ms "
             "| median distance |", "|---|---|---|---|---|---|---|"]
    for col in columns:
        parts = [col]
        for scale in (True, False):
            sel = [r for r in rows if _column(r) == col and r["scale"] == scale]
            counts = " / ".join(str(sum(r["outcome"] == o for r in sel)) for o in OUTCOMES)
            good = [r for r in sel if r["outcome"] == "ok"]
            ms = f"{np.median([r['seconds'] for r in good]) * 1e3:.3g}" if good else "–"
            dist = f"{np.median([r['distance'] for r in good]):.1e}" if good else "–"
            parts += [counts, ms, dist]
        lines.append("| " + " | ".join(parts) + " |")
    return "\n".join(lines)


def failures_markdown(rows: list[dict[str, Any]]) -> str:
    """Every run that is neither ``ok`` nor ``refused``, with its message (one line)."""
    lines = ["| case | solver | scaled | outcome | message |", "|---|---|---|---|---|"]
    for r in rows:
        if r["outcome"] not in ("ok", "refused"):
            message = " ".join(str(r.get("message", "")).split())[:220].replace("|", "\\|")
            lines.append(f"| {r['case']} | {_column(r)} | {'yes' if r['scale'] else 'no'} | {r['outcome']} | {message} |")
    return "\n".join(lines)


def condition_markdown(preps: dict[str, Prepared]) -> str:
    """Per case: ``cond₁(Ã)`` and what estimating it costs on top of the plain linear solve."""
    lines = ["| case | K × n | cond₁(Ã) | linear solve ms | with estimate ms |", "|---|---|---|---|---|"]
    for name, prep in preps.items():
        if prep.system is None:
            continue
        cond = "singular (LU failed, LSMR used)" if prep.condition is None else f"{prep.condition:.2e}"
        lines.append(f"| {name} | {'×'.join(map(str, prep.system.shape))} | {cond} | {prep.linear_seconds * 1e3:.3g} "
                     f"| {prep.condition_seconds * 1e3:.3g} |")
    return "\n".join(lines)


def write_markdown(rows: list[dict[str, Any]], preps: dict[str, Prepared], path: Path, header: str) -> None:
    """``stability.md``: the summary, the condition estimates, the matrices and the failures."""
    text = [header, "## Summary per solver\n", summary_markdown(rows), "\n## Condition estimates (single runs)\n",
            condition_markdown(preps), "\n## Scaled (default)\n", matrix_markdown(rows, preps, True)]
    if any(not r["scale"] for r in rows):
        text += ["\n## Unscaled (`scale=False`)\n", matrix_markdown(rows, preps, False)]
    text += ["\n## Every run that is not ok (refused combinations left out)\n", failures_markdown(rows), ""]
    write_text(path, "\n".join(text))


#: Cases and ε values of the regularization study (``--regularization``).
REGULARIZATION_CASES = ("mass_ratio_1e-08", "aspect_10000", "growth_inertia_1e-08", "velocity_mixed", "jammed_fcc",
                        "duplicate_contacts")
REGULARIZATIONS = (0.0, 1e-9, 1e-6, 1e-3)


def regularization_markdown(solvers: tuple[str, ...] = ("clarabel", "osqp"), seed: int = 0) -> str:
    """Distance to the reference of least_squares answers for several ε (``regularization``);
    ``error`` where resolve rejected the answer."""
    lines = ["| case | solver | " + " | ".join(f"ε = {e:g}" for e in REGULARIZATIONS) + " |",
             "|---" * (len(REGULARIZATIONS) + 2) + "|"]
    for name in REGULARIZATION_CASES:
        prep = prepare(CATALOGUE[name], seed)
        for solver in solvers:
            cells = []
            for eps in REGULARIZATIONS:
                result = resolve(prep.cells, solver=solver, formulation="least_squares", contacts=prep.contacts,
                                 tolerance=TOLERANCE, regularization=eps, on_failure="return", **prep.case.options)
                if result.converged:
                    cells.append(f"{check(prep, 'least_squares', result.impulses, result.contact_impulses)['distance']:.1e}")
                else:
                    cells.append("error")
            lines.append(f"| {name} | {solver} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``qpcontact stability``."""
    parser.description = ("Run every installed solver × formulation on the catalogue of stiff and extreme cases, with "
                          "and without the internal scaling, and classify each run: ok, refused (the solver does not "
                          "take that formulation), error, wrong, crash, timeout. Writes stability.csv and stability.md "
                          "into --out. Ctrl-C stops and writes what was done.")
    parser.add_argument("--cases", type=comma_list(), default=["*"], metavar="PATTERNS",
                        help="comma-separated case names or fnmatch patterns (default: all; --quick: "
                             f"{len(QUICK_CASES)} cases); known: {', '.join(CATALOGUE)}")
    parser.add_argument("--solvers", type=comma_list(), default=available_solvers(), metavar="LIST",
                        help=f"comma-separated solver names (default: every installed one: {', '.join(available_solvers())})")
    parser.add_argument("--formulations", type=comma_list(choices=QP_FORMULATIONS), default=list(QP_FORMULATIONS),
                        metavar="LIST", help="comma-separated formulations of the QP solvers (plain solvers always run "
                        f"the plain problem) (default: {','.join(QP_FORMULATIONS)})")
    parser.add_argument("--forms", type=comma_list(choices=("auto", *QP_FORMS)), default=None, metavar="LIST",
                        help="comma-separated QP forms (default: primal,contact; --quick: auto, each formulation's "
                             "default)")
    parser.add_argument("--scaling", type=comma_list(on_off), default=None, metavar="LIST",
                        help="the internal scaling: on, off or on,off (default: on,off; --quick: on)")
    parser.add_argument("--time-limit", type=positive_float, default=20.0,
                        help="solver time limit [s], where the solver takes one (default: 20)")
    parser.add_argument("--guard", type=positive_float, default=60.0,
                        help="wall-clock limit of one run [s]; a run still going is killed (default: 60)")
    parser.add_argument("--seed", type=non_negative_int, default=0, help="random seed of the cases (default: 0)")
    parser.add_argument("--repeats", type=positive_int, default=None,
                        help=f"repeats of runs faster than {REPEAT_BELOW:g} s, median time kept (default: 3; --quick: 1)")
    parser.add_argument("--quick", action="store_true", help=f"{len(QUICK_CASES)} cases, default forms, scaling on, "
                        "one repeat (a minute or two)")
    add_output_arguments(parser, "stability", "stability.csv and stability.md")
    parser.add_argument("--regularization", action="store_true",
                        help="only the ε study: least_squares distance to the reference for several ε "
                             "(stability_regularization.md)")
    cluster.add_cluster_arguments(parser, local_by_default=False)


def run_command(args: argparse.Namespace) -> int:
    """``qpcontact stability``: exit status 1 if any run was wrong, crashed or timed out."""
    outputs = ("stability_regularization.md",) if args.regularization else ("stability.csv", "stability.md")
    names = [name for name in CATALOGUE if any(fnmatch.fnmatch(name, p) for p in args.cases)
             and (not args.quick or args.cases != ["*"] or name in QUICK_CASES)]
    if not names:
        raise InvalidArgumentError(f"no case matches {','.join(args.cases)!r}; known: {', '.join(CATALOGUE)}")
    forms = args.forms or (["auto"] if args.quick else ["primal", "contact"])
    triples = runs(args.solvers, args.formulations, forms)  # an unknown or uninstalled solver: a named error
    prepare_folder(args.out, outputs, overwrite=args.overwrite)
    if args.regularization:
        out = write_text(args.out / outputs[0], f"# least_squares: distance to the reference against ε (seed {args.seed}, "
                         f"tolerance {TOLERANCE:g})\n\n" + regularization_markdown(seed=args.seed) + "\n")
        print(describe_written([out]))
        return 0

    from tqdm import tqdm

    cases = [CATALOGUE[name] for name in names]
    scalings = args.scaling or ([True] if args.quick else [True, False])
    repeats = args.repeats or (1 if args.quick else 3)
    preps: dict[str, Prepared] = {}
    started = datetime.now(UTC)
    total = len(cases) * len(triples) * len(scalings)
    with cluster.client_if_asked(args) as client, tqdm(total=total, unit="run") as bar:

        def calls() -> Iterator[tuple[Prepared, str, str, str, bool]]:
            for case in cases:
                bar.set_description(case.name)
                prep = preps[case.name] = prepare(case, args.seed)
                for scale in scalings:
                    for solver, formulation, form in triples:
                        yield prep, solver, formulation, form, scale

        rows, _ = cluster.results_in_order(
            guarded, calls(), client=client,
            kwargs={"time_limit": args.time_limit, "guard": args.guard, "repeats": repeats}, each=bar.update)
    interrupted = len(rows) < total
    header = (f"# Stability run\n\n{started:%Y-%m-%d %H:%M} UTC, {platform.node()} ({multiprocessing.cpu_count()} cores, "
              f"{platform.processor() or platform.machine()}), seed {args.seed}, tolerance {TOLERANCE:g}, time limit "
              f"{args.time_limit:g} s, guard {args.guard:g} s. Times (wall clock of one resolve call, detection to checks) are "
              f"medians of {repeats} repeats for runs under {REPEAT_BELOW:g} s, single runs above.\n"
              + (f"\n**Interrupted (Ctrl-C) after {len(rows)} of {total} runs: the tables hold the runs that were done.**\n"
                 if interrupted else ""))
    if rows:
        write_csv(rows, args.out / "stability.csv")
        write_markdown(rows, {name: prep for name, prep in preps.items() if any(r["case"] == name for r in rows)},
                       args.out / "stability.md", header)
    counts = {o: sum(r["outcome"] == o for r in rows) for o in OUTCOMES}
    print(f"{len(rows)} runs: " + ", ".join(f"{v} {k}" for k, v in counts.items()))
    print(describe_written([args.out / name for name in outputs] if rows else []))
    if interrupted:
        print(f"qpcontact stability: interrupted after {len(rows)} of {total} runs", file=sys.stderr)
        return 130
    return 0 if counts["wrong"] == counts["crash"] == counts["timeout"] == 0 else 1


def main(argv: list[str] | None = None) -> int:
    return run_standalone("qpcontact stability", add_arguments, run_command, argv)
